"""Recordings: turning one recording id per row into contiguous, time-ordered sequences.

scikit-learn slices per-row metadata (``groups``) per cross-validation fold, so the package keeps
one recording id per row and derives the sequence boundaries from it. The rows of a recording
must be contiguous and in time order; everything here checks that and says which recording is
at fault.
"""

from dataclasses import dataclass

import numpy as np
import pandas as pd


@dataclass(frozen=True)
class Recordings:
    """Contiguous recordings of a data set.

    Attributes
    ----------
    ids : ndarray of shape (n_recordings,)
        Recording id of every recording, in order of appearance.
    starts, stops : ndarray of shape (n_recordings,)
        Row ``starts[i]`` (inclusive) to ``stops[i]`` (exclusive) hold recording ``ids[i]``.
    """

    ids: np.ndarray
    starts: np.ndarray
    stops: np.ndarray

    @property
    def lengths(self):
        return self.stops - self.starts

    def __len__(self):
        return len(self.ids)

    def slices(self):
        """Iterate over ``(recording_id, slice)`` pairs."""
        for rec_id, start, stop in zip(self.ids, self.starts, self.stops, strict=True):
            yield rec_id, slice(int(start), int(stop))

    def recording_of_row(self, row):
        """Recording id that holds ``row``."""
        index = int(np.searchsorted(self.stops, row, side="right"))
        return self.ids[index]

    def row_ids(self):
        """One recording id per row."""
        return np.repeat(self.ids, self.lengths)

    def reordered(self, rank):
        """The recordings after moving recording ``rank[i]`` to position ``i`` (their rows
        moved with them, contiguous)."""
        lengths = self.lengths[rank]
        stops = np.cumsum(lengths)
        return Recordings(ids=self.ids[rank], starts=stops - lengths, stops=stops)

    def row_order(self, rank):
        """The rows of :meth:`reordered`, as positions in the current rows."""
        return np.concatenate(
            [np.arange(self.starts[r], self.stops[r]) for r in rank] or [np.array([], int)]
        )


def as_recordings(groups, n_samples, *, time=None, min_length=1):
    """Validate ``groups`` (one recording id per row) and return the recordings.

    Parameters
    ----------
    groups : array-like of shape (n_samples,) or None
        Recording id of every row; ``None`` means all rows form one recording.
    n_samples : int
        Number of rows of the data.
    time : array-like of shape (n_samples,), default=None
        Time stamps; when given they must increase strictly within every recording.
    min_length : int, default=1
        Minimum number of rows a recording needs.

    Returns
    -------
    Recordings
    """
    if groups is None:
        recordings = one_recording(n_samples)
    else:
        recordings = _contiguous_recordings(groups, n_samples)
    if time is not None:
        check_time_order(time, recordings, n_samples)
    check_min_length(recordings, min_length)
    return recordings


def one_recording(n_samples):
    """All ``n_samples`` rows as one recording (id 0)."""
    return Recordings(ids=np.array([0]), starts=np.array([0]), stops=np.array([n_samples]))


def check_min_length(recordings, min_length):
    """Refuse a recording shorter than ``min_length`` rows, naming it."""
    short = recordings.lengths < min_length
    if np.any(short):
        first = int(np.flatnonzero(short)[0])
        raise ValueError(
            f"recording {recordings.ids[first]!r} has n_samples={recordings.lengths[first]} "
            f"row(s); at least {min_length} are needed"
        )


def _contiguous_recordings(groups, n_samples):
    groups = np.asarray(groups.to_numpy() if isinstance(groups, pd.Series) else groups)
    if groups.ndim != 1:
        raise ValueError(f"groups must be 1-D (one recording id per row), got shape {groups.shape}")
    if groups.shape[0] != n_samples:
        raise ValueError(
            f"groups has {groups.shape[0]} entries but X has {n_samples} rows; "
            "give one recording id per row"
        )
    if n_samples == 0:
        raise ValueError("X has no rows")
    # Recordings start where the id changes; a missing id (None, NaN) starts a recording too
    # (NaN differs from itself), so the checks below need only the first id of each.
    # Object ids are compared through their codes: ids such as pd.NA have no boolean
    # comparison (numpy < 1.25 then returns one scalar instead of raising).
    if groups.dtype == object:
        codes = pd.factorize(groups, sort=False, use_na_sentinel=False)[0]
        differs = codes[1:] != codes[:-1]
    else:
        differs = groups[1:] != groups[:-1]
    change = np.flatnonzero(differs) + 1
    starts = np.concatenate(([0], change))
    stops = np.concatenate((change, [n_samples]))
    missing = pd.isna(groups[starts])
    if missing.any():
        row = int(starts[np.flatnonzero(missing)[0]])
        raise ValueError(f"groups contains a missing recording id (first at row {row})")
    block_codes, _ = pd.factorize(groups[starts], sort=False)
    if len(np.unique(block_codes)) != len(block_codes):
        _raise_not_contiguous(groups.tolist(), block_codes, starts, stops)
    # Plain Python ids (not NumPy scalars), so that messages show 'r1' rather than np.str_('r1').
    ids = np.empty(len(starts), dtype=object)
    ids[:] = groups[starts].tolist()
    return Recordings(ids=ids, starts=starts, stops=stops)


def _raise_not_contiguous(groups, block_codes, starts, stops):
    seen = {}
    for code, start, stop in zip(block_codes, starts, stops, strict=True):
        if code in seen:
            first_start, first_stop = seen[code]
            raise ValueError(
                f"the rows of recording {groups[start]!r} are not contiguous (rows "
                f"{first_start}-{first_stop - 1} and {start}-{stop - 1}); sort the rows by "
                "recording, then by time, before fitting or predicting"
            )
        seen[code] = (start, stop)


def check_time_order(time, recordings, n_samples):
    """Refuse time stamps that are not finite or do not increase within every recording."""
    time = np.asarray(time, dtype=float)
    if time.shape != (n_samples,):
        raise ValueError(f"time has shape {time.shape}, expected ({n_samples},)")
    if not np.all(np.isfinite(time)):
        row = int(np.flatnonzero(~np.isfinite(time))[0])
        raise ValueError(
            f"time contains NaN or infinity at row {row} "
            f"(recording {recordings.recording_of_row(row)!r})"
        )
    steps = np.diff(time)
    inside = np.ones(max(n_samples - 1, 0), dtype=bool)
    inside[recordings.starts[1:] - 1] = False
    bad = np.flatnonzero(inside & (steps <= 0))
    if bad.size:
        row = int(bad[0]) + 1
        raise ValueError(
            f"time does not increase within recording {recordings.recording_of_row(row)!r} "
            f"at row {row} ({time[row - 1]} then {time[row]}); rows of a recording must be "
            "in time order"
        )


def median_time_step(time, groups=None):
    """The sampling period of recordings read from their time stamps: the median step in
    seconds between consecutive rows of the same recording (``groups``, one recording id per
    row, recordings contiguous and in time order; ``None``: one recording), missing times
    left out; ``None`` when no two rows of a recording have a time.

    The one inference of the sampling period, shared by the command line and the torque
    pipeline's velocity filter (``SteeringFeatures.sampling_period_``).
    """
    steps = np.diff(np.asarray(time, dtype=float))
    if groups is not None:
        codes = pd.factorize(np.asarray(groups), sort=False, use_na_sentinel=False)[0]
        steps = steps[codes[1:] == codes[:-1]]
    steps = steps[~np.isnan(steps)]
    return float(np.median(steps)) if steps.size else None
