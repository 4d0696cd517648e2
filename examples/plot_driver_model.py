"""
A driver model that estimates the torque and drives the car
===========================================================

A model of the driver's torque fitted on ordinary recordings learns mostly the steering
system's inverse: it estimates recorded torque well and, put at the wheel, weaves through
the lane. :func:`~skhmmgmr.make_driver_model` is fitted instead on recordings with a
perturbation experiment: a small torque on the steering wheel that the driver does not know
(here 0.2 Nm RMS, a multisine over 0.05-5 Hz, in a third of the training recordings), which
shows what part of the wheel's motion the driver did not cause.

Here, for a defensive driver at 100 Hz: the torque pipeline fitted on the ordinary
recordings and the driver model fitted on the same recordings with the perturbation, their
accuracy on the (never perturbed) test recordings, then each at the wheel of a held-out
road beside the human it learned from. The user guide page "The driver model at the wheel"
has the benchmark of every style, rate and car.
"""

import os
import warnings

import matplotlib.pyplot as plt

from skhmmgmr import make_driver_model, make_torque_pipeline
from skhmmgmr.datasets import DRIVER_MODEL_FEATURES, FEATURE_NAMES, drive, make_driving_protocol
from skhmmgmr.metrics import accuracy_score, lane_keeping_metrics

quick = bool(os.environ.get("SKHMMGMR_DOCS_QUICK"))
rate, features = 100.0, list(FEATURE_NAMES)
protocol = dict(
    n_train_per_setting=1 if quick else 2,
    n_validation=0,
    n_test=2,
    duration=60.0,
    sampling_rate=rate,
    random_state=0,
)

# %%
# The same protocol twice, same seeds: as recorded, and with the perturbation experiment in
# a third of the training recordings (``steering_perturbation``, the torque it applied, 0 in
# the others; the test recordings are never perturbed). The driver model reads
# :data:`~skhmmgmr.datasets.DRIVER_MODEL_FEATURES`: every sensed feature but the steering
# wheel's acceleration.
plain = make_driving_protocol(("defensive",), **protocol)
perturbed = make_driving_protocol(
    ("defensive",), perturbation=0.2, perturbed_share=1 / 3, **protocol
)
train, train_p = plain[plain["split"] == "train"], perturbed[perturbed["split"] == "train"]
test = plain[plain["split"] == "test"]

pipeline = make_torque_pipeline(5, sampling_period=1 / rate, random_state=0)
pipeline.fit(train[features], train["driver_torque"], groups=train["recording"])
driver = make_driver_model(sampling_period=1 / rate, random_state=0)
driver.fit(
    train_p[list(DRIVER_MODEL_FEATURES)],
    train_p["driver_torque"],
    groups=train_p["recording"],
    perturbation=train_p["steering_perturbation"],
)
for name, model in [("torque pipeline", pipeline), ("driver model", driver)]:
    columns = list(model.feature_names_in_)
    estimate = model.predict(test[columns], groups=test["recording"])
    accuracy = accuracy_score(test["driver_torque"], estimate, groups=test["recording"])
    print(f"{name}: {accuracy:.1f} % on the test recordings")

# %%
# At the wheel of a held-out road (setting 1, the sharpest radii), beside the human: the
# same road, the same sensor errors.
road = dict(setting=1, duration=60.0 if quick else 120.0, sampling_rate=rate, random_state=11)
runs = {"human (defensive)": drive("defensive", **road)}
with warnings.catch_warnings():
    warnings.simplefilter("ignore")  # a model that leaves the road says so
    runs["torque pipeline"] = drive(pipeline, **road)
    runs["driver model"] = drive(driver, **road)
human = lane_keeping_metrics(runs["human (defensive)"])
for name, frame in runs.items():
    metrics = lane_keeping_metrics(frame)
    ratio = metrics["lateral_deviation_rms"] / human["lateral_deviation_rms"]
    print(
        f"{name}: lateral deviation {metrics['lateral_deviation_rms']:.2f} m RMS "
        f"({ratio:.2f} x the human's), {int(metrics['departures'])} departures, "
        f"torque {metrics['torque_rms']:.2f} Nm RMS"
    )

fig, (top, bottom) = plt.subplots(2, 1, figsize=(9, 5.5), sharex=True)
for name, frame in runs.items():
    top.plot(frame["time"], frame["lateral_deviation_0m"], lw=1, label=name)
    bottom.plot(frame["time"], frame["driver_torque"], lw=1, label=name)
for limit in (-0.85, 0.85):
    top.axhline(limit, color="grey", ls=":", lw=1)
top.set_ylabel("lateral deviation [m]")
bottom.set_ylabel("driver torque [Nm]")
bottom.set_xlabel("time [s]")
top.legend(loc="upper right", fontsize=8)
top.set_title("The human and two models at the wheel of one road")
fig.tight_layout()
plt.show()
