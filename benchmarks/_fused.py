"""A fused reference for the EM engine's E-step: plain numba, written for clarity.

One pass per recording does everything the engine splits into stages:

1. forward: the emission log-densities of a row through the precision Cholesky factors,
   inline; their exponentials relative to the row's largest; the forward recursion, every row
   normalised to sum to one (``c_t``, the log-likelihood is ``sum_t log c_t`` plus the
   largest log-densities);
2. backward: the posteriors of a row, added to the weighted moments (about ``shift``) at
   once; the terms of the expected transitions, added in place; the backward variable of
   the previous row.

Recordings run in parallel (``prange``) in a fixed number of groups of about equal rows, each
group into its own accumulators, summed at the end in group order (the result does not
depend on the number of threads). The M-step is the package's (:func:`skhmmgmr._hmm._em.m_step`):
its cost is negligible, and the two log-likelihood histories then differ by round-off only
(``tests/test_fused_reference.py``).
"""

import numpy as np
from numba import njit, prange

from skhmmgmr._hmm._em import HMMParameters, Statistics, m_step
from skhmmgmr._hmm._emissions import MomentStatistics

# exp() below this is subnormal or zero: the frame is set to zero.
UNDERFLOW = -708.0
# Recordings are split into this many groups of about equal rows, run in parallel.
GROUPS = 16


@njit(cache=True, nogil=True, error_model="numpy")
def _forward(X, stacked, offsets, norms, startprob, transmat, frames, alpha, scale):
    """Frames, normalised forward variables and their normalisers ``c_t`` of one recording;
    returns its log-likelihood.

    ``stacked`` (n_dims, n_states * n_dims) holds the precision Cholesky factors ``P_k`` side
    by side and ``offsets`` the products ``-mu_k P_k``: ``x @ stacked + offsets`` holds every
    state's ``(x - mu_k) P_k`` (one long loop, which vectorises).
    """
    n_rows, n_dims = X.shape
    n_states = norms.shape[0]
    log_density = np.empty(n_states)
    projection = np.empty(offsets.shape[0])
    log_likelihood = 0.0
    for t in range(n_rows):
        # log N(x | mu_k, S_k) = norms[k] - ||(x - mu_k) P_k||^2 / 2
        projection[:] = offsets
        for i in range(n_dims):
            value = X[t, i]
            for m in range(projection.shape[0]):
                projection[m] += value * stacked[i, m]
        for k in range(n_states):
            distance = 0.0
            for m in range(k * n_dims, (k + 1) * n_dims):
                distance += projection[m] * projection[m]
            log_density[k] = norms[k] - 0.5 * distance
        top = log_density.max()
        log_likelihood += top
        for k in range(n_states):
            gap = log_density[k] - top
            frames[t, k] = 1.0 if gap == 0.0 else (0.0 if gap < UNDERFLOW else np.exp(gap))
        total = 0.0
        for j in range(n_states):
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
    return log_likelihood


@njit(cache=True, nogil=True, error_model="numpy")
def _backward(X, shift, transmat, frames, alpha, scale, moments, transitions, start_counts):
    """Backward recursion of one recording (after :func:`_forward`), adding the weighted
    moments (K, n_pairs) of the upper triangle of ``[x - shift, 1] [x - shift, 1]^T``, the
    terms ``alpha_t(i) b_j(x_{t+1}) beta_{t+1}(j) / c_{t+1}`` (times ``transmat`` later) and
    the first row's posteriors."""
    n_rows, n_dims = X.shape
    n_states = transmat.shape[0]
    beta = np.ones(n_states)
    weighted = np.empty(n_states)
    column = np.ones(n_dims + 1)
    pairs = np.empty(moments.shape[1])
    for t in range(n_rows - 1, -1, -1):
        # posteriors alpha_t beta_t, normalised against round-off
        norm = 0.0
        for k in range(n_states):
            norm += alpha[t, k] * beta[k]
        for d in range(n_dims):
            column[d] = X[t, d] - shift[d]
        p = 0
        for a in range(n_dims + 1):
            for b in range(a, n_dims + 1):
                pairs[p] = column[a] * column[b]
                p += 1
        for k in range(n_states):
            posterior = alpha[t, k] * beta[k] / norm
            for p in range(pairs.shape[0]):
                moments[k, p] += posterior * pairs[p]
            if t == 0:
                start_counts[k] += posterior
        if t == 0:
            break
        # beta_{t-1}(i) = sum_j A_ij b_j(x_t) beta_t(j) / c_t
        for j in range(n_states):
            weighted[j] = frames[t, j] * beta[j] / scale[t]
        for i in range(n_states):
            value = 0.0
            for j in range(n_states):
                transitions[i, j] += alpha[t - 1, i] * weighted[j]
                value += transmat[i, j] * weighted[j]
            beta[i] = value


@njit(cache=True, parallel=True, error_model="numpy")
def _all_recordings(X, bounds, groups, shift, stacked, offsets, norms, startprob, transmat):
    n_groups, n_states, n_dims = groups.shape[0] - 1, norms.shape[0], X.shape[1]
    n_pairs = (n_dims + 1) * (n_dims + 2) // 2
    moments = np.zeros((n_groups, n_states, n_pairs))
    transitions = np.zeros((n_groups, n_states, n_states))
    start_counts = np.zeros((n_groups, n_states))
    log_likelihoods = np.zeros(n_groups)
    for g in prange(n_groups):
        for r in range(groups[g], groups[g + 1]):
            rows = X[bounds[r] : bounds[r + 1]]
            frames = np.empty((rows.shape[0], n_states))
            alpha = np.empty((rows.shape[0], n_states))
            scale = np.empty(rows.shape[0])
            log_likelihoods[g] += _forward(
                rows, stacked, offsets, norms, startprob, transmat, frames, alpha, scale
            )
            _backward(
                rows,
                shift,
                transmat,
                frames,
                alpha,
                scale,
                moments[g],
                transitions[g],
                start_counts[g],
            )
    log_likelihood, starts = 0.0, np.zeros(n_states)
    counts, summed = np.zeros((n_states, n_states)), np.zeros((n_states, n_pairs))
    for g in range(n_groups):
        log_likelihood += log_likelihoods[g]
        starts += start_counts[g]
        counts += transitions[g]
        summed += moments[g]
    return log_likelihood, starts, counts * transmat, summed


def recording_groups(bounds, n_groups=GROUPS):
    """Recording indices splitting ``bounds`` into at most ``n_groups`` runs of about equal
    rows (``n + 1`` edges)."""
    bounds = np.asarray(bounds, dtype=np.int64)
    targets = np.linspace(0, bounds[-1], n_groups + 1)[1:-1]
    inner = np.searchsorted(bounds, targets)
    return np.unique(np.concatenate([[0], inner, [len(bounds) - 1]])).astype(np.int64)


def fused_e_step(X, bounds, params, shift):
    """:class:`~skhmmgmr._hmm._em.Statistics` of rows ``X`` in recordings ``bounds`` (n + 1)."""
    emissions = params.emissions
    bounds = np.asarray(bounds, dtype=np.int64)
    factors = emissions.precisions_chol
    n_states, n_dims = emissions.means.shape
    stacked = np.ascontiguousarray(factors.transpose(1, 0, 2).reshape(n_dims, -1))
    offsets = -np.einsum("ki,kij->kj", emissions.means, factors).ravel()
    log_likelihood, starts, transitions, pairs = _all_recordings(
        X,
        bounds,
        recording_groups(bounds),
        shift,
        stacked,
        offsets,
        emissions.log_normalizers(),
        params.startprob,
        np.ascontiguousarray(params.transmat),
    )
    rows, cols = np.triu_indices(n_dims + 1)
    moments = np.zeros((n_states, n_dims + 1, n_dims + 1))
    moments[:, rows, cols] = pairs
    moments[:, cols, rows] = pairs
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
