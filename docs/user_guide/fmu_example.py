"""The FMU of a fitted torque pipeline, run by FMPy (docs/user_guide/vehicle_simulator.rst).

Needs a C compiler (``cc``) and FMPy (``pip install 'skhmmgmr[fmu]'``); the tests run it.
"""

import tempfile
from pathlib import Path

import fmpy
import numpy as np
from fmpy.validation import validate_fmu

from skhmmgmr import make_torque_pipeline
from skhmmgmr.datasets import FEATURE_NAMES, make_lane_keeping
from skhmmgmr.export import write_fmu

period = 0.05  # seconds between two samples (20 Hz): the FMU's communication step
inputs = list(FEATURE_NAMES)
train = make_lane_keeping(60.0, sampling_rate=1 / period, random_state=0)
model = make_torque_pipeline(4, sampling_period=period, random_state=0)
model.fit(train[inputs], train["driver_torque"])

# a recording as FMPy's input signal: the time, then one column per input, by name
recording = make_lane_keeping(20.0, sampling_rate=1 / period, random_state=1)
signal = np.zeros(len(recording), dtype=[("time", float)] + [(name, float) for name in inputs])
signal["time"] = np.arange(len(recording)) * period
for name in inputs:
    signal[name] = recording[name]

with tempfile.TemporaryDirectory() as folder:
    path = write_fmu(model, Path(folder) / "driver.fmu", fmi_version="3.0")
    assert validate_fmu(str(path)) == []  # FMPy's checks of the standard: no problem
    result = fmpy.simulate_fmu(
        str(path),
        input=signal,
        stop_time=len(recording) * period,
        output_interval=period,  # one communication step per sample
    )

# the outputs after the step from t to t + period are the estimate of the sample at t
estimate = result["driver_torque"][1:]
difference = np.max(np.abs(estimate - model.predict(recording[inputs])))
print(f"{len(estimate)} steps; largest difference from predict: {difference:.1e} Nm")
