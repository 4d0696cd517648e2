"""Synthetic driving-like recordings shared by the benchmarks.

Smooth random inputs (a road-curvature-like signal and its filtered responses) and a torque
that depends on them nonlinearly, in ``n_recordings`` recordings of roughly equal length. The
joint data are standardised, as :class:`skhmmgmr.HMMGMRRegressor` does before calling the EM
engine.
"""

import numpy as np


def make_recordings(n_rows, n_recordings, n_inputs, seed=0):
    """Return ``X`` (n_rows, n_inputs), ``y`` (n_rows,) and the recording bounds."""
    rng = np.random.default_rng(seed)
    drive = np.cumsum(rng.normal(scale=0.02, size=(n_rows, 2)), axis=0)
    base = np.sin(drive) + 0.05 * rng.normal(size=(n_rows, 2))
    mix = rng.normal(size=(2, n_inputs))
    X = base @ mix + 0.3 * rng.normal(size=(n_rows, n_inputs))
    y = 2.0 * np.tanh(base[:, 0]) - 0.5 * base[:, 1] + 0.1 * rng.normal(size=n_rows)
    bounds = np.linspace(0, n_rows, n_recordings + 1).astype(int)
    return X, y, bounds


def standardized_joint(X, y):
    joint = np.column_stack([X, y])
    return (joint - joint.mean(axis=0)) / joint.std(axis=0)
