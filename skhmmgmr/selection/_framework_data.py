"""The data of the one-call framework: features, target, recordings and split of a tidy table."""

import numpy as np
import pandas as pd

from .._core._schema import FEATURE_NAMES, RECORDING, SPLIT, TIME


def split_recordings_table(data, split, candidate_features, target):
    """Features, target, recording ids and split of every row of a tidy table or arrays."""
    if isinstance(data, pd.DataFrame):
        if candidate_features is None:
            candidate_features = [c for c in FEATURE_NAMES if c in data.columns]
            if not candidate_features:
                meta = {RECORDING, SPLIT, TIME, target, "driver", "setting"}
                candidate_features = [
                    c
                    for c in data.columns
                    if c not in meta and pd.api.types.is_numeric_dtype(data[c])
                ]
        X = data[list(candidate_features)].reset_index(drop=True)
        y = data[target].to_numpy(dtype=float)
        groups = data[RECORDING].to_numpy()
        split = data[SPLIT].to_numpy() if split is None else split
    else:
        X, y, groups = data
        if split is None:
            raise ValueError("give split (per row or recording -> split) with (X, y, groups)")
        if not isinstance(X, pd.DataFrame):
            names = candidate_features or [f"x{i}" for i in range(np.shape(X)[1])]
            X = pd.DataFrame(np.asarray(X, dtype=float), columns=list(names))
        X = X.reset_index(drop=True)
        y, groups = np.asarray(y, dtype=float), np.asarray(groups)
    if isinstance(split, dict):
        split = np.asarray([split[g] for g in groups])
    split = np.asarray(split)
    for name in ("train", "validation", "test"):
        if not np.any(split == name):
            raise ValueError(f"no {name!r} recordings in split")
    return X, y, groups, split


def sampling_period_of(data, sampling_period):
    """The given sampling period, else the median time step of the ``time`` column."""
    if sampling_period is not None:
        return float(sampling_period)
    if isinstance(data, pd.DataFrame) and TIME in data.columns:
        steps = data.groupby(RECORDING, sort=False)[TIME].diff().dropna()
        return float(steps.median())
    raise ValueError("give sampling_period (seconds between rows)")
