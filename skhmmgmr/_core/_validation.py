"""Input checks whose messages name the column and the recording at fault, and the scale of
values they rely on (round-off constancy, exact binary units)."""

import numbers
import warnings

import numpy as np
from scipy import sparse
from sklearn.utils.validation import check_array, check_consistent_length, validate_data

from ._compat import Interval, validate_parameter_constraints
from ._panel import RecordingLayout, recordings_of

# Parameters of the methods that adapt a fitted model or forecast with it (not estimator
# parameters, so that they are checked where they are passed): one set of constraints, so that
# a stream, adapt and predict_ahead refuse the same values with the same message. The
# relevance is a stream's; adapt's also takes inf, 0 and "auto" (estimator/_adaptation_choice).
ADAPTATION_CONSTRAINTS = {
    "relevance": [Interval(numbers.Real, 0, None, closed="neither")],
    "forgetting": [Interval(numbers.Real, 0, 1, closed="right")],
    "n_iter": [Interval(numbers.Integral, 1, None, closed="left")],
    # a billion rows is 116 days at 100 Hz, far past the time the state probabilities take
    # to reach the chain's stationary distribution
    "steps": [Interval(numbers.Integral, 0, 10**9, closed="both")],
}


def check_adaptation_params(caller, **params):
    """Check ``params`` (names of :data:`ADAPTATION_CONSTRAINTS`) as scikit-learn checks an
    estimator's parameters; the error (a ValueError) names the parameter, ``caller`` and the
    value given."""
    validate_parameter_constraints(
        {name: ADAPTATION_CONSTRAINTS[name] for name in params}, params, caller_name=caller
    )


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


def check_finite(values, *, name, column_names, recordings, allow_nan=False):
    """Raise a ValueError naming the first NaN or infinite entry of ``values``.

    With ``allow_nan`` (missing values the model marginalises), only infinities are refused.

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
    if allow_nan:
        finite |= np.isnan(values)
    if finite.all():
        return
    rows, columns = np.nonzero(~finite)
    row, column = int(rows[0]), int(columns[0])
    bad_value = values[row, column]
    kind = "NaN" if np.isnan(bad_value) else "infinity"
    n_bad = int((~finite).sum())
    raise ValueError(
        f"Input {name} contains {kind} in column {column_names[column]!r} of "
        f"{row_location(recordings, row)[:-1]}; {n_bad} "
        + (
            "infinite value(s) in all). An infinity is not a missing value: replace it by NaN "
            "or drop it."
            if allow_nan
            else "non-finite value(s) in all). Fill or drop them before fitting or predicting: "
            "a NaN or infinity cannot be filtered."
        )
    )


def row_location(recordings, row):
    """Where ``row`` (a position in filter order) is, for a message: ``"recording 'a' (row 3
    of the recording, row 203 overall)"``."""
    index = int(np.searchsorted(recordings.stops, row, side="right"))
    start = int(recordings.starts[index])
    return (
        f"recording {_shown(recordings.ids[index])} (row {row - start} of the recording, "
        f"row {row} overall)"
    )


def _shown(recording):
    """A recording id as the user wrote it: NumPy scalars as plain Python values."""
    return repr(recording.item() if isinstance(recording, np.generic) else recording)


def check_target_finite(y, groups, allow_nan=False):
    """Name the column and recording of a NaN (unless ``allow_nan``) or infinite target
    before generic validation (``groups``: the recording ids, or the call's
    :class:`~skhmmgmr._core._panel.RecordingLayout`)."""
    try:
        values = np.asarray(y)
    except (TypeError, ValueError):
        return
    check_numeric_target(values)
    # anything not plainly real-valued is left to scikit-learn's own validation
    if values.dtype.kind not in "biuf":
        return
    values = values.astype(float, copy=False)
    if values.ndim not in (1, 2) or np.isfinite(values).all():
        return
    layout = groups if isinstance(groups, RecordingLayout) else None
    if layout is not None:
        groups = layout.groups
    if groups is not None and len(groups) != values.shape[0]:
        return
    values = values.reshape(values.shape[0], -1)
    if hasattr(y, "columns"):
        names = [str(c) for c in y.columns]
    elif getattr(y, "name", None) is not None:
        names = [str(y.name)]
    else:
        names = [f"output {i}" for i in range(values.shape[1])]
    if layout is not None:
        recordings = layout.recordings(values.shape[0])
    else:
        recordings = recordings_of(groups, values.shape[0])
    check_finite(values, name="y", column_names=names, recordings=recordings, allow_nan=allow_nan)


def validate_joint(estimator, X, y, *, allow_nan, reset=True, ensure_all_finite=False):
    """``validate_data`` of ``X`` and ``y`` (floats, one or several outputs) for ``estimator``.

    ``ensure_all_finite`` applies to ``X`` (the default leaves the check to
    :func:`check_finite`, which names the recording). ``y`` must be finite, or with
    ``allow_nan`` may hold NaN (missing values), which ``validate_data`` always refuses.
    """
    if not allow_nan or y is None:  # (None: validate_data says that y is required)
        return validate_data(
            estimator,
            X,
            y,
            reset=reset,
            multi_output=True,
            y_numeric=True,
            ensure_all_finite=ensure_all_finite,
            dtype=float,
        )
    X = validate_data(
        estimator, X, "no_validation", reset=reset, ensure_all_finite=ensure_all_finite, dtype=float
    )
    y = check_array(
        y,
        ensure_2d=False,
        dtype=float,
        ensure_all_finite="allow-nan",
        input_name="y",
        estimator=estimator,
    )
    check_consistent_length(X, y)
    return X, y


def check_enough_rows(n_samples, n_states, n_dims):
    """Refuse fewer rows than states; warn when the full covariances of ``n_states`` states
    over ``n_dims`` columns rest on the regularisation."""
    if n_samples < n_states:
        raise ValueError(
            f"n_states={n_states} is more than the data support: every state needs at "
            f"least one row, and X has n_samples={n_samples}"
        )
    if n_samples < n_states * (n_dims + 1):
        warnings.warn(
            f"n_states={n_states} states over {n_dims} columns need at least "
            f"{n_states * (n_dims + 1)} rows for full covariances; with {n_samples} "
            "rows they are determined by reg_covar.",
            UserWarning,
            stacklevel=4,
        )


def column_names_of(estimator, n_columns, prefix="x"):
    """Feature names seen in fit, or positional names."""
    names = getattr(estimator, "feature_names_in_", None)
    if names is not None and len(names) == n_columns:
        return [str(name) for name in names]
    return [f"{prefix}{i}" for i in range(n_columns)]


def check_numeric_target(values, name="y"):
    """Raise a ValueError if the array ``values`` holds strings, dates or other non-numbers.

    Object arrays pass unless they hold a string (missing values such as ``pd.NA`` are left
    to the finiteness checks, which name the recording).
    """
    kind = values.dtype.kind
    if kind in "biufc" or values.size == 0:
        return
    if kind == "O":
        strings = [v for v in values.ravel() if isinstance(v, str | bytes)]
        if not strings:
            return
        example = strings[0]
    else:
        example = str(values.ravel()[0])
    raise ValueError(
        f"{name} must be numeric (the target values, e.g. the torque in Nm); got an array of "
        f"dtype {values.dtype} holding {example!r}"
    )


def check_sampling_period(sampling_period, name="sampling_period"):
    """Return ``sampling_period`` as a float: a positive, finite number of seconds.

    ``None`` passes (the caller decides whether the time step is needed). A bool is refused:
    ``True`` is a number in Python, but not a time step.
    """
    if sampling_period is None:
        return None
    if (
        isinstance(sampling_period, bool | np.bool_)
        or not isinstance(sampling_period, numbers.Real)
        or not np.isfinite(sampling_period)
        or sampling_period <= 0
    ):
        raise ValueError(
            f"{name} must be a positive number of seconds, got {sampling_period!r}"
            + (" (a bool is not a time step)" if isinstance(sampling_period, bool) else "")
        )
    return float(sampling_period)


# A column (or recording of a target) whose standard deviation is at most this fraction of
# its largest absolute value is constant up to round-off: float64 carries about 16 digits, so
# such variation is below a few thousand units in the last place of the values themselves.
CONSTANT_RTOL = 1e-12


def constant_to_round_off(spread, magnitude):
    """Whether a standard deviation ``spread`` is round-off for values up to ``magnitude``
    (largest absolute value); elementwise, scale-invariant."""
    return np.asarray(spread) <= CONSTANT_RTOL * np.asarray(magnitude)


def binary_unit(magnitude):
    """The power of two at or just below each ``magnitude`` (1 for 0), elementwise.

    Dividing values by it is exact in floating point and brings the largest into [1, 2):
    sums of squares then neither overflow nor underflow, whatever the unit of the values.
    """
    magnitude = np.asarray(magnitude, dtype=float)
    exponent = np.frexp(magnitude)[1] - 1
    return np.where(magnitude > 0, np.ldexp(1.0, exponent), 1.0)


# Every standard deviation the model keeps in the data's units must have a square (the
# variance in covars_ and the JSON file) that float64 holds with all its digits, with room for
# the factors of the covariance prior: 1e-150..1e150 (float64 spans 2e-308..1.8e308).
SCALE_RANGE = (1e-150, 1e150)


def check_column_scales(scale, column_names):
    """Raise a ValueError naming the first column whose standard deviation ``scale`` is NaN
    (no observed value) or out of :data:`SCALE_RANGE`, so that its variance in the data's
    units is not a float64."""
    empty = np.flatnonzero(np.isnan(scale))
    if empty.size:
        raise ValueError(
            f"column {column_names[int(empty[0])]!r} is missing (NaN) in every row: the model "
            "cannot marginalise a column it has never seen; drop it."
        )
    low, high = SCALE_RANGE
    bad = np.flatnonzero((scale < low) | (scale > high))
    if bad.size == 0:
        return
    i = int(bad[0])
    how = "overflow" if scale[i] > high else "underflow"
    raise ValueError(
        f"column {column_names[i]!r} has standard deviation {scale[i]:.3g}: the model keeps "
        "its means and covariances in the data's units (means_, covars_, the JSON model "
        f"file), and this column's variance would {how} float64 (standard deviations must "
        f"lie within {low:g}..{high:g}). Change the column's unit (e.g. multiply it by a "
        "power of ten) before fitting."
    )


def check_filter_period(step, period, *, what, remedy):
    """Refuse rows ``step`` seconds apart for a velocity filter made for rows ``period``
    seconds apart (more than 1 % off): its time constant would be off by their ratio.

    One rule and one message for ``predict`` (a time level) and for the simulator driven by a
    fitted pipeline (its sampling rate). ``what`` says whose step it is, ending with the step
    (``"The time level of X steps 0.01 s (median) in recording 'a'"``); ``remedy`` what to
    do instead.
    """
    if abs(step - period) > 0.01 * period:
        raise ValueError(
            f"{what}, but sampling_period={period!r}: the velocity filter would run "
            f"{period / step:.3g} times too fast or slow. {remedy}"
        )
