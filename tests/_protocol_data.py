"""Simulated selection protocols shared by the selection tests."""

import numpy as np
import pandas as pd

PERIOD = 0.05


def make_protocol(n_recordings=(4, 3, 2), length=150, n_features=4, seed=0):
    """Tidy table like skhmmgmr.datasets: the torque depends on f0 and f1 only."""
    rng = np.random.default_rng(seed)
    frames = []
    for split, n in zip(("train", "validation", "test"), n_recordings, strict=True):
        for r in range(n):
            x = np.cumsum(rng.normal(scale=0.15, size=(length, n_features)), axis=0)
            x -= x.mean(axis=0)
            frame = pd.DataFrame(x, columns=[f"f{i}" for i in range(n_features)])
            frame.insert(0, "recording", f"{split}{r}")
            frame.insert(1, "split", split)
            frame.insert(2, "time", np.arange(length) * PERIOD)
            torque = 1.5 * np.tanh(2 * x[:, 0]) + 0.8 * x[:, 1]
            frame["driver_torque"] = torque + rng.normal(scale=0.05, size=length)
            frames.append(frame)
    return pd.concat(frames, ignore_index=True)
