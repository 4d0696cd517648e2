"""
The torque model as a Functional Mock-up Unit
=============================================

Vehicle simulators load models made elsewhere as Functional Mock-up Units (FMUs, the FMI
standard). :func:`skhmmgmr.export.write_fmu` writes a fitted model as a co-simulation FMU: the
C filter of :func:`~skhmmgmr.export.write_c`, an FMI wrapper and a binary for this machine. This
example fits a torque pipeline on simulated drivers, writes its FMU for FMI 2.0 and 3.0, lets
FMPy check both, and runs them as a simulator would: one communication step per sample, the
sensed signals of a test recording as inputs. The FMU's torque is ``predict``'s, to round-off.
Then an FMU drives the package's simulator (:func:`~skhmmgmr.datasets.drive` takes an FMU as
its driver), on the same road as the model it was written from.

It needs a C compiler (``cc``) and FMPy (``pip install "skhmmgmr[fmu]"``). The user guide page
"Using the model in a vehicle simulator" describes the FMU's variables and how it steps.
"""

import os
import tempfile
from pathlib import Path

import fmpy
import matplotlib.pyplot as plt
import numpy as np
import pandas as pd
from fmpy.validation import validate_fmu

from skhmmgmr import HMMGMRRegressor, make_torque_pipeline
from skhmmgmr.datasets import FEATURE_NAMES, PREVIEW_FEATURES, drive, make_driving_protocol
from skhmmgmr.export import write_fmu
from skhmmgmr.metrics import lane_keeping_metrics

quick = bool(os.environ.get("SKHMMGMR_DOCS_QUICK"))
rate = 20.0
period = 1.0 / rate
inputs = list(FEATURE_NAMES)

# %%
# A torque pipeline on simulated drivers
# --------------------------------------
# The pipeline knows its sampling period (``sampling_period``): it is the FMU's communication
# step, the only one the FMU accepts.
data = make_driving_protocol(
    ("defensive", "aggressive"),
    n_train_per_setting=1,
    n_validation=1,
    n_test=1,
    duration=30.0 if quick else 90.0,
    sampling_rate=rate,
    random_state=0,
)
train, test = data[data["split"] == "train"], data[data["split"] == "test"]
model = make_torque_pipeline(4 if quick else 8, sampling_period=period, random_state=0)
model.fit(train[inputs], train["driver_torque"], groups=train["recording"])
recording = test[test["recording"] == test["recording"].iloc[0]]

# %%
# The FMU, for both versions of the standard
# ------------------------------------------
# FMPy validates the model description of each (the XML schema of the standard, the
# variables, the model structure) and runs the FMU with the recording as its input signal.
signal = np.zeros(len(recording), dtype=[("time", float)] + [(name, float) for name in inputs])
signal["time"] = np.arange(len(recording)) * period
for name in inputs:
    signal[name] = recording[name]
results = {}
with tempfile.TemporaryDirectory() as folder:
    for version in ("2.0", "3.0"):
        path = write_fmu(model, Path(folder) / f"driver{version[0]}.fmu", fmi_version=version)
        problems = validate_fmu(str(path))
        size = path.stat().st_size / 1000
        print(f"FMI {version}: {size:.0f} kB, validation problems: {problems}")
        results[version] = fmpy.simulate_fmu(
            str(path), input=signal, stop_time=len(recording) * period, output_interval=period
        )
    description = fmpy.read_model_description(str(path))
for variable in description.modelVariables:
    if variable.causality == "output":
        print(f"output {variable.name!r} [{variable.unit or '-'}]: {variable.description}")

# %%
# The FMU's torque is predict's
# -----------------------------
# The outputs after the step from ``t`` to ``t + period`` are the estimate of the sample at
# ``t``: the FMU's first output row is the prior, before any sample.
expected, expected_std = model.predict(recording[inputs], return_std=True)
time = recording["time"].to_numpy()
fig, (top, bottom) = plt.subplots(2, 1, figsize=(8, 5.5), sharex=True)
top.plot(time, recording["driver_torque"], color="0.6", lw=1, label="measured")
top.plot(time, expected, lw=2, label="predict")
for version, style in (("2.0", "--"), ("3.0", ":")):
    estimate = results[version]["driver_torque"][1:]
    top.plot(time, estimate, style, lw=1.5, label=f"FMU, FMI {version}")
    difference = estimate - expected
    bottom.plot(time, difference, style, label=f"FMI {version}")
    std_difference = np.max(np.abs(results[version]["driver_torque_std"][1:] - expected_std))
    print(
        f"FMI {version}: largest difference from predict {np.max(np.abs(difference)):.1e} Nm, "
        f"of the std {std_difference:.1e} Nm"
    )
top.fill_between(
    time, expected - 2 * expected_std, expected + 2 * expected_std, alpha=0.15, label="±2 std"
)
top.set_ylabel("driver torque [Nm]")
top.legend(ncol=3, fontsize=8)
bottom.set_ylabel("FMU - predict [Nm]")
bottom.set_xlabel("time [s]")
bottom.legend(fontsize=8)
fig.tight_layout()
plt.show()

# %%
# The FMU at the wheel
# --------------------
# A model of what the driver sees of the road (the lane position, the heading and the
# curvature ahead) keeps the lane in the closed loop, where models of the steering system's own
# states do not (user guide, "Closed loop"). Its FMU, run by :func:`~skhmmgmr.datasets.drive`
# through FMPy, drives the same road with the same sensor errors as the Python model, sample
# for sample.
preview = list(PREVIEW_FEATURES)
driver = HMMGMRRegressor(n_states=3, output_smoothing="auto", random_state=0)
driver.fit(train[preview], train["driver_torque"], groups=train["recording"])
settings = {"duration": 30.0 if quick else 120.0, "sampling_rate": rate, "random_state": 1}
with tempfile.TemporaryDirectory() as folder:
    path = write_fmu(driver, Path(folder) / "preview.fmu", sampling_period=period)
    by_fmu = drive(path, **settings)
by_model = drive(driver, **settings)
human = drive("defensive", **settings)
columns = [*FEATURE_NAMES, "driver_torque"]
largest = np.max(np.abs(by_fmu[columns].to_numpy() - by_model[columns].to_numpy()))
print(f"the FMU's drive against the model's: largest difference {largest:.1e}")
print(
    lane_keeping_metrics(pd.concat([human, by_model, by_fmu]))[
        ["lateral_deviation_rms", "departures", "torque_rms"]
    ]
)
fig, ax = plt.subplots(figsize=(8, 3))
for frame, style, label in (
    (human, "-", "human (defensive)"),
    (by_model, "-", "model"),
    (by_fmu, ":", "its FMU"),
):
    ax.plot(frame["time"], frame["lateral_deviation_0m"], style, lw=1.5, label=label)
ax.set_xlabel("time [s]")
ax.set_ylabel("lateral deviation [m]")
ax.legend(fontsize=8)
fig.tight_layout()
plt.show()
