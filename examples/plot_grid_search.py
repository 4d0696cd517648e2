"""
Grid search over the number of states and the score's trade-off
===============================================================

The plain scikit-learn route to state selection: ``GridSearchCV`` over ``n_states`` with
``GroupKFold`` (whole recordings per fold) and one performance-score scorer per
accuracy/smoothness trade-off as multi-metric scoring. Metadata routing hands the recording
ids (``groups``) to the splitter, to the model's ``fit`` and to the scorers, so every test
recording is filtered on its own. The refit uses the 50/50 trade-off.
"""

import os

import matplotlib.pyplot as plt
import numpy as np
import pandas as pd
import sklearn
from sklearn.model_selection import GridSearchCV, GroupKFold
from sklearn.pipeline import make_pipeline
from sklearn.preprocessing import StandardScaler

from skhmmgmr import HMMGMRRegressor
from skhmmgmr.datasets import make_driving_protocol
from skhmmgmr.metrics import make_performance_scorers

quick = bool(os.environ.get("SKHMMGMR_DOCS_QUICK"))
data = make_driving_protocol(
    drivers=("defensive",),
    n_validation=0,
    n_test=0,
    duration=8.0 if quick else 40.0,
    sampling_rate=20.0,
    random_state=0,
)
features = ["steering_wheel_angle", "yaw_rate"]
X, y, groups = data[features], data["driver_torque"], data["recording"].to_numpy()

# %%
# The search
# ----------
trade_offs = ["100/0", "50/50", "0/100"]
scoring = make_performance_scorers(trade_offs, sampling_period=0.05)
n_states = [1, 2, 3] if quick else [1, 2, 3, 4, 5, 6, 8]
model = make_pipeline(StandardScaler(), HMMGMRRegressor(random_state=0))
with sklearn.config_context(enable_metadata_routing=True):
    search = GridSearchCV(
        model,
        {"hmmgmrregressor__n_states": n_states},
        cv=GroupKFold(n_splits=3),
        scoring=scoring,
        refit="neg_performance_50/50",
    ).fit(X, y, groups=groups)
print("best K at 50/50:", search.best_params_["hmmgmrregressor__n_states"])
columns = [f"mean_test_neg_performance_{t}" for t in trade_offs]
results = pd.DataFrame(search.cv_results_).set_index("param_hmmgmrregressor__n_states")
print(results[[*columns, "mean_test_accuracy", "mean_test_neg_smoothness"]].round(3))

# %%
# Scores against K for every trade-off
# ------------------------------------
# The performance score is normalised within each fold's compared set, so only its shape
# over K matters; lower is better (the scorers return its negative).
fig, (ax_ps, ax_metrics) = plt.subplots(1, 2, figsize=(9, 3.5))
for trade_off, column in zip(trade_offs, columns, strict=True):
    ax_ps.plot(n_states, -results[column], marker="o", label=trade_off)
ax_ps.axvline(search.best_params_["hmmgmrregressor__n_states"], color="k", ls="--", lw=1)
ax_ps.set(xlabel="number of states K", ylabel="performance score", title="per trade-off")
ax_ps.legend(title="accuracy/smoothness")
ax_metrics.plot(n_states, results["mean_test_accuracy"], marker="o", color="tab:blue")
ax_metrics.set(xlabel="number of states K", ylabel="accuracy [%]", title="metrics")
twin = ax_metrics.twinx()
twin.plot(n_states, -results["mean_test_neg_smoothness"], marker="s", color="tab:orange")
twin.set_ylabel("smoothness [Nm/s]")
fig.tight_layout()
print("refitted on", np.unique(groups).size, "recordings:", search.best_estimator_[-1])
plt.show()
