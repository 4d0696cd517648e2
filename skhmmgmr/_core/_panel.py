"""Recordings in the index: the panel form of a data set.

A pandas ``DataFrame`` or ``Series`` whose index has a level named ``recording`` (and optionally
a level ``time``; sktime's names ``instances`` and ``timepoints`` are read as well) carries its
recording ids with its rows, so they survive every tool that
slices, resamples or shuffles rows without passing ``groups`` on: ``cross_val_predict``,
built-in scorers, ``permutation_importance``, successive halving, conformal wrappers. This
module reads that index and puts the rows into the order the filter needs (recordings
contiguous, each in time order); the estimator gives its results back in the caller's order.
"""

from dataclasses import dataclass

import numpy as np
import pandas as pd

from ._schema import RECORDING, TIME
from ._sequences import as_recordings


@dataclass(frozen=True)
class RowOrder:
    """Per-row metadata of a call, in the order the filter reads the rows.

    Attributes
    ----------
    groups : ndarray or None
        Recording id of every row (``None``: one recording).
    time : ndarray or None
        Time stamp of every row, when known.
    order : ndarray of int or None
        ``rows[order]`` are the caller's rows in filter order; ``None`` when they already are.
    """

    groups: object
    time: object
    order: object

    def to_filter_order(self, values):
        """Rows of ``values`` (array, DataFrame or Series) in filter order."""
        if self.order is None or values is None:
            return values
        if isinstance(values, pd.DataFrame | pd.Series):
            return values.iloc[self.order]
        return np.asarray(values)[self.order]

    def to_caller_order(self, values):
        """Rows of a result computed in filter order, back in the caller's order."""
        if self.order is None:
            return values
        restored = np.empty_like(values)
        restored[self.order] = values
        return restored


# Names under which the index levels are read: the package's own, then sktime's (its panel
# form, "pd-multiindex", names them instances and timepoints).
RECORDING_LEVELS = (RECORDING, "instances")
TIME_LEVELS = (TIME, "timepoints")


def _level(index, names, what):
    found = [name for name in names if name in index.names]
    if len(found) > 1:
        raise ValueError(
            f"X's index has both a {found[0]!r} and a {found[1]!r} level: which holds the "
            f"{what}? Drop or rename one (its levels are {list(index.names)})."
        )
    return index.get_level_values(found[0]) if found else None


def index_levels(X):
    """The recording and time levels of the index of ``X`` (each ``None`` if absent), read
    under the names of :data:`RECORDING_LEVELS` and :data:`TIME_LEVELS`.

    An index of two levels or more without a recording level is refused naming its levels:
    read as one recording, a panel whose levels bear other names would filter across its
    recordings without a word.
    """
    if not isinstance(X, pd.DataFrame | pd.Series):
        return None, None
    index = X.index
    recording = _level(index, RECORDING_LEVELS, "recording ids")
    time = _level(index, TIME_LEVELS, "times")
    if recording is None and index.nlevels > 1:
        raise ValueError(
            f"X's index has the levels {list(index.names)}, none of which holds the recording "
            "ids. Name them, 'recording' (or sktime's 'instances') and 'time' (or "
            "'timepoints'), e.g. X.rename_axis(['recording', 'time']); or give X a plain index "
            "and the recordings as groups=."
        )
    return recording, time


def has_recording_index(X):
    """Whether ``X`` carries its recording ids in its index."""
    return index_levels(X)[0] is not None


def align_target(X, y):
    """``y`` paired with the rows of ``X`` by label when ``X`` is a panel (recordings in its
    index) and ``y`` a pandas object: reordered to ``X``'s rows if its index holds the same
    labels in another order, refused if it holds other labels. Anything else is returned as
    it is (an array pairs by position)."""
    if not isinstance(y, pd.Series | pd.DataFrame) or not has_recording_index(X):
        return y
    if y.index.equals(X.index):
        return y
    same = (
        len(y) == len(X)
        and X.index.is_unique
        and y.index.is_unique
        and y.index.nlevels == X.index.nlevels
        and y.index.isin(X.index).all()
    )
    if not same:
        raise ValueError(
            f"y is a pandas object whose index does not hold the rows of X (X's index has the "
            f"levels {list(X.index.names)}, y's {list(y.index.names)}; {len(X)} and {len(y)} "
            "rows): pass y with X's index (such as a column of the same panel), or an array in "
            "X's row order."
        )
    return y.reindex(X.index)


def read_row_order(X, groups=None, time=None, *, sort_recordings=False, sort_groups=False):
    """Recording ids, time stamps and row order of a call, from arguments or the index of X.

    ``groups`` and ``time`` given explicitly win over nothing: when the index holds them too,
    both must agree row by row. When the index holds the recordings and the time, the rows of
    a recording may come in any order and interleaved with other recordings: the returned order
    makes recordings contiguous (in order of first appearance) and each sorted by time.

    Parameters
    ----------
    X : array-like, pandas.DataFrame or pandas.Series
    groups, time : array-like of shape (n_samples,), default=None
    sort_recordings : bool, default=False
        Put the recordings of an indexed ``X`` in order of their ids (as text) rather than of
        first appearance, so that the filter order does not depend on how the rows were
        shuffled: a fit (whose initialization reads the rows in order) then gives the same
        model for any permutation of the rows.
    sort_groups : bool, default=False
        Likewise for the recordings of a plain ``X`` given by ``groups`` (contiguous, each in
        time order): a fit then gives the same model as for the panel of the same rows,
        whatever the order of the recordings. Not for callers whose other inputs are indexed
        by row position (a ``PredefinedSplit``).

    Returns
    -------
    RowOrder
    """
    index_recording, index_time = index_levels(X)
    if index_recording is None:
        if index_time is not None and time is None:
            time = np.asarray(index_time)
        if sort_groups and groups is not None:
            return _recordings_in_id_order(groups, time)
        return RowOrder(groups=groups, time=time, order=None)
    ids = _text_ids(index_recording)
    if groups is not None:
        _check_agree(groups, ids, "groups", "the recording level of the index")
    if index_time is not None:
        index_time = _as_seconds(index_time)
        if time is not None:
            _check_agree(time, index_time, "time", "the time level of the index")
        time = index_time
    codes, uniques = pd.factorize(ids, sort=False)
    if sort_recordings:
        rank = np.empty(len(uniques), dtype=np.intp)
        rank[np.argsort(np.asarray(uniques, dtype=str), kind="stable")] = np.arange(len(uniques))
        codes = rank[codes]
    if time is None:
        order = np.argsort(codes, kind="stable")
    else:
        order = np.lexsort((np.asarray(time, dtype=float), codes))
    if np.array_equal(order, np.arange(len(order))):
        order = None
    row_order = RowOrder(groups=ids, time=time, order=order)
    return RowOrder(
        groups=row_order.to_filter_order(ids),
        time=row_order.to_filter_order(time),
        order=order,
    )


def _recordings_in_id_order(groups, time):
    """The rows of contiguous recordings (``groups``) with the recordings in order of their
    ids as text, as :func:`read_row_order` puts a panel's with ``sort_recordings``."""
    groups = np.asarray(groups.to_numpy() if isinstance(groups, pd.Series) else groups)
    recordings = as_recordings(groups, len(groups))  # refuses scattered recordings, naming one
    rank = np.argsort(np.asarray(recordings.ids).astype(str), kind="stable")
    if np.array_equal(rank, np.arange(len(rank))):
        return RowOrder(groups=groups, time=time, order=None)
    order = np.concatenate([np.arange(recordings.starts[r], recordings.stops[r]) for r in rank])
    given = RowOrder(groups=groups, time=time, order=order)
    return RowOrder(
        groups=given.to_filter_order(groups), time=given.to_filter_order(time), order=order
    )


def _text_ids(level):
    ids = np.asarray(level, dtype=object)
    missing = pd.isna(ids)
    if missing.any():
        row = int(np.flatnonzero(missing)[0])
        raise ValueError(
            f"the index level {RECORDING!r} has a missing recording id (first at row {row})"
        )
    return ids


def _as_seconds(level):
    if isinstance(level, pd.TimedeltaIndex):
        return level.total_seconds().to_numpy()
    if isinstance(level, pd.DatetimeIndex):
        return (level - level.min()).total_seconds().to_numpy() if len(level) else np.array([])
    try:
        return np.asarray(level, dtype=float)
    except (TypeError, ValueError) as exc:
        raise ValueError(
            f"the index level {TIME!r} must hold seconds (numbers), timedeltas or datetimes, "
            f"got dtype {level.dtype}"
        ) from exc


def _check_agree(given, from_index, name, where):
    given = np.asarray(given.to_numpy() if isinstance(given, pd.Series) else given)
    if given.shape != (len(from_index),):
        raise ValueError(
            f"{name} has shape {given.shape} but X has {len(from_index)} rows; give one "
            "value per row, or leave it out to use the index"
        )
    if name == "time":
        differs = ~np.isclose(np.asarray(given, dtype=float), from_index, rtol=0, atol=1e-9)
    else:
        differs = (
            pd.Series(given).astype(str).to_numpy() != pd.Series(from_index).astype(str).to_numpy()
        )
    if differs.any():
        row = int(np.flatnonzero(differs)[0])
        raise ValueError(
            f"{name} disagrees with {where} at row {row} ({given[row]!r} != "
            f"{from_index[row]!r}); pass {name} or use the index, not both differently"
        )


def to_panel(frame, *, recording=RECORDING, time=TIME):
    """The panel form of a tidy frame: recording ids (as text) and time moved into the index.

    Every estimator, scorer and selector of the package reads the recordings (and the time
    order) from such an index when ``groups`` is not given, so the recordings travel with the
    rows through tools that never pass ``groups`` on (``cross_val_predict``, built-in scorers,
    ``permutation_importance``, successive halving, conformal wrappers).

    Parameters
    ----------
    frame : pandas.DataFrame
        One row per sample, with a recording column and, optionally, a time column (seconds).
    recording : str, default="recording"
        Column holding the recording id; it becomes the index level ``"recording"``.
    time : str or None, default="time"
        Column holding the time in seconds; it becomes the index level ``"time"``. ``None``
        (or a frame without that column): recordings only, rows already in time order.

    Returns
    -------
    panel : pandas.DataFrame
        The other columns, indexed by ``("recording", "time")`` (or ``"recording"``).

    Examples
    --------
    >>> import pandas as pd
    >>> from skhmmgmr.datasets import to_panel
    >>> frame = pd.DataFrame({"recording": [7, 7], "time": [0.0, 0.05], "x": [1.0, 2.0]})
    >>> to_panel(frame).index.tolist()
    [('7', 0.0), ('7', 0.05)]
    """
    if not isinstance(frame, pd.DataFrame):
        raise TypeError(f"to_panel takes a pandas DataFrame, got {type(frame).__name__}")
    if recording not in frame.columns:
        raise ValueError(f"the frame has no recording column {recording!r}")
    columns = {recording: RECORDING}
    if time is not None and time in frame.columns:
        columns[time] = TIME
    keys = frame[list(columns)].rename(columns=columns)
    keys[RECORDING] = _text_ids(keys[RECORDING].to_numpy()).astype(str)
    if TIME in keys:
        keys[TIME] = _as_seconds(pd.Index(keys[TIME]))
    panel = frame.drop(columns=list(columns))
    panel.index = (
        pd.MultiIndex.from_frame(keys)
        if len(columns) > 1
        else pd.Index(keys[RECORDING], name=RECORDING)
    )
    return panel
