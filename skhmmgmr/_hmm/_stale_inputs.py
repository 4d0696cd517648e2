"""Missing inputs read through their last observed value (``missing_values="carry_forward"``).

A sensor that drops a sample still said something a moment before. With
``missing_values="carry_forward"`` a missing input ``x_j(t)`` is read through the last value
``z_j = x_j(t - g)`` observed ``g`` samples earlier in the same recording, as a noisy
observation of it: ``z_j = x_j(t) + e_j`` with ``e_j ~ N(0, v_j(g))`` independent of the state.
``v_j(g)`` is the column's *variogram*, the mean squared difference of its values ``g``
samples apart (``E[(x_j(t) - x_j(t - g))^2]``), learned in ``fit`` from the pairs of observed
values within the training recordings (standardised units), tabulated at :data:`LAGS` and
interpolated linearly in between.

Under a state's Gaussian ``N(mu, S)`` the row's observed inputs and its carried values are
then jointly Gaussian with covariance ``S + diag(v)`` (``v`` zero on the observed columns),
so the conditioning of :mod:`skhmmgmr._hmm._missing` carries over with the missing columns' block
of the precision ``L_mm`` replaced by ``L_mm + diag(1 / v)``: the row's density, the
completion of its missing inputs and their conditional covariance are those of a Kalman
update of ``x_m | x_o`` by the measurement ``z``. The two limits are the other strategies: with
``v`` infinite the value is marginalised (``"marginalize"``), with ``v = 0`` it is forward-filled
and trusted as if observed. A value with no observed predecessor in its recording, or older
than the longest lag learned, is marginalised; so is a column whose variogram could not be
learned (no two observed values that far apart).
"""

import math
from dataclasses import dataclass

import numpy as np

MISSING_VALUES = ("error", "marginalize", "carry_forward")

# Lags (samples) at which the variogram is tabulated: dense where it changes fast.
LAGS = np.array([1, 2, 3, 4, 5, 6, 8, 10, 12, 16, 20, 24, 32, 40, 48, 64, 80, 96, 128])
# Pairs of values per lag from which a variogram is learned (an evenly spaced sample).
MAX_PAIRS = 200_000
# The smallest variance of a carried value (standardised units): a constant column's variogram
# is floored at it, and a model file may not go below it (1 / 1e-320 overflows the update).
MIN_VARIANCE = 1e-12
# The longest tabulated gap a model file may hold, in samples (about 6 days at 100 Hz).
MAX_LAG = 2**26


def last_observed(values, starts, stops):
    """The last observed value of every missing entry and how many samples ago it was seen.

    ``values`` (n_samples, n_columns) hold NaN where missing; ``starts``/``stops`` bound the
    recordings (rows in order within each). Returns ``(carried, gaps)``: ``carried`` the value
    (NaN where it is observed or has no observed predecessor in its recording) and ``gaps``
    (int) the number of samples since it (0 where it is observed or has none).
    """
    n_samples, n_columns = values.shape
    observed = ~np.isnan(values)
    index = np.where(observed, np.arange(n_samples)[:, np.newaxis], -1)
    np.maximum.accumulate(index, axis=0, out=index)
    first_row = np.repeat(np.asarray(starts), np.asarray(stops) - np.asarray(starts))
    valid = ~observed & (index >= first_row[:, np.newaxis])
    gaps = np.where(valid, np.arange(n_samples)[:, np.newaxis] - index, 0)
    carried = np.full(values.shape, np.nan)
    rows, columns = np.nonzero(valid)
    carried[rows, columns] = values[index[rows, columns], columns]
    return carried, gaps


@dataclass(frozen=True)
class StaleInputNoise:
    """Variance of a carried value's error against its gap, per input column.

    Parameters
    ----------
    lags : ndarray of int of shape (n_lags,)
        Increasing gaps (samples) at which the variances are tabulated.
    variances : ndarray of shape (n_columns, n_lags)
        ``E[(x_j(t) - x_j(t - lag))^2]`` in standardised units; ``inf`` where unknown.
    """

    lags: np.ndarray
    variances: np.ndarray

    def frozen(self, n_inputs):
        """A read-only copy, checked to cover ``n_inputs`` columns."""
        lags = np.asarray(self.lags)
        if (
            lags.ndim != 1
            or lags.dtype.kind not in "iu"
            or np.any(lags < 1)
            or np.any(lags > MAX_LAG)
            or np.any(np.diff(lags) <= 0)
        ):
            raise ValueError(
                f"stale_noise.lags must be increasing whole numbers of samples from 1 to "
                f"{MAX_LAG}, got {self.lags!r}"
            )
        lags = lags.astype(np.int64)
        variances = np.array(self.variances, dtype=float)
        if variances.shape != (n_inputs, lags.size) or not np.all(variances >= MIN_VARIANCE):
            raise ValueError(
                f"stale_noise.variances must be at least {MIN_VARIANCE:g} (standardised units; "
                f"inf where unknown), of shape ({n_inputs}, {lags.size}); got shape "
                f"{variances.shape}, smallest {np.min(variances, initial=np.inf):g}"
            )
        lags.flags.writeable = variances.flags.writeable = False
        return type(self)(lags, variances)

    @classmethod
    def learn(cls, values, starts, stops, lags=LAGS):
        """Variogram of every column of ``values`` (n_samples, n_columns; NaN where missing)
        from the pairs of observed values ``lag`` samples apart within a recording."""
        values = np.asarray(values, dtype=float)
        starts, stops = np.asarray(starts), np.asarray(stops)
        lags = lags[lags < max(int((stops - starts).max(initial=0)), 1)]
        variances = np.full((values.shape[1], lags.size), np.inf)
        # ``position`` of every row within its recording: a pair is in one recording when the
        # later row is at least ``lag`` rows from its recording's start.
        position = np.arange(values.shape[0]) - np.repeat(starts, stops - starts)
        for i, lag in enumerate(lags):
            later = np.flatnonzero(position >= lag)
            # An evenly spaced sample of the pairs is plenty for a mean of squares.
            later = later[:: -(-later.size // MAX_PAIRS)] if later.size > MAX_PAIRS else later
            differences = values[later] - values[later - lag]
            counts = np.sum(~np.isnan(differences), axis=0)
            sums = np.nansum(np.square(differences), axis=0)
            seen = counts > 0
            # A variance of zero (a constant column) would trust the carried value exactly.
            variances[seen, i] = np.maximum(sums[seen] / counts[seen], MIN_VARIANCE)
        return cls(lags.astype(np.int64), variances)

    def precisions(self, gaps):
        """``1 / v_j(g)`` of every entry of ``gaps`` (n_samples, n_columns); 0 where the gap is 0
        (no carried value), longer than the longest lag, or its variance unknown."""
        precisions = np.zeros(gaps.shape)
        if self.lags.size == 0:
            return precisions
        for j in range(gaps.shape[1]):
            rows = np.flatnonzero((gaps[:, j] > 0) & (gaps[:, j] <= self.lags[-1]))
            if rows.size:
                with np.errstate(invalid="ignore"):  # inf - inf between unknown lags
                    variances = np.interp(gaps[rows, j], self.lags, self.variances[j])
                known = np.isfinite(variances)
                precisions[rows[known], j] = 1.0 / variances[known]
        return precisions

    def read(self, values, starts, stops):
        """``(carried, precisions)`` of the missing entries of ``values``: the carried values
        (zero where none) and their precisions (zero where the value is marginalised)."""
        carried, gaps = last_observed(values, starts, stops)
        precisions = self.precisions(gaps)
        return np.where(precisions > 0, carried, 0.0), precisions


class CarriedInputs:
    """A stream's last observed value of every input and the sample it was seen at.

    ``observe(z, count)`` records the finite values of sample number ``count`` (counted from 1
    within a recording); ``read(missing, count)`` gives the ``(carried, precisions)`` of that
    sample's missing inputs, as :meth:`StaleInputNoise.read` gives them for a whole recording.
    """

    def __init__(self, noise, n_inputs):
        self.noise = noise
        self.values = np.zeros(n_inputs)
        self.seen_at = np.zeros(n_inputs, dtype=np.int64)  # 0: not seen in this recording

    def reset(self):
        self.seen_at[:] = 0

    def observe(self, z, count):
        if math.isfinite(z.sum()):  # the usual case, kept cheap: it runs every control cycle
            self.values[:] = z
            self.seen_at[:] = count
            return
        # Infinities are never carried (the stream holds such a sample, predict refuses it).
        seen = np.isfinite(z)
        self.values[seen] = z[seen]
        self.seen_at[seen] = count

    def read(self, missing, count):
        gaps = np.where(missing & (self.seen_at > 0), count - self.seen_at, 0)[np.newaxis]
        precisions = self.noise.precisions(gaps)
        return np.where(precisions > 0, self.values, 0.0), precisions


def learn_stale_noise(missing_values, columns, n_inputs, recordings):
    """The :class:`StaleInputNoise` of the first ``n_inputs`` of the engine's standardised
    ``columns`` (:class:`~skhmmgmr._hmm._em_data.Columns`, missing values still NaN) that ``fit``
    learns when ``missing_values="carry_forward"``, else None."""
    if missing_values != "carry_forward":
        return None
    inputs = columns.values[:n_inputs].T
    return StaleInputNoise.learn(inputs, recordings.starts, recordings.stops)


def stale_noise_for(model, missing_values):
    """The variograms by which ``model`` (a ``FittedHMMGMR``) reads missing inputs, or None."""
    if missing_values != "carry_forward":
        return None
    if model.stale_noise is None:
        raise ValueError(
            "missing_values='carry_forward' needs a model fitted with "
            "missing_values='carry_forward': this one holds no variograms of its inputs "
            "(stale_noise is None)"
        )
    return model.stale_noise


def carried_inputs(model, missing_values):
    """The :class:`CarriedInputs` of a stream of ``model`` (a ``FittedHMMGMR``), or None."""
    noise = stale_noise_for(model, missing_values)
    return None if noise is None else CarriedInputs(noise, model.n_inputs)
