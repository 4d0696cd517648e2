"""
The thesis' parameter selection framework on simulated drivers
==============================================================

Simulate the thesis' protocol for three virtual driver styles, run the whole parameter
selection framework with :func:`~skhmmgmr.selection.select_parameters` (Spearman filter,
exhaustive and forward wrappers, feature relevance, candidate subsets, state selection) and
draw its figures: feature relevance (thesis Fig. 4), state selection (Fig. 8) and the final
model against the all-feature baseline per driver (Fig. 9). ``skhmmgmr demo`` runs the same
job from the command line and writes an HTML report.
"""

import os

import matplotlib.pyplot as plt

from skhmmgmr.datasets import FEATURE_NAMES, make_driving_protocol
from skhmmgmr.metrics import trade_offs
from skhmmgmr.plotting import (
    plot_driver_comparison,
    plot_estimate,
    plot_relevance,
    plot_state_selection,
)
from skhmmgmr.selection import select_parameters

quick = bool(os.environ.get("SKHMMGMR_DOCS_QUICK"))
# The thesis uses 300 s sections at 100 Hz, the 10 best features of the filter and K <= 20.
duration, sampling_rate = (6.0, 10.0) if quick else (20.0, 20.0)
candidates = list(FEATURE_NAMES[:8]) if quick else list(FEATURE_NAMES)
data = make_driving_protocol(
    drivers=("defensive", "aggressive", "novice"),
    duration=duration,
    sampling_rate=sampling_rate,
    random_state=0,
)
print(data.groupby("split")["recording"].nunique().to_string())

# %%
# Run the framework
# -----------------
# Every choice uses the 50/50 accuracy/smoothness trade-off; the relevance is mapped over
# coarser trade-offs than the thesis' 10% steps to keep the example short.
report = select_parameters(
    data,
    candidate_features=candidates,
    n_top=3 if quick else 6,
    k_max=3 if quick else 8,
    relevance_trade_offs=trade_offs(50 if quick else 25),
    progress=False,
    random_state=0,
)
print(report.summary())

# %%
# Feature relevance over the trade-offs
# -------------------------------------
# How often each feature belongs to the best subset of a validation recording, counted over
# both wrappers. Accuracy-heavy trade-offs keep more features.
fig, ax = plot_relevance(report.relevance, source="combined")

# %%
# State selection
# ---------------
# K grows while the mean performance score improves by more than 1%; BIC, the usual
# likelihood-only criterion, keeps decreasing much longer.
fig, axes = plot_state_selection(report.states, bic=report.bic, n_states=report.n_states)

# %%
# Final model against the baseline, per driver
# ---------------------------------------------
fig, axes = plot_driver_comparison(
    report.test,
    labels={"final": f"final ({len(report.features)} features)", "baseline": "baseline (all)"},
)

# %%
# One test recording
# ------------------
test = data[data["split"] == "test"]
rows = test[test["recording"] == test["recording"].iloc[0]]
X = rows[list(report.features)].to_numpy()
estimate, std = report.final_model.predict(X, return_std=True)
fig, axes = plot_estimate(
    rows["time"],
    rows["driver_torque"],
    estimate,
    std=std,
    state_proba=report.final_model.predict_state_proba(X),
    title=rows["recording"].iloc[0],
)
plt.show()
