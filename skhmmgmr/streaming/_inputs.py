"""Input rows of a :class:`~skhmmgmr.FilterStream`: one sample (an array, or a mapping by
name) or a batch (an array or a DataFrame), checked against the model's inputs.

Anything but real numbers is refused with an error that names the input: text, complex
numbers (whose imaginary part a conversion would drop silently), a mapping whose value is a
list, a Series that holds a label twice.
"""

import numbers
from collections.abc import Mapping

import numpy as np

# array kinds read as real numbers: bool, signed and unsigned integers, floats
_REAL_KINDS = "biuf"


def as_row(features, names, n_features):
    """One sample as a float array of shape (n_features,); read by name from a mapping or a
    :class:`pandas.Series` when the model has feature ``names``."""
    if isinstance(features, Mapping) or is_series(features):
        if names is None:
            raise ValueError(
                "features given by name, but the model was fitted without feature names; "
                "give a 1-D array in the order of the training columns"
            )
        missing = [name for name in names if name not in features]
        if missing:
            raise ValueError(f"features lacks the input(s) {missing} the model was fitted on")
        if is_series(features):
            _check_unique_labels(features.index, names)
        return np.array([_number(features[name], name) for name in names], dtype=float)
    row = as_real(np.asarray(features), "features")
    if row.shape != (n_features,):
        raise ValueError(
            f"update takes one sample of shape ({n_features},), got shape "
            f"{row.shape}; use update_batch for several samples"
        )
    return row


def as_batch(X, names, n_features):
    """Consecutive samples as a float array of shape (n_samples, n_features); a DataFrame's
    columns are selected by name when the model has feature ``names``."""
    if hasattr(X, "columns"):
        if names is not None:
            missing = [name for name in names if name not in X.columns]
            if missing:
                raise ValueError(f"X lacks the column(s) {missing} the model was fitted on")
            _check_unique_labels(X.columns, names, "X has the column")
            X = X[list(names)]
        for column, dtype in X.dtypes.items():
            if getattr(dtype, "kind", "O") not in _REAL_KINDS:
                raise ValueError(
                    f"X's column {column!r} holds {dtype}, not real numbers; the stream reads "
                    "numbers only (NaN for a missing value)"
                )
        X = X.to_numpy(dtype=float)
    X = as_real(np.asarray(X), "X")
    if X.ndim != 2 or X.shape[1] != n_features:
        raise ValueError(
            f"update_batch takes an array of shape (n_samples, {n_features}), got shape {X.shape}"
        )
    return X


def as_real(values, name):
    """An array as floats; ValueError naming ``name`` for text, complex numbers, objects that
    are not real numbers (nested lists among them)."""
    if values.dtype.kind in _REAL_KINDS:
        return values.astype(float, copy=False)
    if values.dtype.kind == "O" and all(_is_real(v) for v in values.ravel().tolist()):
        return values.astype(float)
    raise ValueError(
        f"{name} must hold real numbers (NaN for a missing value); got an array of "
        f"{values.dtype} {values.tolist()!r:.100}"
    )


def _is_real(value):
    return isinstance(value, numbers.Real) and not isinstance(value, str)


def _number(value, name):
    """The value of the input ``name`` of a sample given by name, as a float."""
    if _is_real(value) or (
        isinstance(value, np.ndarray) and value.ndim == 0 and value.dtype.kind in _REAL_KINDS
    ):
        return float(value)
    raise ValueError(
        f"features[{name!r}] is {value!r:.100}, not a number: a sample holds one number per "
        "input (NaN for a missing value)"
    )


def _check_unique_labels(labels, names, what="features has the label"):
    """Refuse ``labels`` that repeat one of ``names``: which of them is the input?"""
    labels = list(labels)
    repeated = sorted({str(name) for name in names if labels.count(name) > 1})
    if repeated:
        raise ValueError(f"{what}(s) {repeated} more than once: which one is the input?")


def is_series(features):
    """Whether ``features`` is a 1-D pandas object (a Series), without importing pandas."""
    return hasattr(features, "index") and hasattr(features, "to_numpy") and features.ndim == 1
