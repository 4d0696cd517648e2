"""
Conformal prediction intervals with MAPIE, checked per driver
=============================================================

:meth:`~skhmmgmr.HMMGMRRegressor.predict` gives a predictive standard deviation, but the band
it spans is only as good as the model's Gaussian assumptions. Split conformal prediction
builds a band from the model's absolute errors on held-out *validation* recordings instead:
if new rows are exchangeable with the validation rows, at least 90 % of them fall inside it.
This example wraps a fitted model in MAPIE's :class:`~mapie.regression.SplitConformalRegressor`
and measures, on unseen *test* recordings, how often the measured torque falls inside the
conformal band and inside the model's own ±1.645 std band (90 % for a Gaussian), driver by
driver.

MAPIE does not pass ``groups`` to ``predict``, so the recordings travel with the rows: the
data are in the panel form (:func:`skhmmgmr.datasets.to_panel`), and every prediction MAPIE
asks for filters each recording on its own. See :doc:`/user_guide/other_tools` for other
tools that need this form.
"""

import os
import warnings

import matplotlib.pyplot as plt
import numpy as np
import pandas as pd
from mapie.regression import SplitConformalRegressor

from skhmmgmr import HMMGMRRegressor
from skhmmgmr.datasets import make_driving_protocol, to_panel

quick = bool(os.environ.get("SKHMMGMR_DOCS_QUICK"))
drivers = ("defensive", "aggressive", "novice")
data = to_panel(
    make_driving_protocol(
        drivers=drivers,
        n_train_per_setting=1 if quick else 2,
        n_validation=2 if quick else 4,
        n_test=2 if quick else 4,
        duration=15.0 if quick else 60.0,
        sampling_rate=20.0,
        random_state=0,
    )
)
features = ["steering_wheel_angle", "yaw_rate", "heading_deviation_10m"]
target = "driver_torque"
splits = ("train", "validation", "test")
train, validation, test = (data[data["split"] == split] for split in splits)
print(data.groupby(["split", "driver"]).size().unstack().to_string())

# %%
# Fit on the training recordings, conformalize on the validation recordings
# -------------------------------------------------------------------------
# One model for the three drivers. The index holds the recording and the time of every row,
# so neither ``fit`` nor MAPIE needs ``groups``. With ``prefit=True`` MAPIE leaves the model
# as it is and only computes its absolute errors on the validation recordings.
model = HMMGMRRegressor(n_states=4, random_state=0).fit(train[features], train[target])
conformal = SplitConformalRegressor(model, confidence_level=0.9, prefit=True)
with warnings.catch_warnings():
    # MAPIE checks that the model is fitted by predicting one row of zeros without column
    # names; the warning that this call raises says nothing about the data.
    warnings.filterwarnings("ignore", message="X does not have valid feature names")
    conformal.conformalize(validation[features], validation[target])

# %%
# Coverage on the test recordings, per driver
# -------------------------------------------
# ``predict_interval`` returns the point estimate (the model's own, filtered recording by
# recording) and the band: estimate ± the 90 % quantile of the validation errors, the same
# half-width for every row. The model's own band is ±1.645 std and follows the filtered
# states.
estimate, bounds = conformal.predict_interval(test[features])
lower, upper = bounds[:, 0, 0], bounds[:, 1, 0]
_, std = model.predict(test[features], return_std=True)
measured = test[target].to_numpy()
z = 1.645  # two-sided 90 % of a Gaussian
rows = pd.DataFrame(
    {
        "driver": test["driver"].to_numpy(),
        "conformal": (lower <= measured) & (measured <= upper),
        "own band": np.abs(measured - estimate) <= z * std,
        "conformal width": upper - lower,
        "own width": 2 * z * std,
    }
)
coverage = rows.groupby("driver", sort=False).mean()
coverage.loc["all drivers"] = rows.drop(columns="driver").mean()
coverage[["conformal", "own band"]] *= 100
print(f"coverage on the test recordings [%] (nominal {100 * 0.9:.0f} %) and mean width [Nm]")
print(coverage.round(2).to_string())

# %%
# The conformal guarantee is marginal: at least 90 % over all rows of recordings drawn like
# the validation recordings (here the three drivers together), not 90 % for each driver. One
# half-width for everybody is too wide for a driver whose errors are small and too narrow for
# one whose errors are large, so compare the per-driver rows with the "all drivers" row; to
# aim at 90 % per driver, conformalize each driver on their own validation recordings. The
# model's own band changes its width row by row with the filtered states, and its coverage
# holds only as far as the mixture's Gaussians describe the errors. The rows of a recording
# are not exchangeable either (their errors are correlated in time), so the guarantee holds
# only approximately, and a few test recordings per driver give a noisy estimate of coverage.

# %%
# One test recording
# ------------------
# The conformal band keeps one half-width; the model's own band widens and narrows with the
# filtered states. The titles give the coverage of each band on this recording.
first = test.index.get_level_values("recording")[0]
one = (test.index.get_level_values("recording") == first).nonzero()[0]
time = test.index.get_level_values("time")[one]
bands = {
    "conformal 90 %": (lower[one], upper[one], "tab:orange"),
    "own ±1.645 std": ((estimate - z * std)[one], (estimate + z * std)[one], "tab:blue"),
}
fig, axes = plt.subplots(2, 1, figsize=(9, 5.5), sharex=True, sharey=True)
for ax, (name, (low, high, color)) in zip(axes, bands.items(), strict=True):
    inside = np.mean((low <= measured[one]) & (measured[one] <= high))
    ax.fill_between(time, low, high, color=color, alpha=0.35, lw=0, label=name)
    ax.plot(time, measured[one], color="k", lw=1, label="measured")
    ax.plot(time, estimate[one], color="tab:red", lw=1, label="HMM-GMR estimate")
    ax.set(ylabel="torque [Nm]", title=f"{name}: {inside:.1%} of the rows inside")
    ax.legend(loc="upper right", fontsize="small", ncol=3)
axes[-1].set_xlabel("time [s]")
fig.suptitle(f"test recording {first}")
fig.tight_layout()
plt.show()
