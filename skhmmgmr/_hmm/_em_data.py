"""How the EM reads the data: augmented columns, blocks of whole recordings, chunks of rows.

:class:`Columns` holds the rows once, as columns about a shift plus a row of ones, so that the
weighted moments of all states are one matrix product per chunk. :class:`EStepData` holds what
stays constant during a fit: the columns, the recordings grouped into blocks of about one
cache-sized chunk of rows, the chunk bounds and the moments of all rows, and the rows that miss
a value (:class:`~skhmmgmr._hmm._missing.MissingRows`: their missing values set to zero, their
frames overwritten by the densities of their observed columns).
"""

from dataclasses import dataclass

import numpy as np

from .._core._validation import binary_unit, constant_to_round_off
from ._gaussian import MomentSums, augmented_columns, chunk_size_for
from ._missing import MissingRows

# Consecutive short recordings are grouped into blocks of about this many rows.
BLOCK_ROWS = 8192


@dataclass
class Columns:
    """The data as the engine reads them: the rows of ``X - shift`` as columns, plus ones.

    Attributes
    ----------
    values : ndarray of shape (n_features + 1, n_samples)
        C-contiguous; the last row is ones (see :func:`~skhmmgmr._hmm._gaussian.augmented_columns`).
    shift : ndarray of shape (n_features,)
        Point subtracted from every row; moments are taken about it, so it should be near the
        data (the mean), where the raw second moments lose no significant digits.
    """

    values: np.ndarray
    shift: np.ndarray

    @classmethod
    def from_rows(cls, X):
        """Columns of ``X`` (n_samples, n_features) about its column means (a copy); the means
        of the observed values when some are missing (NaN), 0 for a column with none."""
        X = np.asarray(X, dtype=float)
        shift = X.mean(axis=0) if X.shape[0] else np.zeros(X.shape[1])
        if np.isnan(shift).any():
            counts = np.sum(~np.isnan(X), axis=0)
            shift = np.nansum(X, axis=0) / np.maximum(counts, 1)
        return cls(augmented_columns(X, shift), shift)

    @classmethod
    def standardized(cls, *blocks):
        """Columns of ``hstack(blocks)``, each column standardised, built without the stack.

        Returns ``(columns, center, scale)``: the column means and standard deviations. A
        column whose standard deviation is round-off for its values
        (:func:`~skhmmgmr._core._validation.constant_to_round_off`) is constant: it keeps scale 1.
        Only the columns are allocated at the size of the data; the standardisation runs in
        place, one column at a time. Each column is first divided by the power of two just
        below its largest absolute value (exact in floating point), so that no sum or square
        overflows or underflows whatever the column's unit, and the results are those of the
        unscaled arithmetic (bit for bit when those neither overflow nor underflow). Missing
        values (NaN) stay in place and the statistics are those of the observed values; a
        column with no observed value gets a NaN centre and scale (the caller names it).
        """
        n_samples = blocks[0].shape[0]
        n_features = sum(block.shape[1] for block in blocks)
        values = np.empty((n_features + 1, n_samples))
        row = 0
        for block in blocks:
            values[row : row + block.shape[1]] = block.T
            row += block.shape[1]
        values[n_features] = 1.0
        center, scale = np.empty(n_features), np.ones(n_features)
        for i in range(n_features):
            column = values[i]
            magnitude = max(column.max(), -column.min()) if n_samples else 0.0
            observed = slice(None)  # a view: no copy of a complete column
            if np.isnan(magnitude):  # missing values
                observed = ~np.isnan(column)
                if not observed.any():
                    center[i] = scale[i] = np.nan
                    continue
                magnitude = max(column[observed].max(), -column[observed].min())
            power = float(binary_unit(magnitude))
            column /= power
            mean = column[observed].mean()
            column -= mean
            values_seen = column[observed]
            spread = np.sqrt(np.dot(values_seen, values_seen) / values_seen.size)
            center[i] = mean * power
            if constant_to_round_off(spread, magnitude / power):
                column *= power
            else:
                scale[i] = spread * power
                column /= spread
        return cls(values, np.zeros(n_features)), center, scale

    @property
    def n_features(self):
        return self.values.shape[0] - 1

    @property
    def n_samples(self):
        return self.values.shape[1]

    def rows(self, index=slice(None)):
        """Rows ``index`` of ``X - shift``, shape (n_rows, n_features) (a copy)."""
        return np.ascontiguousarray(self.values[: self.n_features, index].T)


def recording_blocks(recordings, max_rows):
    """Group consecutive recordings into blocks of at most ``max_rows`` rows.

    A recording longer than ``max_rows`` forms a block of its own. Returns ``(start, stop,
    starts, stops)`` tuples with the recording bounds relative to ``start``.
    """
    starts, stops = np.asarray(recordings.starts), np.asarray(recordings.stops)
    blocks = []
    first = 0
    n_recordings = len(starts)
    while first < n_recordings:
        last = first + 1
        while last < n_recordings and stops[last] - starts[first] <= max_rows:
            last += 1
        origin = int(starts[first])
        blocks.append(
            (
                origin,
                int(stops[last - 1]),
                [int(v) - origin for v in starts[first:last]],
                [int(v) - origin for v in stops[first:last]],
            )
        )
        first = last
    return blocks


class EStepData:
    """Per-fit constants: the columns, the recording blocks, the chunk size, the moments of
    all rows, and ``missing``, the rows with a missing value (None when there is none: the
    missing values of ``X`` given as :class:`Columns` are set to zero in place)."""

    def __init__(self, X, recordings, n_states, chunk_size=None, block_size=None):
        self.data = X if isinstance(X, Columns) else Columns.from_rows(X)
        self.shift = self.data.shift
        self.missing = MissingRows.of(self.data.values[:-1], self.shift, fill=True)
        self.n_states = n_states
        self.step = chunk_size_for(n_states * self.data.n_features, chunk_size)
        self.blocks = [
            (start, stop, np.asarray(starts, dtype=np.int64), np.asarray(stops, dtype=np.int64))
            for start, stop, starts, stops in recording_blocks(
                recordings, block_size or max(self.step, BLOCK_ROWS)
            )
        ]
        self._totals = None
        self._chunk_bounds = {}
        # State whose moments the next E-step takes as the total minus the others'.
        self.remainder = None

    def chunks(self, start=0, stop=None):
        """``(lo, hi, columns[:, start + lo : start + hi])`` for chunks of rows ``start:stop``."""
        values = self.data.values
        stop = values.shape[1] if stop is None else stop
        # Every E-step walks the same blocks twice: their bounds are computed once per fit.
        bounds = self._chunk_bounds.get((start, stop))
        if bounds is None:
            n_chunks = max(-(-(stop - start) // self.step), 1)
            edges = np.linspace(0, stop - start, n_chunks + 1).astype(int).tolist()
            bounds = list(zip(edges[:-1], edges[1:], strict=True))
            self._chunk_bounds[start, stop] = bounds
        for lo, hi in bounds:
            yield lo, hi, values[:, start + lo : start + hi]

    def frames(self, density, start, stop, emissions=None):
        """Emission likelihoods of rows ``start:stop`` scaled to a maximum of one per row.

        ``density`` is the evaluator of ``emissions`` about the engine's shift (the emissions
        are needed when rows miss values). Returns ``(frames, log_scale)``: frames of shape
        (rows, n_states), C-contiguous, and the sum over the rows of the logarithms of the
        scales.
        """
        frames = np.empty((stop - start, self.n_states))
        top = np.empty(stop - start)
        for lo, hi, chunk in self.chunks(start, stop):
            density.frames(chunk, frames[lo:hi], top[lo:hi])
        if self.missing is not None:
            self.missing.overwrite(emissions, start, stop, frames, top)
        return frames, float(top.sum())

    @property
    def totals(self):
        """Augmented moments of all rows (computed once)."""
        if self._totals is None:
            n_columns = self.data.values.shape[0]
            sums = MomentSums(1, n_columns)
            for lo, hi, _ in self.chunks():
                sums.add(np.ones((1, hi - lo)), self.data.values, lo)
            self._totals = sums.result()[0]
        return self._totals

    def adopt_totals(self, moments):
        """Take ``moments`` (augmented, of all rows, computed by the caller anyway) as
        :attr:`totals` unless they are known already."""
        if self._totals is None:
            self._totals = moments
