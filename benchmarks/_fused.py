"""A fused reference for the EM engine's E-step: plain numba, written for clarity.

One pass per recording does everything the engine splits into stages: the emission
log-densities through the precision Cholesky factors, inline; the scaled forward recursion;
the backward recursion, which accumulates the posteriors, the expected transitions and the
weighted moments (about ``shift``) in place. Recordings run in parallel (``prange``), each
into its own slot of the statistics, summed at the end. The M-step is the package's
(:func:`skhmmgmr._em.m_step`): its cost is negligible, and the two log-likelihood histories
then differ by round-off only (``tests/test_fused_reference.py``).
"""

import numpy as np
from numba import njit, prange

from skhmmgmr._em import HMMParameters, Statistics, m_step
from skhmmgmr._emissions import MomentStatistics


@njit(cache=True)
def _recording(X, shift, means, factors, norms, startprob, transmat, moments, transitions):
    """E-step of one recording ``X`` (n_rows, n_dims); adds to ``moments`` (K, D+1, D+1),
    ``transitions`` (K, K); returns ``(log_likelihood, first-row posteriors)``."""
    n_rows, n_dims = X.shape
    n_states = means.shape[0]
    frames = np.empty((n_rows, n_states))
    alpha = np.empty((n_rows, n_states))
    scale = np.empty(n_rows)
    log_likelihood = 0.0
    log_density = np.empty(n_states)
    for t in range(n_rows):
        # log N(x | mu_k, S_k) = norms[k] - ||(x - mu_k) P_k||^2 / 2, P_k upper triangular.
        for k in range(n_states):
            distance = 0.0
            for j in range(n_dims):
                projection = 0.0
                for i in range(j + 1):
                    projection += (X[t, i] - means[k, i]) * factors[k, i, j]
                distance += projection * projection
            log_density[k] = norms[k] - 0.5 * distance
        top = log_density.max()
        log_likelihood += top
        total = 0.0
        for j in range(n_states):
            frames[t, j] = np.exp(log_density[j] - top)
            if t == 0:
                prior = startprob[j]
            else:
                prior = 0.0
                for i in range(n_states):
                    prior += alpha[t - 1, i] * transmat[i, j]
            alpha[t, j] = prior * frames[t, j]
            total += alpha[t, j]
        scale[t] = total
        log_likelihood += np.log(total)
        for j in range(n_states):
            alpha[t, j] /= total
    beta = np.ones(n_states)
    previous = np.empty(n_states)
    column = np.empty(n_dims + 1)
    column[n_dims] = 1.0
    for t in range(n_rows - 1, -1, -1):
        if t < n_rows - 1:
            # beta_t(i) = sum_j A_ij b_j(x_{t+1}) beta_{t+1}(j) / c_{t+1}; xi adds in place.
            for j in range(n_states):
                previous[j] = frames[t + 1, j] * beta[j] / scale[t + 1]
            for i in range(n_states):
                value = 0.0
                for j in range(n_states):
                    term = transmat[i, j] * previous[j]
                    transitions[i, j] += alpha[t, i] * term
                    value += term
                beta[i] = value
        for d in range(n_dims):
            column[d] = X[t, d] - shift[d]
        for k in range(n_states):
            weight = alpha[t, k] * beta[k]
            for a in range(n_dims + 1):
                scaled = weight * column[a]
                for b in range(a, n_dims + 1):
                    moments[k, a, b] += scaled * column[b]
    first_posteriors = alpha[0] * beta
    return log_likelihood, first_posteriors


@njit(cache=True, parallel=True)
def _all_recordings(X, bounds, shift, means, factors, norms, startprob, transmat):
    n_recordings, n_states, n_dims = bounds.shape[0] - 1, means.shape[0], means.shape[1]
    moments = np.zeros((n_recordings, n_states, n_dims + 1, n_dims + 1))
    transitions = np.zeros((n_recordings, n_states, n_states))
    starts = np.zeros((n_recordings, n_states))
    log_likelihoods = np.zeros(n_recordings)
    for r in prange(n_recordings):
        log_likelihoods[r], starts[r] = _recording(
            X[bounds[r] : bounds[r + 1]],
            shift,
            means,
            factors,
            norms,
            startprob,
            transmat,
            moments[r],
            transitions[r],
        )
    return log_likelihoods.sum(), starts.sum(axis=0), transitions.sum(axis=0), moments.sum(axis=0)


def fused_e_step(X, bounds, params, shift):
    """:class:`skhmmgmr._em.Statistics` of rows ``X`` in recordings ``bounds`` (n + 1 edges)."""
    emissions = params.emissions
    norms = emissions.log_normalizers()
    log_likelihood, starts, transitions, moments = _all_recordings(
        X,
        np.asarray(bounds, dtype=np.int64),
        shift,
        emissions.means,
        np.ascontiguousarray(emissions.precisions_chol),
        norms,
        params.startprob,
        params.transmat,
    )
    n_dims = X.shape[1]
    upper = np.triu(moments, 1)
    moments = moments + upper.transpose(0, 2, 1)
    return Statistics(
        float(log_likelihood),
        starts,
        transitions,
        MomentStatistics(
            moments[:, n_dims, n_dims].copy(),
            moments[:, :n_dims, n_dims].copy(),
            moments[:, :n_dims, :n_dims].copy(),
            shift,
        ),
    )


def fused_baum_welch(X, bounds, params, *, n_iter, reg_covar=0.0, callback=None):
    """``n_iter`` EM iterations from ``params``; returns the log-likelihood history (one per
    E-step). ``callback(iteration)`` is called after each E-step."""
    X = np.ascontiguousarray(X, dtype=float)
    shift = X.mean(axis=0)
    prior = type(params.emissions).prior_for(reg_covar, X.shape[0], params.n_states)
    history = []
    for iteration in range(n_iter):
        stats = fused_e_step(X, bounds, params, shift)
        history.append(stats.log_likelihood)
        if callback is not None:
            callback(iteration)
        params = m_step(stats, params, prior)
    return history, params


__all__ = ["HMMParameters", "fused_baum_welch", "fused_e_step"]
