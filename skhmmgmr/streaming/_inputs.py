"""Input rows of a :class:`~skhmmgmr.FilterStream`: one sample (an array, or a mapping by
name) or a batch (an array or a DataFrame), checked against the model's inputs."""

from collections.abc import Mapping

import numpy as np


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
        return np.array([features[name] for name in names], dtype=float)
    row = np.asarray(features, dtype=float)
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
            X = X[list(names)]
        X = X.to_numpy(dtype=float)
    X = np.asarray(X, dtype=float)
    if X.ndim != 2 or X.shape[1] != n_features:
        raise ValueError(
            f"update_batch takes an array of shape (n_samples, {n_features}), got shape {X.shape}"
        )
    return X


def is_series(features):
    """Whether ``features`` is a 1-D pandas object (a Series), without importing pandas."""
    return hasattr(features, "index") and hasattr(features, "to_numpy") and features.ndim == 1
