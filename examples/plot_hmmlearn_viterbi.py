"""
Viterbi states of an HMM-GMR model, with hmmlearn
=================================================

An HMM-GMR model is a Gaussian HMM over the joint columns ``[inputs, torque]``, read out by
causal Gaussian Mixture Regression. :meth:`~skhmmgmr.HMMGMRRegressor.to_hmmlearn` hands the
same HMM to hmmlearn as a fitted :class:`hmmlearn.hmm.GaussianHMM`, so hmmlearn's own tools
work on it: here its Viterbi decoding, the single most likely state sequence given the whole
recording, which a causal filter cannot compute. The plot sets it beside the state
probabilities the regressor filters row by row (only the past is known), which is what the
torque estimate uses. :meth:`~skhmmgmr.HMMGMRRegressor.from_hmmlearn` goes the other way: a
model trained with hmmlearn is read out by our GMR.
"""

import os

import matplotlib.pyplot as plt
import numpy as np

from skhmmgmr import HMMGMRRegressor
from skhmmgmr.datasets import make_lane_keeping

quick = bool(os.environ.get("SKHMMGMR_DOCS_QUICK"))
duration = 40.0 if quick else 180.0
features = ["steering_wheel_angle", "yaw_rate", "heading_deviation_10m"]
train = make_lane_keeping(duration, setting=7, sampling_rate=20.0, random_state=0, recording="a")
test = make_lane_keeping(60.0, setting=1, sampling_rate=20.0, random_state=1, recording="b")

model = HMMGMRRegressor(n_states=4, random_state=0)
model.fit(train[features], train["driver_torque"], groups=train["recording"])

# %%
# The same model, twice
# ---------------------
# The converted model scores the joint columns exactly as the regressor does.
hmm = model.to_hmmlearn()
joint = np.column_stack([test[features], test["driver_torque"]])
print(f"hmmlearn log-likelihood: {hmm.score(joint):.6f}")
print(f"skhmmgmr log-likelihood: {model.log_likelihood(test[features], test['driver_torque']):.6f}")

# %%
# Viterbi path against the filtered state probabilities
# -----------------------------------------------------
# The Viterbi path uses the torque and the whole recording; the filter uses the inputs up to
# each row only. Where they agree, the estimate already knows the state the full record would
# give.
log_probability, viterbi = hmm.decode(joint, algorithm="viterbi")
filtered = model.predict_state_proba(test[features])
agreement = np.mean(filtered.argmax(axis=1) == viterbi)
print(f"Viterbi log-probability {log_probability:.1f}; filter argmax agrees on {agreement:.1%}")

time = test["time"].to_numpy()
fig, axes = plt.subplots(3, 1, figsize=(9, 6), sharex=True)
axes[0].plot(time, test["driver_torque"], color="k", lw=1, label="measured")
axes[0].plot(time, model.predict(test[features]), color="tab:red", lw=1, label="HMM-GMR")
axes[0].set(ylabel="torque [Nm]")
axes[0].legend(loc="center left", bbox_to_anchor=(1.0, 0.5), fontsize="small")
axes[1].stackplot(time, filtered.T, labels=[f"state {k}" for k in range(model.n_states)])
axes[1].set(ylabel="filtered P(state)", ylim=(0, 1))
axes[1].legend(loc="center left", bbox_to_anchor=(1.0, 0.5), fontsize="small")
axes[2].step(time, viterbi, where="post", color="tab:purple")
axes[2].set(ylabel="Viterbi state", xlabel="time [s]", yticks=range(model.n_states))
fig.suptitle("hmmlearn's Viterbi path of an HMM-GMR model")
fig.tight_layout()
plt.show()
