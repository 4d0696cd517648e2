"""Baum-Welch (EM) engine for a Gaussian HMM over several recordings.

The engine is generic over the emission model (:mod:`skhmmgmr._hmm._emissions`): it asks the
emission object for the scaled emission likelihoods of a block of rows, its M-step, its
prior and its initialisation, and accumulates the sufficient statistics the Gaussian family
needs (weighted moments of the columns, :class:`~skhmmgmr._hmm._emissions.MomentStatistics`).

The template follows ``sklearn.mixture``: initialise, E-step, M-step, objective, convergence
test, ``n_init`` restarts keeping the best objective.

The objective is a penalised log-likelihood: the regularisation ``reg_covar`` is a prior on
every covariance matrix of the emission
(:meth:`~skhmmgmr._hmm._emissions.GaussianEmissions.prior_for`), and the M-step is its exact
maximiser, so that every EM iteration raises the objective (up to round-off). Adding
``reg_covar`` to the covariances after a maximum-likelihood M-step, as ``sklearn.mixture``
does, optimises no fixed function: with nearly collinear columns the log-likelihood then falls
by up to 1e-5 (relative) in some iterations.

The data are held once, as augmented columns (:class:`~skhmmgmr._hmm._em_data.Columns`). With
complete data the E-step is one compiled pass per block of whole consecutive recordings
(:mod:`skhmmgmr._hmm._fused_estep`: densities, forward, backward, expected transitions and moments
row by row, blocks on several threads). The staged E-step below computes the same statistics
(to round-off) and serves the rows with missing values. It works block by block, a block
holding whole consecutive recordings of about one cache-sized chunk of rows:

1. the emission log-densities of all states, one BLAS product per chunk
   (:meth:`~skhmmgmr._hmm._emissions.GaussianEmissions.density`), scaled to a maximum of one
   per row and exponentiated (:func:`~skhmmgmr._hmm._kernels.scaled_densities`: one compiled
   pass, then NumPy's exp where it is vectorised, else an exp in the pass only where the value
   is not known);
2. the compiled forward and backward recursions (:mod:`skhmmgmr._hmm._kernels`), which also give
   the posteriors and the terms of the expected transitions;
3. the expected transitions as one product, and the weighted moments of all states as one
   product of the posteriors with the pairwise products of the columns
   (:class:`~skhmmgmr._hmm._gaussian.MomentSums`), while the block's rows are still in cache.

An iteration reads the data once and holds no array of the size of the data besides the
posteriors of one block (and those of the rows that miss a value, if any). The moments of one
state (the heaviest of the previous E-step) are those of all rows minus the others': every
row's posteriors sum to one, so with K=2 only one state's products are computed.

Rows with missing values (NaN) take part through their observed columns (the missing-data EM,
:mod:`skhmmgmr._hmm._missing`): the engine's columns hold zeros in their place, so the steps above
run unchanged; the frames of these rows are then overwritten by their marginal densities, and
the expected statistics of their missing columns are added to the moments of every state.

The estimator talks to this module only through :class:`Columns`, :func:`fit_hmm`,
:func:`score_hmm` and :class:`HMMParameters`.
"""

from dataclasses import dataclass, replace

import numpy as np
from sklearn.utils import check_random_state

from ._em_data import EStepData
from ._em_init import initial_emissions
from ._emissions import MomentStatistics, make_emissions
from ._fused_estep import applies, fused_pass
from ._gaussian import MomentSums, NotPositiveDefiniteError, one_blas_thread, split_moments
from ._kernels import backward_posteriors, forward


@dataclass
class HMMParameters:
    """Parameters of an HMM (in the engine's working units): start probabilities, transition
    matrix and the emission model (:mod:`skhmmgmr._hmm._emissions`)."""

    startprob: np.ndarray
    transmat: np.ndarray
    emissions: object

    @classmethod
    def gaussian(cls, startprob, transmat, means, covariances, covariance_type="full"):
        """Parameters with Gaussian emissions (covariances in the family's shape)."""
        return cls(startprob, transmat, make_emissions(covariance_type, means, covariances))

    @property
    def n_states(self):
        return self.emissions.n_states

    @property
    def means(self):
        return self.emissions.means

    @property
    def covariances(self):
        """Every state's full covariance, shape (n_states, n_dims, n_dims)."""
        return self.emissions.state_covariances()


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
class Statistics:
    """Expected sufficient statistics of one E-step (or of a part of the recordings).

    Statistics of disjoint sets of recordings (other workers) add up (:meth:`merge`).
    """

    log_likelihood: float
    start_counts: np.ndarray
    transition_counts: np.ndarray
    emission: MomentStatistics

    def merge(self, other):
        """Statistics of the recordings of both."""
        return Statistics(
            self.log_likelihood + other.log_likelihood,
            self.start_counts + other.start_counts,
            self.transition_counts + other.transition_counts,
            self.emission.merge(other.emission),
        )


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
    density = params.emissions.density(engine.shift)
    for block in engine.blocks:
        start, stop, rec_starts, rec_stops = block
        frames, log_scale = engine.frames(density, start, stop, params.emissions)
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

    def __init__(self, engine, params, method=None):
        self.engine, self.params = engine, params
        n_states = params.n_states
        self.accumulated = [k for k in range(n_states) if k != engine.remainder]
        self.start_counts = np.zeros(n_states)
        self.transition_sums = np.zeros((n_states, n_states))
        n_columns = engine.data.values.shape[0]
        self.sums = MomentSums(n_states, n_columns, states=self.accumulated, method=method)
        self.missing_moments = 0.0  # what the missing values add (see _missing)

    @classmethod
    def fused(cls, engine, params, density):
        """Statistics of every recording in one fused pass (:mod:`skhmmgmr._hmm._fused_estep`)."""
        expectations = cls(engine, params, method="pairs")
        log_likelihood, starts, transitions, pairs = fused_pass(
            engine, params, density, expectations.accumulated
        )
        if log_likelihood == -np.inf:
            _raise_impossible()
        expectations.start_counts += starts
        expectations.transition_sums += transitions
        expectations.sums.add_pair_sums(pairs)
        return expectations.statistics(log_likelihood)

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
        if self.engine.missing is not None:
            emissions = self.params.emissions
            self.missing_moments += self.engine.missing.moments(emissions, posteriors, start, stop)

    def statistics(self, log_likelihood):
        engine, remainder = self.engine, self.engine.remainder
        moments = self.sums.result()
        if remainder is not None:
            moments[remainder] = engine.totals - moments[self.accumulated].sum(axis=0)
        moments += self.missing_moments
        weights, first, second = split_moments(moments)
        engine.remainder = int(np.argmax(weights))
        return Statistics(
            log_likelihood,
            self.start_counts,
            self.transition_sums * self.params.transmat,
            MomentStatistics(weights.copy(), first.copy(), second.copy(), engine.shift),
        )


def e_step(engine, params):
    """Forward-backward over every recording, accumulating the sufficient statistics."""
    with one_blas_thread():
        density = params.emissions.density(engine.shift)
        if applies(engine, density):
            return _Expectations.fused(engine, params, density)
    expectations, log_likelihood = _Expectations(engine, params), 0.0
    with one_blas_thread():
        for block, frames, alpha, scale, block_log_likelihood in _forward_blocks(engine, params):
            log_likelihood += block_log_likelihood
            expectations.add(block, frames, alpha, scale)
    return expectations.statistics(log_likelihood)


def _e_step_unless(engine, params, is_last):
    """``(log_likelihood, statistics)``; the statistics are None when ``is_last(log_likelihood)``
    and the forward pass was kept, which saves the backward pass of the final E-step."""
    if 2 * engine.data.n_samples * params.n_states > KEPT_FORWARD_VALUES or applies(
        engine, params.emissions.density(engine.shift)
    ):
        # the fused E-step keeps no forward pass: its backward pass costs less than a second
        # forward pass would
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
    return _score(EStepData(X, recordings, params.n_states), params)


def state_posteriors(X, recordings, params):
    """Posterior probabilities of the states at every row given its whole recording
    (forward-backward), shape (n_samples, n_states)."""
    engine = EStepData(X, recordings, params.n_states)
    result = np.empty((engine.data.n_samples, params.n_states))
    with one_blas_thread():
        for block, frames, alpha, scale, _ in _forward_blocks(engine, params):
            start, stop, rec_starts, rec_stops = block
            posteriors = np.empty((params.n_states, stop - start))
            backward_posteriors(
                frames,
                rec_starts,
                rec_stops,
                params.transmat,
                alpha,
                scale,
                posteriors,
                np.empty_like(frames),
            )
            result[start:stop] = posteriors.T
    return result


def _score(engine, params):
    with one_blas_thread():
        density = params.emissions.density(engine.shift)
        if applies(engine, density):
            log_likelihood = fused_pass(engine, params, density, [], backward=False)[0]
            if log_likelihood == -np.inf:
                _raise_impossible()
            return float(log_likelihood)
        return float(sum(item[-1] for item in _forward_blocks(engine, params)))


def m_step(stats, previous, prior, transitions=None):
    """Maximisation step of the penalised log-likelihood.

    The emission's M-step (with its ``prior``, see
    :meth:`~skhmmgmr._hmm._emissions.GaussianEmissions.maximize`); a transition row with no
    expected transitions keeps its previous values. Both keep the objective non-decreasing
    (a generalised EM step). Probabilities are floored at :data:`PROBABILITY_FLOOR`.
    ``transitions``, when given, replaces the M-step of the start and transition
    probabilities: an object whose ``maximize(start_counts, transition_counts, previous)``
    returns ``(startprob, transmat)`` (a structured transition matrix, as the manoeuvre
    hierarchy of :mod:`skhmmgmr._hmm._hierarchy`).
    """
    emissions = previous.emissions.maximize(stats.emission, prior)
    if transitions is not None:
        startprob, transmat = transitions.maximize(
            stats.start_counts, stats.transition_counts, previous
        )
        return HMMParameters(startprob, transmat, emissions)
    startprob = _floored(stats.start_counts / stats.start_counts.sum())
    row_sums = stats.transition_counts.sum(axis=1, keepdims=True)
    transmat = np.where(
        row_sums > 0,
        stats.transition_counts / np.where(row_sums > 0, row_sums, 1.0),
        previous.transmat,
    )
    transmat = _floored(transmat)
    return HMMParameters(startprob, transmat, emissions)


# A start or transition probability that the expected counts make exactly zero is raised to
# this. The forward pass zeroes the densities more than exp(-708) below a row's largest, so
# with an exact zero a sharp state can become unreachable at the one row that needs it, and
# the recording impossible (a FloatingPointError in the next E-step). With the floor the
# state a row favours keeps at least floor * 1e-30 (the lazy rescaling's threshold), still a
# normal double; the change to the objective (about 1e-250 per floored entry) is far below
# any tolerance.
PROBABILITY_FLOOR = 1e-250


def _floored(probabilities):
    floored = np.maximum(probabilities, PROBABILITY_FLOOR)
    return floored / floored.sum(axis=-1, keepdims=True)


def initialize_parameters(
    X,
    recordings,
    n_states,
    init_params,
    reg_covar,
    random_state,
    engine=None,
    covariance_type="full",
):
    """Initial parameters, in the manner of ``sklearn.mixture``'s ``init_params``."""
    if engine is None:
        engine = EStepData(X, recordings, n_states)
    emissions = initial_emissions(
        engine, n_states, init_params, reg_covar, random_state, covariance_type
    )
    startprob = np.full(n_states, 1.0 / n_states)
    transmat = random_state.dirichlet(np.ones(n_states), size=n_states)
    return HMMParameters(startprob, transmat, emissions)


def baum_welch(
    X,
    recordings,
    params,
    *,
    n_iter,
    tol,
    reg_covar,
    callback=None,
    engine=None,
    transitions=None,
):
    """Run EM from ``params`` until the per-row gain of the objective is below ``tol``.

    The objective is the penalised log-likelihood (see :class:`EMResult`); ``callback``, when
    given, is called as ``callback(iteration, log_likelihood, objective)``; ``transitions``
    is passed to :func:`m_step`.
    """
    if engine is None:
        engine = EStepData(X, recordings, params.n_states)
    engine.remainder = None
    n_samples = engine.data.n_samples
    prior = type(params.emissions).prior_for(reg_covar, n_samples, params.n_states)
    history, objectives = [], []
    converged = False
    n_done = 0

    def objective_of(log_likelihood, parameters):
        return log_likelihood + parameters.emissions.log_prior(prior)

    def converges(log_likelihood):
        return bool(objectives) and (
            abs(objective_of(log_likelihood, params) - objectives[-1]) < tol * n_samples
        )

    for n_done in range(1, n_iter + 1):
        with one_blas_thread():
            log_likelihood, stats = _e_step_unless(engine, params, converges)
        converged = converges(log_likelihood)
        history.append(log_likelihood)
        objectives.append(objective_of(log_likelihood, params))
        if callback is not None:
            callback(n_done, log_likelihood, objectives[-1])
        if converged:
            break
        params = m_step(stats, params, prior, transitions)
    else:
        history.append(_score(engine, params))
        objectives.append(objective_of(history[-1], params))
    return EMResult(params, history[-1], history, n_done, converged, objectives[-1], objectives)


def em_failure(exc, reg_covar):
    """The user's error for a covariance that lost positive definiteness during EM."""
    return ValueError(
        f"EM failed: {exc}. The data are probably collinear or a state collapsed on "
        f"a few rows (reg_covar={reg_covar})."
    )


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
    covariance_type="full",
    transitions=None,
):
    """Fit a Gaussian HMM with ``n_init`` restarts and return the best :class:`EMResult`.

    The best run is the one with the highest objective (the penalised log-likelihood that EM
    maximises). ``X`` is an array of shape (n_samples, n_features) or :class:`Columns`.
    ``transitions`` (see :func:`m_step`) keeps the transition matrix structured. When
    ``converged`` is reached the last E-step already scored the returned parameters (they
    were not updated after it); otherwise the returned parameters are scored once more.
    """
    random_state = check_random_state(random_state)
    engine = EStepData(X, recordings, n_states)
    best = None
    for _ in range(n_init):
        if initial_parameters is not None:
            params = replace(initial_parameters)
        else:
            params = initialize_parameters(
                None,
                recordings,
                n_states,
                init_params,
                reg_covar,
                random_state,
                engine=engine,
                covariance_type=covariance_type,
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
                transitions=transitions,
            )
        except NotPositiveDefiniteError as exc:
            raise em_failure(exc, reg_covar) from exc
        if best is None or result.objective > best.objective:
            best = result
    return best
