"""Baum-Welch (EM) engine for a full-covariance Gaussian HMM over several recordings.

The template follows ``sklearn.mixture``: initialise, E-step, M-step, log-likelihood,
convergence test, ``n_init`` restarts keeping the best log-likelihood. The forward-backward
recursions run per recording in hmmlearn's compiled kernels (scaled form). Everything else is
done block by block: a block holds whole consecutive recordings of about one cache-sized chunk
of rows; its emission densities (one BLAS product for all states), posteriors, expected
transitions and weighted moments are computed while its rows are in cache, so an iteration
reads the data once and holds no array of the size of the data.

The estimator talks to this module only through :func:`fit_hmm`, :func:`score_hmm` and
:class:`HMMParameters`.
"""

from dataclasses import dataclass, field, replace

import numpy as np
from hmmlearn import _hmmc
from sklearn.cluster import KMeans, kmeans_plusplus
from sklearn.metrics import pairwise_distances_argmin
from sklearn.utils import check_random_state
from threadpoolctl import threadpool_limits

from ._gaussian import (
    NotPositiveDefiniteError,
    accumulate_moments,
    chunk_size_for,
    compute_precision_cholesky,
    gaussians_from_moments,
    log_gaussian_prob_stacked,
    shifted_transpose,
    stack_gaussians,
    weighted_moments,
)

INIT_METHODS = ("kmeans", "k-means++", "random", "random_from_data")

# A state whose expected number of rows falls below this keeps its previous emission
# parameters: less than one row of posterior mass cannot define a Gaussian, and freezing the
# state (instead of re-seeding it) keeps the log-likelihood non-decreasing.
MIN_STATE_WEIGHT = 1.0

# Consecutive short recordings are grouped into blocks of about this many rows.
BLOCK_ROWS = 8192

# Blocks up to this many rows keep their shifted rows between the E-step's two passes.
CACHED_BLOCK_ROWS = 1 << 16

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
    parameters: HMMParameters
    log_likelihood: float
    history: list
    n_iter: int
    converged: bool


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


def _blocks(recordings, max_rows):
    """Group consecutive recordings into blocks of at most ``max_rows`` rows.

    A recording longer than ``max_rows`` forms a block of its own. Yields ``(start, stop,
    starts, stops)`` with the recording bounds relative to ``start``.
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
    """Per-fit constants: the data, its shift point, the recording blocks and chunk size."""

    def __init__(self, X, recordings, n_states, chunk_size=None, block_size=None):
        self.X = X
        self.n_states = n_states
        self.shift = X.mean(axis=0) if X.shape[0] else np.zeros(X.shape[1])
        self.step = chunk_size_for(n_states * X.shape[1], chunk_size)
        self.blocks = _blocks(recordings, block_size or max(self.step, BLOCK_ROWS))

    def chunks(self, start, stop):
        """Shifted, transposed rows ``start:stop`` in chunks of about ``step`` rows.

        A block of up to :data:`CACHED_BLOCK_ROWS` rows comes back as a list, so that the
        E-step shifts its rows once for the emissions and the moments; longer blocks are
        generated lazily, twice, so that memory stays bounded.
        """
        n_chunks = -(-(stop - start) // self.step)
        bounds = np.linspace(0, stop - start, n_chunks + 1).astype(int).tolist()
        chunks = (
            (lo, hi, shifted_transpose(self.X[start + lo : start + hi], self.shift))
            for lo, hi in zip(bounds[:-1], bounds[1:], strict=True)
        )
        return list(chunks) if stop - start <= CACHED_BLOCK_ROWS else chunks

    def frame_probabilities(self, stacked, n_rows, chunks):
        """Emission likelihoods of a block scaled per row (max 1), and the summed log scale."""
        frameprob = np.empty((n_rows, self.n_states))
        log_scale = 0.0
        for lo, hi, chunk in chunks:
            log_prob = log_gaussian_prob_stacked(chunk, *stacked)
            row_max = log_prob.max(axis=0)
            log_prob -= row_max
            np.exp(log_prob, out=log_prob)
            frameprob[lo:hi] = log_prob.T
            log_scale += row_max.sum()
        return frameprob, log_scale


def _forward(params, frames):
    try:
        return _hmmc.forward_scaling(params.startprob, params.transmat, frames)
    except ValueError as exc:
        raise FloatingPointError(
            "the forward pass underflowed: a recording is impossible under the current "
            "transition matrix"
        ) from exc


def e_step(engine, params):
    """Forward-backward over every recording, accumulating the sufficient statistics.

    Emissions, posteriors and moments are computed block by block (whole recordings of about
    one chunk of rows), so no array of the size of the data is held besides the data.
    """
    n_states, n_features = params.means.shape
    stacked = stack_gaussians(params.means, params.precisions_chol, engine.shift)
    start_counts = np.zeros(n_states)
    xi_sum = np.zeros((n_states, n_states))
    weights = np.zeros(n_states)
    first = np.zeros((n_states, n_features))
    second = np.zeros((n_states, n_features, n_features))
    log_likelihood = 0.0
    for start, stop, rec_starts, rec_stops in engine.blocks:
        chunks = engine.chunks(start, stop)
        frameprob, log_scale = engine.frame_probabilities(stacked, stop - start, chunks)
        log_likelihood += log_scale
        fwd = np.empty_like(frameprob)
        bwd = np.empty_like(frameprob)
        for lo, hi in zip(rec_starts, rec_stops, strict=True):
            frames = frameprob[lo:hi]
            log_prob, fwd[lo:hi], scaling = _forward(params, frames)
            bwd[lo:hi] = _hmmc.backward_scaling(params.startprob, params.transmat, frames, scaling)
            log_likelihood += log_prob
        # sum_t fwd[t, i] A[i, j] frameprob[t + 1, j] bwd[t + 1, j], without the terms that
        # would cross from one recording into the next (A[i, j] is applied in the M-step).
        forward_weight = frameprob
        forward_weight *= bwd
        forward_weight[rec_starts] = 0.0
        xi_sum += fwd[:-1].T @ forward_weight[1:]
        post = np.multiply(fwd.T, bwd.T, out=np.empty((n_states, stop - start)))
        post /= post.sum(axis=0)
        start_counts += post[:, rec_starts].sum(axis=1)
        weights += post.sum(axis=1)
        if not isinstance(chunks, list):
            chunks = engine.chunks(start, stop)
        for lo, hi, chunk in chunks:
            accumulate_moments(post[:, lo:hi], chunk, first, second)
    transition_counts = xi_sum * params.transmat
    return _Statistics(
        log_likelihood, start_counts, transition_counts, weights, first, second, engine.shift
    )


def score_hmm(X, recordings, params):
    """Log-likelihood of all recordings (forward pass only)."""
    return _score(_Engine(X, recordings, params.n_states), params)


def _score(engine, params):
    stacked = stack_gaussians(params.means, params.precisions_chol, engine.shift)
    log_likelihood = 0.0
    for start, stop, rec_starts, rec_stops in engine.blocks:
        chunks = engine.chunks(start, stop)
        frameprob, log_scale = engine.frame_probabilities(stacked, stop - start, chunks)
        log_likelihood += log_scale
        for lo, hi in zip(rec_starts, rec_stops, strict=True):
            log_likelihood += _forward(params, frameprob[lo:hi])[0]
    return float(log_likelihood)


def m_step(stats, previous, reg_covar):
    """Maximisation step; every covariance gets ``reg_covar`` on its diagonal."""
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
        safe_weights, stats.first_moments, stats.second_moments, reg_covar, stats.shift
    )
    means[~alive] = previous.means[~alive]
    covariances[~alive] = previous.covariances[~alive]
    return HMMParameters(startprob, transmat, means, covariances)


def _kmeans_labels(X, n_states, random_state):
    # On small data the OpenMP thread start-up of KMeans costs far more than the clustering
    # (tens of milliseconds on a busy machine); one thread is faster there.
    threads = 1 if X.size < SMALL_KMEANS_SIZE else None
    with threadpool_limits(limits=threads, user_api="openmp"):
        kmeans = KMeans(n_clusters=n_states, n_init=1, random_state=random_state)
        return kmeans.fit(X).labels_


def _hard_moments(engine, labels, n_states):
    """Weights and moments of a hard assignment, chunk by chunk."""
    n_features = engine.X.shape[1]
    first = np.zeros((n_states, n_features))
    second = np.zeros((n_states, n_features, n_features))
    for lo, hi, chunk in engine.chunks(0, engine.X.shape[0]):
        respT = np.zeros((n_states, hi - lo))
        respT[labels[lo:hi], np.arange(hi - lo)] = 1.0
        accumulate_moments(respT, chunk, first, second)
    weights = np.bincount(labels, minlength=n_states).astype(float)
    return weights, first, second


def initialize_parameters(
    X, recordings, n_states, init_params, reg_covar, random_state, engine=None
):
    """Initial parameters: emissions from a hard clustering, random transitions."""
    n_samples, n_features = X.shape
    if engine is None:
        engine = _Engine(X, recordings, n_states)
    if init_params == "random":
        resp = random_state.uniform(size=(n_samples, n_states))
        resp /= resp.sum(axis=1, keepdims=True)
        state_weights, first, second = weighted_moments(resp, X, engine.shift, engine.step)
    else:
        if init_params == "kmeans":
            labels = _kmeans_labels(X, n_states, random_state)
        else:
            if init_params == "k-means++":
                centers, _ = kmeans_plusplus(X, n_states, random_state=random_state)
            else:
                centers = X[random_state.choice(n_samples, size=n_states, replace=False)]
            labels = pairwise_distances_argmin(X, centers)
        state_weights, first, second = _hard_moments(engine, labels, n_states)
    safe_weights = np.maximum(state_weights, 1e-12)
    means, covariances = gaussians_from_moments(
        safe_weights, first, second, reg_covar, engine.shift
    )
    # A cluster with fewer rows than dimensions has a singular scatter: give it the pooled
    # covariance instead, so that EM starts from usable Gaussians.
    small = state_weights < n_features + 1
    if np.any(small):
        pooled = np.cov(X, rowvar=False).reshape(n_features, n_features)
        pooled.flat[:: n_features + 1] += reg_covar
        covariances[small] = pooled
        means[small & (state_weights < 1e-12)] = X.mean(axis=0)
    startprob = np.full(n_states, 1.0 / n_states)
    transmat = random_state.dirichlet(np.ones(n_states), size=n_states)
    return HMMParameters(startprob, transmat, means, covariances)


def baum_welch(X, recordings, params, *, n_iter, tol, reg_covar, callback=None, engine=None):
    """Run EM from ``params`` until the per-row log-likelihood gain is below ``tol``.

    ``history`` holds the log-likelihood of the parameters in force before each M-step and,
    last, that of the returned parameters.
    """
    if engine is None:
        engine = _Engine(X, recordings, params.n_states)
    n_samples = X.shape[0]
    history = []
    converged = False
    n_done = 0
    for n_done in range(1, n_iter + 1):
        stats = e_step(engine, params)
        history.append(float(stats.log_likelihood))
        if callback is not None:
            callback(n_done, stats.log_likelihood)
        if len(history) > 1 and abs(history[-1] - history[-2]) < tol * n_samples:
            converged = True
            break
        params = m_step(stats, params, reg_covar)
    else:
        history.append(_score(engine, params))
    return EMResult(params, history[-1], history, n_done, converged)


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

    When ``converged`` is reached the last E-step already scored the returned parameters
    (they were not updated after it); otherwise the returned parameters are scored once more.
    """
    random_state = check_random_state(random_state)
    engine = _Engine(X, recordings, n_states)
    best = None
    for _ in range(n_init):
        if initial_parameters is not None:
            params = replace(initial_parameters)
        else:
            params = initialize_parameters(
                X, recordings, n_states, init_params, reg_covar, random_state, engine=engine
            )
        try:
            result = baum_welch(
                X, recordings, params, n_iter=n_iter, tol=tol, reg_covar=reg_covar, engine=engine
            )
        except NotPositiveDefiniteError as exc:
            raise ValueError(
                f"EM failed: {exc}. The data are probably collinear or a state collapsed on "
                f"a few rows (reg_covar={reg_covar})."
            ) from exc
        if best is None or result.log_likelihood > best.log_likelihood:
            best = result
    return best
