"""Build and validate the tidy frame that every dataset of the package returns.

Every loader hands its columns to :func:`tidy_frame`, which puts them in the order and dtypes of
the schema (:mod:`._schema`) and refuses what the estimators would otherwise get silently wrong:
missing ids, non-finite values, recordings whose rows are scattered or whose times do not
strictly increase. :func:`time_order` puts rows in the order :func:`tidy_frame` requires;
:func:`concat_frames` joins tidy frames of distinct recordings; :func:`check_times` and
:func:`check_rate` lend the same checks to tools that take a frame (resampling).
"""

import numpy as np
import pandas as pd

from .._core._schema import (
    CROSSING_TIME,
    DRIVER,
    EXPERIMENT_COLUMNS,
    FEATURE_UNITS,
    LABEL_UNITS,
    MANOEUVRE,
    META_COLUMNS,
    RECORDING,
    SETTING,
    SPLIT,
    STEERING_PERTURBATION,
    TARGET,
    TARGET_UNIT,
    TIME,
)

UNKNOWN = "unknown"
# Value of a meta column that a source does not have (the recording id has no default).
META_DEFAULTS = {DRIVER: UNKNOWN, SETTING: np.nan, SPLIT: UNKNOWN}
STEP_RTOL = 0.01


def tidy_frame(
    columns,
    *,
    units=None,
    attrs=None,
    sampling_rate=None,
    source=None,
    row=None,
    allow_missing=False,
):
    """Assemble the tidy frame of the schema from its columns, and validate it.

    Parameters
    ----------
    columns : mapping of str to array-like or scalar
        The columns by name (a DataFrame works too): ``recording`` (required), optionally
        ``driver``, ``setting``, ``split`` and ``time`` [s], the features, and optionally
        ``driver_torque``. A scalar is repeated on every row. An absent ``driver`` or ``split``
        is ``"unknown"``, an absent ``setting`` is NaN.
    units : mapping of str to str, default=None
        Units of the numeric columns, overriding the defaults: ``"s"`` for the time, the
        schema's unit for its features (:data:`FEATURE_UNITS`) and for the target (``"Nm"``),
        ``"unknown"`` for any other column. Units of absent columns are ignored.
    attrs : mapping, default=None
        Further entries of ``frame.attrs``, after ``"units"``.
    sampling_rate : float, default=None
        If given, also check that every recording is sampled at this rate [Hz]: each time step
        within 1 % of ``1 / sampling_rate``.
    source : str or array-like of str, default=None
        Where the rows come from, such as ``"file 'monday.csv'"``, named in error messages.
    row : array-like of int, default=None
        Row numbers named in error messages; by default the positions of the rows in
        ``columns``, from 0.
    allow_missing : bool, default=False
        Keep NaN in the features and the target as missing values (the time must still be
        complete; infinities are refused either way).

    Returns
    -------
    frame : pandas.DataFrame
        The meta columns ``recording, driver, setting, split, time`` (``time`` only if given),
        then ``manoeuvre`` (text) and ``crossing_time`` (seconds, NaN allowed) if given,
        the other columns in the order given, then ``driver_torque`` if given, then
        ``steering_perturbation`` (the torque of a perturbation experiment, Nm) if given.
        Recording, driver and split are text; the time, the features and the target are
        float64; the
        setting keeps its dtype. ``attrs["units"]`` maps the time, feature and target columns,
        in column order, to their units.

    Raises
    ------
    ValueError
        Naming the column, the recording and the first offending row (with its source and
        time, when known), when a value is NaN or infinite, an id is missing, the rows of a
        recording are not contiguous, its times do not strictly increase, or it is not sampled
        at ``sampling_rate``.

    Examples
    --------
    >>> frame = tidy_frame({"recording": 7, "time": [0.0, 0.1], "yaw_rate": [0.0, 0.1],
    ...                     "driver_torque": [0.5, 0.4]})
    >>> list(frame.columns)
    ['recording', 'driver', 'setting', 'split', 'time', 'yaw_rate', 'driver_torque']
    >>> frame["recording"].tolist(), frame.attrs["units"]["yaw_rate"]
    (['7', '7'], 'rad/s')
    """
    given = dict(columns.items())
    if RECORDING not in given:
        raise ValueError(f"A tidy frame needs a {RECORDING!r} column; got {list(given)}.")
    lengths = {name: len(v) for name, v in given.items() if np.ndim(v) > 0}
    if not lengths:
        raise ValueError("Cannot tell the number of rows: every column is a scalar.")
    n_rows = next(iter(lengths.values()))
    uneven = {name: n for name, n in lengths.items() if n != n_rows}
    if uneven:
        raise ValueError(f"The columns have different lengths: {lengths}.")
    given = {**META_DEFAULTS, **given}
    others = [c for c in given if c not in (*META_COLUMNS, *EXPERIMENT_COLUMNS, TARGET)]
    numeric = [TIME] * (TIME in given) + others + [TARGET] * (TARGET in given)

    out = {name: _values(given[name], n_rows) for name in (RECORDING, DRIVER, SETTING, SPLIT)}
    if TIME in given:
        out[TIME] = _floats(TIME, given[TIME], n_rows)
    if MANOEUVRE in given:
        out[MANOEUVRE] = _values(given[MANOEUVRE], n_rows)
    if CROSSING_TIME in given:
        out[CROSSING_TIME] = _floats(CROSSING_TIME, given[CROSSING_TIME], n_rows)
    out.update({name: _floats(name, given[name], n_rows) for name in numeric})
    if STEERING_PERTURBATION in given:
        out[STEERING_PERTURBATION] = _floats(
            STEERING_PERTURBATION, given[STEERING_PERTURBATION], n_rows
        )
        numeric.append(STEERING_PERTURBATION)
    rows = _Rows(n_rows, source, row, out.get(TIME))
    out[RECORDING] = rows.recording = rows.text(RECORDING, out[RECORDING])
    for name in (DRIVER, SPLIT, MANOEUVRE):
        if name in out:
            out[name] = rows.text(name, out[name])
    rows.check_finite({name: out[name] for name in numeric}, allow_nan=allow_missing, time=TIME)
    if CROSSING_TIME in given:  # NaN: a manoeuvre row whose car crosses no marking
        rows.check_finite({CROSSING_TIME: out[CROSSING_TIME]}, allow_nan=True)
    codes = rows.check_contiguous()
    if TIME in out:
        rows.check_time(codes, sampling_rate)

    frame = pd.DataFrame(out)
    all_units = {TIME: "s", **LABEL_UNITS, TARGET: TARGET_UNIT, **FEATURE_UNITS}
    all_units.update(units or {})
    measured = [c for c in frame.columns if c in numeric or c == CROSSING_TIME]
    frame.attrs["units"] = {name: all_units.get(name, UNKNOWN) for name in measured}
    frame.attrs.update(attrs or {})
    return frame


def time_order(recording, time=None):
    """Positions that gather the rows of every recording and sort them by time.

    The one row order of the package's loaders and command line: recordings contiguous, in the
    order they first appear, the rows of each sorted by time, stably (rows with equal times
    keep their order, so that :func:`tidy_frame` names the repeated time). No row is dropped.

    Parameters
    ----------
    recording : array-like of shape (n_rows,)
        The recording id of every row.
    time : array-like of shape (n_rows,), default=None
        The time of every row; None keeps the rows of a recording in their order.

    Returns
    -------
    order : ndarray of int of shape (n_rows,)
        ``frame.iloc[order]`` is the frame in that order.

    Examples
    --------
    >>> time_order(["b", "a", "b", "a"], [0.2, 0.1, 0.1, 0.0]).tolist()
    [2, 0, 3, 1]
    """
    codes = pd.factorize(np.asarray(recording, dtype=object))[0]
    if time is None:
        return np.argsort(codes, kind="stable")
    # lexsort is stable; its last key is the primary one
    return np.lexsort((np.asarray(time, dtype=float), codes))


# Recordings for a driver model are sampled at tens to hundreds of Hz; a faster grid only
# interpolates, while its rows (and the memory of every array built on them) grow with the rate.
MAX_SAMPLING_RATE = 1000.0


def check_rate(sampling_rate, *, why=""):
    """Refuse a sampling rate above :data:`MAX_SAMPLING_RATE`; return it as a float (or None).

    The rate is a positive, finite number of Hz (or None) already: the public functions that
    take it say so in their ``validate_params``.

    Parameters
    ----------
    sampling_rate : float or None
        The rate to check [Hz].
    why : str, default=""
        What a faster rate would do with this source, added to the error of a rate above the
        bound.

    Raises
    ------
    ValueError
        Naming the rate given.
    """
    if sampling_rate is None:
        return None
    if sampling_rate > MAX_SAMPLING_RATE:
        raise ValueError(
            f"sampling_rate must be at most {MAX_SAMPLING_RATE:g} Hz, got {sampling_rate!r}: "
            + (
                why
                or "a faster grid only interpolates the samples, while its rows and memory "
                "grow with the rate."
            )
        )
    return float(sampling_rate)


def check_times(recording, time, *, names=(RECORDING, TIME)):
    """Run :func:`tidy_frame`'s checks of the recording ids and times alone.

    Parameters
    ----------
    recording : array-like of shape (n_rows,)
        The recording id of every row.
    time : array-like of shape (n_rows,)
        The time of every row [s].
    names : tuple of (str, str), default=("recording", "time")
        Names of the two columns in error messages.

    Returns
    -------
    recording : pandas.api.extensions.ExtensionArray of str
        The ids as text, as in the tidy frame.
    codes : ndarray of int of shape (n_rows,)
        The recordings numbered in order of first appearance.
    time : ndarray of float of shape (n_rows,)
        The times.

    Raises
    ------
    ValueError
        Naming the recording and the first offending row (its position, from 0) and time, when
        an id is missing, a time is NaN or infinite or not numeric, the rows of a recording
        are not contiguous, or its times do not strictly increase.
    """
    recording = _values(recording, None)
    time = _floats(names[1], time, len(recording))
    rows = _Rows(len(recording), None, None, time)
    recording = rows.recording = rows.text(names[0], recording)
    rows.check_finite({names[1]: time})
    codes = rows.check_contiguous()
    rows.check_time(codes, None)
    return recording, codes, time


def concat_frames(frames, *, attrs=None):
    """Join tidy frames of distinct recordings, one after the other.

    Parameters
    ----------
    frames : iterable of pandas.DataFrame
        Tidy frames (from :func:`tidy_frame`) with the same columns and units.
    attrs : mapping, default=None
        Further entries of ``frame.attrs``, after the common ``"units"``.

    Returns
    -------
    frame : pandas.DataFrame
        The rows of every frame in turn, with a fresh index.

    Raises
    ------
    ValueError
        When the frames differ in columns or units, or a recording is in two of them.
    """
    frames = list(frames)
    if not frames:
        raise ValueError("No frame to concatenate.")
    first, owner = frames[0], {}
    for k, part in enumerate(frames):
        if list(part.columns) != list(first.columns):
            raise ValueError(
                f"Frame {k} has the columns {list(part.columns)}, frame 0 {list(first.columns)}."
            )
        if part.attrs.get("units") != first.attrs.get("units"):
            raise ValueError(f"Frames 0 and {k} give their columns different units.")
        for name in pd.unique(part[RECORDING]):
            if owner.setdefault(name, k) != k:
                raise ValueError(f"The recording {name!r} is in frames {owner[name]} and {k}.")
    frame = pd.concat(frames, ignore_index=True)
    frame.attrs = {"units": dict(first.attrs.get("units", {})), **(attrs or {})}
    return frame


def _values(values, n_rows):
    """The column as an array, without its index if it was a Series."""
    if np.ndim(values) == 0:
        return np.full(n_rows, values)
    if isinstance(values, (pd.Series, pd.Index)):
        return values.array
    if isinstance(values, (np.ndarray, pd.api.extensions.ExtensionArray)):
        return values
    # Through pandas: NumPy would turn a NaN among strings into the text "nan".
    return pd.Series(values).array


def _floats(name, values, n_rows):
    try:
        if hasattr(values, "to_numpy"):
            return values.to_numpy(dtype=float, na_value=np.nan)
        if np.ndim(values) == 0:
            return np.full(n_rows, values, dtype=float)
        return np.asarray(values, dtype=float)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"The column {name!r} is not numeric: {exc}.") from None


class _Rows:
    """Names rows in error messages and runs the checks that need to name them."""

    def __init__(self, n_rows, source, row, time):
        self.source = None if source is None else np.broadcast_to(np.asarray(source), (n_rows,))
        self.row = np.arange(n_rows) if row is None else np.asarray(row)
        self.time = time
        self.recording = None

    def where(self, i):
        details = [] if self.source is None else [str(self.source[i])]
        details.append(f"row {int(self.row[i])}")
        if self.time is not None:
            details.append(f"time {float(self.time[i]):.10g}")
        place = f"({', '.join(details)})"
        return place if self.recording is None else f"recording {self.recording[i]!r} {place}"

    def text(self, name, values):
        missing = pd.isna(values)
        if missing.any():
            i = int(np.flatnonzero(missing)[0])
            raise ValueError(f"The column {name!r} is empty in {self.where(i)}.")
        return pd.Series(values, copy=False).astype(str).array

    def check_finite(self, columns, allow_nan=False, time=None):
        """Refuse non-finite values (with ``allow_nan``, infinities, and NaN in ``time``)."""
        first, n_bad = None, 0
        for name, values in columns.items():
            finite = np.isfinite(values) | (allow_nan and name != time) & np.isnan(values)
            bad = np.flatnonzero(~finite)
            n_bad += bad.size
            if bad.size and (first is None or bad[0] < first[1]):
                first = name, int(bad[0])
        if first is not None:
            name, i = first
            kind = "NaN" if np.isnan(columns[name][i]) else "an infinite value"
            raise ValueError(
                f"The column {name!r} holds {kind} in {self.where(i)}; "
                f"{n_bad} non-finite value(s) in all. Fill or drop them first."
            )

    def check_contiguous(self):
        # Codes number the recordings in order of first appearance, so they never decrease
        # exactly when the rows of every recording are contiguous.
        codes = pd.factorize(self.recording)[0]
        back = np.flatnonzero(np.diff(codes) < 0)
        if back.size:
            i = int(back[0]) + 1
            raise ValueError(
                f"The row of {self.where(i)} comes after rows of recording "
                f"{self.recording[i - 1]!r}, but its recording started earlier: the rows of a "
                "recording must be contiguous."
            )
        return codes

    def check_time(self, codes, sampling_rate):
        time = self.time
        same = codes[1:] == codes[:-1]
        step = np.diff(time)
        back = np.flatnonzero(same & (step <= 0))
        if back.size:
            i = int(back[0]) + 1
            problem = "goes back in time"
            if step[i - 1] == 0:
                problem = f"repeats the time of row {int(self.row[i - 1])}"
            raise ValueError(
                f"The row of {self.where(i)} {problem} (previous time {time[i - 1]:.10g}). "
                "Rows of a recording must have strictly increasing times."
            )
        if sampling_rate is None:
            return
        period = 1.0 / sampling_rate
        off = np.flatnonzero(same & (np.abs(step - period) > STEP_RTOL * period))
        if off.size:
            i = int(off[0]) + 1
            steps = step[same & (codes[1:] == codes[i])]
            raise ValueError(
                f"The recording {self.recording[i]!r} is not sampled at {sampling_rate} Hz: the "
                f"row of {self.where(i)} comes {step[i - 1]:.6g} s after the previous one "
                f"instead of {period:.6g} s (the median step of the recording is "
                f"{np.median(steps):.6g} s). Resample the recording first, or pass "
                "sampling_rate=None."
            )
