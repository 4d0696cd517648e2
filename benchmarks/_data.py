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


# Simulated drivers of the thesis-scale framework benchmark: the three styles in turn, each
# driver with its own seed (its own per-recording parameters, remnant and roads).
STYLES_IN_TURN = ("defensive", "aggressive", "novice")


def thesis_protocol(n_drivers=7, *, duration=300.0, sampling_rate=20.0, seed=0, cache=None):
    """The thesis protocol (12 train, 6 validation, 6 test sections per driver) for
    ``n_drivers`` simulated drivers, as one tidy frame; ids are prefixed ``d{i}-``.

    Driver ``i`` is simulated with seed ``seed + i``; the novice style occasionally leaves the
    road (the simulator raises), and such a driver moves on to the next free seed. The seeds
    used are in ``frame.attrs["seeds"]``.
    """
    import pandas as pd

    from skhmmgmr.datasets import make_driving_protocol

    frames, seeds, next_seed = [], [], seed + n_drivers
    for i in range(n_drivers):
        style = STYLES_IN_TURN[i % len(STYLES_IN_TURN)]
        driver_seed = seed + i
        while True:
            try:
                frame = make_driving_protocol(
                    (style,),
                    duration=duration,
                    sampling_rate=sampling_rate,
                    random_state=driver_seed,
                    n_jobs=-1,
                    cache=cache,
                )
                break
            except RuntimeError:  # the driver lost control of the vehicle
                driver_seed, next_seed = next_seed, next_seed + 1
        seeds.append(driver_seed)
        frame["recording"] = f"d{i}-" + frame["recording"].astype(str)
        frame["driver"] = f"d{i}-{style}"
        frames.append(frame)
    attrs = frames[0].attrs
    data = pd.concat(frames, ignore_index=True)
    data.attrs = {**attrs, "seeds": seeds}
    return data
