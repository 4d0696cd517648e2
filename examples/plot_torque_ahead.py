"""
A generic model personalised in two minutes, and the torque ahead on a curve entry
==================================================================================

A steering-assistance function cannot record an hour of every customer. Here a generic
HMM-GMR, fitted on three simulated drivers (one of each style), becomes a new driver's model
from two minutes of that driver's driving:

- :meth:`~skhmmgmr.HMMGMRRegressor.adapt` moves the fitted parameters towards the new
  recordings, the fitted ones acting as the prior (MAP adaptation with a relevance factor:
  the rows of evidence a state needs before it moves halfway);
- a :class:`~skhmmgmr.FilterStream` with ``relevance`` does the same online, while it
  estimates: every update given the measured torque moves the state means;
- for comparison, a model fitted from scratch on the same two minutes.

Then the torque the driver is about to apply, 0.5 s ahead, on a curve entry: an HMM-GMR of
the target shifted within every recording (:func:`skhmmgmr.datasets.shift_target`), generic
and adapted to the new driver alike, reads the road preview (heading deviation and curvature
30 m ahead); holding the current estimate and the model's own forecast
(:meth:`~skhmmgmr.HMMGMRRegressor.predict_ahead`) lag behind. The user guide page "Adapting a
model and estimating the torque ahead" has the benchmarks behind both parts: on the
simulated population, a generic model is already close to a driver's own, and adaptation
moves it little; the printed accuracies below say how much it moves for this driver.
"""

import copy
import os
from dataclasses import replace

import matplotlib.pyplot as plt
import numpy as np

from skhmmgmr import HMMGMRRegressor
from skhmmgmr.datasets import (
    DRIVER_STYLES,
    make_driving_protocol,
    make_lane_keeping,
    shift_target,
)
from skhmmgmr.metrics import accuracy_score, smoothness_score

quick = bool(os.environ.get("SKHMMGMR_DOCS_QUICK"))
rate, horizon = 20.0, 0.5
steps = int(horizon * rate)
features = [
    "steering_wheel_angle",
    "yaw_rate",
    "lateral_deviation_0m",
    "heading_deviation_30m",
    "road_curvature_30m",
]

# %%
# The generic model: one training section per radius setting of each of three drivers.
generic_data = make_driving_protocol(
    ("defensive", "aggressive", "novice"),
    n_train_per_setting=1,
    n_validation=0,
    n_test=0,
    duration=30.0 if quick else 90.0,
    sampling_rate=rate,
    random_state=0,
)
X, y, groups = generic_data[features], generic_data["driver_torque"], generic_data["recording"]
generic = HMMGMRRegressor(n_states=5, random_state=0).fit(X, y, groups=groups)

# %%
# A new driver: a novice of its own, with a firmer arm, a heavier steering feel and a later
# reaction than the style. Two minutes to adapt to (a radius setting of 300-900 m), then two
# test minutes on all radii.
new_driver = replace(DRIVER_STYLES["novice"], feel_gain=1.0, arm_stiffness=10.0, reaction_time=0.3)
two_minutes = make_lane_keeping(
    120.0, setting=4, driver=new_driver, sampling_rate=rate, random_state=1
)
test = make_lane_keeping(
    60.0 if quick else 120.0, setting=7, driver=new_driver, sampling_rate=rate, random_state=2
)
X_new, y_new = two_minutes[features], two_minutes["driver_torque"].to_numpy()
X_test, y_test = test[features], test["driver_torque"].to_numpy()
g_test = test["recording"]  # one recording: the filter runs over all of it

adapted = copy.deepcopy(generic).adapt(X_new, y_new, relevance=64.0, parameters="mvt")
scratch = HMMGMRRegressor(n_states=5, random_state=0).fit(X_new, y_new)
stream = generic.filter_stream(relevance=64.0)
stream.update_batch(X_new, y=y_new)  # estimates and learns, sample by sample
online = HMMGMRRegressor.from_fitted_model(stream.adapted_model())

models = {
    "generic": generic,
    "adapted (adapt)": adapted,
    "adapted online (FilterStream)": online,
    "from scratch, 2 min": scratch,
}
fig, axes = plt.subplots(2, 1, figsize=(9, 6.5))
time = test["time"].to_numpy()
axes[0].plot(time, y_test, color="black", lw=1.5, label="driver torque")
for name, model in models.items():
    estimate = model.predict(X_test, groups=g_test)
    accuracy = accuracy_score(y_test, estimate)
    roughness = smoothness_score(estimate, sampling_period=1.0 / rate)
    axes[0].plot(time, estimate, lw=1, label=f"{name} ({accuracy:.1f} %)")
    print(f"{name:<30} accuracy {accuracy:5.1f} %   roughness {roughness:4.2f} Nm/s")
axes[0].set_xlim(0.0, 40.0)  # the first 40 s; accuracies over the whole section
axes[0].set_xlabel("time [s]")
axes[0].set_ylabel("torque [Nm]")
axes[0].set_title("The new driver's test section", fontsize=10)
axes[0].legend(fontsize=8, loc="upper right", ncol=2)

# %%
# The torque 0.5 s ahead: a generic model of the shifted target, adapted to the new driver's
# two minutes (their shifted target), against holding the adapted estimate now and the
# adapted model's own forecast. Shown on the first curve entry of the test section, where the
# road preview tells what is coming.
ahead_target = shift_target(y.to_numpy(), steps, groups=groups.to_numpy())
keep = ~np.isnan(ahead_target)
ahead = HMMGMRRegressor(n_states=5, random_state=0).fit(
    X[keep], ahead_target[keep], groups=groups[keep]
)
new_target = shift_target(y_new, steps)
known = ~np.isnan(new_target)
ahead.adapt(X_new[known], new_target[known], relevance=64.0, parameters="mvt")

truth = shift_target(y_test, steps)
curvature = np.abs(test["road_curvature_0m"].rolling(10, center=True, min_periods=1).mean())
settled = time > 8.0
entries = np.flatnonzero(settled[1:] & (curvature.to_numpy()[1:] > 5e-4) & (curvature[:-1] <= 5e-4))
entry = time[entries[0] + 1] if len(entries) else time[len(time) // 2]
window = (time > entry - 5.0) & (time < entry + 5.0) & ~np.isnan(truth)
estimates = {
    "hold the current estimate": adapted.predict(X_test, groups=g_test),
    "predict_ahead (conditional)": adapted.predict_ahead(
        X_test, steps, groups=g_test, state_output="conditional"
    ),
    "model of the shifted target": ahead.predict(X_test, groups=g_test),
}
axes[1].plot(time[window], truth[window], color="black", lw=1.5, label="torque 0.5 s ahead")
for name, estimate in estimates.items():
    accuracy = accuracy_score(truth[~np.isnan(truth)], estimate[~np.isnan(truth)])
    axes[1].plot(time[window], estimate[window], lw=1, label=f"{name} ({accuracy:.0f} %)")
    print(f"0.5 s ahead, {name:<27} accuracy {accuracy:5.1f} % (whole test section)")
axes[1].axvline(entry, color="0.5", ls=":", lw=1)
axes[1].set_xlabel("time [s] (dotted: curve entry)")
axes[1].set_ylabel("torque [Nm]")
axes[1].set_title("Torque 0.5 s ahead on a curve entry (accuracy on the section)", fontsize=10)
axes[1].legend(fontsize=8, loc="upper left")
fig.tight_layout()
plt.show()
