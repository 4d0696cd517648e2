"""A batch of consecutive samples for :meth:`FilterStream.update_batch
<skhmmgmr.FilterStream.update_batch>`: the rows in filter order, the measured outputs paired
with them, and the rows where a recording begins.

The batch's layout (:func:`~skhmmgmr._core._panel.read_layout`: a ``"recording"`` and a
``"time"`` level of a DataFrame's index) puts the rows in filter order and the results back in
the caller's order; the stream restarts where the recording changes, also from the last row of
the batch before.
"""

from dataclasses import dataclass

import numpy as np

from .._core._panel import align_target, read_layout, recordings_of
from ._inputs import as_batch


@dataclass(frozen=True)
class Batch:
    """The rows of a batch in filter order (``X``, float, (n_samples, n_features)), their
    measured outputs (``y`` or None), the recordings beginning at a row (``restarts``: {row:
    recording id}) and the layout (``rows``) that gives the results back in the caller's
    order."""

    X: np.ndarray
    y: object
    restarts: dict
    rows: object


def read_batch(X, y, *, names, n_features, stages, current, read_targets):
    """The :class:`Batch` of ``X`` (and ``y``, read by ``read_targets(y, n_samples)``) for a
    stream of inputs ``names`` (None when fitted on an array) and ``n_features`` columns,
    derived-input ``stages`` and ``current`` recording (that of the last row streamed)."""
    rows = read_layout(X)
    y = align_target(X, y, rows)
    X = as_batch(rows.to_filter_order(X), names, n_features)
    if y is not None:
        y = read_targets(rows.to_filter_order(y), X.shape[0])
    for stage in stages:  # a time level at another period than the filter's
        stage.check_time(rows.time, rows.groups)
    return Batch(X, y, recording_starts(rows.groups, X.shape[0], current), rows)


def recording_starts(groups, n_samples, current):
    """{row: recording id} of the rows where a recording of an indexed batch begins; the
    first row of a batch that goes on with the ``current`` recording is not one."""
    if groups is None or n_samples == 0:
        return {}
    recordings = recordings_of(groups, n_samples)
    starts = {int(start): rec for rec, start in zip(recordings.ids, recordings.starts, strict=True)}
    if current is not None and recordings.ids[0] == current:
        del starts[0]  # the batch goes on with the recording of the previous batch
    return starts
