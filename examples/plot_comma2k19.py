"""
Real driving data: who steers, and what one minute can tell
============================================================

One real minute of the public comma2k19 dataset (comma.ai, MIT licence): a Toyota RAV4 on a
California highway, with openpilot's lane keeping engaged for part of the minute.
:func:`skhmmgmr.datasets.load_comma2k19_sample` loads this minute, which ships with the
package (:func:`~skhmmgmr.datasets.load_comma2k19_segment` reads any other segment folder the
same way). The loader decodes from the raw CAN frames the driver torque, the steering and
vehicle-motion signals and, with the extra ``skhmmgmr[can]`` (needed here), the signals that
tell who steers.

A model of the driver's torque can only learn from the time the driver steers alone: where
openpilot steers, the power steering turns the wheel and the torque sensor measures something
else. In this minute that is one span at the start. The span is cut into consecutive
3-second recordings, and each recording is tested once by a model trained on the others (leave
one recording out), beside two baselines. The torque sensor reports raw, uncalibrated units
(not Nm); every torque figure below is in those units.
"""

import matplotlib.pyplot as plt
import numpy as np
import pandas as pd
from sklearn.linear_model import RidgeCV
from sklearn.pipeline import make_pipeline
from sklearn.preprocessing import StandardScaler

from skhmmgmr import HMMGMRRegressor
from skhmmgmr.datasets import RECORDING, TARGET, TIME, load_comma2k19_sample
from skhmmgmr.metrics import evaluate_recordings, normalize_performance, smoothness_score

SAMPLING_RATE = 20.0  # Hz
PERIOD = 1.0 / SAMPLING_RATE  # s
CHUNK_SECONDS = 3.0
FEATURES = ["steering_wheel_angle", "steering_wheel_velocity"]
N_STATES = 2
FLAGS = {
    "cruise_active": "cruise active",
    "openpilot_steer_request": "openpilot\nsteer request",
    "eps_lka_active": "EPS LKA active",
}


def short(recording):
    """A recording id without the segment name, for tables and titles."""
    return recording.split("/", 1)[1] if "/" in recording else recording


def ordered_states(model, X, y, groups):
    """Order of the states by their mean |torque| on the training rows (each row weighted by
    its filtered state probability), lowest first, and those means."""
    proba = model.predict_state_proba(X, groups=groups)
    mean_abs = proba.T @ np.abs(np.asarray(y)) / proba.sum(axis=0)
    order = np.argsort(mean_abs)
    return order, mean_abs[order]


def state_check(proba, measured, state_torque):
    """The training |torque| of the lowest and highest states; where the filter's most probable
    state is the highest one: share of the rows, and the mean measured |torque| there and
    elsewhere."""
    high = proba.argmax(axis=1) == proba.shape[1] - 1
    size = np.abs(measured)
    return {
        "low state, training |torque|": state_torque[0],
        "high state, training |torque|": state_torque[-1],
        "rows in high state": high.mean(),
        "|torque| high state": size[high].mean() if high.any() else np.nan,
        "|torque| other": size[~high].mean() if (~high).any() else np.nan,
    }


def runs_of(flag):
    """Number of the run of equal values every row belongs to (0, 1, ...)."""
    flag = np.asarray(flag)
    return np.concatenate(([0], np.cumsum(flag[1:] != flag[:-1])))


minute = load_comma2k19_sample(sampling_rate=SAMPLING_RATE, engagement=True)
driver = load_comma2k19_sample(sampling_rate=SAMPLING_RATE, steering="driver")
# Place every driver span on the minute's time axis (the loader restarts its time at 0).
minute_origin = minute.attrs["time_origin"][minute[RECORDING].iloc[0]]
span_origin = driver[RECORDING].map(driver.attrs["time_origin"]) - minute_origin
driver["minute_time"] = driver[TIME] + span_origin

print(f"{len(minute)} rows at {SAMPLING_RATE:g} Hz; torque in {minute.attrs['units'][TARGET]}")
print("seconds with each flag set:")
print((minute[list(FLAGS)].sum() * PERIOD).round(2).to_string())
spans = driver.groupby(RECORDING, sort=False).agg(
    start=("minute_time", "first"), rows=(TIME, "size")
)
spans["seconds"] = spans["rows"] * PERIOD
spans.index = spans.index.map(short)
print("spans where the driver steers alone (start on the minute's time axis, s):")
print(spans.round(2).to_string())

# %%
# Who steers during the minute
# ----------------------------
# The bottom panel shows the decoded engagement signals: the car's cruise control (on a
# Toyota, openpilot is engaged exactly when it is), openpilot's request that the power
# steering apply its torque command, and the power steering's lane-keeping state. The middle
# panel is the command openpilot sends. The driver steers alone in the green spans only:
# neither openpilot requests steering nor the power steering applies it. The dotted lines at
# +-100 raw units are openpilot's own threshold for "the driver is steering".
t = minute[TIME].to_numpy()
fig, axes = plt.subplots(
    3, 1, sharex=True, figsize=(9, 6.5), gridspec_kw={"height_ratios": [2.2, 1.2, 1.2]}
)
axes[0].plot(t, minute[TARGET], color="black", lw=0.8, label="measured driver torque")
for sign in (-1, 1):
    axes[0].axhline(sign * 100, color="tab:red", ls=":", lw=0.8)
axes[0].set_ylabel("driver torque\n[raw units]")
axes[1].plot(t, minute["openpilot_steer_command"], color="tab:orange", lw=0.8)
axes[1].set_ylabel("openpilot steer\ncommand [raw]")
for i, column in enumerate(FLAGS):
    axes[2].step(t, 1.2 * i + 0.8 * minute[column], where="post", lw=1.2)
axes[2].set_yticks(1.2 * np.arange(len(FLAGS)) + 0.4, list(FLAGS.values()), fontsize="small")
axes[2].set_xlabel("time in the minute [s]")
for start, seconds in zip(spans["start"], spans["seconds"], strict=True):
    for ax in axes:
        ax.axvspan(start, start + seconds, color="tab:green", alpha=0.15, lw=0)
axes[0].axvspan(0, 0, color="tab:green", alpha=0.15, label="driver steers alone")
axes[0].legend(loc="upper right", fontsize="small")
axes[0].set_title("comma2k19 segment: driver torque and who steers")
fig.tight_layout()

# %%
# Recordings: the driver span cut into 3-second chunks
# ----------------------------------------------------
# Every span is cut into consecutive chunks of 3 s (the last chunk of a span keeps the few
# rows left over), each chunk a recording of its own: the causal filter restarts at its first
# row, and no chunk is both trained and tested on. The torque's standard deviation (SD) of
# each chunk matters for what follows: the thesis' accuracy is ``(1 - RMSE / SD) * 100``, so
# a chunk whose torque barely moves has a small SD and turns a small RMSE into a negative
# accuracy. The smoothness of the measured torque (SD of its time derivative) is the scale
# against which the smoothness of an estimate can be read.
span_seconds = driver.groupby(RECORDING)[TIME].transform("size") * PERIOD
n_chunks = np.maximum(np.floor(span_seconds / CHUNK_SECONDS + 1e-9), 1)
chunk = np.minimum(np.floor(driver[TIME] / CHUNK_SECONDS + 1e-9), n_chunks - 1).astype(int)
driver[RECORDING] = driver[RECORDING] + "/chunk" + chunk.astype(str)
chunks = list(driver[RECORDING].unique())

by_chunk = driver.groupby(RECORDING, sort=False)
chunk_table = pd.DataFrame(
    {
        "start [s]": by_chunk["minute_time"].first(),
        "seconds": by_chunk.size() * PERIOD,
        "torque mean": by_chunk[TARGET].mean(),
        "torque SD": by_chunk[TARGET].std(ddof=0),
        "measured smoothness": [
            smoothness_score(g[TARGET].to_numpy(), sampling_period=PERIOD) for _, g in by_chunk
        ],
    }
)
chunk_table.index = chunk_table.index.map(short)
print(chunk_table.round(2).to_string())

# %%
# Leave one chunk out
# -------------------
# Every chunk is tested once, by models trained on the other chunks:
#
# - HMM-GMR with a fixed feature subset, the steering wheel angle and its rate (the two
#   signals of the wheel itself; with a few hundred training rows there is no room for a
#   feature search), and a fixed ``K = 2``. K is not chosen by validation because, inside a
#   fold, a validation would rest on a single 3-second chunk; two states is the smallest model
#   whose filtered state sequence says something (with ``K = 1`` HMM-GMR is one
#   linear-Gaussian regression, close to the ridge baseline);
# - RidgeCV on the same standardised features (its penalty chosen by its own leave-one-row-out
#   on the training rows);
# - the training mean: the mean torque of the training chunks, a constant. Its accuracy is
#   never above 0, since the RMSE of a constant is at least the SD.
#
# Per test chunk the table gives the torque SD of that chunk, the RMSE, the accuracy, the
# smoothness (SD of the estimate's derivative, raw units/s, lower is smoother) and, for
# HMM-GMR, the share of measured samples inside the +-2 std predictive band (``return_std``)
# with the band's mean half-width (a band holds every sample if it is wide enough), and the
# thesis' performance score at the 50/50 trade-off, normalised over the three models on each
# chunk (D.5; lower is better). The training mean, a constant, is perfectly smooth, so its
# smoothness term is 0.
results, states, curves = [], [], {}
for test_chunk in chunks:
    train = driver[driver[RECORDING] != test_chunk]
    test = driver[driver[RECORDING] == test_chunk]
    model = HMMGMRRegressor(n_states=N_STATES, n_init=5, random_state=0)
    model.fit(train[FEATURES], train[TARGET], groups=train[RECORDING])
    estimate, std = model.predict(test[FEATURES], groups=test[RECORDING], return_std=True)
    ridge = make_pipeline(StandardScaler(), RidgeCV(alphas=np.logspace(-3, 3, 13)))
    ridge.fit(train[FEATURES], train[TARGET])
    estimates = {
        "HMM-GMR": estimate,
        "RidgeCV": ridge.predict(test[FEATURES]),
        "training mean": np.full(len(test), train[TARGET].mean()),
    }
    measured = test[TARGET].to_numpy()
    inside = np.mean(np.abs(measured - estimate) <= 2 * std)
    order, state_torque = ordered_states(model, train[FEATURES], train[TARGET], train[RECORDING])
    state_proba = model.predict_state_proba(test[FEATURES], groups=test[RECORDING])[:, order]
    states.append(
        {"test chunk": short(test_chunk), **state_check(state_proba, measured, state_torque)}
    )
    for name, values in estimates.items():
        metrics = evaluate_recordings(
            measured, values, groups=test[RECORDING].to_numpy(), sampling_period=PERIOD
        ).iloc[0]
        results.append(
            {
                "test chunk": short(test_chunk),
                "model": name,
                "torque SD": measured.std(),
                "RMSE": metrics["rmse"],
                "accuracy [%]": metrics["accuracy"],
                "smoothness": metrics["smoothness"],
                "inside +-2 std": inside if name == "HMM-GMR" else np.nan,
                "2 std": np.mean(2 * std) if name == "HMM-GMR" else np.nan,
            }
        )
    curves[test_chunk] = {
        "time": test["minute_time"].to_numpy(),
        "measured": measured,
        "std": std,
        "state_proba": state_proba,
        "state_torque": state_torque,
        **estimates,
    }
results = pd.DataFrame(results)
scores = normalize_performance(
    results,
    weights="50/50",
    recording="test chunk",
    accuracy="accuracy [%]",
    smoothness="smoothness",
)
results = results.merge(scores[["test chunk", "model", "performance_score"]])
results = results.rename(columns={"performance_score": "PS 50/50"})
print(results.round(2).to_string(index=False))

# %%
# What one minute supports
# ------------------------
# The averages over the test chunks (each chunk counts once, as the thesis averages its
# recordings), then a verdict computed from the table above.
averaged = ["RMSE", "accuracy [%]", "smoothness", "PS 50/50"]
averages = results.groupby("model", sort=False)[averaged].mean()
print(averages.round(2).to_string())
hmm = results[results["model"] == "HMM-GMR"].set_index("test chunk")
n_positive = int((hmm["accuracy [%]"] > 0).sum())
print(
    f"HMM-GMR accuracy is positive in {n_positive} of {len(hmm)} test chunks "
    f"(mean {hmm['accuracy [%]'].mean():.1f} %)."
)
for baseline in ("training mean", "RidgeCV"):
    other = results[results["model"] == baseline].set_index("test chunk")
    n_better = int((hmm["RMSE"] < other["RMSE"]).sum())
    print(f"HMM-GMR has a lower RMSE than {baseline} in {n_better} of {len(hmm)} test chunks.")
if n_positive == len(hmm):
    print("Verdict: this minute supports a positive accuracy on every test chunk.")
else:
    print(
        f"Verdict: this minute does not support a positive accuracy: {len(hmm) - n_positive} "
        f"of {len(hmm)} test chunks score at or below 0 %, i.e. no better than that chunk's "
        "own mean torque."
    )

# %%
# The verdict follows from the table, not from a hope: with one driver-steered span of
# a few seconds, every model is trained on a handful of seconds of steering and tested on
# another handful, and a chunk with a small torque SD is scored against that small SD. The
# numbers say how little one minute can show; they do not tell how HMM-GMR performs on real
# driving, which would need many recordings of manual steering.
#
# Estimates, predictive band and state sequence per test chunk
# ------------------------------------------------------------
# Top: the measured torque, the HMM-GMR estimate with its +-2 std band, and the two
# baselines. Bottom: the filtered state probabilities of that chunk's HMM-GMR model. Each
# fold's model has its own states; they are ordered here by their mean absolute torque on that
# fold's training rows (given in the legend), lowest first, so that the same colour means
# "the low-torque state" or "the high-torque state" in every panel. The state sequence and
# the band are what the model can be judged on here: whether the filter is in its
# high-torque state when the driver turns the wheel, and whether the band holds the measured
# torque (a Gaussian band of +-2 std holds about 95 % of the samples when it is calibrated).
# The table after the figure checks the first on the test chunks: the training ``|torque|`` of
# the low and the high state (the states can only describe what the training chunks hold),
# then, where the most probable state is the high-torque one, the share of rows, and the mean
# measured ``|torque|`` there and elsewhere.
fig, axes = plt.subplots(
    2,
    len(chunks),
    sharex="col",
    figsize=(3.6 * len(chunks), 5.5),
    squeeze=False,
    gridspec_kw={"height_ratios": [2, 1]},
)
for column, test_chunk in enumerate(chunks):
    c = curves[test_chunk]
    ax = axes[0, column]
    ax.plot(c["time"], c["measured"], color="black", lw=1, label="measured")
    ax.plot(c["time"], c["HMM-GMR"], color="tab:blue", lw=1, label="HMM-GMR")
    band = 2 * c["std"]
    ax.fill_between(
        c["time"],
        c["HMM-GMR"] - band,
        c["HMM-GMR"] + band,
        color="tab:blue",
        alpha=0.2,
        label="+-2 std",
    )
    ax.plot(c["time"], c["RidgeCV"], color="tab:orange", ls="--", lw=1, label="RidgeCV")
    ax.plot(c["time"], c["training mean"], color="gray", ls=":", lw=1, label="training mean")
    row = hmm.loc[short(test_chunk)]
    ax.set_title(
        f"{short(test_chunk)}\nA = {row['accuracy [%]']:.0f} %, "
        f"inside band = {row['inside +-2 std']:.2f}",
        fontsize="small",
    )
    proba = c["state_proba"]
    labels = [f"|torque| {m:.0f} in training" for m in c["state_torque"]]
    axes[1, column].stackplot(c["time"], proba.T, labels=labels, alpha=0.85)
    axes[1, column].set_ylim(0, 1)
    axes[1, column].set_xlabel("time in the minute [s]")
    axes[1, column].legend(loc="lower left", fontsize="x-small")
axes[0, 0].set_ylabel("driver torque [raw units]")
axes[1, 0].set_ylabel("filtered state\nprobability")
axes[0, 0].legend(loc="best", fontsize="x-small")
fig.tight_layout()

print(pd.DataFrame(states).round(2).to_string(index=False))

# %%
# For contrast: the model on the openpilot-engaged part
# -----------------------------------------------------
# A model trained on all the driver chunks (same features, same K) now filters the part of
# the minute where cruise control, hence openpilot, is engaged. There the power steering
# applies openpilot's command and turns the wheel; the torque sensor measures what the
# driver's hands add to it (a hand resting on the wheel, following or resisting it), not the
# torque that turns the wheel. The model learned, in the driver span, the torque that goes
# with a steering angle and rate when the driver alone turns the wheel, so it estimates a
# torque the driver is not applying here: accuracy and RMSE against the measured torque say
# less about the model than about how different the two situations are. The printed
# correlations with openpilot's command show which of the two signals goes with the
# steering openpilot does; the last lines apply the state check of the test chunks to this
# part (how often the filter is in the state it learned from the driver's turning).
final = HMMGMRRegressor(n_states=N_STATES, n_init=5, random_state=0)
final.fit(driver[FEATURES], driver[TARGET], groups=driver[RECORDING])

# Every run of engaged rows is a recording of its own: the filter restarts at its start.
is_engaged = minute["cruise_active"].to_numpy() == 1
run = pd.factorize(runs_of(is_engaged)[is_engaged])[0]
engaged = minute[is_engaged].copy()
engaged[RECORDING] = engaged[RECORDING] + "/engaged" + run.astype(str)
groups = engaged[RECORDING].to_numpy()
estimate, std = final.predict(engaged[FEATURES], groups=groups, return_std=True)
order, state_torque = ordered_states(final, driver[FEATURES], driver[TARGET], driver[RECORDING])
state_proba = final.predict_state_proba(engaged[FEATURES], groups=groups)[:, order]
measured = engaged[TARGET].to_numpy()
command = engaged["openpilot_steer_command"].to_numpy()

table = evaluate_recordings(measured, estimate, groups=groups, sampling_period=PERIOD)
table["recording"] = table["recording"].map(short)
table["torque SD"] = pd.Series(measured).groupby(groups).std(ddof=0).to_numpy()
print(table.round(2).to_string(index=False))
print(
    f"engaged: {len(engaged) * PERIOD:.2f} s; measured |torque| > 100 in "
    f"{np.mean(np.abs(measured) > 100):.1%} of the rows (driver SD in the driver span: "
    f"{driver[TARGET].std(ddof=0):.1f}, engaged: {measured.std():.1f})"
)
print(
    f"estimate from {estimate.min():.0f} to {estimate.max():.0f}, measured from "
    f"{measured.min():.0f} to {measured.max():.0f}; inside +-2 std: "
    f"{np.mean(np.abs(measured - estimate) <= 2 * std):.2f}"
)
print(
    "correlation with openpilot's command: "
    f"estimate {np.corrcoef(estimate, command)[0, 1]:+.2f}, "
    f"measured torque {np.corrcoef(measured, command)[0, 1]:+.2f}"
)
print(pd.Series(state_check(state_proba, measured, state_torque)).round(2).to_string())

te = engaged[TIME].to_numpy()
fig, axes = plt.subplots(
    3, 1, sharex=True, figsize=(9, 6.5), gridspec_kw={"height_ratios": [2.2, 1.2, 1]}
)
axes[0].plot(te, measured, color="black", lw=0.8, label="measured")
axes[0].plot(te, estimate, color="tab:blue", lw=0.8, label="HMM-GMR (trained on driver span)")
axes[0].fill_between(
    te, estimate - 2 * std, estimate + 2 * std, color="tab:blue", alpha=0.2, label="+-2 std"
)
axes[0].set_ylabel("driver torque\n[raw units]")
axes[0].legend(loc="upper right", fontsize="small")
axes[0].set_title("openpilot engaged: the measured torque is not the driver's steering")
axes[1].plot(te, command, color="tab:orange", lw=0.8)
axes[1].set_ylabel("openpilot steer\ncommand [raw]")
labels = [f"|torque| {m:.0f} in training" for m in state_torque]
axes[2].stackplot(te, state_proba.T, labels=labels, alpha=0.85)
axes[2].set_ylim(0, 1)
axes[2].set_ylabel("filtered state\nprobability")
axes[2].legend(loc="upper right", fontsize="x-small")
axes[2].set_xlabel("time in the minute [s]")
fig.tight_layout()
