"""Missing values (NaN) handled by the model: Gaussians conditioned on a row's observed columns.

A row whose columns ``o`` are observed and ``m`` missing enters the model through its observed
columns only (the standard missing-data EM for Gaussians). Under a state's Gaussian
``N(mu, S)``:

- the row's density is the marginal ``N(x_o; mu_o, S_oo)``, and 1 when nothing is observed
  (the forward variable then only passes through the transition matrix);
- the missing columns have the conditional mean ``E[x_m | x_o] = mu_m + S_mo S_oo^-1 (x_o -
  mu_o)`` and the conditional covariance ``S_mm - S_mo S_oo^-1 S_om``.

Both are computed row by row from the state's precision ``L = S^-1``, with no factorisation
of ``S_oo`` per pattern of missing columns: the conditional covariance is ``(L_mm)^-1``, the
conditional mean ``mu_m - (L_mm)^-1 L_mo (x_o - mu_o)``, ``log det S_oo = log det S + log det
L_mm``, and the Mahalanobis distance of ``x_o`` under ``S_oo`` is the full one of the row
completed by its conditional mean (the minimum over ``x_m``), a sum of squares with no
cancellation. The emission model gives what this needs whatever the form of its covariances
(:meth:`~skhmmgmr._hmm._emissions.GaussianEmissions.precisions`, ``precision_times``,
``mahalanobis``, ``half_log_det_precision``). Rows are grouped by their number
``r`` of missing columns only: each group costs a few batched products and ``r x r``
inversions, whatever the patterns of missing columns.

Three users:

- the EM engine (:class:`~skhmmgmr._hmm._em_data.EStepData`): the missing values are set to zero in
  the engine's columns (to the shift), so that the fast moment sums of every row (and the
  moments of all rows, from which the remainder state's are taken) hold the weights and the
  observed values of these rows; their frames are overwritten by the marginal densities
  (:meth:`MissingRows.overwrite`), and what the missing columns add to the moments of every
  state is added block by block (:meth:`MissingRows.moments`): with ``x_hat`` the row
  completed by its conditional mean in state ``k`` and ``V_k`` its conditional covariance
  (on the missing block), ``sum_t g_tk (x_hat - x)`` to the first moments and
  ``sum_t g_tk (x_hat x_hat^T - x x^T + V_k)`` to the second;
- the GMR filter (:mod:`skhmmgmr._hmm._gmr`): the gating density of the observed inputs, and in
  every state the mean of the outputs given the observed inputs (the state's regression
  applied to the inputs completed by their conditional mean), whose covariance gains
  ``coef_m V coef_m^T`` (:func:`gmr_given_observed`); with no input observed, these are the
  state's output mean and covariance;
- :class:`~skhmmgmr.FilterStream`, one row at a time (:func:`gmr_given_observed`).
"""

from dataclasses import dataclass

import numpy as np

LOG_2PI = np.log(2.0 * np.pi)

# Rows with missing values are conditioned in chunks of at most this many rows, so that the
# temporaries (rows x states x columns) stay small.
CHUNK_ROWS = 8192


@dataclass
class RowConditionals:
    """Every state's Gaussian given the observed columns of each of ``n`` rows.

    ``log_prob`` (n, K): the marginal log-densities of the observed columns. ``deltas``
    (K, n, D): the completion of every row minus the row (its conditional mean in the missing
    columns, about the shift, zero in the observed ones). ``groups``: per number ``r`` of
    missing columns, ``(rows, columns, covariances)``: the rows (n_r,), their missing columns
    (n_r, r) and the conditional covariances of those (K, n_r, r, r).
    """

    log_prob: np.ndarray
    deltas: np.ndarray
    groups: list


def condition_rows(emissions, x, missing, shift=None, stale=None):
    """:class:`RowConditionals` of rows ``x`` (n, D) about ``shift``, zero where ``missing``
    (bool, n x D), under every state of ``emissions``.

    ``stale``: ``(carried, precisions)``, both (n, D), for values read through their last
    observed value (:mod:`skhmmgmr._hmm._stale_inputs`): a missing column with a positive precision
    ``1 / v`` is observed through ``carried`` (about ``shift``) with noise variance ``v``; its
    block of the precision gains ``1 / v`` on the diagonal and its completion is the Kalman
    update of the conditional mean by the carried value.
    """
    centres = emissions.means if shift is None else emissions.means - shift
    deltas = np.where(missing, 0.0, x[np.newaxis] - centres[:, np.newaxis, :])  # d = x - mu
    gradients = emissions.precision_times(deltas)  # L d for every row and state, L = S^-1
    precisions = emissions.precisions()
    n_missing = missing.sum(axis=1)
    log_det_missing = np.zeros(deltas.shape[:2])
    n_seen = missing.shape[1] - n_missing  # observed values, carried ones included
    if stale is not None:
        carried, weights = stale  # weights: the carried values' precisions 1 / v
        # z - mu where a value is carried; L d - diag(1/v) (z - mu) replaces L d below.
        stale_deltas = np.where(weights > 0, carried[np.newaxis] - centres[:, np.newaxis], 0.0)
        gradients -= weights * stale_deltas
        n_seen = n_seen + np.count_nonzero(weights, axis=1)
    groups = []
    for r in np.unique(n_missing[n_missing > 0]):
        rows = np.flatnonzero(n_missing == r)
        columns = np.nonzero(missing[rows])[1].reshape(-1, r)
        block = precisions[:, columns[:, :, np.newaxis], columns[:, np.newaxis, :]]
        if stale is not None:
            added = weights[rows[:, np.newaxis], columns]  # (n_r, r)
            block = block + added[..., np.newaxis] * np.eye(r)
            with np.errstate(divide="ignore"):
                log_noise = np.where(added > 0, np.log(added), 0.0).sum(axis=1)
            log_det_missing[:, rows] -= log_noise  # + sum log v of the carried values
        if r == 1:  # the most common group: no LAPACK call per row
            covariances = 1.0 / block
            log_det_missing[:, rows] += np.log(block[..., 0, 0])
        else:
            covariances = np.linalg.inv(block)  # (L_mm)^-1, the conditional covariance
            log_det_missing[:, rows] += np.linalg.slogdet(block)[1]
        shifts = covariances @ gradients[:, rows[:, np.newaxis], columns][..., np.newaxis]
        # x_hat_m - mu_m = -(L_mm)^-1 L_mo d_o, and L_mo d_o = (L d)_m while d_m = 0
        deltas[:, rows[:, np.newaxis], columns] = -shifts[..., 0]
        groups.append((rows, columns, covariances))
    distances = emissions.mahalanobis(deltas)  # completed: x_o's own
    if stale is not None:  # and the carried values' distance to the completion
        distances += np.sum(weights * np.square(stale_deltas - deltas), axis=2)
    log_det = emissions.half_log_det_precision()
    log_prob = log_det[:, np.newaxis] - 0.5 * (distances + log_det_missing + n_seen * LOG_2PI)
    # From x_hat - mu to x_hat - x: x is zero in the missing columns, d in the observed ones.
    deltas = np.where(missing, deltas + centres[:, np.newaxis, :], 0.0)
    return RowConditionals(log_prob.T, deltas, groups)


def gmr_given_observed(params, x, missing, stale=None):
    """GMR of standardised input rows ``x`` (n, F), zero where ``missing``, given their
    observed inputs (and carried values, ``stale``: see :func:`condition_rows`): the gating
    log-densities (n, K), every state's output means and the variances added to its
    conditional variances, both (n, K, n_outputs).

    ``params`` is a :class:`~skhmmgmr._hmm._gmr.GMRParameters`.
    """
    conditionals = condition_rows(params.gating, x, missing, stale=stale)
    completed = conditionals.deltas + x
    means = completed @ params.coef.transpose(0, 2, 1) + params.intercept[:, np.newaxis, :]
    added = np.zeros_like(means)
    for rows, columns, covariances in conditionals.groups:
        coef = params.coef[:, :, columns]  # (K, n_outputs, n_r, r)
        added[:, rows] = np.einsum("konr,knrs,kons->kno", coef, covariances, coef)
    return conditionals.log_prob, means.transpose(1, 0, 2), added.transpose(1, 0, 2)


class MissingRows:
    """The rows of columns ``values`` (D, n_rows) that miss a value.

    ``values`` are the engine's augmented columns without their row of ones (about ``shift``)
    or the transposed rows of standardised inputs. With ``fill=True`` the missing values are
    set to zero in place (see the module docstring). ``stale``: ``(noise, starts, stops)``,
    a :class:`~skhmmgmr._hmm._stale_inputs.StaleInputNoise` of the first columns and the bounds of
    the recordings, to read missing values through their last observed value.

    Attributes
    ----------
    rows : ndarray of int
        The rows with a missing value, increasing.
    missing : ndarray of bool of shape (len(rows), D)
        Their missing columns.
    """

    def __init__(self, values, shift=None, *, fill=False, stale=None):
        nan = np.isnan(values)
        self.rows = np.flatnonzero(nan.any(axis=0))
        self.missing = np.ascontiguousarray(nan[:, self.rows].T)
        self.stale = None
        if stale is not None:
            noise, starts, stops = stale
            carried = np.zeros(self.missing.shape)
            precisions = np.zeros(self.missing.shape)
            n_read = noise.variances.shape[0]
            read = noise.read(values[:n_read].T, starts, stops)
            carried[:, :n_read], precisions[:, :n_read] = (part[self.rows] for part in read)
            self.stale = (carried, precisions)
        if fill:
            values[nan] = 0.0
        self.values, self.shift = values, shift

    @classmethod
    def of(cls, values, shift=None, *, fill=False, stale=None):
        """:class:`MissingRows` of ``values``, or None when no value is missing."""
        if not np.isnan(np.sum(values)):
            return None
        missing = cls(values, shift, fill=fill, stale=stale)
        return missing if missing.rows.size else None

    def _chunks(self, start, stop):
        """``(rows - start, x, missing, stale)`` of the rows ``start:stop`` with a missing value,
        in chunks; ``x`` (n, D) holds zeros where values are missing."""
        lo, hi = np.searchsorted(self.rows, [start, stop])
        for first in range(lo, hi, CHUNK_ROWS):
            part = slice(first, min(first + CHUNK_ROWS, hi))
            x = self.values[:, self.rows[part]].T
            x[self.missing[part]] = 0.0
            stale = None if self.stale is None else tuple(a[part] for a in self.stale)
            yield self.rows[part] - start, x, self.missing[part], stale

    def overwrite(self, emissions, start, stop, frames, top):
        """Write the marginal densities of the rows ``start:stop`` that miss a value into
        ``frames`` and ``top`` (those of rows ``start:stop``: the densities scaled to a maximum
        of one per row, and the logarithms of the scales)."""
        for rows, x, missing, stale in self._chunks(start, stop):
            log_prob = condition_rows(emissions, x, missing, self.shift, stale).log_prob
            top[rows] = log_prob.max(axis=1)
            frames[rows] = np.exp(log_prob - top[rows, np.newaxis])

    def moments(self, emissions, posteriors, start, stop):
        """Augmented moments (K, D + 1, D + 1) that the missing values of rows ``start:stop``
        add to their moment sums, given the rows' posteriors (K, stop - start)."""
        n_states, n_dims = emissions.n_states, self.values.shape[0]
        second = np.zeros((n_states, n_dims, n_dims))
        first = np.zeros((n_states, n_dims))
        for rows, x, missing, stale in self._chunks(start, stop):
            conditionals = condition_rows(emissions, x, missing, self.shift, stale)
            weights = posteriors[:, rows]
            weighted = conditionals.deltas * weights[:, :, np.newaxis]
            first += weighted.sum(axis=1)
            cross = weighted.transpose(0, 2, 1) @ x
            second += cross + cross.transpose(0, 2, 1)
            second += weighted.transpose(0, 2, 1) @ conditionals.deltas
            for group_rows, columns, covariances in conditionals.groups:
                weighted_covariances = covariances * weights[:, group_rows, np.newaxis, np.newaxis]
                flat = (
                    np.arange(n_states)[:, np.newaxis, np.newaxis, np.newaxis] * n_dims**2
                    + columns[:, :, np.newaxis] * n_dims
                    + columns[:, np.newaxis, :]
                )
                flat = np.broadcast_to(flat, weighted_covariances.shape)
                second += np.bincount(
                    flat.ravel(), weighted_covariances.ravel(), minlength=second.size
                ).reshape(second.shape)
        moments = np.zeros((n_states, n_dims + 1, n_dims + 1))
        moments[:, :n_dims, :n_dims] = second
        moments[:, :n_dims, n_dims] = moments[:, n_dims, :n_dims] = first
        return moments

    def outputs(self, params):
        """GMR of the rows given their observed inputs: the state output means and added
        variances, both (len(rows), K, n_outputs); ``params`` is a ``GMRParameters``."""
        n_states, n_outputs = params.intercept.shape
        means = np.empty((self.rows.size, n_states, n_outputs))
        added = np.empty_like(means)
        first = 0
        for rows, x, missing, stale in self._chunks(0, self.values.shape[1]):
            part = slice(first, first + rows.size)
            _, means[part], added[part] = gmr_given_observed(params, x, missing, stale)
            first += rows.size
        return means, added


def observed_counts(*blocks):
    """Rows, or per column the number of observed (non-NaN) values of ``hstack(blocks)``."""
    if not any(np.isnan(np.sum(block)) for block in blocks):  # complete: one pass, no mask
        return blocks[0].shape[0]
    counts = np.concatenate([np.sum(~np.isnan(block), axis=0) for block in blocks])
    n_rows = blocks[0].shape[0]
    return n_rows if np.all(counts == n_rows) else counts
