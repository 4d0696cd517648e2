"""Where an EM starts from a model fitted already: the marginal of a joint model over some of its
columns, and a model of ``K + 1`` states grown from one of ``K`` by splitting a state.

Both are starts (not fits): the parameters they return are those of the model they come from,
re-read, and EM (:func:`~skhmmgmr._hmm._em.fit_hmm` with ``initial_parameters``) takes it from
there. Everything is in the engine's (standardised) units.

- :func:`marginal_start`: a Gaussian's marginal over a subset of its columns keeps the means
  and the covariance block of those columns exactly, so the HMM of a feature subset starts from
  the states of the joint model over all candidates (same start and transition probabilities);
  only what the other columns decided (which rows a state holds, how often it is left) has to
  move, in the EM iterations that may follow (the fast search scores the marginal itself).
- :func:`split_state`: a state is replaced by two halves whose equal mixture has its mean and
  covariance (:meth:`~skhmmgmr._hmm._emissions.GaussianEmissions.split`), offset along the
  principal axis of its covariance; the halves share its start probability and its incoming
  transitions, and each leaves as it did.

:func:`refined` runs a fixed number of EM iterations from such a start, with neither a
convergence test nor a score of the result (the E-steps :func:`~skhmmgmr._hmm._em.fit_hmm`
would spend on them).
"""

import numpy as np

from ._em import HMMParameters, e_step, m_step
from ._em_data import EStepData

# A split moves the halves' means this many standard deviations (of the state, along its
# principal axis) apart from the state's mean, each way.
SPLIT_OFFSET = 0.5


def marginal_start(params, dims):
    """The HMM of ``params`` over the columns ``dims`` alone (same transitions).

    Parameters
    ----------
    params : HMMParameters
        A model over all the columns (e.g. fitted on every candidate feature and the target).
    dims : sequence of int
        Columns kept, in the order the new model reads them.

    Returns
    -------
    start : HMMParameters
    """
    return HMMParameters(
        np.array(params.startprob), np.array(params.transmat), params.emissions.marginal(dims)
    )


def stationary_distribution(transmat):
    """The distribution ``p`` over the states with ``p A = p`` (a left eigenvector of the
    transition matrix for eigenvalue one), summing to one."""
    n_states = transmat.shape[0]
    system = np.vstack([transmat.T - np.eye(n_states), np.ones((1, n_states))])
    target = np.zeros(n_states + 1)
    target[-1] = 1.0
    weights = np.linalg.lstsq(system, target, rcond=None)[0]
    weights = np.maximum(weights, 0.0)
    return weights / weights.sum()


def widest_state(params):
    """The state holding the largest share of the scatter: the largest stationary weight
    times the trace of its covariance."""
    traces = np.trace(params.emissions.state_covariances(), axis1=1, axis2=2)
    return int(np.argmax(stationary_distribution(params.transmat) * traces))


def split_state(params, state=None, *, offset=SPLIT_OFFSET):
    """The HMM of ``K + 1`` states with ``state`` split in two (the new state last).

    Parameters
    ----------
    params : HMMParameters
        A model of ``K`` states.
    state : int, default=None
        The state split; ``None``: :func:`widest_state`.
    offset : float, default=0.5
        The halves' means are ``offset`` standard deviations of the state along its principal
        axis on either side of its mean (below one, so that the split keeps a full covariance
        positive definite).

    Returns
    -------
    start : HMMParameters
        Start probability and every incoming transition of the state shared equally by the
        halves; each half leaves as the state did (its row, with the state's column shared
        too). Every row still sums to one.
    """
    if state is None:
        state = widest_state(params)
    n_states = params.n_states
    if not 0 <= state < n_states:
        raise ValueError(f"state={state} is not one of the {n_states} states")
    if not 0 < offset < 1:
        raise ValueError(f"offset={offset} must be in (0, 1)")
    variances, axes = np.linalg.eigh(params.emissions.state_covariances()[state])
    shift = offset * np.sqrt(max(variances[-1], 0.0)) * axes[:, -1]
    startprob = np.append(params.startprob, 0.5 * params.startprob[state])
    startprob[state] *= 0.5
    transmat = np.zeros((n_states + 1, n_states + 1))
    transmat[:n_states, :n_states] = params.transmat
    transmat[:n_states, state] *= 0.5
    transmat[:n_states, n_states] = transmat[:n_states, state]
    transmat[n_states] = transmat[state]
    return HMMParameters(startprob, transmat, params.emissions.split(state, shift))


def refined(columns, recordings, start, *, n_iter, reg_covar):
    """``start`` after ``n_iter`` EM iterations (E-step, M-step) on ``columns``.

    Parameters
    ----------
    columns : Columns
        The data, as the engine holds them (:class:`~skhmmgmr._hmm._em_data.Columns`).
    recordings : Recordings
    start : HMMParameters
    n_iter : int
        EM iterations; 0 returns ``start``.
    reg_covar : float
        As :func:`~skhmmgmr._hmm._em.fit_hmm` takes it (the same covariance prior).

    Returns
    -------
    params : HMMParameters

    Raises
    ------
    NotPositiveDefiniteError
        As the engine raises it, when a covariance loses positive definiteness.
    """
    if n_iter <= 0:
        return start
    engine = EStepData(columns, recordings, start.n_states)
    prior = type(start.emissions).prior_for(reg_covar, engine.data.n_samples, start.n_states)
    params = start
    for _ in range(n_iter):
        params = m_step(e_step(engine, params), params, prior)
    return params
