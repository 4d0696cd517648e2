"""Input checks whose messages name the column and the recording at fault."""

import numpy as np
from scipy import sparse

from ._sequences import as_recordings


def check_dense(values, *, name, by):
    """Raise a TypeError if ``values`` is a sparse matrix or array.

    Parameters
    ----------
    values : object
        The input as the user gave it.
    name : str
        What the array is for the user ("X", "y").
    by : str
        Who needs dense input, for the message (a function or estimator name).
    """
    if sparse.issparse(values):
        raise TypeError(
            f"{by} got sparse input for {name} ({type(values).__name__}); it needs a dense "
            f"array, one row per sample: convert it with {name}.toarray()"
        )


def check_finite(values, *, name, column_names, recordings):
    """Raise a ValueError naming the first NaN or infinite entry of ``values``.

    Parameters
    ----------
    values : ndarray of shape (n_samples, n_columns)
    name : str
        What the array is for the user ("X", "y").
    column_names : sequence of str
        Name of every column.
    recordings : Recordings
        Recordings of the rows, to say where the bad entry is.
    """
    finite = np.isfinite(values)
    if finite.all():
        return
    rows, columns = np.nonzero(~finite)
    row, column = int(rows[0]), int(columns[0])
    bad_value = values[row, column]
    kind = "NaN" if np.isnan(bad_value) else "infinity"
    recording = recordings.recording_of_row(row)
    start = int(recordings.starts[np.searchsorted(recordings.stops, row, side="right")])
    n_bad = int((~finite).sum())
    raise ValueError(
        f"Input {name} contains {kind} in column {column_names[column]!r} of recording "
        f"{recording!r} (row {row - start} of the recording, row {row} overall; {n_bad} "
        "non-finite value(s) in all). Fill or drop them before fitting or predicting: "
        "a NaN or infinity cannot be filtered."
    )


def check_target_finite(y, groups):
    """Name the column and recording of a NaN or infinite target before generic validation."""
    try:
        values = np.asarray(y)
    except (TypeError, ValueError):
        return
    # anything not plainly real-valued is left to scikit-learn's own validation
    if values.dtype.kind not in "biuf":
        return
    values = values.astype(float, copy=False)
    if values.ndim not in (1, 2) or np.isfinite(values).all():
        return
    if groups is not None and len(groups) != values.shape[0]:
        return
    values = values.reshape(values.shape[0], -1)
    if hasattr(y, "columns"):
        names = [str(c) for c in y.columns]
    elif getattr(y, "name", None) is not None:
        names = [str(y.name)]
    else:
        names = [f"output {i}" for i in range(values.shape[1])]
    recordings = as_recordings(groups, values.shape[0])
    check_finite(values, name="y", column_names=names, recordings=recordings)


def column_names_of(estimator, n_columns, prefix="x"):
    """Feature names seen in fit, or positional names."""
    names = getattr(estimator, "feature_names_in_", None)
    if names is not None and len(names) == n_columns:
        return [str(name) for name in names]
    return [f"{prefix}{i}" for i in range(n_columns)]
