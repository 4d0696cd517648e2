"""The E-step as one compiled pass per block of recordings (numba), blocks on several threads.

What :mod:`skhmmgmr._hmm._em` otherwise does in stages (BLAS products for the densities, the
recursions of :mod:`skhmmgmr._hmm._kernels`, BLAS products for the expected transitions and the
moments) is done here row by row while the row is in registers:

1. forward: the projections of the row's augmented column on the stacked factors of every
   state (:func:`~skhmmgmr._hmm._gaussian.stack_gaussians`, one long loop that vectorises), the
   log-densities, the frames scaled to a maximum of one (no exponential where the value is
   known: one at the largest, zero below :data:`~skhmmgmr._hmm._kernels.UNDERFLOW`), and the
   forward variables, rescaled lazily as in :func:`~skhmmgmr._hmm._kernels.forward`;
2. backward: the posteriors of the row, added at once to the weighted moments (the pairwise
   products ``x_a x_b``, ``a <= b``, of the row's augmented column, in the order of
   :func:`numpy.triu_indices`) of every accumulated state, the terms of the expected
   transitions (``alpha_t(i) b_j(x_{t+1}) beta_{t+1}(j) / c_{t+1}``, times the transition
   matrix by the caller) and the backward variables of the previous row.

Each block (:class:`~skhmmgmr._hmm._em_data.EStepData`'s blocks of whole recordings) has its own
accumulators; they are summed in block order, so the result does not depend on the number of
threads: numba's (:func:`numba.get_num_threads`, so ``NUMBA_NUM_THREADS``, which joblib sets
to one in its workers, applies), each running a contiguous run of blocks of about equal rows.
Why fused: with few columns and states the staged E-step is dominated by passes over
memory and per-block overhead, not by arithmetic (issue #27); fused, an iteration reads the
data once and the work runs on every core.

Used for complete data and Gaussian emissions on more than one thread (:func:`applies`); rows
with missing values, and a single thread, take the staged path.
"""

import os
from concurrent.futures import ThreadPoolExecutor
from functools import partial

import numpy as np
from numba import get_num_threads, njit

from ._kernels import RESCALE_BELOW, UNDERFLOW, normalise_row

# Reassociation lets the compiler vectorise the sums over states and columns; the results
# differ from the staged E-step's by round-off (tests/test_fused_estep.py: 1e-10).
_FASTMATH = {"reassoc", "contract"}


@njit(inline="always", cache=True, nogil=True, fastmath=_FASTMATH, error_model="numpy")
def state_log_densities(projection, norms, n_dims, log_density):
    """Fill ``log_density[k]`` of every state ``k`` from a row's projections on the stacked
    factors (``norms[k]`` minus the squared norm of state ``k``'s ``n_dims`` projections);
    return the largest. Inlined where it is called: one row's step of the fused pass and of
    :func:`~skhmmgmr._hmm._gmr_scores.error_sums`."""
    top = -np.inf
    for k in range(norms.shape[0]):
        half = 0.0
        for m in range(k * n_dims, (k + 1) * n_dims):
            half += projection[m] * projection[m]
        log_density[k] = norms[k] - half
        top = max(top, log_density[k])
    return top


@njit(cache=True, nogil=True, fastmath=_FASTMATH, error_model="numpy")
def _forward(values, lo, hi, stacked, norms, startprob, transmat, frames, alpha, scale):
    """Forward pass over rows ``lo:hi`` of ``values`` into rows ``0:hi-lo`` of the buffers.

    Returns ``(sum of the largest log-densities + sum of log c_t)``, -inf when a row is
    impossible."""
    n_columns = values.shape[0]
    n_states = norms.shape[0]
    n_dims = n_columns - 1
    projection = np.empty(stacked.shape[1])
    log_density = np.empty(n_states)
    log_likelihood = 0.0
    for t in range(hi - lo):
        for m in range(projection.shape[0]):
            projection[m] = stacked[n_dims, m]  # the offsets, times the column's one
        for a in range(n_dims):
            value = values[a, lo + t]
            for m in range(projection.shape[0]):
                projection[m] += value * stacked[a, m]
        top = state_log_densities(projection, norms, n_dims, log_density)
        log_likelihood += top
        total = 0.0
        for j in range(n_states):
            difference = log_density[j] - top
            if difference == 0.0:
                frame = 1.0
            elif difference < UNDERFLOW:
                frame = 0.0
            else:
                frame = np.exp(difference)
            frames[t, j] = frame
            if t == 0:
                prior = startprob[j]
            else:
                prior = 0.0
                for i in range(n_states):
                    prior += alpha[t - 1, i] * transmat[i, j]
            alpha[t, j] = prior * frame
            total += alpha[t, j]
        if total >= RESCALE_BELOW and t != hi - lo - 1:
            scale[t] = 1.0
            continue
        if not total > 0.0:
            return -np.inf
        scale[t] = total
        log_likelihood += normalise_row(alpha, t, total)
    return log_likelihood


@njit(cache=True, nogil=True, fastmath=_FASTMATH, error_model="numpy")
def _backward(values, lo, hi, transmat, frames, alpha, scale, states, moments, transitions, starts):
    """Backward pass over rows ``lo:hi`` after :func:`_forward`: adds the moments of
    ``states`` (one row of ``moments`` each), the terms of the expected transitions and the
    first row's posteriors."""
    n_columns = values.shape[0]
    n_states = transmat.shape[0]
    n_pairs = moments.shape[1]
    beta = np.ones(n_states)
    weighted = np.empty(n_states)
    column = np.empty(n_columns)
    pairs = np.empty(n_pairs)
    for t in range(hi - lo - 1, -1, -1):
        for a in range(n_columns):
            column[a] = values[a, lo + t]
        p = 0
        for a in range(n_columns):
            for b in range(a, n_columns):
                pairs[p] = column[a] * column[b]
                p += 1
        total = 0.0
        for k in range(n_states):
            total += alpha[t, k] * beta[k]
        inverse = 1.0 / total
        for s in range(states.shape[0]):
            k = states[s]
            posterior = alpha[t, k] * beta[k] * inverse
            for p in range(n_pairs):
                moments[s, p] += posterior * pairs[p]
        if t == 0:
            for k in range(n_states):
                starts[k] += alpha[t, k] * beta[k] * inverse
            break
        inverse = 1.0 / scale[t]
        for j in range(n_states):
            weighted[j] = frames[t, j] * beta[j] * inverse
        for i in range(n_states):
            previous = alpha[t - 1, i]
            value = 0.0
            for j in range(n_states):
                transitions[i, j] += previous * weighted[j]
                value += transmat[i, j] * weighted[j]
            beta[i] = value


@njit(cache=True, nogil=True, error_model="numpy")
def _block_range(first, last, data, parameters, states, backward, out):
    """Blocks ``first:last`` (recordings ``edges[b]:edges[b + 1]``, rows
    ``firsts[r]:lasts[r]``), each into its own row of the accumulators ``out``."""
    values, edges, firsts, lasts = data
    stacked, norms, startprob, transmat = parameters
    log_likelihoods, moments, transitions, starts = out
    n_states = norms.shape[0]
    for b in range(first, last):
        longest = 0
        for r in range(edges[b], edges[b + 1]):
            longest = max(longest, lasts[r] - firsts[r])
        frames = np.empty((longest, n_states))
        alpha = np.empty((longest, n_states))
        scale = np.empty(longest)
        for r in range(edges[b], edges[b + 1]):
            lo, hi = firsts[r], lasts[r]
            log_likelihoods[b] += _forward(
                values, lo, hi, stacked, norms, startprob, transmat, frames, alpha, scale
            )
            if log_likelihoods[b] == -np.inf:
                break  # an impossible recording: the caller raises
            if backward:
                _backward(
                    values,
                    lo,
                    hi,
                    transmat,
                    frames,
                    alpha,
                    scale,
                    states,
                    moments[b],
                    transitions[b],
                    starts[b],
                )


_POOL = {}


def _run_in_threads(tasks):
    """Run the callables ``tasks`` on as many threads (the kernels release the GIL).

    A pool of Python threads rather than numba's ``prange``: its workers wait on a lock when
    idle, where OpenMP's spin, which on a loaded machine made an E-step up to 15x slower than
    on one thread (measured, 2 cores, issue #27). The pool belongs to the process that made it.
    """
    key = (os.getpid(), len(tasks))
    if key not in _POOL:
        _POOL.clear()
        _POOL[key] = ThreadPoolExecutor(max_workers=len(tasks))
    for future in [_POOL[key].submit(task) for task in tasks]:
        future.result()


def applies(engine, density):
    """Whether the fused E-step serves this fit: complete data, stacked Gaussian factors and
    more than one thread (numba's) over more than one block.

    On one thread the staged E-step is faster (measured, one core: 1.2x at D=3, K=5 to 2x at
    D=12, K=2: its BLAS products vectorise across rows, the fused loops only across states and
    columns); the fused one runs its blocks on every core (issue #27).
    """
    return (
        engine.missing is None
        and hasattr(density, "factors")
        and len(engine.blocks) > 1
        and get_num_threads() > 1
    )


def _layout(engine):
    """Block edges (into the recordings) and the first and last + 1 rows of every recording."""
    edges, firsts, lasts = [0], [], []
    for start, _, rec_starts, rec_stops in engine.blocks:
        firsts.append(start + rec_starts)
        lasts.append(start + rec_stops)
        edges.append(edges[-1] + len(rec_starts))
    return (
        np.asarray(edges, dtype=np.int64),
        np.concatenate(firsts).astype(np.int64),
        np.concatenate(lasts).astype(np.int64),
    )


def fused_pass(engine, params, density, states, backward=True):
    """One fused pass over all recordings.

    Returns ``(log_likelihood, start_counts, transition_sums, pair_sums)``: the
    log-likelihood, the posteriors of the first rows, the expected transitions before the
    product with the transition matrix and the moments of ``states`` as pairwise sums
    (``len(states), n_pairs``; see :meth:`~skhmmgmr._hmm._gaussian.MomentSums.add_pair_sums`).
    """
    factors, norms = density.factors, density.norms[:, 0]
    n_dims, n_states = engine.data.n_features, norms.shape[0]
    # (n_dims + 1, n_states * n_dims): the factors of all states side by side, offsets last.
    stacked = np.ascontiguousarray(factors.T)
    assert stacked.shape == (n_dims + 1, n_states * n_dims)
    edges, firsts, lasts = _layout(engine)
    data = (engine.data.values, edges, firsts, lasts)
    parameters = (
        stacked,
        np.ascontiguousarray(norms),
        np.ascontiguousarray(params.startprob, dtype=float),
        np.ascontiguousarray(params.transmat, dtype=float),
    )
    states = np.asarray(states, dtype=np.int64)
    n_blocks, n_columns = len(edges) - 1, n_dims + 1
    out = (
        np.zeros(n_blocks),
        np.zeros((n_blocks, len(states), n_columns * (n_columns + 1) // 2)),
        np.zeros((n_blocks, n_states, n_states)),
        np.zeros((n_blocks, n_states)),
    )
    # contiguous runs of blocks of about equal rows, one per thread
    rows = np.concatenate([[0], np.cumsum(lasts - firsts)[edges[1:] - 1]])
    n_threads = max(min(get_num_threads(), n_blocks), 1)
    cuts = np.searchsorted(rows, np.linspace(0, rows[-1], n_threads + 1)[1:-1])
    bounds = np.unique(np.concatenate([[0], cuts, [n_blocks]])).tolist()
    tasks = [
        partial(_block_range, first, last, data, parameters, states, backward, out)
        for first, last in zip(bounds[:-1], bounds[1:], strict=True)
    ]
    if len(tasks) == 1:
        tasks[0]()
    else:
        _run_in_threads(tasks)
    log_likelihoods, moments, transitions, starts = out
    # summed in block order: the same result on any number of threads
    return (
        float(np.sum(log_likelihoods)),
        starts.sum(axis=0),
        transitions.sum(axis=0),
        moments.sum(axis=0),
    )
