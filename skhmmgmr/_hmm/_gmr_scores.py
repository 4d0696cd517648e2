"""The causal GMR estimate scored as it is filtered: one compiled pass over the rows of every
recording (numba), no array of the size of the data.

What :func:`~skhmmgmr._hmm._gmr.filter_state_probabilities` and
:func:`~skhmmgmr._hmm._gmr.gmr_estimates` compute in stages (the input densities of every
state, the normalised forward recursion on them, restarted at a row no state explains, the
per-state conditional means mixed by the filtered probabilities) is done here row by row, and
each estimate is compared with the observed output at once: per recording, the sum of the
squared errors and the sum and sum of squares of the estimate's steps (from one row to the
next) are kept, which is what the accuracy and the smoothness of the estimate are read from
(:func:`error_sums`). It serves searches that score many models on the same validation
recordings (the selection's fast search): the inputs are read in place, a subset of the
columns by their indices, without a copy.

Complete data, one output, no read-out; the estimate is that of ``predict`` to round-off
(``tests/test_gmr_scores.py``).
"""

import numpy as np
from numba import njit

from ._fused_estep import state_log_densities


@njit(cache=True, nogil=True, fastmath={"reassoc", "contract"}, error_model="numpy")
def _error_sums(
    X, columns, starts, stops, startprob, transmat, factors, norms, coef, intercept, y, units, out
):
    """Fill ``out[r] = (squared errors, sum of steps, sum of squared steps)`` of recording
    ``r``; ``units = (output centre, output scale)`` of the estimate."""
    n_states = norms.shape[0]
    n_dims = columns.shape[0]
    x = np.empty(n_dims)
    projection = np.empty(factors.shape[1])
    log_density = np.empty(n_states)
    frames = np.empty(n_states)
    previous = np.empty(n_states)
    alpha = np.empty(n_states)
    for r in range(starts.shape[0]):
        squared, steps, squared_steps, last = 0.0, 0.0, 0.0, 0.0
        for t in range(starts[r], stops[r]):
            for m in range(projection.shape[0]):
                projection[m] = factors[n_dims, m]  # the offsets, times the column's one
            for a in range(n_dims):
                x[a] = X[t, columns[a]]
                for m in range(projection.shape[0]):
                    projection[m] += x[a] * factors[a, m]
            top = state_log_densities(projection, norms, n_dims, log_density)
            total = 0.0
            for j in range(n_states):
                frames[j] = np.exp(log_density[j] - top)
                if t == starts[r]:
                    prior = startprob[j]
                else:
                    prior = 0.0
                    for i in range(n_states):
                        prior += previous[i] * transmat[i, j]
                alpha[j] = prior * frames[j]
                total += alpha[j]
            if not total > 0.0:  # no state the transitions allow explains the row: restart
                total = 0.0
                for j in range(n_states):
                    alpha[j] = frames[j]
                    total += frames[j]
            estimate = 0.0
            for j in range(n_states):
                alpha[j] /= total
                previous[j] = alpha[j]
                mean = intercept[j]
                for a in range(n_dims):
                    mean += coef[j, a] * x[a]
                estimate += alpha[j] * mean
            estimate = units[0] + units[1] * estimate
            error = estimate - y[t]
            squared += error * error
            if t > starts[r]:
                step = estimate - last
                steps += step
                squared_steps += step * step
            last = estimate
        out[r, 0] = squared
        out[r, 1] = steps
        out[r, 2] = squared_steps


def error_sums(X, columns, recordings, gmr, y, output_center, output_scale):
    """Per recording: the squared errors of the causal GMR estimate and its steps' sums.

    Parameters
    ----------
    X : ndarray of shape (n_samples, n_all)
        Standardised inputs (any memory layout); the model reads the columns ``columns``.
    columns : sequence of int
        The model's inputs, in its order.
    recordings : Recordings
        Bounds of the recordings of ``X`` (the filter restarts at each).
    gmr : GMRParameters
        The model's read-out (:func:`~skhmmgmr._hmm._gmr.condition_on_inputs`), one output,
        in the units of ``X``.
    y : ndarray of shape (n_samples,)
        Observed output, in the data's units.
    output_center, output_scale : float
        The estimate in the data's units is ``output_center + output_scale * estimate``.

    Returns
    -------
    sums : ndarray of shape (n_recordings, 3)
        Per recording: the sum of squared errors, the sum of the estimate's steps
        ``e[t] - e[t-1]`` and the sum of their squares.
    """
    density = gmr.gating.density()
    if gmr.coef.shape[1] != 1:
        raise ValueError(f"error_sums scores one output, the model has {gmr.coef.shape[1]}")
    out = np.empty((len(recordings), 3))
    _error_sums(
        X,
        np.asarray(columns, dtype=np.int64),
        np.asarray(recordings.starts, dtype=np.int64),
        np.asarray(recordings.stops, dtype=np.int64),
        np.ascontiguousarray(gmr.startprob, dtype=float),
        np.ascontiguousarray(gmr.transmat, dtype=float),
        np.ascontiguousarray(density.factors.T),  # (n_dims + 1, n_states * n_dims)
        np.ascontiguousarray(density.norms[:, 0]),
        np.ascontiguousarray(gmr.coef[:, 0, :]),
        np.ascontiguousarray(gmr.intercept[:, 0]),
        np.asarray(y, dtype=float),
        np.array([output_center, output_scale], dtype=float),
        out,
    )
    return out
