"""
Quick start: a driver-torque model on simulated lane keeping
=============================================================

Simulate a virtual driver keeping the centre lane of a pseudo-random highway (the thesis'
protocol at a reduced size), fit an HMM-GMR model on the training recordings and estimate the
driver torque of unseen test recordings, causally and recording by recording.
"""

import os

from sklearn.pipeline import make_pipeline
from sklearn.preprocessing import StandardScaler

from skhmmgmr import HMMGMRRegressor
from skhmmgmr.datasets import RECORDING, SPLIT, TARGET, TIME, make_driving_protocol
from skhmmgmr.metrics import evaluate_recordings
from skhmmgmr.plotting import plot_estimate

# Short sections keep the example quick; the thesis uses 300 s.
duration = 30.0 if os.environ.get("SKHMMGMR_DOCS_QUICK") else 90.0
data = make_driving_protocol(
    drivers=("defensive",), duration=duration, sampling_rate=20.0, random_state=0
)
print(data.groupby(SPLIT)[RECORDING].nunique().to_string())

# %%
# Fit on the training recordings
# ------------------------------
# ``groups`` gives the recording of every row: EM runs over every recording, and the filter
# restarts at the first row of each.
features = ["steering_wheel_angle", "yaw_rate", "heading_deviation_10m"]
train = data[data[SPLIT] == "train"]
test = data[data[SPLIT] == "test"]
model = make_pipeline(StandardScaler(), HMMGMRRegressor(n_states=5, random_state=0))
model.fit(train[features], train[TARGET], hmmgmrregressor__groups=train[RECORDING])

# %%
# Estimate the test recordings
# ----------------------------
hmm = model[-1]
X_test = model[:-1].transform(test[features])
estimate, std = hmm.predict(X_test, groups=test[RECORDING], return_std=True)
state_proba = hmm.predict_state_proba(X_test, groups=test[RECORDING])
table = evaluate_recordings(
    test[TARGET].to_numpy(), estimate, groups=test[RECORDING].to_numpy(), sampling_period=0.05
)
print(table.round(3).to_string(index=False))
print(
    f"mean accuracy {table['accuracy'].mean():.1f} %, smoothness "
    f"{table['smoothness'].mean():.2f} Nm/s"
)

# %%
# One test recording, with the +-2 std band and the filtered state probabilities
# ------------------------------------------------------------------------------
first = test[RECORDING] == test[RECORDING].iloc[0]
fig, axes = plot_estimate(
    test.loc[first, TIME].to_numpy(),
    test.loc[first, TARGET].to_numpy(),
    estimate[first.to_numpy()],
    std=std[first.to_numpy()],
    state_proba=state_proba[first.to_numpy()],
    title=str(test[RECORDING].iloc[0]),
)
