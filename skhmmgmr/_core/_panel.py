"""Recordings in the index: the panel form of a data set.

A pandas ``DataFrame`` or ``Series`` whose index has a level named ``recording`` (and optionally
a level ``time``; sktime's names ``instances`` and ``timepoints`` are read as well) carries its
recording ids with its rows, so they survive every tool that
slices, resamples or shuffles rows without passing ``groups`` on: ``cross_val_predict``,
built-in scorers, ``permutation_importance``, successive halving, conformal wrappers. This
module reads that index and puts the rows into the order the filter needs (recordings
contiguous, each in time order); the estimator gives its results back in the caller's order.
"""

from collections.abc import Hashable

import numpy as np
import pandas as pd

from ._compat import validate_params
from ._schema import RECORDING, TIME
from ._sequences import as_recordings, check_min_length, check_time_order, one_recording


class RecordingLayout:
    """The recordings of a call: recording id, time and position of every row, read once.

    The one parser, :func:`read_layout`, makes it at the outermost public call; what that
    call hands on (a pipeline's steps, the ``predict`` of a scorer, the metric code) gets the
    rows in filter order with :meth:`handed_down`, this layout for those rows, as ``groups``,
    and reads it back instead of parsing again (:func:`in_filter_order` does all of that).

    A handed-down layout stands for the recording ids of its rows: ``numpy.asarray`` and
    ``len`` give them, iterating reads them; it is never sliced (a ``TypeError``), because
    a slice would need a layout of its own: ``numpy.asarray(groups)[rows]`` gives the ids of
    some rows, to be read afresh.

    Attributes
    ----------
    groups : ndarray or None
        Recording id of every row, in filter order (``None``: one recording).
    time : ndarray or None
        Time stamp of every row, in filter order, when known.
    order : ndarray of int or None
        ``rows[order]`` are the caller's rows in filter order; ``None`` when they already are.
    canonical : bool
        Whether the recordings come in the order of their ids (as text), the order of a fit.
    from_index : bool
        Whether the recordings were read from the index of the rows (a panel).
    """

    __slots__ = (
        "groups",
        "time",
        "order",
        "canonical",
        "from_index",
        "_recordings",
        "_time_checked",
        "_handed",
    )

    def __init__(self, groups, time, order, *, canonical=False, from_index=False, recordings=None):
        self.groups, self.time, self.order = groups, time, order
        self.canonical, self.from_index = canonical, from_index
        self._recordings = recordings
        self._time_checked = False
        self._handed = None

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

    def answer(self, result):
        """A result computed in filter order (an array, a tuple of them, or anything else,
        given back as it is) in the caller's rows."""
        if isinstance(result, tuple):
            return tuple(self.answer(part) for part in result)
        return self.to_caller_order(result) if isinstance(result, np.ndarray) else result

    def recordings(self, n_samples, *, min_length=1):
        """The contiguous recordings of the ``n_samples`` rows in filter order
        (:class:`~skhmmgmr._core._sequences.Recordings`): parsed at the first call, then
        kept; the time stamps, when known, are checked to increase within each."""
        if self.groups is None:
            recordings = one_recording(n_samples)
        elif self._recordings is None:
            recordings = self._recordings = as_recordings(self.groups, n_samples)
        else:
            recordings = self._recordings
            if len(self.groups) != n_samples:  # as as_recordings says it
                as_recordings(self.groups, n_samples)
        if self.time is not None and not self._time_checked:
            check_time_order(self.time, recordings, n_samples)
            self._time_checked = True
        check_min_length(recordings, min_length)
        return recordings

    def handed_down(self):
        """This layout for the rows in filter order, to pass on as ``groups`` with them
        (``None`` for one recording): read back by :func:`read_layout` and
        :func:`recordings_of` without parsing."""
        if self.groups is None:
            return None
        if self.order is None and self._handed is self:  # handed down already
            return self
        if self._handed is not None:
            return self._handed
        ids = np.array(self.groups, copy=True)
        ids.flags.writeable = False
        layout = RecordingLayout(
            ids,
            self.time,
            None,
            canonical=self.canonical,
            from_index=self.from_index,
            recordings=self._recordings,
        )
        layout._time_checked = self._time_checked
        layout._handed = layout
        self._handed = layout
        return layout

    def with_time(self, time):
        """This handed-down layout with the time stamps ``time`` (one per row, in filter
        order; a time column may count from another origin than an index level), its
        recordings kept and the time checked to increase within each when they are read."""
        if time is self.time:
            return self
        layout = RecordingLayout(
            self.groups,
            time,
            None,
            canonical=self.canonical,
            from_index=self.from_index,
            recordings=self._recordings,
        )
        layout._handed = layout
        return layout

    # A handed-down layout stands for its recording ids wherever ``groups`` is read as an
    # array (scikit-learn's splitters, a user's estimator); a slice of it is refused.
    def __array__(self, dtype=None, copy=None):
        if copy:
            return np.array(self._ids(), dtype=dtype, copy=True)
        return np.asarray(self._ids(), dtype=dtype)

    def __len__(self):
        return len(self._ids())

    def __bool__(self):  # given recordings, whatever their number of rows
        return True

    def __iter__(self):
        return iter(self._ids())

    def __getitem__(self, key):
        raise TypeError(
            "these groups are the recordings skhmmgmr handed down with the rows (a "
            "RecordingLayout), which are not sliced: a slice needs a layout of its own. Take "
            "the ids of some rows with numpy.asarray(groups)[rows]."
        )

    def _ids(self):
        if self.groups is None:
            raise TypeError("a layout of one recording holds no recording ids")
        return self.groups


class RowOrder(RecordingLayout):
    """The name 0.1.0 gave the row order of a call (now :class:`RecordingLayout`), kept so
    that references to it still resolve."""

    __slots__ = ()


def _handed(groups, n_samples):
    """``groups`` when it is a handed-down :class:`RecordingLayout` for ``n_samples`` rows
    (``None`` when it is no layout); a layout for other rows is refused, naming both."""
    if not isinstance(groups, RecordingLayout):
        return None
    if groups.order is not None:
        raise TypeError(
            "groups is a RecordingLayout in the caller's row order; hand down "
            "layout.handed_down() with the rows in filter order"
        )
    if n_samples is not None and len(groups) != n_samples:
        raise ValueError(
            f"groups holds the recordings of {len(groups)} rows but X has {n_samples} rows; "
            "the recordings handed down belong to other rows"
        )
    return groups


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


def align_target(X, y, layout=None):
    """``y`` paired with the rows of ``X`` by label when ``X`` is a panel (recordings in its
    index; ``layout``, the call's :class:`RecordingLayout`, says so when given) and ``y`` a
    pandas object: reordered to ``X``'s rows if its index holds the same labels in another
    order, refused if it holds other labels. Anything else is returned as it is (an array
    pairs by position)."""
    if not isinstance(y, pd.Series | pd.DataFrame):
        return y
    if not (has_recording_index(X) if layout is None else layout.from_index):
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


def read_layout(X, groups=None, time=None, *, canonical=False, reorder_groups=True):
    """The one parser of recordings: recording ids, time stamps and row order of a call, from
    its arguments or the index of ``X``.

    ``groups`` handed down by an outer call (:meth:`RecordingLayout.handed_down`) are their
    layout, given back without parsing (with ``time``, its time; read afresh from its ids
    when ``canonical`` asks for an order it is not in); a layout of another number of rows
    than ``X`` is refused. Otherwise ``groups`` and ``time`` given explicitly win over
    nothing: when the index holds them too, both must agree row by row. When the index holds
    the recordings and the time, the rows of a recording may come in any order and
    interleaved with other recordings: the returned order makes recordings contiguous and
    each sorted by time.

    Parameters
    ----------
    X : array-like, pandas.DataFrame, pandas.Series or None
        The rows (``None``: only ``groups`` and ``time`` are read).
    groups, time : array-like of shape (n_samples,), default=None
    canonical : bool, default=False
        Put the recordings in the order of their ids (as text), from a panel or from
        ``groups``, so that the filter order depends neither on how the rows were shuffled
        nor on the order of the recordings: a fit, whose initialization reads the rows in
        order, then gives the same model for the same rows in any order. Otherwise a panel's
        recordings come in order of first appearance and plain rows keep their order (a
        prediction gives its results back by position).
    reorder_groups : bool, default=True
        With ``canonical``, whether the recordings given by ``groups`` are put in order too;
        ``False`` for callers whose other inputs index the rows by position (a
        ``PredefinedSplit``), which then get a panel's recordings in id order only.

    Returns
    -------
    RecordingLayout
    """
    layout = _handed(groups, None if X is None else _n_rows(X))
    if layout is not None:
        if canonical and not layout.canonical:
            groups = np.asarray(layout)
        else:
            return layout if time is None else layout.with_time(time)
    index_recording, index_time = index_levels(X)
    if index_recording is None:
        if index_time is not None and time is None:
            time = np.asarray(index_time)
        if canonical and reorder_groups and groups is not None:
            return _recordings_in_id_order(groups, time)
        return RecordingLayout(groups, time, None, canonical=groups is None)
    ids = _text_ids(index_recording)
    if groups is not None:
        _check_agree(groups, ids, "groups", "the recording level of the index")
    if index_time is not None:
        index_time = _as_seconds(index_time)
        if time is not None:
            _check_agree(time, index_time, "time", "the time level of the index")
        time = index_time
    codes, uniques = pd.factorize(ids, sort=False)
    if canonical:
        rank = np.empty(len(uniques), dtype=np.intp)
        rank[np.argsort(np.asarray(uniques, dtype=str), kind="stable")] = np.arange(len(uniques))
        codes = rank[codes]
    if time is None:
        order = np.argsort(codes, kind="stable")
    else:
        order = np.lexsort((np.asarray(time, dtype=float), codes))
    if np.array_equal(order, np.arange(len(order))):
        order = None
    return _moved(ids, time, order, canonical=canonical, from_index=True)


def recordings_of(groups, n_samples, *, time=None, min_length=1):
    """The recordings of ``n_samples`` rows in filter order whose ids are ``groups`` (those
    handed down by an outer call carry them already), with ``time`` checked to increase
    within each and every recording at least ``min_length`` rows long."""
    layout = _handed(groups, n_samples)
    if layout is None:
        return as_recordings(groups, n_samples, time=time, min_length=min_length)
    recordings = layout.recordings(n_samples, min_length=min_length)
    if time is not None:
        check_time_order(np.asarray(time, dtype=float), recordings, n_samples)
    return recordings


def in_filter_order(run, X, groups=None, *, time=None, y=None, rows=None, canonical=False):
    """Read the layout of a call, run it in filter order, answer in the caller's order.

    The prologue of every public method that reads recordings: every per-row argument is
    checked to have the rows of ``X`` (:func:`check_named_lengths`), the layout read once
    (:func:`read_layout` of ``X``, ``groups`` and ``time``), then ``run(layout, X, **rows)``
    gets the layout of the rows in filter order (its :meth:`~RecordingLayout.handed_down`
    is what to pass on as ``groups``; ``layout.time`` and ``layout.recordings`` read it) and
    ``X``, ``y`` and every array of ``rows`` in filter order. Arrays in what ``run``
    returns (alone or in a tuple) come back in the caller's row order.

    Parameters
    ----------
    run : callable
        ``run(layout, X, **rows)``, with ``y=`` among ``rows`` when ``y`` is given.
    X : array-like, pandas.DataFrame or pandas.Series
        The rows; a panel's index gives the recordings and the time.
    groups, time : array-like of shape (n_samples,), default=None
        As for :func:`read_layout`.
    y : array-like, default=None
        The target: a pandas object is paired with a panel ``X`` by label
        (:func:`align_target`).
    rows : dict of str to array-like, default=None
        Other per-row arguments (``None`` values are passed as they are), paired by position.
    canonical : bool, default=False
        As for :func:`read_layout` (a fit).
    """
    rows = dict(rows or {})
    if y is not None:
        rows["y"] = y
    check_named_lengths(X=X, **rows)  # (groups and time: the parser names them)
    layout = read_layout(X, groups, time, canonical=canonical)
    if y is not None:
        rows["y"] = align_target(X, y, layout)
    ordered = {name: layout.to_filter_order(values) for name, values in rows.items()}
    # one recording: no reordering (only a recording level reorders), nothing to hand down
    in_order = layout if layout.groups is None else layout.handed_down()
    return layout.answer(run(in_order, layout.to_filter_order(X), **ordered))


def check_named_lengths(**arrays):
    """Refuse per-row arguments of different numbers of rows, naming the first and every
    one whose rows differ from its (``None`` values are left out)."""
    lengths = {name: _n_rows(a) for name, a in arrays.items() if a is not None}
    if len(set(lengths.values())) > 1:
        first, rows = next(iter(lengths.items()))
        named = {first: rows, **{name: n for name, n in lengths.items() if n != rows}}
        described = ", ".join(f"{name} has {n}" for name, n in named.items())
        raise ValueError(f"inconsistent numbers of samples: {described}")


def _n_rows(values):
    shape = getattr(values, "shape", None)
    if shape is None and not hasattr(values, "__len__"):  # array-like by __array__ alone
        shape = np.asarray(values).shape
    if shape is not None:
        return int(shape[0]) if len(shape) else 1
    return len(values)


def _recordings_in_id_order(groups, time):
    """The rows of contiguous recordings (``groups``) with the recordings in order of their
    ids as text, as :func:`read_layout` puts a panel's when ``canonical``."""
    groups = np.asarray(groups.to_numpy() if isinstance(groups, pd.Series) else groups)
    recordings = as_recordings(groups, len(groups))  # refuses scattered recordings, naming one
    rank = np.argsort(np.asarray(recordings.ids).astype(str), kind="stable")
    if np.array_equal(rank, np.arange(len(rank))):
        return RecordingLayout(groups, time, None, canonical=True, recordings=recordings)
    order = recordings.row_order(rank)
    return _moved(groups, time, order, canonical=True, recordings=recordings.reordered(rank))


def _moved(groups, time, order, **facts):
    """The layout of rows whose ids and times, in the caller's order, are ``groups`` and
    ``time``, read in ``order``."""
    given = RecordingLayout(groups, time, order)
    return RecordingLayout(
        given.to_filter_order(groups), given.to_filter_order(time), order, **facts
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


@validate_params(
    {"frame": [pd.DataFrame], "recording": [Hashable], "time": [Hashable, None]},
    prefer_skip_nested_validation=True,
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
