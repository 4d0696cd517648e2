"""Compiled per-row recursions of the HMM (numba), in Rabiner's scaled form.

Mainly what is sequential in time is here: the forward and the backward recursion. Everything
that is a product or an elementwise pass over a block of rows (emission densities, their
exponential, the logarithms of the normalisers, expected transitions, moments) stays in
NumPy/BLAS, which vectorises it.

Conventions (all kernels):

- ``frames`` has shape (n_rows, n_states): the emission likelihoods of the rows of a block of
  consecutive recordings, each row scaled by a positive constant (the caller keeps the
  logarithms of the constants);
- ``starts`` / ``stops`` are the recording bounds within the block (int64 arrays);
- the forward variable of a row is divided by a normaliser ``c_t`` kept in ``scale`` (its sum,
  so that it sums to one; in training only when needed, see :func:`forward`): the
  log-likelihood of the block is ``sum_t log c_t`` plus the frame scales;
- the backward variable is divided by ``c_{t+1}`` at every step, so that the posterior is the
  product of the two.

Every sum over states is a dot product along a contiguous row (the transposed transition matrix
for the forward step, the transition matrix for the backward step). Each recursion is compiled
twice from one body: as written, and with reassociation allowed so that the compiler
vectorises those sums. With a handful of states the plain version is faster (no vector set-up
per row); from :data:`VECTORISED_STATES` states on the vectorised one is (about 2x at K=20).
"""

import numpy as np
from numba import njit

# Number of states from which the vectorised compilations are used (measured per EM iteration,
# 540,000 rows, D=3: equal at K=5, 10 % faster at K=6, 14 % at K=7; issue #27).
VECTORISED_STATES = 6

# The training forward pass (``rescale="lazy"``) rescales a row only when its total falls below
# this (or at a recording's last row); far above the smallest normal double, so that no state
# that still matters underflows, and the backward variables stay below 1 / RESCALE_BELOW.
RESCALE_BELOW = 1e-30

_VECTORISED = {"reassoc", "contract"}


@njit(inline="always")
def normalise_row(alpha, t, total):
    """Divide the forward variables of row ``t`` by their ``total``; returns ``log(total)``."""
    inverse = 1.0 / total
    for j in range(alpha.shape[1]):
        alpha[t, j] *= inverse
    return np.log(total)


@njit(inline="always")
def _forward_body(frames, starts, stops, startprob, transmat_t, alpha, scale, restart, lazy):
    n_states = frames.shape[1]
    log_likelihood = 0.0
    for r in range(starts.shape[0]):
        lo, hi = starts[r], stops[r]
        for t in range(lo, hi):
            total = 0.0
            for j in range(n_states):
                if t == lo:
                    prior = startprob[j]
                else:
                    prior = 0.0
                    for i in range(n_states):
                        prior += alpha[t - 1, i] * transmat_t[j, i]
                value = prior * frames[t, j]
                alpha[t, j] = value
                total += value
            if lazy and total >= RESCALE_BELOW and t != hi - 1:
                # The next row's recursion then does not wait for a division.
                scale[t] = 1.0
                continue
            if not total > 0.0:
                if not restart:
                    return -np.inf
                total = 0.0
                for j in range(n_states):
                    alpha[t, j] = frames[t, j]
                    total += frames[t, j]
            scale[t] = total
            log_likelihood += normalise_row(alpha, t, total)
    return log_likelihood


@njit(inline="always")
def _backward_body(frames, starts, stops, transmat, alpha, scale, posteriors, weighted):
    n_states = frames.shape[1]
    beta = np.empty(n_states)
    for r in range(starts.shape[0]):
        lo, hi = starts[r], stops[r]
        for t in range(hi - 1, lo - 1, -1):
            total = 0.0
            for i in range(n_states):
                if t == hi - 1:
                    value = 1.0
                else:
                    value = 0.0
                    for j in range(n_states):
                        value += transmat[i, j] * weighted[t + 1, j]
                beta[i] = value
                total += alpha[t, i] * value
            inverse = 1.0 / total
            for j in range(n_states):
                posteriors[j, t] = alpha[t, j] * beta[j] * inverse
            inverse = 0.0 if t == lo else 1.0 / scale[t]
            for j in range(n_states):
                weighted[t, j] = frames[t, j] * beta[j] * inverse


@njit(cache=True, nogil=True)
def _forward_plain(frames, starts, stops, startprob, transmat_t, alpha, scale, restart, lazy):
    return _forward_body(frames, starts, stops, startprob, transmat_t, alpha, scale, restart, lazy)


@njit(cache=True, nogil=True, fastmath=_VECTORISED)
def _forward_vectorised(frames, starts, stops, startprob, transmat_t, alpha, scale, restart, lazy):
    return _forward_body(frames, starts, stops, startprob, transmat_t, alpha, scale, restart, lazy)


@njit(cache=True, nogil=True)
def _backward_plain(frames, starts, stops, transmat, alpha, scale, posteriors, weighted):
    _backward_body(frames, starts, stops, transmat, alpha, scale, posteriors, weighted)


@njit(cache=True, nogil=True, fastmath=_VECTORISED)
def _backward_vectorised(frames, starts, stops, transmat, alpha, scale, posteriors, weighted):
    _backward_body(frames, starts, stops, transmat, alpha, scale, posteriors, weighted)


def forward(frames, starts, stops, startprob, transmat, alpha, scale, *, restart=False, lazy=False):
    """Scaled forward variables of every recording of a block.

    Parameters
    ----------
    frames : ndarray of shape (n_rows, n_states)
        Scaled emission likelihoods, C-contiguous.
    starts, stops : ndarray of int64
        Recording bounds within the block.
    startprob : ndarray of shape (n_states,)
    transmat : ndarray of shape (n_states, n_states)
    alpha : ndarray of shape (n_rows, n_states)
        Receives the forward variables.
    scale : ndarray of shape (n_rows,)
        Receives the normalisers ``c_t``; the log-likelihood of the block is the sum of their
        logarithms plus the frame scales.
    restart : bool, default=False
        What to do at a row that no state the transitions allow can explain (every product
        is zero): return False (training: the recording is impossible), or restart the
        recursion at that row from its frame probabilities alone (the causal filter, which
        must give an estimate).
    lazy : bool, default=False
        False: every row is normalised to sum to one (the filter reads them as state
        probabilities). True (training): a row is divided by its total only when the total
        falls below :data:`RESCALE_BELOW` and at the last row of every recording, ``c_t = 1``
        elsewhere (no logarithm to take there either). The recursion's dependency chain then
        holds no division (about twice as fast with few states); the last rows still sum to
        one, so :func:`backward_posteriors` and the expected transitions are unchanged. Any
        positive scales give the same posteriors and log-likelihood up to rounding.

    Returns
    -------
    log_likelihood : float
        ``sum_t log c_t``: with the frame scales, the log-likelihood of the block; ``-inf``
        when a row was impossible and ``restart`` is False (with restarts, the sum is not a
        likelihood).
    """
    kernel = _forward_vectorised if frames.shape[1] >= VECTORISED_STATES else _forward_plain
    transmat_t = np.ascontiguousarray(transmat.T)
    return kernel(frames, starts, stops, startprob, transmat_t, alpha, scale, restart, lazy)


def backward_posteriors(frames, starts, stops, transmat, alpha, scale, posteriors, weighted):
    """Backward recursion: state posteriors and the terms of the expected transitions.

    ``alpha`` and ``scale`` must come from :func:`forward` on the same block. On return
    ``posteriors`` (n_states, n_rows), state-major for the moment products, holds the
    posteriors of every row, and ``weighted`` (n_rows, n_states) holds
    ``frames[t] * beta_t / c_t``, zero at the first row of every recording, so that the
    expected transition counts of the block are ``(alpha[:-1].T @ weighted[1:]) * transmat``
    with no term crossing from one recording into the next.
    """
    kernel = _backward_vectorised if frames.shape[1] >= VECTORISED_STATES else _backward_plain
    kernel(frames, starts, stops, transmat, alpha, scale, posteriors, weighted)


@njit(cache=True, nogil=True)
def pairwise_products(columns, first, rows, cols, out):
    """``out[p, t] = columns[rows[p], first + t] * columns[cols[p], first + t]`` for every pair
    ``p`` and ``t < out.shape[1]``.

    ``columns`` is the whole C-contiguous array rather than a view of the chunk, and the loop
    runs over contiguous row slices of it: numba vectorises that loop, but neither one over a
    strided view nor one indexed by ``first + t`` (5x slower).
    """
    n_rows = out.shape[1]
    for p in range(rows.shape[0]):
        left = columns[rows[p], first : first + n_rows]
        right = columns[cols[p], first : first + n_rows]
        row = out[p]
        for t in range(n_rows):
            row[t] = left[t] * right[t]


# Rows per block of weighted_pair_sums: its columns and weighted row stay in L1.
PAIR_BLOCK_ROWS = 256


@njit(cache=True, nogil=True, fastmath={"reassoc", "contract"})
def weighted_pair_sums(columns, first, weights, out):
    """``out[s, p] += sum_t weights[s, t] x_a[first + t] x_b[first + t]`` for the pairs
    ``p = (a, b)``, ``a <= b``, of the rows of ``columns`` in the order of
    :func:`numpy.triu_indices`, and ``t < weights.shape[1]``.

    ``weights`` (n_states, n_rows) and ``columns`` are C-contiguous. Per block of rows in L1,
    each column is weighted once (``w x_a``) and then reduced against the columns after it:
    one multiply-add per pair and row, and no array of products (the reductions are
    reassociated, so they vectorise; the sums differ from a product with the pairwise
    products, :func:`pairwise_products`, by round-off).
    """
    n_states, n_rows = weights.shape
    n_columns = columns.shape[0]
    weighted = np.empty(PAIR_BLOCK_ROWS)
    for lo in range(0, n_rows, PAIR_BLOCK_ROWS):
        hi = min(lo + PAIR_BLOCK_ROWS, n_rows)
        for s in range(n_states):
            w = weights[s, lo:hi]
            p = 0
            for a in range(n_columns):
                left = columns[a, first + lo : first + hi]
                for t in range(hi - lo):
                    weighted[t] = w[t] * left[t]
                for b in range(a, n_columns):
                    right = columns[b, first + lo : first + hi]
                    total = 0.0
                    for t in range(hi - lo):
                        total += weighted[t] * right[t]
                    out[s, p] += total
                    p += 1


# Below this, exp() of a log-density difference is subnormal (exp(-708.4) is the smallest
# normal double): such a frame is set to zero, which changes no sum it enters (every row also
# holds a frame of exactly one) and avoids the slow subnormal path of exp. It can make a row
# impossible only together with an exact-zero transition, which the M-step rules out
# (``_em.PROBABILITY_FLOOR``).
UNDERFLOW = -708.0


def _numpy_exp_is_vectorised():
    """Whether NumPy's double-precision exp runs on AVX-512 on this CPU (about 0.9 ns a value;
    elsewhere, as on AVX2 CPUs, it is a scalar exp of about 5 ns, like the compiled one)."""
    try:
        from numpy._core._multiarray_umath import __cpu_features__
    except ImportError:  # NumPy 1.x
        from numpy.core._multiarray_umath import __cpu_features__
    return bool(__cpu_features__.get("AVX512F", False))


NUMPY_VECTOR_EXP = _numpy_exp_is_vectorised()


def scaled_densities(projected, norms, frames, top):
    """Emission likelihoods of a chunk, scaled to a maximum of one per row.

    ``projected`` (n_states * n_features, n_rows) is the product of the stacked factors with the
    chunk's augmented columns (:func:`~skhmmgmr._hmm._gaussian.stack_gaussians`): the log-density
    of row ``t`` under state ``k`` is ``norms[k]`` minus the squares of its ``n_features``
    rows. Writes ``top[t]``, the largest log-density of row ``t``, and
    ``frames[t, k] = exp(log_density[k, t] - top[t])`` (row-major, as the recursions read it);
    frames below ``exp(UNDERFLOW)`` are zero.

    One compiled pass. Where NumPy's exp is vectorised (:data:`NUMPY_VECTOR_EXP`) the pass
    writes the differences and NumPy exponentiates them all in place, 0.9 ns a value against
    4.3 ns for the compiled exp: 1.5-1.9x faster from 2 to 20 states (measured, one core,
    AVX-512). Elsewhere the pass takes the exp itself, only where the value is not known in
    advance (one at the row's largest, zero below the underflow).
    """
    _scaled_densities(projected, norms, frames, top, not NUMPY_VECTOR_EXP)
    if NUMPY_VECTOR_EXP:
        np.exp(frames, out=frames)


@njit(cache=True, nogil=True)
def _scaled_densities(projected, norms, frames, top, exponentiate):
    """:func:`scaled_densities`; without ``exponentiate``, ``frames`` receives the differences
    ``log_density[k, t] - top[t]`` (-inf below ``UNDERFLOW``) for the caller's exp."""
    n_states = norms.shape[0]
    n_features = projected.shape[0] // n_states
    n_rows = projected.shape[1]
    log_density = np.empty((n_states, n_rows))
    for k in range(n_states):
        for t in range(n_rows):
            log_density[k, t] = norms[k]
        for d in range(k * n_features, (k + 1) * n_features):
            for t in range(n_rows):
                value = projected[d, t]
                log_density[k, t] -= value * value
    for t in range(n_rows):
        largest = log_density[0, t]
        for k in range(1, n_states):
            largest = max(largest, log_density[k, t])
        top[t] = largest
        for k in range(n_states):
            difference = log_density[k, t] - largest
            if not exponentiate:
                frames[t, k] = difference if difference >= UNDERFLOW else -np.inf
            elif difference == 0.0:
                frames[t, k] = 1.0
            elif difference < UNDERFLOW:
                frames[t, k] = 0.0
            else:
                frames[t, k] = np.exp(difference)
