"""Put recordings on a uniform time grid: bridge short gaps, split at long ones.

A vehicle log is sampled on a jittered clock and loses samples. :func:`resample_recordings`
treats every recording (its rows contiguous, times strictly increasing, as the tidy frame has
them) in three steps:

1. Split. A step between two consecutive samples longer than ``max_gap`` ends a *piece*; the
   next sample starts the next one. Nothing is ever interpolated across such a step.
2. Grid. Every piece gets its own grid ``t0 + k / sampling_rate``, ``k = 0, 1, ...``, from its
   first sample ``t0`` to its last sample; the grid never extrapolates past the last sample.
3. Values. A grid time that falls on a sample (within rounding: ``1e-9`` of a period plus a few
   units in the last place of the times) takes that sample's values as they are. Any other grid
   time lies between two consecutive samples ``i`` and ``i + 1`` of its piece: float columns are
   interpolated linearly between them, so NaN (a missing sample) in either gives NaN; other
   columns (integers, booleans, text, categories), the meta columns ``driver``, ``setting``
   and ``split`` and the columns listed in ``hold`` take the value of sample ``i``.

Layout: one pass over flat arrays. ``start``/``stop`` hold the row positions that bound every
piece; for every grid row, ``left`` is the position of the latest sample at or before its time,
``right`` that of the next sample of the piece, ``weight`` the fraction of the way from one to
the other and ``exact`` whether the grid time falls on sample ``left``. Every column is then read
by indexing with these arrays.
"""

import copy
import warnings
from numbers import Integral, Real

import numpy as np
import pandas as pd

from ..._core._compat import FiniteInterval, Interval, validate_params
from ..._core._schema import CROSSING_TIME, DRIVER, MANOEUVRE, RECORDING, SETTING, SPLIT, TIME
from .._frame import check_rate, check_times

SEPARATOR = "/"
# Bounds of the grid: a piece gets at most this many grid rows per sample (a 10 Hz log on a
# 1000 Hz grid), or MIN_GRID_ROWS for a short piece; all pieces at most MAX_GRID_ROWS.
MAX_ROWS_PER_SAMPLE = 100
MIN_GRID_ROWS = 10_000
MAX_GRID_ROWS = 1_000_000_000
# meta columns held whatever their dtype (a simulated frame's labels among them)
_LABELS = (DRIVER, SETTING, SPLIT, MANOEUVRE, CROSSING_TIME)


#: The resampling's options that :func:`load_recordings` passes on (the bounds of ``max_gap``
#: depend on the sampling rate: :func:`check_max_gap`).
RESAMPLING_CONSTRAINTS = {
    "max_gap": [Interval(Real, None, None, closed="both")],  # inf: no gap splits
    "min_length": [Interval(Integral, 1, None, closed="left")],
}


def check_max_gap(max_gap, sampling_rate):
    """Refuse a ``max_gap`` shorter than one sampling period.

    Parameters
    ----------
    max_gap : float
        The longest step between samples that is interpolated [s], a number
        (:data:`RESAMPLING_CONSTRAINTS`); ``inf`` is accepted.
    sampling_rate : float
        The rate of the grid [Hz], already checked.

    Returns
    -------
    max_gap : float

    Raises
    ------
    ValueError
        Naming the value given and the period.
    """
    period = 1.0 / sampling_rate
    if not max_gap >= period * (1 - 1e-9):  # also refuses NaN
        raise ValueError(
            f"max_gap must be at least one sampling period ({period:.6g} s at {sampling_rate:g} "
            f"Hz), got {max_gap!r}: a shorter one would split the recordings at every sample."
        )
    return float(max_gap)


@validate_params(
    {
        "frame": [pd.DataFrame],
        "sampling_rate": [FiniteInterval(Real, 0, None, closed="neither")],
        "recording": [str],
        "time": [str],
        "hold": [str, "array-like"],
    }
    | RESAMPLING_CONSTRAINTS,
    prefer_skip_nested_validation=True,
)
def resample_recordings(
    frame,
    sampling_rate,
    *,
    max_gap,
    recording=RECORDING,
    time=TIME,
    min_length=1,
    hold=(),
):
    """Put every recording on a uniform time grid, interpolating short gaps and splitting at long.

    A real vehicle log has jitter (steps a little off the period) and gaps (lost samples). Every
    recording is cut into pieces at each step between consecutive samples longer than
    ``max_gap``; each piece is then sampled on its own grid, from its first sample on, every
    ``1 / sampling_rate`` seconds, up to its last sample. Steps up to ``max_gap`` are bridged by
    interpolation; longer steps never are.

    Parameters
    ----------
    frame : pandas.DataFrame
        One row per sample, with a recording-id column and a time column [s], such as the tidy
        frame of :func:`load_recordings`. The rows of a recording must be contiguous, their
        times strictly increasing (sort them with :func:`load_recordings` or
        ``frame.sort_values([recording, time])``).
    sampling_rate : float
        Rate of the grid [Hz], at most 1000.
    max_gap : float
        The longest step between two consecutive samples of a recording that is interpolated
        [s]; a longer step splits the recording. At least one period ``1 / sampling_rate``;
        leave room for the jitter (with ``max_gap`` equal to the period, a step a little longer
        splits). ``numpy.inf`` never splits.
    recording : str, default="recording"
        Name of the recording-id column.
    time : str, default="time"
        Name of the time column, in seconds.
    min_length : int, default=1
        Pieces with fewer grid samples are dropped, with a warning that lists them. By default
        every piece is kept, even one of a single sample.
    hold : list of str, default=()
        Float columns to resample by previous-value hold rather than linearly, such as flags
        stored as 0.0/1.0.

    Returns
    -------
    resampled : pandas.DataFrame
        The columns of ``frame`` in their order, with a fresh index and ``frame.attrs``. The
        time column holds the grid (float64). Recording ids are text: a recording that is not
        split keeps its id, the pieces of a split one are ``"<id>/0"``, ``"<id>/1"``... in time
        order, numbered before ``min_length`` drops any (an id names the same stretch of the
        drive whatever ``min_length``). Float columns are interpolated linearly, the other
        columns (and the meta columns ``driver``, ``setting``, ``split``, and ``hold``) keep
        their dtype and take the value of the latest sample at or before the grid time.

    Raises
    ------
    ValueError
        When ``sampling_rate`` is not a positive number of at most 1000 Hz, ``max_gap`` is
        shorter than one period, a piece would take more than 100 grid rows per sample (at
        least 10,000; named with its recording and size, before any row is built) or the grid
        more than 1e9 rows in all,
        a column is missing, a piece would take the id of an existing recording, or, naming the
        recording, the row (its position in ``frame``, from 0) and its time: a recording id is
        missing, a time is NaN or infinite, the rows of a recording are not contiguous, or its
        times do not strictly increase (unsorted or repeated).

    See Also
    --------
    load_recordings : Reads files and resamples them on request (``max_gap=``).

    Notes
    -----
    Edges. The grid of a piece starts at its first sample, whose values it keeps unchanged, and
    ends at the last grid time not after its last sample: the samples after that time (less
    than one period) only serve to interpolate it. Apart from that tail, and from the
    pieces ``min_length`` drops with a warning, every stretch of every recording is on the
    grid; no sample is extrapolated.

    Missing values. NaN in a float column marks a missing sample and stays missing: a grid
    time that falls on it is NaN, and so is every grid time between it and its neighbours,
    since interpolating there would need it. A held column gives NaN where the latest sample
    is NaN. Nothing is filled across a missing sample.

    Rates. Only the two samples around a grid time are read: the function is meant for a grid
    at about the recording's own rate. To downsample, low-pass filter first.

    Examples
    --------
    >>> import pandas as pd
    >>> from skhmmgmr.datasets import resample_recordings
    >>> raw = pd.DataFrame({"recording": "drive7",
    ...                     "time": [0.0, 0.101, 0.198, 0.4, 1.5, 1.6],
    ...                     "speed": [10.0, 10.101, 10.198, 10.4, 11.5, 11.6],
    ...                     "gear": [3, 3, 3, 4, 4, 4]})
    >>> resample_recordings(raw, 10.0, max_gap=0.25).round(6)
      recording  time  speed  gear
    0  drive7/0   0.0   10.0     3
    1  drive7/0   0.1   10.1     3
    2  drive7/0   0.2   10.2     3
    3  drive7/0   0.3   10.3     3
    4  drive7/0   0.4   10.4     4
    5  drive7/1   1.5   11.5     4
    6  drive7/1   1.6   11.6     4
    """
    check_rate(sampling_rate)
    max_gap = check_max_gap(max_gap, sampling_rate)
    hold = [hold] if isinstance(hold, str) else list(hold)
    columns = list(frame.columns)
    missing = [c for c in dict.fromkeys([recording, time, *hold]) if c not in columns]
    if missing:
        raise ValueError(
            f"The frame lacks the column(s) {missing}; its columns are {columns}. Name yours "
            "with the recording= and time= parameters."
        )
    if frame.columns.duplicated().any():
        repeated = sorted({str(c) for c in frame.columns[frame.columns.duplicated()]})
        raise ValueError(f"The frame has repeated column names: {repeated}.")
    if frame.empty:
        return frame.reset_index(drop=True)

    ids, codes, t = check_times(frame[recording], frame[time], names=(recording, time))
    grid = _Grid(t, codes, ids, sampling_rate, max_gap)
    labels = _piece_ids(ids, codes, grid.start)
    keep = grid.n_grid >= min_length
    if not keep.all():
        _warn_dropped(labels, t, grid, keep, min_length)
    rows = keep[grid.piece]

    out = {}
    for name in columns:
        column = frame[name]
        if name == recording:
            values = np.repeat(labels, grid.n_grid)[rows]
            out[name] = pd.Series(values, dtype=object).astype(str).array
        elif name == time:
            out[name] = grid.time[rows]
        elif name in hold or name in _LABELS or not pd.api.types.is_float_dtype(column.dtype):
            out[name] = column.iloc[grid.left[rows]].array
        else:
            values = grid.linear(column.to_numpy(dtype=float, na_value=np.nan))[rows]
            same = column.dtype == np.float64
            out[name] = values if same else pd.Series(values).astype(column.dtype).array
    resampled = pd.DataFrame(out, columns=frame.columns)
    resampled.attrs = copy.deepcopy(frame.attrs)
    return resampled


class _Grid:
    """The pieces of the recordings and, for every grid row, where its values come from."""

    def __init__(self, t, codes, ids, sampling_rate, max_gap):
        n_rows = len(t)
        tol = 1e-9 / sampling_rate + 4 * np.spacing(np.abs(t).max())
        step = np.diff(t)
        first = np.r_[True, (codes[1:] != codes[:-1]) | (step > max_gap + tol)]
        self.start = np.flatnonzero(first)
        stop = np.r_[self.start[1:], n_rows]
        span = t[stop - 1] - t[self.start]
        n_grid = np.floor((span + tol) * sampling_rate) + 1  # float: checked before it is used
        _check_grid_size(n_grid, stop - self.start, span, ids[self.start], sampling_rate)
        self.n_grid = n_grid.astype(np.int64)
        self.piece = np.repeat(np.arange(len(self.start)), self.n_grid)
        offset = np.cumsum(self.n_grid) - self.n_grid
        k = np.arange(self.n_grid.sum()) - offset[self.piece]
        self.time = t[self.start][self.piece] + k / sampling_rate
        left = np.empty(len(self.time), dtype=np.int64)
        for p, (a, b) in enumerate(zip(self.start, stop, strict=True)):
            where = slice(offset[p], offset[p] + self.n_grid[p])
            found = np.searchsorted(t[a:b], self.time[where] + tol, side="right") - 1
            left[where] = a + np.clip(found, 0, b - a - 1)
        self.left = left
        self.right = np.minimum(left + 1, stop[self.piece] - 1)
        after = self.time - t[left]
        self.exact = after <= tol
        with np.errstate(divide="ignore", invalid="ignore"):
            weight = after / (t[self.right] - t[left])
        self.weight = np.where(self.exact, 0.0, weight)

    def linear(self, values):
        """The column on the grid: a sample's value on it, else linear between two samples."""
        a, b = values[self.left], values[self.right]
        with np.errstate(invalid="ignore"):
            between = a + self.weight * (b - a)
        return np.where(self.exact, a, between)


def _check_grid_size(n_grid, n_samples, span, owners, sampling_rate):
    """Refuse a grid with more than :data:`MAX_ROWS_PER_SAMPLE` rows per sample of its piece
    (at least :data:`MIN_GRID_ROWS`), or more than :data:`MAX_GRID_ROWS` rows in all, naming
    the recording, its samples and the rows it would take, before any row is built."""
    allowed = np.maximum(MAX_ROWS_PER_SAMPLE * n_samples, MIN_GRID_ROWS)
    over = np.flatnonzero(n_grid > allowed)
    if over.size:
        p = over[np.argmax(n_grid[over])]
        raise ValueError(
            f"The recording {owners[p]!r} would take {n_grid[p]:.4g} grid rows at "
            f"{sampling_rate:g} Hz: {n_samples[p]} sample(s) over {span[p]:.6g} s, more than "
            f"{MAX_ROWS_PER_SAMPLE} grid rows per sample. Between two samples resampling only "
            "interpolates: split long gaps with a finite max_gap, or lower sampling_rate."
        )
    total = n_grid.sum()
    if total > MAX_GRID_ROWS:
        raise ValueError(
            f"The grid would take {total:.4g} rows in all at {sampling_rate:g} Hz (at most "
            f"{MAX_GRID_ROWS:.0e}, about {MAX_GRID_ROWS * 8 / 2**30:.0f} GiB per float "
            "column): resample the recordings in parts, or lower sampling_rate."
        )


def _piece_ids(ids, codes, start):
    """Ids of the pieces: the recording's own if it is whole, else ``<id>/<k>``."""
    owner = codes[start]
    n_pieces = np.bincount(owner)
    first_piece = np.r_[0, np.cumsum(n_pieces)[:-1]]
    labels = np.empty(len(start), dtype=object)
    taken = set(ids)
    for p, code in enumerate(owner):
        name = str(ids[start[p]])
        if n_pieces[code] == 1:
            labels[p] = name
            continue
        labels[p] = f"{name}{SEPARATOR}{p - first_piece[code]}"
        if labels[p] in taken:
            raise ValueError(
                f"The recording {name!r} has gaps longer than max_gap and would be split into "
                f"pieces, one of them {labels[p]!r}, which is already a recording: rename it."
            )
    return labels


def _warn_dropped(labels, t, grid, keep, min_length):
    dropped = np.flatnonzero(~keep)
    stop = np.r_[grid.start[1:], len(t)] - 1
    listed = [
        f"{labels[p]!r} ({t[grid.start[p]]:.10g} to {t[stop[p]]:.10g} s, "
        f"{grid.n_grid[p]} sample(s))"
        for p in dropped[:5]
    ]
    more = f" and {dropped.size - 5} more" if dropped.size > 5 else ""
    warnings.warn(
        f"resample_recordings dropped {dropped.size} piece(s) shorter than "
        f"min_length={min_length} samples: {', '.join(listed)}{more}.",
        UserWarning,
        stacklevel=3,
    )
