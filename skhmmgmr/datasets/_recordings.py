"""Load a user's own driving recordings from CSV or Parquet files into the tidy frame."""

import os
from pathlib import Path

import numpy as np
import pandas as pd

from ._schema import DRIVER, FEATURE_UNITS, RECORDING, SETTING, SPLIT, TARGET, TARGET_UNIT, TIME

UNKNOWN = "unknown"
_CSV_SUFFIXES = (".csv", ".csv.gz", ".csv.bz2", ".csv.zip", ".csv.xz")
_PARQUET_SUFFIXES = (".parquet", ".pq")
_SOURCE = "__source__"
_ROW = "__row__"
_STEP_RTOL = 0.01


def _suffix(path):
    name = path.name.lower()
    for suffix in _CSV_SUFFIXES + _PARQUET_SUFFIXES:
        if name.endswith(suffix):
            return suffix
    return None


def _sources(data):
    """Yield (description, frame, recording id when the frame has no recording column)."""
    if isinstance(data, pd.DataFrame):
        yield "the DataFrame", data, None
        return
    items = [data] if isinstance(data, (str, os.PathLike)) else list(data)
    if not items:
        raise ValueError(
            "No recordings given: pass a DataFrame, a file, a folder or a list of files."
        )
    paths = []
    for item in items:
        path = Path(item)
        if path.is_dir():
            found = sorted(p for p in path.iterdir() if p.is_file() and _suffix(p))
            if not found:
                raise ValueError(f"The folder {str(path)!r} holds no CSV or Parquet file.")
            paths.extend(found)
        else:
            paths.append(path)
    stems = {}
    for path in paths:
        suffix = _suffix(path)
        if not path.is_file():
            raise FileNotFoundError(f"No recording file at {str(path)!r}.")
        if suffix is None:
            raise ValueError(
                f"Cannot read {str(path)!r}: recording files must be CSV "
                f"({', '.join(_CSV_SUFFIXES)}) or Parquet ({', '.join(_PARQUET_SUFFIXES)})."
            )
        stem = path.name[: -len(suffix)]
        if stem in stems:
            raise ValueError(
                f"The files {str(stems[stem])!r} and {str(path)!r} would both be recording "
                f"{stem!r}: rename one of them or give the files a recording column."
            )
        stems[stem] = path
        frame = pd.read_csv(path) if suffix in _CSV_SUFFIXES else pd.read_parquet(path)
        yield f"file {str(path)!r}", frame, stem


def _select(description, frame, stem, *, recording, time, target, features):
    """Return the source as a frame with schema column names, and its feature names."""
    available = [str(c) for c in frame.columns]
    frame = frame.set_axis(available, axis=1)
    required = [time, target] + (list(features) if features is not None else [])
    if stem is None:
        required.insert(0, recording)
    missing = [c for c in dict.fromkeys(required) if c not in available]
    if missing:
        raise ValueError(
            f"{description[0].upper()}{description[1:]} lacks the column(s) {missing}; its "
            f"columns are {available}. Name yours with the recording=, time=, target= and "
            "features= parameters."
        )
    meta = {recording, time, target, RECORDING, DRIVER, SETTING, SPLIT, TIME, TARGET}
    if features is not None and meta.intersection(features):
        raise ValueError(
            f"The features {sorted(meta.intersection(features))} are meta, time or target "
            "columns, which cannot be features."
        )
    if features is None:
        features = [c for c in available if c not in meta]
        non_numeric = [c for c in features if not pd.api.types.is_numeric_dtype(frame[c])]
        if non_numeric:
            raise ValueError(
                f"The column(s) {non_numeric} of {description} are not numeric: list the "
                "feature columns with features=."
            )
    for column in [time, target, *features]:
        if not pd.api.types.is_numeric_dtype(frame[column]):
            raise ValueError(
                f"The column {column!r} of {description} is not numeric "
                f"(dtype {frame[column].dtype})."
            )
    if recording in available and frame[recording].isna().any():
        row = int(np.flatnonzero(frame[recording].isna().to_numpy())[0])
        raise ValueError(
            f"The recording column {recording!r} of {description} is empty in row {row}."
        )
    n_rows = len(frame)
    out = {
        RECORDING: frame[recording].astype(str).to_numpy()
        if recording in available
        else np.full(n_rows, stem, dtype=object),
    }
    for name, fill in ((DRIVER, UNKNOWN), (SETTING, np.nan), (SPLIT, UNKNOWN)):
        out[name] = frame[name].to_numpy() if name in available else np.full(n_rows, fill)
    out[TIME] = frame[time].to_numpy(dtype=float)
    for column in features:
        out[column] = frame[column].to_numpy(dtype=float)
    out[TARGET] = frame[target].to_numpy(dtype=float)
    out[_SOURCE] = np.full(n_rows, description, dtype=object)
    out[_ROW] = np.arange(n_rows)
    return pd.DataFrame(out), list(features)


def _where(frame, i):
    row = frame.iloc[i]
    return (
        f"recording {row[RECORDING]!r} ({row[_SOURCE]}, row {int(row[_ROW])}, "
        f"time {float(row[TIME]):.10g})"
    )


def _check_finite(frame, columns):
    values = frame[columns].to_numpy(dtype=float)
    bad = ~np.isfinite(values)
    if bad.any():
        i, j = (int(k[0]) for k in np.nonzero(bad))
        kind = "NaN" if np.isnan(values[i, j]) else "an infinite value"
        raise ValueError(
            f"The column {columns[j]!r} holds {kind} in {_where(frame, i)}; "
            f"{int(bad.sum())} non-finite value(s) in all. Fill or drop them first."
        )


def _check_time(frame, sampling_rate):
    recordings = frame[RECORDING].to_numpy()
    time = frame[TIME].to_numpy()
    same = recordings[1:] == recordings[:-1]
    step = np.diff(time)
    for mask, problem in (
        (same & (step < 0), "goes back in time"),
        (same & (step == 0), "repeats the time of the previous row"),
    ):
        if mask.any():
            i = int(np.flatnonzero(mask)[0]) + 1
            raise ValueError(
                f"The row of {_where(frame, i)} {problem} (previous time {time[i - 1]:.10g}). "
                "Rows of a recording must have strictly increasing times."
            )
    if sampling_rate is None:
        return
    period = 1.0 / sampling_rate
    off = same & (np.abs(step - period) > _STEP_RTOL * period)
    if off.any():
        i = int(np.flatnonzero(off)[0]) + 1
        steps = step[same & (recordings[1:] == recordings[i])]
        raise ValueError(
            f"The recording {recordings[i]!r} is not sampled at {sampling_rate} Hz: the row of "
            f"{_where(frame, i)} comes {step[i - 1]:.6g} s after the previous one instead of "
            f"{period:.6g} s (the median step of the recording is {np.median(steps):.6g} s). "
            "Resample the recording first, or pass sampling_rate=None."
        )


def load_recordings(
    data,
    *,
    recording=RECORDING,
    time=TIME,
    target=TARGET,
    features=None,
    sampling_rate=None,
    units=None,
):
    """Load driving recordings from CSV or Parquet files, or a DataFrame, into the tidy frame.

    Each source has one row per sample, with a time column [s], the feature columns and the
    driver torque. A source holds one recording, named after the file (its name without the
    extension), or several, told apart by a recording column. Optional ``driver``, ``setting``
    and ``split`` columns are kept; when absent, ``driver`` and ``split`` are filled with
    ``"unknown"`` and ``setting`` (a simulator setting) with NaN.

    Parameters
    ----------
    data : DataFrame, str, path-like or list of str or path-like
        A DataFrame (it must have the recording column), a file, a folder (its CSV and Parquet
        files, in name order) or a list of files. Files ending in ``.csv`` (optionally
        compressed: ``.csv.gz``...) are read with :func:`pandas.read_csv`, files ending in
        ``.parquet`` or ``.pq`` with :func:`pandas.read_parquet`.
    recording : str, default="recording"
        Name of the recording-id column. A file without it is one recording named after the
        file.
    time : str, default="time"
        Name of the time column, in seconds.
    target : str, default="driver_torque"
        Name of the driver-torque column.
    features : list of str, default=None
        Feature columns, in this order. By default every other column, which must then be
        numeric.
    sampling_rate : float, default=None
        If given, check that every recording is sampled at this rate (steps within 1 % of
        ``1 / sampling_rate``); recordings are never resampled.
    units : dict of str to str, default=None
        Units of the columns, by their name in the source, added to ``attrs["units"]``. The
        schema's columns default to their SI units, others to ``"unknown"``.

    Returns
    -------
    frame : pandas.DataFrame
        Columns ``recording``, ``driver``, ``setting``, ``split``, ``time``, the features, and
        ``driver_torque``; the recording ids are strings. Rows of a recording are contiguous,
        in their original order; recordings come in the order they first appear.
        ``attrs["units"]`` maps the time, feature and target columns to their units.

    Raises
    ------
    ValueError
        Naming the file, recording, column and first offending row (0-based, among the data
        rows of its source) and time, when a column is missing, a value is NaN or infinite,
        times do not strictly increase within a recording (unsorted or duplicated), a
        recording is not sampled at ``sampling_rate``, or one recording id is in two files.

    Notes
    -----
    Rows of a recording interleaved with rows of others are gathered (stably, keeping their
    order) rather than refused; times are never sorted, since out-of-order times more likely
    reveal an error than a harmless shuffle.

    Examples
    --------
    >>> import pandas as pd
    >>> from skhmmgmr.datasets import load_recordings
    >>> raw = pd.DataFrame({"run": ["a", "a", "b", "b"], "t": [0.0, 0.1, 0.0, 0.1],
    ...                     "steering_wheel_angle": [0.0, 0.01, 0.02, 0.01],
    ...                     "torque": [0.1, 0.2, -0.1, 0.0]})
    >>> df = load_recordings(raw, recording="run", time="t", target="torque",
    ...                      sampling_rate=10.0)
    >>> list(df.columns)
    ['recording', 'driver', 'setting', 'split', 'time', 'steering_wheel_angle', 'driver_torque']
    """
    if sampling_rate is not None and (
        isinstance(sampling_rate, bool)
        or not isinstance(sampling_rate, (int, float, np.number))
        or not np.isfinite(sampling_rate)
        or sampling_rate <= 0
    ):
        raise ValueError(
            f"sampling_rate must be None or a positive number of Hz, got {sampling_rate!r}."
        )
    if isinstance(features, str):
        features = [features]
    parts, feature_names, first = [], None, None
    for description, frame, stem in _sources(data):
        part, names = _select(
            description,
            frame,
            stem,
            recording=recording,
            time=time,
            target=target,
            features=features,
        )
        if feature_names is None:
            feature_names, first = names, description
        elif set(names) != set(feature_names):
            raise ValueError(
                f"The features of {description} ({names}) differ from those of {first} "
                f"({feature_names}): pass features= to choose the common ones."
            )
        parts.append(part[[*part.columns[:5], *feature_names, TARGET, _SOURCE, _ROW]])
    frame = pd.concat(parts, ignore_index=True) if len(parts) > 1 else parts[0]

    owners = frame.drop_duplicates([RECORDING, _SOURCE])
    shared = owners[RECORDING].duplicated(keep=False)
    if shared.any():
        name = owners.loc[shared, RECORDING].iloc[0]
        files = owners.loc[owners[RECORDING] == name, _SOURCE].tolist()
        raise ValueError(f"The recording {name!r} is in more than one source: {', '.join(files)}.")

    order = pd.factorize(frame[RECORDING])[0]
    frame = frame.iloc[np.argsort(order, kind="stable")].reset_index(drop=True)
    _check_finite(frame, [TIME, *feature_names, TARGET])
    _check_time(frame, sampling_rate)

    frame = frame.drop(columns=[_SOURCE, _ROW])
    frame[RECORDING] = frame[RECORDING].astype(str)
    renamed = {time: TIME, target: TARGET}
    all_units = {TIME: "s", TARGET: TARGET_UNIT}
    all_units.update({name: FEATURE_UNITS.get(name, UNKNOWN) for name in feature_names})
    for name, unit in (units or {}).items():
        all_units[renamed.get(name, name)] = unit
    frame.attrs["units"] = {c: all_units[c] for c in [TIME, *feature_names, TARGET]}
    return frame
