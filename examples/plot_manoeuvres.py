"""
Manoeuvres as a hierarchy: which manoeuvre is under way
=======================================================

:class:`~skhmmgmr.HierarchicalHMMGMRRegressor` gives every manoeuvre (lane keeping, a lane
change to the left or to the right) its own HMM and sequences the manoeuvres by a Markov
chain (thesis Appendix E.3). Fitted with the simulator's manoeuvre labels, it predicts the
torque with its band as :class:`~skhmmgmr.HMMGMRRegressor` does, and says which manoeuvre is
under way: the filtered probability of each manoeuvre, causal, row by row.
"""

import os

import matplotlib.pyplot as plt
import numpy as np
import pandas as pd

from skhmmgmr import HierarchicalHMMGMRRegressor
from skhmmgmr.datasets import make_lane_keeping

quick = bool(os.environ.get("SKHMMGMR_DOCS_QUICK"))
duration = 60.0 if quick else 150.0
frames = [
    make_lane_keeping(
        duration,
        setting=1 + i % 7,
        driver=("defensive", "aggressive", "novice")[i % 3],
        scenario="lane_change",
        sampling_rate=20.0,
        random_state=i,
        recording=f"lane_change-{i}",
    )
    for i in range(3 if quick else 7)
]
train, test = pd.concat(frames[:-1], ignore_index=True), frames[-1]
features = ["steering_wheel_angle", "yaw_rate", "lateral_deviation_0m", "heading_deviation_0m"]
manoeuvres = ["lane_keeping", "lane_change_left", "lane_change_right"]

# %%
# Fit with the labels
# -------------------
# Lane keeping gets three states (the centre lane and both neighbouring ones: the lateral
# deviation is measured from the centre lane), each lane change two.
model = HierarchicalHMMGMRRegressor(
    manoeuvres=manoeuvres,
    n_states={"lane_keeping": 3, "lane_change_left": 2, "lane_change_right": 2},
    random_state=0,
)
model.fit(
    train[features], train["driver_torque"], groups=train["recording"], manoeuvre=train["manoeuvre"]
)
print("chain over manoeuvres (row: from, column: to):")
print(pd.DataFrame(model.manoeuvre_transmat_, manoeuvres, manoeuvres).round(2).to_string())

# %%
# Manoeuvre probabilities and the torque on a test recording
# ----------------------------------------------------------
estimate, std = model.predict(test[features], return_std=True)
states = model.predict_state_proba(test[features])
proba = model.predict_manoeuvre_proba(test[features])
labels = test["manoeuvre"].to_numpy()
found = np.asarray(manoeuvres)[proba.argmax(axis=1)]
print(f"rows whose most probable manoeuvre is the label: {np.mean(found == labels):.1%}")

# the first lane change with a crossing, and 6 s either side
first = int(np.flatnonzero(labels != "lane_keeping")[0])
crossing = test["crossing_time"].iloc[first]
window = (test["time"] > crossing - 8.0) & (test["time"] < crossing + 6.0)
t = test["time"][window]

fig, axes = plt.subplots(3, 1, figsize=(7, 7), sharex=True)
for k in range(states.shape[1]):
    name = manoeuvres[model.state_manoeuvre_[k]]
    axes[0].plot(t, states[window.to_numpy(), k], lw=1, label=f"state {k} ({name})")
axes[0].set(ylabel="state probability")
axes[0].legend(fontsize=6, ncol=2, loc="upper left")
for m, name in enumerate(manoeuvres):
    axes[1].plot(t, proba[window.to_numpy(), m], label=name)
changing = np.isin(labels[window.to_numpy()], manoeuvres[1:])
axes[1].fill_between(t, 0, 1, where=changing, color="0.85", label="labelled lane change")
axes[1].set(ylabel="manoeuvre probability", ylim=(0, 1.02))
axes[1].legend(fontsize=7, loc="upper left")
axes[2].plot(t, test["driver_torque"][window], color="k", lw=1, label="measured")
axes[2].plot(t, estimate[window.to_numpy()], color="tab:blue", label="estimate")
axes[2].fill_between(
    t,
    (estimate - 2 * std)[window.to_numpy()],
    (estimate + 2 * std)[window.to_numpy()],
    color="tab:blue",
    alpha=0.2,
    label="+-2 std",
)
axes[2].set(xlabel="time [s]", ylabel="torque [Nm]")
axes[2].legend(fontsize=7, loc="upper left")
for ax in axes:
    ax.axvline(crossing, color="tab:red", ls="--", lw=1)
fig.suptitle("a lane change: the dashed line is the lane crossing")
fig.tight_layout()
plt.show()
