"""Gaussian Mixture Regression weighted by the forward variable on the inputs (METHOD.md s. 2).

For every state ``k`` the emission over ``[F, T]`` gives (:meth:`GaussianEmissions.condition
<skhmmgmr._hmm._emissions.GaussianEmissions.condition>`)
- the input marginal ``N(F; mu_k^F, S_k^FF)``,
- the conditional mean ``m_k(F) = mu_k^T + S_k^TF (S_k^FF)^-1 (F - mu_k^F)``, an affine map
  stored as ``coef_k`` and ``intercept_k``,
- the conditional covariance ``S_k^TT - S_k^TF (S_k^FF)^-1 S_k^FT``.

The filter runs the normalised forward recursion on the input marginals only (causal, no
look-ahead) and mixes the per-state conditional means with the filtered state probabilities.

A row with missing inputs (NaN) is read through its observed inputs (:mod:`skhmmgmr._hmm._missing`):
the gating density of those, and in every state the conditional mean and covariance of the
outputs given them; a row with no input observed passes the state probabilities through the
transition matrix and mixes the state output means.
"""

from dataclasses import dataclass

import numpy as np

from ._gaussian import augmented_columns, chunk_size_for
from ._holds import HeldRows, check_top_finite
from ._kernels import forward
from ._missing import MissingRows


@dataclass(frozen=True)
class GMRParameters:
    """Everything the filter needs (in the units of the emission it was read from).

    ``gating`` is the emission model of the inputs (the input marginal of every state); the
    conditional mean of the outputs in state ``k`` is ``coef[k] @ x + intercept[k]`` and its
    covariance ``conditional_covariances[k]``.
    """

    startprob: np.ndarray  # (K,)
    transmat: np.ndarray  # (K, K)
    gating: object  # emission over the inputs
    coef: np.ndarray  # (K, n_outputs, n_inputs)
    intercept: np.ndarray  # (K, n_outputs)
    conditional_covariances: np.ndarray  # (K, n_outputs, n_outputs)

    @property
    def n_states(self):
        return self.startprob.shape[0]

    @property
    def conditional_variances(self):
        """Diagonals of the conditional covariances, shape (K, n_outputs)."""
        return np.diagonal(self.conditional_covariances, axis1=1, axis2=2)


def condition_on_inputs(startprob, transmat, emissions, n_inputs):
    """GMR read-out of an HMM whose emission covers ``[inputs, outputs]``."""
    gating, coef, intercept, conditional = emissions.condition(n_inputs)
    return GMRParameters(startprob, transmat, gating, coef, intercept, conditional)


def read_missing(X, recordings, stale_noise=None):
    """The rows of standardised inputs ``X`` that miss a value (a
    :class:`~skhmmgmr._hmm._missing.MissingRows`, None when none does), read through the last
    observed values of the missing ones when ``stale_noise`` is given
    (:mod:`skhmmgmr._hmm._stale_inputs`). Read once, for both the filter and the read-out."""
    stale = None if stale_noise is None else (stale_noise, recordings.starts, recordings.stops)
    return MissingRows.of(X.T, stale=stale)


def filter_state_probabilities(X, recordings, params, chunk_size=None, missing=None, **holding):
    """Filtered state probabilities ``alpha_t,k`` given the inputs up to ``t``: those of
    :func:`causal_filter` (``holding``: its ``min_log_density``)."""
    return causal_filter(X, recordings, params, chunk_size=chunk_size, missing=missing, **holding)[
        0
    ]


def causal_filter(X, recordings, params, *, chunk_size=None, missing=None, min_log_density=None):
    """Filtered state probabilities ``alpha_t,k`` given the inputs up to ``t``, and the rows
    the outlier policy holds (a :class:`~skhmmgmr._hmm._holds.HeldRows`, None when none is).

    The recursion restarts from the start probabilities at the first row of every recording.
    The input densities are computed chunk by chunk (all states in one product per chunk),
    relative to the row's best state. When no state that the transitions allow explains a row
    (every product underflows), the recursion restarts at that row from the input densities
    alone instead of producing NaN. A row with missing inputs (NaN) takes the densities of its
    observed inputs (and of the carried values of the missing ones when ``missing``, from
    :func:`read_missing`, holds them; None: read here from ``X``). A row whose largest input
    log-density is not finite is refused, and with ``min_log_density`` a row whose largest
    one is below it is held: its state probabilities are those of the last accepted row of
    its recording (the start probabilities before any), and the recursion goes on from there
    (:mod:`skhmmgmr._hmm._holds`).
    """
    frames, top, missing = scaled_input_densities(X, params, chunk_size, missing)
    check_top_finite(top, recordings)
    unobserved = None
    if min_log_density is not None and missing is not None:
        unobserved = missing.rows[missing.missing.all(axis=1)]
    holds = HeldRows.of(top, recordings, min_log_density, unobserved)
    if holds is not None:
        accepted = holds.accepted_rows
        alpha = _forward(frames[accepted], holds.accepted, params)
        return holds.expand(alpha, params.startprob), holds
    return _forward(frames, recordings, params), None


def scaled_input_densities(X, params, chunk_size=None, missing=None):
    """``(frames, top, missing)``: the input densities of the rows of ``X`` relative to each
    row's best state (n_samples, n_states), the logarithms of the best ones (n_samples,), as
    :func:`~skhmmgmr._hmm._kernels.scaled_densities` writes them, and the rows that miss an
    input (``missing``, or read from ``X``; None when none does)."""
    n_samples = X.shape[0]
    n_states, n_inputs = params.n_states, params.gating.n_dims
    density = params.gating.density()
    step = chunk_size_for(n_states * n_inputs, chunk_size)
    frames, top = np.empty((n_samples, n_states)), np.empty(n_samples)
    for start in range(0, n_samples, step):
        rows = slice(start, start + step)
        density.frames(augmented_columns(X[rows]), frames[rows], top[rows])
    missing = MissingRows.of(X.T) if missing is None else missing
    if missing is not None:
        missing.overwrite(params.gating, 0, n_samples, frames, top)
    return frames, top, missing


def _forward(frames, recordings, params):
    """The normalised forward recursion with restarts over ``frames`` (C-contiguous)."""
    alpha = np.empty_like(frames)
    forward(
        frames,
        np.asarray(recordings.starts, dtype=np.int64),
        np.asarray(recordings.stops, dtype=np.int64),
        params.startprob,
        params.transmat,
        alpha,
        np.empty(frames.shape[0]),
        restart=True,
    )
    return alpha


def conditional_means(X, params):
    """Per-state conditional means ``m_t,k``, shape (n_samples, n_states, n_outputs)."""
    n_states, n_outputs, n_inputs = params.coef.shape
    # One product with all states' coefficients side by side, shape (n_inputs, K * n_outputs).
    stacked = params.coef.reshape(n_states * n_outputs, n_inputs).T
    state_means = X @ stacked
    state_means += params.intercept.reshape(-1)
    return state_means.reshape(X.shape[0], n_states, n_outputs)


def _sum_over_states(alpha, values):
    """``sum_k alpha[:, k] * values[:, k, :]`` as a product with ones (a vectorised reduction
    over the short state axis)."""
    n_samples, n_states, n_outputs = values.shape
    ones = np.ones(n_states)
    out = np.empty((n_samples, n_outputs))
    for o in range(n_outputs):
        np.matmul(alpha * values[:, :, o], ones, out=out[:, o])
    return out


def gmr_estimates(X, alpha, params, return_std=False, missing=None):
    """Estimates of the outputs (and their std) given the state probabilities ``alpha``.

    The conditional means of every state given the inputs of each row (given the observed
    ones in a row with missing inputs, and the carried values of the missing ones when
    ``missing``, from :func:`read_missing`, holds them; None: read here from ``X``), mixed by
    :func:`mix_estimates`.
    """
    state_means = conditional_means(X, params)
    missing = MissingRows.of(X.T) if missing is None else missing
    if missing is None:
        return mix_estimates(alpha, state_means, params, return_std=return_std)
    state_means[missing.rows], added = missing.outputs(params)
    return mix_estimates(alpha, state_means, params, return_std, added=(missing.rows, added))


def mix_estimates(alpha, state_means, params, return_std=False, added=None):
    """Mix per-state conditional means; optionally the law-of-total-variance std.

    ``added``: ``(rows, variances)``, variances (n_rows, K, n_outputs) added to the states'
    conditional variances in those rows (rows with missing inputs).
    """
    estimate = _sum_over_states(alpha, state_means)
    if not return_std:
        return estimate, None
    within = alpha @ params.conditional_variances
    if added is not None:
        rows, variances = added
        within[rows] += np.einsum("nk,nko->no", alpha[rows], variances)
    spread = state_means - estimate[:, np.newaxis, :]
    np.square(spread, out=spread)
    between = _sum_over_states(alpha, spread)
    return estimate, np.sqrt(within + between)
