"""
Real driving data: one minute of comma2k19
==========================================

Fit an HMM-GMR model on a real one-minute segment of the public comma2k19 dataset (comma.ai,
MIT licence): a Toyota RAV4 on a California highway. The driver torque, steering angle and rate,
yaw rate and lateral acceleration are decoded from the raw CAN frames by
:func:`skhmmgmr.datasets.load_comma2k19_segment`.

Two facts shape what to expect: the torque sensor reports raw, uncalibrated units (not Nm),
and openpilot's lane keeping was engaged for most of the minute, so much of the "driver" torque
is a hand resting on the wheel. The segment is cut into 10-second recordings; the first four
train the model and the last two test it, filtered recording by recording.
"""

import os
from pathlib import Path

import numpy as np

from skhmmgmr import HMMGMRRegressor
from skhmmgmr.datasets import RECORDING, TARGET, TIME, load_comma2k19_segment
from skhmmgmr.metrics import evaluate_recordings
from skhmmgmr.plotting import plot_estimate


def find_segment():
    """The segment shipped beside the repository (``../shared/data/comma2k19``)."""
    if "SKHMMGMR_COMMA2K19" in os.environ:
        return Path(os.environ["SKHMMGMR_COMMA2K19"])
    for folder in [Path.cwd(), *Path.cwd().parents]:
        matches = sorted((folder / "shared" / "data" / "comma2k19").glob("*/40"))
        if matches:
            return matches[0]
    raise FileNotFoundError("set SKHMMGMR_COMMA2K19 to a comma2k19 segment folder")


data = load_comma2k19_segment(find_segment(), sampling_rate=20.0)
print(data.shape, data.attrs["units"][TARGET])

# %%
# Ten-second recordings, four to train and two to test
# -----------------------------------------------------
data[RECORDING] = "chunk-" + (data[TIME] // 10).astype(int).astype(str)
features = ["steering_wheel_angle", "steering_wheel_velocity", "yaw_rate", "lateral_acceleration"]
is_train = data[TIME] < 40.0
train, test = data[is_train], data[~is_train]

model = HMMGMRRegressor(n_states=3, n_init=3, random_state=0)
model.fit(train[features], train[TARGET], groups=train[RECORDING])
estimate, std = model.predict(test[features], groups=test[RECORDING], return_std=True)
state_proba = model.predict_state_proba(test[features], groups=test[RECORDING])

table = evaluate_recordings(
    test[TARGET].to_numpy(), estimate, groups=test[RECORDING].to_numpy(), sampling_period=0.05
)
print(table.round(3).to_string(index=False))
print(data.groupby(RECORDING)[TARGET].std().round(1).rename("torque SD").to_string())

# %%
# The thesis' accuracy ``(1 - RMSE / SD) * 100`` is harsh here: in the test chunks the torque
# barely moves (SD of a few raw units, a hand resting on the wheel while openpilot steers), so
# an estimate that follows the steering the inputs describe scores below zero. The predictive
# band remains honest: most measured samples fall inside it.

# %%
# Estimate, predictive band and filtered state probabilities
# -----------------------------------------------------------
fig, axes = plot_estimate(
    test[TIME].to_numpy(),
    test[TARGET].to_numpy(),
    estimate,
    std=std,
    state_proba=state_proba,
    torque_unit="raw units",
    title="comma2k19, test chunks",
)

coverage = np.mean(np.abs(test[TARGET].to_numpy() - estimate) <= 2 * std)
print(f"share of test samples inside the +-2 std band: {coverage:.2f}")
