"""Baum-Welch (EM) engine for a full-covariance Gaussian HMM over several recordings.

The template follows ``sklearn.mixture``: initialise, E-step, M-step, objective, convergence
test, ``n_init`` restarts keeping the best objective.

The objective is a penalised log-likelihood: the regularisation ``reg_covar`` is a prior on
every state covariance (:func:`covariance_prior_scale`, :func:`log_covariance_prior`), and the
M-step is its exact maximiser, so that every EM iteration raises the objective (up to
round-off). Adding ``reg_covar`` to the covariances after a maximum-likelihood M-step, as
``sklearn.mixture`` does, optimises no fixed function: with nearly collinear columns the
log-likelihood then falls by up to 1e-5 (relative) in some iterations.

The data are held once, as augmented columns (:class:`Columns`). The E-step works block by
block, a block holding whole consecutive recordings of about one cache-sized chunk of rows:

1. the emission log-densities of all states, one BLAS product per chunk
   (:func:`~skhmmgmr._gaussian.stack_gaussians`), scaled to a maximum of one per row and
   exponentiated in one compiled pass (:func:`~skhmmgmr._kernels.scaled_densities`), which
   skips the exponential where its value is known (one at the row's largest, zero below the
   underflow);
2. the compiled forward and backward recursions (:mod:`skhmmgmr._kernels`), which also give
   the posteriors and the terms of the expected transitions;
3. the expected transitions as one product, and the weighted moments of all states as one
   product of the posteriors with the pairwise products of the columns
   (:class:`~skhmmgmr._gaussian.MomentSums`), while the block's rows are still in cache.

An iteration reads the data once and holds no array of the size of the data besides the
posteriors of one block. The moments of one state (the heaviest of the previous E-step) are
those of all rows minus the others': every row's posteriors sum to one, so with K=2 only one
state's products are computed.

The estimator talks to this module only through :class:`Columns`, :func:`fit_hmm`,
:func:`score_hmm` and :class:`HMMParameters`.
"""

from dataclasses import dataclass, field, replace

import numpy as np
from sklearn.cluster import KMeans, kmeans_plusplus
from sklearn.utils import check_random_state
from threadpoolctl import threadpool_limits

from ._gaussian import (
    MomentSums,
    NotPositiveDefiniteError,
    augmented_columns,
    chunk_size_for,
    compute_precision_cholesky,
    gaussians_from_moments,
    split_moments,
    stack_gaussians,
)
from ._kernels import backward_posteriors, forward, scaled_densities

INIT_METHODS = ("kmeans", "k-means++", "random", "random_from_data")

# A state whose expected number of rows falls below this keeps its previous emission
# parameters: less than one row of posterior mass cannot define a Gaussian, and freezing the
# state (instead of re-seeding it) keeps the log-likelihood non-decreasing.
MIN_STATE_WEIGHT = 1.0

# Consecutive short recordings are grouped into blocks of about this many rows.
BLOCK_ROWS = 8192

# The k-means initialisations cluster an evenly spaced sample of at most this many rows;
# every row then joins its nearest centre.
INIT_SAMPLE_ROWS = 100_000

# Below this many values (rows x columns) KMeans runs on one OpenMP thread.
SMALL_KMEANS_SIZE = 1_000_000


@dataclass
class HMMParameters:
    """Parameters of a Gaussian HMM (in the engine's working units)."""

    startprob: np.ndarray
    transmat: np.ndarray
    means: np.ndarray
    covariances: np.ndarray
    precisions_chol: np.ndarray = field(default=None)

    def __post_init__(self):
        if self.precisions_chol is None:
            self.precisions_chol = compute_precision_cholesky(self.covariances)

    @property
    def n_states(self):
        return self.means.shape[0]


@dataclass
class EMResult:
    """Outcome of one EM run.

    ``history`` holds the log-likelihood of the parameters in force before each M-step and,
    last, that of the returned parameters; ``objective_history`` the penalised log-likelihood
    (log-likelihood plus :func:`log_covariance_prior`) of the same parameters, which EM
    maximises: it is non-decreasing up to round-off. With ``reg_covar=0`` both are equal.
    """

    parameters: HMMParameters
    log_likelihood: float
    history: list
    n_iter: int
    converged: bool
    objective: float = None
    objective_history: list = None

    def __post_init__(self):
        # Engines without a prior (the benchmarks' peers) report the log-likelihood alone.
        if self.objective is None:
            self.objective = self.log_likelihood
        if self.objective_history is None:
            self.objective_history = list(self.history)


@dataclass
class _Statistics:
    """Expected sufficient statistics of one E-step, moments about ``shift``."""

    log_likelihood: float
    start_counts: np.ndarray
    transition_counts: np.ndarray
    state_weights: np.ndarray
    first_moments: np.ndarray
    second_moments: np.ndarray
    shift: np.ndarray


@dataclass
class Columns:
    """The data as the engine reads them: the rows of ``X - shift`` as columns, plus ones.

    Attributes
    ----------
    values : ndarray of shape (n_features + 1, n_samples)
        C-contiguous; the last row is ones (see :func:`~skhmmgmr._gaussian.augmented_columns`).
    shift : ndarray of shape (n_features,)
        Point subtracted from every row; moments are taken about it, so it should be near the
        data (the mean), where the raw second moments lose no significant digits.
    """

    values: np.ndarray
    shift: np.ndarray

    @classmethod
    def from_rows(cls, X):
        """Columns of ``X`` (n_samples, n_features) about its column means (a copy)."""
        X = np.asarray(X, dtype=float)
        shift = X.mean(axis=0) if X.shape[0] else np.zeros(X.shape[1])
        return cls(augmented_columns(X, shift), shift)

    @classmethod
    def standardized(cls, *blocks):
        """Columns of ``hstack(blocks)``, each column standardised, built without the stack.

        Returns ``(columns, center, scale)``: the column means and standard deviations (a
        constant column keeps scale 1). Only the columns are allocated at the size of the
        data; the standardisation runs in place, one column at a time.
        """
        n_samples = blocks[0].shape[0]
        n_features = sum(block.shape[1] for block in blocks)
        values = np.empty((n_features + 1, n_samples))
        row = 0
        for block in blocks:
            values[row : row + block.shape[1]] = block.T
            row += block.shape[1]
        values[n_features] = 1.0
        center, scale = np.empty(n_features), np.empty(n_features)
        for i in range(n_features):
            column = values[i]
            center[i] = column.mean()
            column -= center[i]
            spread = np.sqrt(np.dot(column, column) / n_samples)
            scale[i] = spread if spread > 1e-12 * max(abs(center[i]), 1.0) else 1.0
            column /= scale[i]
        return cls(values, np.zeros(n_features)), center, scale

    @property
    def n_features(self):
        return self.values.shape[0] - 1

    @property
    def n_samples(self):
        return self.values.shape[1]

    def rows(self, index=slice(None)):
        """Rows ``index`` of ``X - shift``, shape (n_rows, n_features) (a copy)."""
        return np.ascontiguousarray(self.values[: self.n_features, index].T)


def _blocks(recordings, max_rows):
    """Group consecutive recordings into blocks of at most ``max_rows`` rows.

    A recording longer than ``max_rows`` forms a block of its own. Returns ``(start, stop,
    starts, stops)`` tuples with the recording bounds relative to ``start``.
    """
    starts, stops = np.asarray(recordings.starts), np.asarray(recordings.stops)
    blocks = []
    first = 0
    n_recordings = len(starts)
    while first < n_recordings:
        last = first + 1
        while last < n_recordings and stops[last] - starts[first] <= max_rows:
            last += 1
        origin = int(starts[first])
        blocks.append(
            (
                origin,
                int(stops[last - 1]),
                [int(v) - origin for v in starts[first:last]],
                [int(v) - origin for v in stops[first:last]],
            )
        )
        first = last
    return blocks


class _Engine:
    """Per-fit constants: the columns, the recording blocks, the chunk size, and the moments
    of all rows."""

    def __init__(self, X, recordings, n_states, chunk_size=None, block_size=None):
        self.data = X if isinstance(X, Columns) else Columns.from_rows(X)
        self.shift = self.data.shift
        self.n_states = n_states
        self.step = chunk_size_for(n_states * self.data.n_features, chunk_size)
        self.blocks = [
            (start, stop, np.asarray(starts, dtype=np.int64), np.asarray(stops, dtype=np.int64))
            for start, stop, starts, stops in _blocks(
                recordings, block_size or max(self.step, BLOCK_ROWS)
            )
        ]
        self._totals = None
        self._chunk_bounds = {}
        # State whose moments the next E-step takes as the total minus the others'.
        self.remainder = None

    def chunks(self, start=0, stop=None):
        """``(lo, hi, columns[:, start + lo : start + hi])`` for chunks of rows ``start:stop``."""
        values = self.data.values
        stop = values.shape[1] if stop is None else stop
        # Every E-step walks the same blocks twice: their bounds are computed once per fit.
        bounds = self._chunk_bounds.get((start, stop))
        if bounds is None:
            n_chunks = max(-(-(stop - start) // self.step), 1)
            edges = np.linspace(0, stop - start, n_chunks + 1).astype(int).tolist()
            bounds = list(zip(edges[:-1], edges[1:], strict=True))
            self._chunk_bounds[start, stop] = bounds
        for lo, hi in bounds:
            yield lo, hi, values[:, start + lo : start + hi]

    def frames(self, stacked, start, stop):
        """Emission likelihoods of rows ``start:stop`` scaled to a maximum of one per row.

        Returns ``(frames, log_scale)``: frames of shape (rows, n_states), C-contiguous, and
        the sum over the rows of the logarithms of the scales.
        """
        factors, norms = stacked
        frames = np.empty((stop - start, self.n_states))
        top = np.empty(stop - start)
        for lo, hi, chunk in self.chunks(start, stop):
            scaled_densities(factors @ chunk, norms[:, 0], frames[lo:hi], top[lo:hi])
        return frames, float(top.sum())

    @property
    def totals(self):
        """Augmented moments of all rows (computed once)."""
        if self._totals is None:
            n_columns = self.data.values.shape[0]
            sums = MomentSums(1, n_columns)
            for lo, hi, _ in self.chunks():
                sums.add(np.ones((1, hi - lo)), self.data.values, lo)
            self._totals = sums.result()[0]
        return self._totals


def _raise_impossible():
    raise FloatingPointError(
        "the forward pass underflowed: a recording is impossible under the current "
        "transition matrix"
    )


# The EM keeps the forward pass of all rows (frames and forward variables) and runs the
# backward pass only once the log-likelihood shows that the M-step is needed, when the two
# arrays take at most this many values; above, both passes run block by block and the E-step
# that detects convergence is a full one.
KEPT_FORWARD_VALUES = 8_000_000


def _forward_blocks(engine, params):
    """Forward pass block by block: ``(block, frames, alpha, scale, log_likelihood)``."""
    stacked = stack_gaussians(params.means, params.precisions_chol, engine.shift)
    for block in engine.blocks:
        start, stop, rec_starts, rec_stops = block
        frames, log_scale = engine.frames(stacked, start, stop)
        alpha, scale = np.empty_like(frames), np.empty(stop - start)
        log_likelihood = forward(
            frames,
            rec_starts,
            rec_stops,
            params.startprob,
            params.transmat,
            alpha,
            scale,
            lazy=True,
        )
        if log_likelihood == -np.inf:
            _raise_impossible()
        yield block, frames, alpha, scale, log_scale + log_likelihood


class _Expectations:
    """Backward pass block by block, accumulating the sufficient statistics."""

    def __init__(self, engine, params):
        self.engine, self.params = engine, params
        n_states = params.n_states
        self.accumulated = [k for k in range(n_states) if k != engine.remainder]
        self.start_counts = np.zeros(n_states)
        self.transition_sums = np.zeros((n_states, n_states))
        self.sums = MomentSums(n_states, engine.data.values.shape[0], states=self.accumulated)

    def add(self, block, frames, alpha, scale):
        (start, stop, rec_starts, rec_stops), n_states = block, self.params.n_states
        posteriors, weighted = np.empty((n_states, stop - start)), np.empty_like(frames)
        backward_posteriors(
            frames, rec_starts, rec_stops, self.params.transmat, alpha, scale, posteriors, weighted
        )
        # weighted is zero at every recording's first row: no term crosses recordings.
        self.transition_sums += alpha[:-1].T @ weighted[1:]
        self.start_counts += posteriors[:, rec_starts].sum(axis=1)
        for lo, hi, _ in self.engine.chunks(start, stop):
            self.sums.add(posteriors[:, lo:hi], self.engine.data.values, start + lo)

    def statistics(self, log_likelihood):
        engine, remainder = self.engine, self.engine.remainder
        moments = self.sums.result()
        if remainder is not None:
            moments[remainder] = engine.totals - moments[self.accumulated].sum(axis=0)
        weights, first, second = split_moments(moments)
        engine.remainder = int(np.argmax(weights))
        return _Statistics(
            log_likelihood,
            self.start_counts,
            self.transition_sums * self.params.transmat,
            weights.copy(),
            first.copy(),
            second.copy(),
            engine.shift,
        )


def e_step(engine, params):
    """Forward-backward over every recording, accumulating the sufficient statistics."""
    expectations, log_likelihood = _Expectations(engine, params), 0.0
    for block, frames, alpha, scale, block_log_likelihood in _forward_blocks(engine, params):
        log_likelihood += block_log_likelihood
        expectations.add(block, frames, alpha, scale)
    return expectations.statistics(log_likelihood)


def _e_step_unless(engine, params, is_last):
    """``(log_likelihood, statistics)``; the statistics are None when ``is_last(log_likelihood)``
    and the forward pass was kept, which saves the backward pass of the final E-step."""
    if 2 * engine.data.n_samples * params.n_states > KEPT_FORWARD_VALUES:
        stats = e_step(engine, params)
        return stats.log_likelihood, stats
    passes = list(_forward_blocks(engine, params))
    log_likelihood = float(sum(item[-1] for item in passes))
    if is_last(log_likelihood):
        return log_likelihood, None
    expectations = _Expectations(engine, params)
    for block, frames, alpha, scale, _ in passes:
        expectations.add(block, frames, alpha, scale)
    return log_likelihood, expectations.statistics(log_likelihood)


def score_hmm(X, recordings, params):
    """Log-likelihood of all recordings (forward pass only)."""
    return _score(_Engine(X, recordings, params.n_states), params)


def _score(engine, params):
    return float(sum(item[-1] for item in _forward_blocks(engine, params)))


def covariance_prior_scale(reg_covar, n_samples, n_states):
    """Scale ``psi`` of the covariance prior ``p(S_k) ∝ exp(-psi / 2 tr(S_k^-1))``.

    ``psi = reg_covar * n_samples / n_states``: the prior's scatter matrix ``psi I`` is that of
    ``n_samples / n_states`` rows (an average state's share) of variance ``reg_covar``, so the
    M-step ``S_k = (scatter_k + psi I) / N_k`` adds exactly ``reg_covar`` to the diagonal of a
    state with the average weight, more to a lighter state, less to a heavier one.
    """
    return float(reg_covar) * n_samples / n_states


def log_covariance_prior(params, prior_scale):
    """``-psi / 2 sum_k tr(S_k^-1)``, the penalty EM adds to the log-likelihood.

    ``tr(S^-1)`` is the squared Frobenius norm of the precision Cholesky factor. The prior is
    improper (no normalising constant); the penalty is zero when ``psi`` is.
    """
    if prior_scale == 0:
        return 0.0
    return -0.5 * prior_scale * float(np.sum(np.square(params.precisions_chol)))


def m_step(stats, previous, prior_scale):
    """Maximisation step of the penalised log-likelihood (see :func:`covariance_prior_scale`).

    A state with less than :data:`MIN_STATE_WEIGHT` of posterior mass and a transition row
    with no expected transitions keep their previous values: their terms of the expected
    complete-data objective are then unchanged while the others are maximised, so the
    iteration still cannot lower the objective (a generalised EM step).
    """
    startprob = stats.start_counts / stats.start_counts.sum()
    row_sums = stats.transition_counts.sum(axis=1, keepdims=True)
    transmat = np.where(
        row_sums > 0,
        stats.transition_counts / np.where(row_sums > 0, row_sums, 1.0),
        previous.transmat,
    )
    alive = stats.state_weights >= MIN_STATE_WEIGHT
    safe_weights = np.where(alive, stats.state_weights, 1.0)
    means, covariances = gaussians_from_moments(
        safe_weights,
        stats.first_moments,
        stats.second_moments,
        prior_scale / safe_weights,
        stats.shift,
    )
    means[~alive] = previous.means[~alive]
    covariances[~alive] = previous.covariances[~alive]
    return HMMParameters(startprob, transmat, means, covariances)


def _init_sample(data, random_state):
    """The rows (about the shift) that the k-means initialisations cluster.

    All rows, or every ``step``-th row from a random offset: evenly spread over all
    recordings, and a slice that is copied without a gather.
    """
    if data.n_samples <= INIT_SAMPLE_ROWS:
        return data.rows()
    step = -(-data.n_samples // INIT_SAMPLE_ROWS)
    return data.rows(slice(random_state.randint(step), None, step))


def _kmeans_centers(sample, n_states, random_state):
    # On small data the OpenMP thread start-up of KMeans costs far more than the clustering
    # (tens of milliseconds on a busy machine); one thread is faster there.
    threads = 1 if sample.size < SMALL_KMEANS_SIZE else None
    with threadpool_limits(limits=threads, user_api="openmp"):
        kmeans = KMeans(n_clusters=n_states, n_init=1, random_state=random_state)
        return kmeans.fit(sample).cluster_centers_


def _initial_moments(engine, n_states, responsibilities):
    """Augmented moments of the responsibilities ``responsibilities(lo, hi, chunk)`` returns
    for every chunk of rows, state-major."""
    sums = MomentSums(n_states, engine.data.values.shape[0])
    for lo, hi, chunk in engine.chunks():
        sums.add(responsibilities(lo, hi, chunk), engine.data.values, lo)
    return split_moments(sums.result())


def _nearest_centre(centers):
    """Hard responsibilities: every row to its nearest centre (centres about the shift)."""
    n_states = centers.shape[0]
    half_norms = 0.5 * np.einsum("kf,kf->k", centers, centers)[:, np.newaxis]

    def responsibilities(lo, hi, chunk):
        # argmin_k ||x - c_k||^2 = argmin_k (||c_k||^2 / 2 - c_k . x)
        labels = np.argmin(half_norms - centers @ chunk[:-1], axis=0)
        respT = np.zeros((n_states, hi - lo))
        respT[labels, np.arange(hi - lo)] = 1.0
        return respT

    return responsibilities


def initialize_parameters(
    X, recordings, n_states, init_params, reg_covar, random_state, engine=None
):
    """Initial parameters, in the manner of ``sklearn.mixture``'s ``init_params``."""
    if engine is None:
        engine = _Engine(X, recordings, n_states)
    data = engine.data
    n_samples, n_features = data.n_samples, data.n_features
    if init_params == "random":
        resp = random_state.uniform(size=(n_samples, n_states))
        resp /= resp.sum(axis=1, keepdims=True)
        state_weights, first, second = _initial_moments(
            engine, n_states, lambda lo, hi, chunk: np.ascontiguousarray(resp[lo:hi].T)
        )
    else:
        sample = _init_sample(data, random_state)
        if init_params == "kmeans":
            centers = _kmeans_centers(sample, n_states, random_state)
        elif init_params == "k-means++":
            centers, _ = kmeans_plusplus(sample, n_states, random_state=random_state)
        else:
            centers = sample[random_state.choice(len(sample), size=n_states, replace=False)]
        state_weights, first, second = _initial_moments(engine, n_states, _nearest_centre(centers))
    safe_weights = np.maximum(state_weights, 1e-12)
    means, covariances = gaussians_from_moments(
        safe_weights, first, second, reg_covar, engine.shift
    )
    # A state with too few rows for a full covariance (or none at all) takes the pooled
    # covariance instead, so that EM starts from usable Gaussians.
    small = state_weights < n_features + 1
    if np.any(small):
        total_weight, total_first, total_second = split_moments(engine.totals[np.newaxis])
        pooled_mean, pooled = gaussians_from_moments(
            total_weight, total_first, total_second, reg_covar, engine.shift
        )
        covariances[small] = pooled[0]
        means[small & (state_weights < 1e-12)] = pooled_mean[0]
    startprob = np.full(n_states, 1.0 / n_states)
    transmat = random_state.dirichlet(np.ones(n_states), size=n_states)
    return HMMParameters(startprob, transmat, means, covariances)


def baum_welch(X, recordings, params, *, n_iter, tol, reg_covar, callback=None, engine=None):
    """Run EM from ``params`` until the per-row gain of the objective is below ``tol``.

    The objective is the penalised log-likelihood (see :class:`EMResult`); ``callback``, when
    given, is called as ``callback(iteration, log_likelihood, objective)``.
    """
    if engine is None:
        engine = _Engine(X, recordings, params.n_states)
    engine.remainder = None
    n_samples = engine.data.n_samples
    prior_scale = covariance_prior_scale(reg_covar, n_samples, params.n_states)
    history, objectives = [], []
    converged = False
    n_done = 0

    def objective_of(log_likelihood, parameters):
        return log_likelihood + log_covariance_prior(parameters, prior_scale)

    def converges(log_likelihood):
        return bool(objectives) and (
            abs(objective_of(log_likelihood, params) - objectives[-1]) < tol * n_samples
        )

    for n_done in range(1, n_iter + 1):
        log_likelihood, stats = _e_step_unless(engine, params, converges)
        converged = converges(log_likelihood)
        history.append(log_likelihood)
        objectives.append(objective_of(log_likelihood, params))
        if callback is not None:
            callback(n_done, log_likelihood, objectives[-1])
        if converged:
            break
        params = m_step(stats, params, prior_scale)
    else:
        history.append(_score(engine, params))
        objectives.append(objective_of(history[-1], params))
    return EMResult(params, history[-1], history, n_done, converged, objectives[-1], objectives)


def fit_hmm(
    X,
    recordings,
    n_states,
    *,
    n_init=1,
    init_params="kmeans",
    n_iter=100,
    tol=1e-4,
    reg_covar=1e-6,
    random_state=None,
    initial_parameters=None,
):
    """Fit a Gaussian HMM with ``n_init`` restarts and return the best :class:`EMResult`.

    The best run is the one with the highest objective (the penalised log-likelihood that EM
    maximises). ``X`` is an array of shape (n_samples, n_features) or :class:`Columns`. When
    ``converged`` is reached the last E-step already scored the returned parameters (they
    were not updated after it); otherwise the returned parameters are scored once more.
    """
    random_state = check_random_state(random_state)
    engine = _Engine(X, recordings, n_states)
    best = None
    for _ in range(n_init):
        if initial_parameters is not None:
            params = replace(initial_parameters)
        else:
            params = initialize_parameters(
                None, recordings, n_states, init_params, reg_covar, random_state, engine=engine
            )
        try:
            result = baum_welch(
                None,
                recordings,
                params,
                n_iter=n_iter,
                tol=tol,
                reg_covar=reg_covar,
                engine=engine,
            )
        except NotPositiveDefiniteError as exc:
            raise ValueError(
                f"EM failed: {exc}. The data are probably collinear or a state collapsed on "
                f"a few rows (reg_covar={reg_covar})."
            ) from exc
        if best is None or result.objective > best.objective:
            best = result
    return best
