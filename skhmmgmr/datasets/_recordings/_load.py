"""Load a user's own driving recordings from CSV or Parquet files into the tidy frame."""

import os
import warnings
from collections.abc import Mapping
from numbers import Real
from pathlib import Path

import numpy as np
import pandas as pd

from ..._core._compat import FiniteInterval, validate_params
from ..._core._schema import (
    CROSSING_TIME,
    DRIVER,
    EXPERIMENT_COLUMNS,
    MANOEUVRE,
    META_COLUMNS,
    RECORDING,
    SPLIT,
    STEERING_PERTURBATION,
    TARGET,
    TIME,
)
from .._frame import META_DEFAULTS, check_rate, tidy_frame, time_order
from ._resample import RESAMPLING_CONSTRAINTS, check_max_gap, resample_recordings

_CSV_SUFFIXES = (".csv", ".csv.gz", ".csv.bz2", ".csv.zip", ".csv.xz")
_PARQUET_SUFFIXES = (".parquet", ".pq")
_SOURCE = "__source__"
_ROW = "__row__"
# The package's own labels of a simulated frame (what the driver does, when it crosses a
# marking, the torque of a perturbation experiment): metadata kept as they are when a source
# has them, never features.
_LABELS = (MANOEUVRE, CROSSING_TIME, STEERING_PERTURBATION)


def _suffix(path):
    name = path.name.lower()
    for suffix in _CSV_SUFFIXES + _PARQUET_SUFFIXES:
        if name.endswith(suffix):
            return suffix
    return None


def read_table(path, text_columns=()):
    """Read one CSV or Parquet file, every failure a ValueError naming the file.

    Parameters
    ----------
    path : str or path-like
        A file ending in one of the CSV suffixes (``.csv``, ``.csv.gz``...) or ``.parquet``/
        ``.pq``.
    text_columns : iterable of str, default=()
        Columns read as text from a CSV file, so that ids such as ``"007"`` and ``"7"``, or
        ``"TRUE"`` and ``"True"``, stay distinct; absent ones are ignored.

    Returns
    -------
    frame : pandas.DataFrame
        At least one row.

    Raises
    ------
    FileNotFoundError
        When there is no file at ``path``.
    ValueError
        When the file is not CSV or Parquet by its name, is empty or has no data row, is not
        UTF-8 text, is truncated or corrupt, or a CSV row has more fields than the header.
    """
    path = Path(path)
    suffix = _suffix(path)
    if not path.is_file():
        raise FileNotFoundError(f"No recording file at {str(path)!r}.")
    if suffix is None:
        raise ValueError(
            f"Cannot read {str(path)!r}: recording files must be CSV "
            f"({', '.join(_CSV_SUFFIXES)}) or Parquet ({', '.join(_PARQUET_SUFFIXES)})."
        )
    try:
        if suffix in _PARQUET_SUFFIXES:
            frame = pd.read_parquet(path)
        else:
            with warnings.catch_warnings():
                # index_col=False: a row longer than the header warns instead of silently
                # turning the first column into the index
                warnings.simplefilter("error", pd.errors.ParserWarning)
                dtype = dict.fromkeys(text_columns, str)
                frame = pd.read_csv(path, dtype=dtype, index_col=False)
    except UnicodeDecodeError as exc:
        raise ValueError(
            f"Cannot read {str(path)!r}: it is not UTF-8 text (it holds the byte "
            f"{exc.object[exc.start]:#x}); save it as UTF-8."
        ) from None
    except pd.errors.EmptyDataError:
        raise ValueError(f"Cannot read {str(path)!r}: the file is empty.") from None
    except pd.errors.ParserWarning as exc:
        raise ValueError(
            f"Cannot read {str(path)!r}: a row has more fields than the header ({exc})."
        ) from None
    except Exception as exc:  # pandas, pyarrow and the decompressors raise many types
        text = str(exc).strip()
        raise ValueError(f"Cannot read {str(path)!r}: {type(exc).__name__}: {text}") from None
    if frame.empty:
        columns = [str(c) for c in frame.columns]
        raise ValueError(f"The file {str(path)!r} holds no data row (columns: {columns}).")
    return frame


def _sources(data, recording):
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
        stem = path.name[: -len(suffix)] if suffix else path.name
        if stem in stems:
            raise ValueError(
                f"The files {str(stems[stem])!r} and {str(path)!r} would both be recording "
                f"{stem!r}: rename one of them or give the files a recording column."
            )
        stems[stem] = path
        # Ids are text: read as numbers, "007" and "7" would be one recording.
        frame = read_table(path, (recording, DRIVER, SPLIT, MANOEUVRE))
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
    meta = {recording, time, target, *META_COLUMNS, *EXPERIMENT_COLUMNS, TARGET}
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
    # Filled per source, so that sources with and without these columns can be joined.
    for name, fill in META_DEFAULTS.items():
        out[name] = frame[name].to_numpy() if name in available else np.full(n_rows, fill)
    out[TIME] = frame[time].to_numpy(dtype=float)
    out.update({name: frame[name].to_numpy() for name in _LABELS if name in available})
    for column in features:
        out[column] = frame[column].to_numpy(dtype=float)
    out[TARGET] = frame[target].to_numpy(dtype=float)
    out[_SOURCE] = np.full(n_rows, description, dtype=object)
    out[_ROW] = np.arange(n_rows)
    return pd.DataFrame(out), list(features)


@validate_params(
    {
        "data": [pd.DataFrame, str, os.PathLike, "array-like"],
        "recording": [str],
        "time": [str],
        "target": [str],
        "features": [str, "array-like", None],
        "sampling_rate": [FiniteInterval(Real, 0, None, closed="neither"), None],
        "max_gap": [*RESAMPLING_CONSTRAINTS["max_gap"], None],
        "min_length": RESAMPLING_CONSTRAINTS["min_length"],
        "allow_missing": ["boolean"],
        "units": [Mapping, None],
    },
    prefer_skip_nested_validation=True,
)
def load_recordings(
    data,
    *,
    recording=RECORDING,
    time=TIME,
    target=TARGET,
    features=None,
    sampling_rate=None,
    max_gap=None,
    min_length=1,
    allow_missing=False,
    units=None,
):
    """Load driving recordings from CSV or Parquet files, or a DataFrame, into the tidy frame.

    Each source has one row per sample, with a time column [s], the feature columns and the
    driver torque. A source holds one recording, named after the file (its name without the
    extension), or several, told apart by a recording column. Optional ``driver``, ``setting``
    and ``split`` columns are kept; when absent, ``driver`` and ``split`` are filled with
    ``"unknown"`` and ``setting`` (a simulator setting) with NaN. The labels of a simulated
    frame, ``manoeuvre`` and ``crossing_time`` (:func:`make_lane_keeping`), are kept as
    labels, never taken for features, so that a frame of the simulator written to a file
    loads back as it was.

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
        If given without ``max_gap``, check that every recording is sampled at this rate
        (steps within 1 % of ``1 / sampling_rate``); recordings are then never resampled. With
        ``max_gap``, the rate of the grid the recordings are resampled to. At most 1000 Hz.
    max_gap : float, default=None
        If given, put every recording on a uniform grid at ``sampling_rate`` with
        :func:`resample_recordings`: gaps up to ``max_gap`` seconds between samples are
        interpolated, a longer gap splits its recording into ``"<id>/0"``, ``"<id>/1"``...
        Features that are integer or boolean in their source (flags, gears, counters) take the
        value of the latest sample (previous-value hold), the others and the target are
        interpolated linearly. By default recordings are not resampled.
    min_length : int, default=1
        With ``max_gap``: pieces of a recording (between long gaps) with fewer grid samples
        are dropped, with a warning (see :func:`resample_recordings`).
    allow_missing : bool, default=False
        Keep NaN in the features and the target as missing values, for a model that handles
        them (``HMMGMRRegressor(missing_values="marginalize")`` or ``"carry_forward"``). A
        missing sample stays missing on the grid (nothing is interpolated from or across it).
        Times and recording ids must be complete, and infinities are refused either way.
    units : dict of str to str, default=None
        Units of the columns, by their name in the source, added to ``attrs["units"]``. The
        schema's columns default to their SI units, others to ``"unknown"``.

    Returns
    -------
    frame : pandas.DataFrame
        Columns ``recording``, ``driver``, ``setting``, ``split``, ``time`` (then
        ``manoeuvre`` and ``crossing_time`` where the sources have them), the features, and
        ``driver_torque``; recording ids, drivers and splits are text (read as text from CSV
        files, so that ``"007"`` and ``"7"`` stay two recordings). Rows of a recording are
        contiguous and sorted by time; recordings come in the order they first appear. No row
        is dropped (with ``max_gap``, the rows are those of the grid, see
        :func:`resample_recordings`). ``attrs["units"]`` maps the time, feature and target
        columns to their units.

    Raises
    ------
    ValueError
        Naming the file, recording, column and first offending row (0-based, among the data
        rows of its source) and time, when a file cannot be read (empty, no data row, not
        UTF-8, truncated, a row longer than the header), a column is missing, a value is NaN
        (unless ``allow_missing``) or infinite, a recording id, driver or split is empty, a
        time is repeated within a recording, a recording is not sampled at ``sampling_rate``
        (without ``max_gap``), or one recording id is in two files. Also when ``max_gap`` is
        given without ``sampling_rate`` or is shorter than one period.

    Notes
    -----
    The rows of every recording are gathered and sorted by time (stably), as the command line
    does: a file shuffled within its recordings, or with recordings interleaved, gives the
    frame of the sorted file.

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
    check_rate(sampling_rate)
    if max_gap is not None:
        if sampling_rate is None:
            raise ValueError("max_gap needs sampling_rate, the rate of the grid to resample to.")
        check_max_gap(max_gap, sampling_rate)
    if isinstance(features, str):
        features = [features]
    parts, feature_names, labels, first, held = [], None, None, None, set()
    for description, frame, stem in _sources(data, recording):
        part, names = _select(
            description,
            frame,
            stem,
            recording=recording,
            time=time,
            target=target,
            features=features,
        )
        kept = [name for name in _LABELS if name in part.columns]
        if feature_names is None:
            feature_names, labels, first = names, kept, description
        elif set(names) != set(feature_names):
            raise ValueError(
                f"The features of {description} ({names}) differ from those of {first} "
                f"({feature_names}): pass features= to choose the common ones."
            )
        elif kept != labels:
            raise ValueError(
                f"{description[0].upper()}{description[1:]} has the label column(s) {kept}, "
                f"{first} {labels}: give every source the same, or drop them."
            )
        parts.append(part[[*part.columns[:5], *labels, *feature_names, TARGET, _SOURCE, _ROW]])
        dtypes = {str(column): dtype for column, dtype in frame.dtypes.items()}
        held.update(name for name in names if not pd.api.types.is_float_dtype(dtypes[name]))
    frame = pd.concat(parts, ignore_index=True) if len(parts) > 1 else parts[0]

    owners = frame.drop_duplicates([RECORDING, _SOURCE])
    shared = owners[RECORDING].duplicated(keep=False)
    if shared.any():
        name = owners.loc[shared, RECORDING].iloc[0]
        files = owners.loc[owners[RECORDING] == name, _SOURCE].tolist()
        raise ValueError(f"The recording {name!r} is in more than one source: {', '.join(files)}.")

    frame = frame.iloc[time_order(frame[RECORDING], frame[TIME])].reset_index(drop=True)
    renamed = {time: TIME, target: TARGET}
    frame = tidy_frame(
        frame.drop(columns=[_SOURCE, _ROW]),
        units={renamed.get(name, name): unit for name, unit in (units or {}).items()},
        sampling_rate=sampling_rate if max_gap is None else None,
        source=frame[_SOURCE].to_numpy(),
        row=frame[_ROW].to_numpy(),
        allow_missing=allow_missing,
    )
    if max_gap is None:
        return frame
    return resample_recordings(
        frame, sampling_rate, max_gap=max_gap, min_length=min_length, hold=sorted(held)
    )
