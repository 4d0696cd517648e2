"""The inputs of the estimator's methods, each read by one reader: :func:`read_joint_inputs`
for the methods that read inputs and outputs (fit, adapt, log_likelihood), :func:`read_inputs`
for those that read inputs only (predict and the filter's other read-outs): the rows in filter
order, their recordings, the validated values, and for a prediction the standardised inputs
and the rows that miss a value (read once for the filter and the read-out); inputs out of the
model's range are refused (:mod:`skhmmgmr._hmm._holds`)."""

import warnings
from dataclasses import dataclass
from functools import partial

import numpy as np
from sklearn.utils.validation import check_is_fitted, validate_data

from .._core._panel import in_filter_order, read_layout
from .._core._validation import (
    check_finite,
    check_target_finite,
    column_names_of,
    validate_joint,
)
from .._hmm._gmr import read_missing
from .._hmm._holds import check_in_range
from .._hmm._stale_inputs import stale_noise_for


def read_inputs(estimator, X, groups, time):
    """``(standardized, recordings, layout, missing)`` of the inputs ``X`` of a fitted
    :class:`~skhmmgmr.HMMGMRRegressor`: ``layout``
    (:func:`~skhmmgmr._core._panel.read_layout`) puts results back in the caller's order,
    ``missing`` is :func:`~skhmmgmr._hmm._gmr.read_missing` of the standardised rows."""
    check_is_fitted(estimator)
    layout = read_layout(X, groups, time)
    X = validate_data(
        estimator, layout.to_filter_order(X), reset=False, ensure_all_finite=False, dtype=float
    )
    if layout.groups is None:
        warn_if_one_long_recording(estimator, X.shape[0])
    recordings = layout.recordings(X.shape[0])
    names = column_names_of(estimator, X.shape[1])
    allow_nan = estimator.missing_values != "error"
    check_finite(X, name="X", column_names=names, recordings=recordings, allow_nan=allow_nan)
    model = estimator.model_
    standardized = model.standardization.inputs(X)
    check_in_range(standardized, column_names=names, recordings=recordings)
    noise = stale_noise_for(model, estimator.missing_values)
    return standardized, recordings, layout, read_missing(standardized, recordings, noise)


@dataclass(frozen=True)
class JointInputs:
    """Inputs and outputs of one call, validated, in filter order, with their recordings."""

    X: np.ndarray
    Y: np.ndarray  # always 2-D
    scalar_output: bool  # whether y was 1-D
    recordings: object  # skhmmgmr._core._sequences.Recordings
    grouped: bool  # whether the recordings were given (groups or a recording index)
    input_names: list
    output_names: list


def read_joint_inputs(estimator, X, y, groups, time, *, fitting):
    """Read ``X`` and ``y`` of ``fit`` (``fitting=True``: the recordings in order of their
    ids, the estimator's input attributes set, at least two rows per recording) or of a
    method of the fitted estimator (``adapt``, ``log_likelihood``: checked against what fit
    saw, one output count, a warning for many rows without recordings).

    A ``y`` with an index is paired with a panel ``X`` by label; a NaN target is refused
    unless the estimator reads missing values, naming the column and recording, as is a NaN
    or infinite input. ``fit`` remembers the names of the outputs (``output_names_``, see
    :func:`target_names`).
    """
    names_of_y = target_names(y)
    if fitting:
        if names_of_y is not None:
            estimator.output_names_ = np.asarray(names_of_y, dtype=object)
        elif hasattr(estimator, "output_names_"):
            del estimator.output_names_
    run = partial(_joint_inputs_in_filter_order, estimator, fitting=fitting, names_of_y=names_of_y)
    return in_filter_order(run, X, groups, time=time, y=y, canonical=fitting)


def _joint_inputs_in_filter_order(estimator, layout, X, y=None, *, fitting, names_of_y):
    """:func:`read_joint_inputs` of rows in filter order, their recordings' ``layout``
    (``names_of_y``: the outputs' names, :func:`target_names`)."""
    groups = layout.groups
    allow_nan = estimator.missing_values != "error"
    check_target_finite(y, layout, allow_nan=allow_nan)
    X, y = validate_joint(estimator, X, y, allow_nan=allow_nan, reset=fitting)
    Y = y.reshape(-1, 1) if y.ndim == 1 else y
    if not fitting and Y.shape[1] != estimator.model_.n_outputs:
        raise ValueError(f"y has {Y.shape[1]} outputs, the model {estimator.model_.n_outputs}")
    if groups is None:
        if fitting:
            warn_if_fitted_as_one_recording(X.shape[0])
        else:
            warn_if_one_long_recording(estimator, X.shape[0])
    recordings = layout.recordings(X.shape[0], min_length=2 if fitting else 1)
    input_names = column_names_of(estimator, X.shape[1])
    output_names = names_of_y or [f"output {i}" for i in range(Y.shape[1])]
    for values, name, names in ((X, "X", input_names), (Y, "y", output_names)):
        check_finite(
            values, name=name, column_names=names, recordings=recordings, allow_nan=allow_nan
        )
    return JointInputs(X, Y, y.ndim == 1, recordings, groups is not None, input_names, output_names)


def target_names(y):
    """The names of the outputs ``y`` carries: a pandas Series' name, a DataFrame's columns,
    when every one is text (as scikit-learn reads ``feature_names_in_`` from ``X``); else
    None."""
    columns = getattr(y, "columns", None)
    if columns is not None:
        names = list(columns)
    elif hasattr(y, "name") and hasattr(y, "index"):  # a Series
        names = [y.name]
    else:
        return None
    return names if names and all(isinstance(name, str) for name in names) else None


def warn_if_one_long_recording(estimator, n_samples):
    """Warn when ``n_samples`` rows without recordings outnumber the longest training
    recording of ``estimator`` (its ``longest_recording_``)."""
    longest = getattr(estimator, "longest_recording_", None)
    if longest is not None and n_samples > longest:
        warnings.warn(
            f"{n_samples} rows without groups are filtered as ONE recording, longer than "
            f"the longest training recording ({longest} rows). If they hold several "
            "recordings, pass groups=<recording id per row>, or give X a pandas index with "
            "a 'recording' level (skhmmgmr.datasets.to_panel), so that the filter restarts "
            "at every recording.",
            UserWarning,
            stacklevel=3,
        )


# Rows a fit reads as one recording without a word: more is longer than any one drive of the
# thesis' protocol (5-minute sections at 100 Hz are 30,000 rows) by far.
ONE_RECORDING_ROWS = 50_000


def warn_if_fitted_as_one_recording(n_samples):
    """Warn when a fit gets ``n_samples`` rows, more than :data:`ONE_RECORDING_ROWS`, with
    neither ``groups`` nor a recording index: they are fitted as one recording."""
    if n_samples > ONE_RECORDING_ROWS:
        warnings.warn(
            f"{n_samples} rows without groups are fitted as ONE recording. If they hold "
            "several recordings, pass groups=<recording id per row>, or give X a pandas index "
            "with a 'recording' level (skhmmgmr.datasets.to_panel); if they are one "
            "recording, say so with groups=<the same id on every row>, which also lets "
            "predict warn about longer inputs.",
            UserWarning,
            stacklevel=3,
        )
