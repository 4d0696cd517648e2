"""The FMU of ``skhmmgmr.export.write_fmu``: its size, the time per ``doStep`` and its difference
from ``predict``.

Three models fitted on the simulator's protocol (one driver style, 100 Hz): the torque
pipeline (K=8 over the 18 sensed inputs, 23 with the derived ones, velocity filter and
read-out chosen in ``fit``), an HMM-GMR of the road preview (K=5, 7 inputs) and the
hierarchical model on the same inputs (2 manoeuvres of 3 states, started from the flat
model). Each is written as an FMU for FMI 2.0 and 3.0 (compiled with ``cc -O2``), and:

- its size (bytes of the ``.fmu``);
- the time per communication step in C: a small importer written in C (``HARNESS`` below)
  loads the FMU's binary with ``dlopen``, instantiates it through the FMI functions and runs
  ``--samples`` steps of set inputs, ``doStep``, get the estimate, timed with
  ``clock_gettime`` (best of ``--rounds``), i.e. what a simulator that loads the FMU pays,
  without Python;
- beside it, the time per update of the same filter without the FMU, as
  ``bench_export.py`` times it (``write_c``'s code in a C loop), so that the difference is
  what the FMI layer costs;
- the time per step through FMPy (``setReal``/``setFloat64``, ``doStep``, ``getReal``, one
  Python call each, as a Python master pays it);
- the largest difference of the FMU's estimates and std from ``predict``, over the test
  recordings (one instance, reset between recordings), relative to ``|predict| +`` the
  output's standard deviation (the measure of the tests), and in Nm.

Run with::

    python benchmarks/bench_fmu.py
"""

import argparse
import ctypes
import shutil
import subprocess
import tempfile
import time
import warnings
from pathlib import Path

import fmpy
import numpy as np
from bench_export import compiled_loop, time_c
from sklearn.exceptions import ConvergenceWarning

from skhmmgmr import HierarchicalHMMGMRRegressor, HMMGMRRegressor, make_torque_pipeline
from skhmmgmr.datasets import FEATURE_NAMES, PREVIEW_FEATURES, make_driving_protocol
from skhmmgmr.export import write_fmu
from skhmmgmr.export._fmu import fmi_headers

HARNESS = r"""
#include <dlfcn.h>
#include <stdio.h>
#include <stdlib.h>
#include <time.h>
#include "fmiVFunctions.h"

#define LOAD(name) name##TYPE *name = (name##TYPE *)dlsym(library, #name)

static double now(void)
{
    struct timespec t;
    clock_gettime(CLOCK_MONOTONIC, &t);
    return t.tv_sec + 1e-9 * t.tv_nsec;
}

/* Seconds per step (set the inputs, doStep, get the estimate) over n samples, best of rounds. */
double run(const char *path, const char *token, int n_inputs, int n, const double *inputs,
           double period, int rounds, double *estimates)
{
    void *library = dlopen(path, RTLD_NOW | RTLD_LOCAL);
    unsigned int references[64], estimate = (unsigned int)n_inputs + 1;
    double best = 1e300;
    int i, t, r;
    if (library == NULL) {
        return -1.0;
    }
    for (i = 0; i < n_inputs; ++i) {
        references[i] = (unsigned int)i + 1;
    }
#if V == 2
    LOAD(fmi2Instantiate); LOAD(fmi2SetupExperiment); LOAD(fmi2EnterInitializationMode);
    LOAD(fmi2ExitInitializationMode); LOAD(fmi2SetReal); LOAD(fmi2DoStep); LOAD(fmi2GetReal);
    LOAD(fmi2Reset); LOAD(fmi2FreeInstance);
    fmi2CallbackFunctions callbacks = {0};
    fmi2Component c = fmi2Instantiate("bench", fmi2CoSimulation, token, "", &callbacks, 0, 0);
    for (r = 0; r < rounds; ++r) {
        double start;
        fmi2Reset(c);
        fmi2SetupExperiment(c, 0, 0.0, 0.0, 0, 0.0);
        fmi2EnterInitializationMode(c);
        fmi2ExitInitializationMode(c);
        start = now();
        for (t = 0; t < n; ++t) {
            fmi2SetReal(c, references, (size_t)n_inputs, inputs + (size_t)t * n_inputs);
            fmi2DoStep(c, t * period, period, 1);
            fmi2GetReal(c, &estimate, 1, estimates + t);
        }
        best = (now() - start) / n < best ? (now() - start) / n : best;
    }
    fmi2FreeInstance(c);
#else
    LOAD(fmi3InstantiateCoSimulation); LOAD(fmi3EnterInitializationMode);
    LOAD(fmi3ExitInitializationMode); LOAD(fmi3SetFloat64); LOAD(fmi3DoStep);
    LOAD(fmi3GetFloat64); LOAD(fmi3Reset); LOAD(fmi3FreeInstance);
    fmi3Instance c = fmi3InstantiateCoSimulation("bench", token, "", 0, 0, 0, 0, NULL, 0, NULL,
                                                 NULL, NULL);
    for (r = 0; r < rounds; ++r) {
        double start;
        fmi3Boolean event, terminate, early;
        fmi3Float64 last;
        fmi3Reset(c);
        fmi3EnterInitializationMode(c, 0, 0.0, 0.0, 0, 0.0);
        fmi3ExitInitializationMode(c);
        start = now();
        for (t = 0; t < n; ++t) {
            fmi3SetFloat64(c, references, (size_t)n_inputs, inputs + (size_t)t * n_inputs,
                           (size_t)n_inputs);
            fmi3DoStep(c, t * period, period, 1, &event, &terminate, &early, &last);
            fmi3GetFloat64(c, &estimate, 1, estimates + t, 1);
        }
        best = (now() - start) / n < best ? (now() - start) / n : best;
    }
    fmi3FreeInstance(c);
#endif
    return best;
}
"""


def _fit(model, data, inputs):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)
        return model.fit(data[inputs], data["driver_torque"], groups=data["recording"])


def models(train, period, n_iter):
    preview = list(PREVIEW_FEATURES)
    pipeline = make_torque_pipeline(8, sampling_period=period, n_iter=n_iter, random_state=0)
    regressor = HMMGMRRegressor(n_states=5, n_iter=n_iter, random_state=0)
    hierarchical = HierarchicalHMMGMRRegressor(
        manoeuvres=2, n_states=3, start="flat", n_iter=n_iter, refine_iter=3, random_state=0
    )
    return {
        "torque pipeline": _fit(pipeline, train, list(FEATURE_NAMES)),
        "regressor": _fit(regressor, train, preview),
        "hierarchical": _fit(hierarchical, train, preview),
    }


def harness(version, folder):
    """The C importer's ``run``, compiled against FMPy's headers."""
    source = Path(folder) / f"harness{version[0]}.c"
    source.write_text(HARNESS.replace("fmiV", f"fmi{version[0]}"))
    library = Path(folder) / f"libharness{version[0]}.so"
    command = [shutil.which("cc"), "-std=gnu99", "-O2", "-shared", "-fPIC", f"-DV={version[0]}"]
    command += [f"-I{fmi_headers()}", "-o", str(library), str(source), "-ldl"]
    subprocess.run(command, check=True)
    run = ctypes.CDLL(str(library)).run
    double_p = ctypes.POINTER(ctypes.c_double)
    run.argtypes = [ctypes.c_char_p, ctypes.c_char_p, ctypes.c_int, ctypes.c_int, double_p]
    run.argtypes += [ctypes.c_double, ctypes.c_int, double_p]
    run.restype = ctypes.c_double
    return run


class Instance:
    """One FMPy instance of an extracted FMU with the three calls of a step."""

    def __init__(self, folder, description, version):
        self.fmu = fmpy.instantiate_fmu(folder, description, fmi_type="CoSimulation")
        names = {v.name: v.valueReference for v in description.modelVariables}
        self.inputs = [
            v.valueReference for v in description.modelVariables if v.causality == "input"
        ]
        self.outputs = [names["driver_torque"], names["driver_torque_std"]]
        self.version = version
        if version == "2.0":
            self.set, self.get = self.fmu.setReal, self.fmu.getReal
        else:
            self.set, self.get = self.fmu.setFloat64, self.fmu.getFloat64

    def start(self):
        self.fmu.reset()
        if self.version == "2.0":
            self.fmu.setupExperiment(startTime=0.0)
            self.fmu.enterInitializationMode()
        else:
            self.fmu.enterInitializationMode(startTime=0.0)
        self.fmu.exitInitializationMode()

    def run(self, X, period):
        self.start()
        out = np.empty((len(X), 2))
        for t, row in enumerate(X.tolist()):
            self.set(self.inputs, row)
            self.fmu.doStep(currentCommunicationPoint=t * period, communicationStepSize=period)
            out[t] = self.get(self.outputs)
        return out


def measure(name, model, version, test, period, folder, runs, samples, rounds):
    file = Path(folder) / f"{name.replace(' ', '_')}{version[0]}.fmu"
    path = write_fmu(model, file, fmi_version=version, sampling_period=period)
    extracted = fmpy.extract(str(path), str(Path(folder) / f"x{name.replace(' ', '_')}{version}"))
    description = fmpy.read_model_description(extracted)
    inputs = [v.name for v in description.modelVariables if v.causality == "input"]
    scale = (model[-1] if hasattr(model, "steps") else model).model_.standardization.output_scale
    instance = Instance(extracted, description, version)
    relative, absolute = 0.0, 0.0
    for _, rows in test.groupby("recording", sort=False):
        X = rows[inputs].to_numpy()
        fmu = instance.run(X, period)
        expected = np.column_stack(model.predict(rows[inputs], return_std=True))
        relative = max(relative, float(np.max(np.abs(fmu - expected) / (np.abs(expected) + scale))))
        absolute = max(absolute, float(np.max(np.abs(fmu - expected))))
    X = np.ascontiguousarray(test[inputs].to_numpy()[:samples])
    start = time.perf_counter()
    instance.run(X, period)
    python_us = (time.perf_counter() - start) / len(X) * 1e6
    instance.fmu.terminate()
    instance.fmu.freeInstance()
    platform = fmpy.platform if version == "2.0" else fmpy.platform_tuple
    identifier = description.coSimulation.modelIdentifier
    binary = Path(extracted) / "binaries" / platform / f"{identifier}{fmpy.sharedLibraryExtension}"
    estimates = np.empty(len(X))
    per_step = runs[version](
        str(binary).encode(),
        description.guid.encode(),
        len(inputs),
        len(X),
        X.ctypes.data_as(ctypes.POINTER(ctypes.c_double)),
        period,
        rounds,
        estimates.ctypes.data_as(ctypes.POINTER(ctypes.c_double)),
    )
    expected = model.predict(test[inputs].iloc[: len(X)])
    assert np.max(np.abs(estimates - expected)) < 1e-9, "the C importer's estimates differ"
    loop = compiled_loop(model, folder, f"plain_{name.replace(' ', '_')}{version[0]}", "float64")
    plain_us, _ = time_c(loop, X, 1, rounds, with_std=False)
    return path.stat().st_size, per_step * 1e6, plain_us, python_us, relative, absolute


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rate", type=float, default=100.0)
    parser.add_argument("--duration", type=float, default=60.0, help="seconds per recording")
    parser.add_argument("--samples", type=int, default=5000, help="steps timed")
    parser.add_argument("--rounds", type=int, default=5)
    parser.add_argument("--n-iter", type=int, default=30)
    args = parser.parse_args()
    period = 1.0 / args.rate
    data = make_driving_protocol(
        ("defensive",),
        n_train_per_setting=1,
        n_validation=1,
        n_test=3,
        duration=args.duration,
        sampling_rate=args.rate,
        random_state=0,
    )
    train, test = data[data["split"] == "train"], data[data["split"] == "test"]
    fitted = models(train, period, args.n_iter)
    print(f"{len(test)} test rows in 3 recordings at {args.rate:g} Hz; {args.samples} steps timed")
    header = (
        f"{'model':>16} {'FMI':>4} {'inputs':>6} {'size [kB]':>9} {'C step [us]':>11} "
        f"{'write_c [us]':>12} {'FMPy step [us]':>14} {'max rel. diff':>13} "
        f"{'max diff [Nm]':>13}"
    )
    print(header)
    with tempfile.TemporaryDirectory() as folder:
        runs = {version: harness(version, folder) for version in ("2.0", "3.0")}
        for name, model in fitted.items():
            for version in ("2.0", "3.0"):
                size, c_us, plain_us, python_us, relative, absolute = measure(
                    name, model, version, test, period, folder, runs, args.samples, args.rounds
                )
                n_inputs = len(model.feature_names_in_)
                print(
                    f"{name:>16} {version:>4} {n_inputs:>6} {size / 1000:>9.1f} {c_us:>11.3f} "
                    f"{plain_us:>12.3f} {python_us:>14.1f} {relative:>13.1e} {absolute:>13.1e}"
                )


if __name__ == "__main__":
    main()
