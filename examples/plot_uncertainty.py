"""
Predictive uncertainty: coverage of the +-2 std band
====================================================

Besides the estimate, :meth:`~skhmmgmr.HMMGMRRegressor.predict` returns the predictive
standard deviation of the mixture (law of total variance over the filtered states). If the
model is calibrated, about 95 % of the measured torque falls inside the +-2 std band. This
example measures that coverage on every test recording.
"""

import os

import matplotlib.pyplot as plt
import numpy as np
import pandas as pd

from skhmmgmr import HMMGMRRegressor
from skhmmgmr.datasets import make_driving_protocol
from skhmmgmr.plotting import plot_estimate

quick = bool(os.environ.get("SKHMMGMR_DOCS_QUICK"))
data = make_driving_protocol(
    drivers=("defensive", "novice"),
    n_validation=0,
    n_test=3,
    duration=10.0 if quick else 60.0,
    sampling_rate=20.0,
    random_state=0,
)
features = ["steering_wheel_angle", "yaw_rate", "heading_deviation_10m"]
train, test = data[data["split"] == "train"], data[data["split"] == "test"]
model = HMMGMRRegressor(n_states=4, random_state=0)
model.fit(train[features], train["driver_torque"], groups=train["recording"])

# %%
# Coverage per recording
# ----------------------
estimate, std = model.predict(test[features], groups=test["recording"], return_std=True)
inside = np.abs(test["driver_torque"].to_numpy() - estimate) <= 2 * std
coverage = (
    pd.DataFrame({"recording": test["recording"], "inside": inside, "std": std})
    .groupby("recording", sort=False)
    .agg(coverage=("inside", "mean"), mean_std=("std", "mean"))
)
print(coverage.round(3).to_string())
print(f"overall coverage of the +-2 std band: {inside.mean():.1%} (nominal 95.4 %)")

# %%
# Plot
# ----
fig, ax = plt.subplots(figsize=(7, 3))
ax.bar(range(len(coverage)), 100 * coverage["coverage"], color="tab:blue")
ax.axhline(95.4, color="k", ls="--", lw=1, label="nominal (Gaussian) 95.4 %")
ax.set_xticks(range(len(coverage)), coverage.index, rotation=30, ha="right")
ax.set(ylabel="inside +-2 std [%]", ylim=(0, 105), title="coverage per test recording")
ax.legend(loc="lower right")
fig.tight_layout()

first = test["recording"] == test["recording"].iloc[0]
fig, axes = plot_estimate(
    test.loc[first, "time"],
    test.loc[first, "driver_torque"],
    estimate[first.to_numpy()],
    std=std[first.to_numpy()],
    title=test["recording"].iloc[0],
)
plt.show()
