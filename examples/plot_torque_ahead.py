"""
The torque ahead, and a model adapted to a new driver
=====================================================

Two uses of a fitted HMM-GMR beyond the estimate of the torque now.

*The torque 0.5 s ahead.* :func:`skhmmgmr.datasets.shift_target` builds the target ``h`` rows
ahead within every recording (the last ``h`` rows, whose future lies outside the recording,
are NaN and left out of the fit); an HMM-GMR fitted on it learns to read the road preview
(heading deviation 30 m ahead). :meth:`~skhmmgmr.HMMGMRRegressor.predict_ahead` is the model's
own forecast, the filtered state probabilities propagated through the transition matrix; it
adds little to holding the current estimate (see the user guide, "Adapting a model and
estimating the torque ahead").

*Adaptation.* :meth:`~skhmmgmr.HMMGMRRegressor.adapt` moves a fitted model towards a minute of
recordings from another driver in another car, the fitted parameters acting as the prior (MAP
adaptation with a relevance factor).
"""

import copy
import os

import matplotlib.pyplot as plt
import numpy as np

from skhmmgmr import HMMGMRRegressor
from skhmmgmr.datasets import make_lane_keeping, shift_target
from skhmmgmr.metrics import accuracy_score

quick = bool(os.environ.get("SKHMMGMR_DOCS_QUICK"))
duration = 60.0 if quick else 240.0
rate, horizon = 20.0, 0.5
steps = int(horizon * rate)
features = ["steering_wheel_angle", "yaw_rate", "heading_deviation_30m", "road_curvature_30m"]
train = make_lane_keeping(duration, setting=7, sampling_rate=rate, random_state=0)
test = make_lane_keeping(60.0, setting=1, sampling_rate=rate, random_state=1)
X, y = train[features], train["driver_torque"].to_numpy()
X_test, y_test = test[features], test["driver_torque"].to_numpy()

# %%
# Models of the torque now and 0.5 s ahead.
now = HMMGMRRegressor(n_states=4, random_state=0).fit(X, y)
ahead_target = shift_target(y, steps)
keep = ~np.isnan(ahead_target)
ahead = HMMGMRRegressor(n_states=4, random_state=0).fit(X[keep], ahead_target[keep])

truth = shift_target(y_test, steps)
shown = ~np.isnan(truth)
estimates = {
    "hold the current estimate": now.predict(X_test),
    "predict_ahead (conditional)": now.predict_ahead(X_test, steps, state_output="conditional"),
    "HMM-GMR on the shifted target": ahead.predict(X_test),
}
time = test["time"].to_numpy()
fig, axes = plt.subplots(2, 1, figsize=(9, 6), sharex=True)
axes[0].plot(time[shown], truth[shown], color="black", lw=1.5, label="torque 0.5 s ahead")
for name, estimate in estimates.items():
    accuracy = accuracy_score(truth[shown], estimate[shown])
    axes[0].plot(time[shown], estimate[shown], lw=1, label=f"{name} ({accuracy:.0f} %)")
    print(f"{name:<32} accuracy {accuracy:5.1f} %")
axes[0].set_ylabel("torque [Nm]")
axes[0].legend(fontsize=8, loc="upper right")

# %%
# A minute of another driver in another car, whose steering-wheel angle sensor reads 3 degrees
# off, and the model adapted to it (its means move; the covariances and transitions stay).
other = make_lane_keeping(120.0, setting=7, driver="aggressive", sampling_rate=rate, random_state=2)
other["steering_wheel_angle"] += np.deg2rad(3.0)
first, rest = other.iloc[: int(60 * rate)], other.iloc[int(60 * rate) :]
adapted = copy.deepcopy(now).adapt(
    first[features], first["driver_torque"], relevance=16.0, parameters="m"
)
for name, model in {"fitted model": now, "adapted to the driver": adapted}.items():
    estimate = model.predict(rest[features])
    accuracy = accuracy_score(rest["driver_torque"], estimate)
    axes[1].plot(rest["time"], estimate, lw=1, label=f"{name} ({accuracy:.0f} %)")
    print(f"{name:<32} accuracy {accuracy:5.1f} %")
axes[1].plot(rest["time"], rest["driver_torque"], color="black", lw=1.5, label="torque")
axes[1].set_xlabel("time [s]")
axes[1].set_ylabel("torque [Nm]")
axes[1].legend(fontsize=8, loc="upper right")
fig.tight_layout()
plt.show()
