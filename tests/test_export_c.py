"""The generated C filter (``skhmmgmr.export.write_c``) against predict and FilterStream.

Every model is exported, compiled once with the system compiler (``-std=c99 -O2 -Wall -Wextra
-Werror -pedantic``, and ``-Wdouble-promotion`` for single precision) into a shared library
with a small loop over the samples, and run on simulated recordings, reset at every recording.
Expectations: ``predict`` (estimates and std), :class:`~skhmmgmr.FilterStream` on samples
``predict`` refuses (NaN, infinite, out of range), and for the torque pipeline
``SteeringFeatures.transform`` for the derived inputs, velocity filter included. The outlier
policy against predict on held-out recordings: ``tests/test_deployed_filters.py``.
"""

import ctypes
import re
import shutil
import subprocess
import warnings
from dataclasses import replace
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from sklearn.exceptions import ConvergenceWarning, NotFittedError
from sklearn.pipeline import Pipeline
from sklearn.preprocessing import StandardScaler

from skhmmgmr import (
    FilterStream,
    HMMGMRRegressor,
    SteeringFeatures,
    make_driver_model,
    make_torque_pipeline,
)
from skhmmgmr.datasets import DRIVER_MODEL_FEATURES, FEATURE_NAMES, make_driving_protocol
from skhmmgmr.export import write_c

CC = shutil.which("cc")
pytestmark = [
    pytest.mark.skipif(CC is None, reason="no C compiler (cc) on this machine"),
    pytest.mark.filterwarnings("ignore::sklearn.exceptions.ConvergenceWarning"),
]
FLAGS = ["-std=c99", "-O2", "-Wall", "-Wextra", "-Werror", "-pedantic"]
# single precision: no float silently promoted to double on the way
FLOAT32_FLAGS = [*FLAGS, "-Wdouble-promotion"]
ROOT = Path(__file__).resolve().parents[1]
EXAMPLE = ROOT / "docs" / "user_guide" / "export_c_example.c"
RTOL = 1e-10
FLOAT32_RTOL = 1e-5

LOOP = """
#include <stddef.h>
#include "NAME.h"

/* Filter n samples, reset where restart[t] is set. */
void run(int n, const NAME_real *inputs, const int *restart, NAME_real *estimates,
         NAME_real *stds, int *codes)
{
    NAME_state state;
    int t;
    NAME_reset(&state);
    for (t = 0; t < n; ++t) {
        if (restart[t]) {
            NAME_reset(&state);
        }
        codes[t] = NAME_update(&state, inputs + (size_t)t * NAME_n_inputs(),
                               estimates + (size_t)t * NAME_n_outputs(),
                               stds == NULL ? NULL : stds + (size_t)t * NAME_n_outputs());
    }
}
"""


class Compiled:
    """A generated filter compiled into a shared library; :meth:`run` filters recordings."""

    def __init__(self, fitted, folder, name="model", dtype="float64"):
        self.name = name
        self.paths = write_c(fitted, folder, name=name, dtype=dtype, overwrite=True)
        (folder / "loop.c").write_text(LOOP.replace("NAME", name))
        library = folder / f"lib{name}.so"
        self.real = ctypes.c_float if dtype == "float32" else ctypes.c_double
        flags = FLOAT32_FLAGS if dtype == "float32" else FLAGS
        command = [CC, *flags, "-shared", "-fPIC", "-o", str(library)]
        command += [str(self.paths[1]), str(folder / "loop.c"), "-lm"]
        result = subprocess.run(command, capture_output=True, text=True)
        assert result.returncode == 0, result.stderr
        self.library = ctypes.CDLL(str(library))
        self.n_inputs = self.function("n_inputs", ctypes.c_int)()
        self.n_outputs = self.function("n_outputs", ctypes.c_int)()

    def function(self, suffix, restype, *argtypes):
        function = getattr(self.library, f"{self.name}_{suffix}")
        function.restype, function.argtypes = restype, argtypes
        return function

    def run(self, X, recordings, std=True):
        """Estimates (n, n_outputs), std and return codes of the rows of ``X``."""
        real = np.float32 if self.real is ctypes.c_float else np.float64
        with np.errstate(over="ignore"):  # beyond float's range: inf, held as non-finite
            X = np.ascontiguousarray(X, dtype=real)
        n = X.shape[0]
        restart = np.r_[1, np.asarray(recordings)[1:] != np.asarray(recordings)[:-1]]
        restart = np.ascontiguousarray(restart, dtype=np.intc)
        estimates = np.empty((n, self.n_outputs), dtype=real)
        stds = np.empty((n, self.n_outputs), dtype=real) if std else None
        codes = np.empty(n, dtype=np.intc)
        real_p = ctypes.POINTER(self.real)
        int_p = ctypes.POINTER(ctypes.c_int)
        self.library.run(
            ctypes.c_int(n),
            X.ctypes.data_as(real_p),
            restart.ctypes.data_as(int_p),
            estimates.ctypes.data_as(real_p),
            stds.ctypes.data_as(real_p) if std else None,
            codes.ctypes.data_as(int_p),
        )
        return estimates.astype(float), None if stds is None else stds.astype(float), codes


@pytest.fixture(scope="module")
def protocol():
    data = make_driving_protocol(
        ("defensive",),
        n_train_per_setting=1,
        n_validation=1,
        n_test=1,
        duration=8.0,
        sampling_rate=20.0,
        random_state=0,
    )
    return data


def _fit(model, data, columns, target="driver_torque"):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)
        return model.fit(data[columns], data[target], groups=data["recording"])


def _close(actual, expected, scale, rtol=RTOL):
    """Largest difference relative to ``|expected| + scale`` (the output's standard scale)."""
    actual, expected = np.asarray(actual, dtype=float), np.asarray(expected, dtype=float)
    error = np.max(np.abs(actual - expected) / (np.abs(expected) + scale))
    assert error <= rtol, error
    return error


# (n_states, covariance_type, inputs, outputs, output_smoothing): K from 1 to 12, 1 to 18 raw
# inputs, the GMR estimate or the first-order read-out (3 rows; and 0.5 on the yaw rate)
REGRESSORS = {
    "k1-full": (1, "full", FEATURE_NAMES[:2], ["driver_torque"], None),
    "k3-tied": (3, "tied", FEATURE_NAMES[:4], ["driver_torque"], None),
    "k3-full-smoothed": (3, "full", FEATURE_NAMES[:4], ["driver_torque"], 3.0),
    "k5-full-2-outputs": (5, "full", FEATURE_NAMES[:3], ["driver_torque", "yaw_rate"], None),
    "k5-2-outputs-smoothed": (5, "full", FEATURE_NAMES[:3], ["driver_torque", "yaw_rate"], 3.0),
    "k12-full": (12, "full", FEATURE_NAMES[:10], ["driver_torque"], None),
    "k8-tied-18": (8, "tied", list(FEATURE_NAMES), ["driver_torque"], None),
}


@pytest.fixture(scope="module", params=sorted(REGRESSORS))
def regressor(request, protocol, tmp_path_factory):
    n_states, covariance_type, inputs, outputs, smoothing = REGRESSORS[request.param]
    model = HMMGMRRegressor(
        n_states=n_states,
        covariance_type=covariance_type,
        n_iter=15,
        output_smoothing=smoothing,
        random_state=0,
    )
    target = outputs[0] if len(outputs) == 1 else outputs
    model = _fit(model, protocol, list(inputs), target)
    if request.param == "k5-2-outputs-smoothed":  # another read-out per output
        decay = np.exp(-1.0 / np.array([3.0, 0.5]))
        model = HMMGMRRegressor.from_fitted_model(model.model_.with_output_decay(decay))
    folder = tmp_path_factory.mktemp(request.param)
    return model, list(inputs), Compiled(model, folder)


def test_the_c_filter_gives_the_estimates_and_std_of_predict(regressor, protocol):
    model, inputs, compiled = regressor
    X, groups = protocol[inputs], protocol["recording"]
    estimates, stds, codes = compiled.run(X, groups)
    expected, expected_std = model.predict(X, groups=groups, return_std=True)
    scale = model.model_.standardization.output_scale
    assert not codes.any()
    _close(estimates, np.reshape(expected, estimates.shape), scale)
    _close(stds, np.reshape(expected_std, stds.shape), scale)
    assert compiled.n_inputs == len(inputs)
    assert compiled.n_outputs == model.n_outputs_
    name = compiled.function("input_name", ctypes.c_char_p, ctypes.c_int)
    assert [name(i).decode() for i in range(len(inputs))] == inputs
    assert name(-1) is None and name(len(inputs)) is None


def _corrupted(X, rng):
    """``X`` with NaN, infinite and far outlying samples, a few at the start of recordings."""
    X = np.array(X, dtype=float)
    rows = rng.choice(np.arange(1, X.shape[0]), size=30, replace=False)
    X[rows[:8], 0] = np.nan
    X[rows[8:12], -1] = np.inf
    X[rows[12:20]] = X[rows[12:20]] * 1e6
    X[rows[20:24], 0] = 1e120  # the standardised inputs' absolute sum passes 1e100
    X[0, 0] = np.nan  # held before any accepted sample: the prior mixture
    X[1] = X[1] * 1e6
    return X


def test_held_samples_are_those_of_the_filter_stream(regressor, protocol):
    model, inputs, compiled = regressor
    X = _corrupted(protocol[inputs], np.random.default_rng(1))
    groups = protocol["recording"].to_numpy()
    estimates, stds, codes = compiled.run(X, groups)
    stream = FilterStream(model)
    expected, expected_std, flags = [], [], []
    for row, restart in zip(X, np.r_[True, groups[1:] != groups[:-1]], strict=True):
        if restart:
            stream.reset()
        estimate, std, flag = stream.update(row, return_std=True, return_flag=True)
        expected.append(estimate)
        expected_std.append(std)
        flags.append(flag)
    flags = np.array(flags)
    assert {"non-finite", "outlier"} <= set(flags)
    codes_of = {"ok": 0, "restarted": 0, "non-finite": 1, "outlier": 2}
    assert codes.tolist() == [codes_of[f] for f in flags]
    scale = model.model_.standardization.output_scale
    _close(estimates, np.reshape(expected, estimates.shape), scale)
    _close(stds, np.reshape(expected_std, stds.shape), scale)


def test_a_restart_from_the_input_densities_as_predict_does(tmp_path):
    # Two regimes that never follow each other (the identity as transition matrix) and whose
    # densities underflow far from them: a jump between them is impossible, and the filter
    # restarts from the input densities.
    rng = np.random.default_rng(0)
    low, high = rng.normal(-3, 0.05, size=(300, 1)), rng.normal(3, 0.05, size=(300, 1))
    X = np.vstack([low, high])
    y = np.where(X[:, 0] < 0, -1.0, 1.0) + X[:, 0] + rng.normal(scale=0.1, size=600)
    fitted = HMMGMRRegressor(n_states=2, random_state=0).fit(X, y, groups=np.repeat([0, 1], 300))
    model = HMMGMRRegressor.from_fitted_model(replace(fitted.model_, transmat=np.eye(2)))
    test = np.vstack([low[:20], high[:20], low[:20]])
    stream = model.filter_stream()
    flags = [stream.update(row, return_flag=True)[1] for row in test]
    assert flags.count("restarted") == 2
    estimates, stds, codes = Compiled(model, tmp_path).run(test, np.zeros(60))
    expected, expected_std = model.predict(test, return_std=True)
    assert not codes.any()
    _close(estimates[:, 0], expected, model.model_.standardization.output_scale)
    _close(stds[:, 0], expected_std, model.model_.standardization.output_scale)


def _compiled_is_predict(model, compiled, X, groups):
    """Check the compiled pipeline's estimates and std against predict's; the estimates."""
    estimates, stds, codes = compiled.run(X, groups)
    expected, expected_std = model.predict(X, groups=groups, return_std=True)
    scale = model[-1].model_.standardization.output_scale
    assert not codes.any()
    _close(estimates[:, 0], expected, scale)
    _close(stds[:, 0], expected_std, scale)
    return expected


@pytest.fixture(scope="module")
def pipeline(protocol, tmp_path_factory):
    """K=12 over the 18 sensed inputs and the derived ones (friction, hysteresis and load
    inputs, chosen in fit), velocity filter on."""
    model = make_torque_pipeline(
        12, velocity_filter=0.2, sampling_period=0.05, n_iter=10, random_state=0
    )
    model = _fit(model, protocol, list(FEATURE_NAMES))
    folder = tmp_path_factory.mktemp("pipeline")
    return model, Compiled(model, folder, name="torque")


def test_the_pipelines_derived_inputs_and_velocity_filter(pipeline, protocol):
    model, compiled = pipeline
    features = model[0]
    # the C filter's plays are tested here too
    assert features.friction_angle_ is not None and features.friction_velocity_ is not None
    # the friction basis of the velocity (and of the slow velocity, when chosen) and the plays
    slowed = 1 + (features.slow_velocity_filter_ is not None)
    n_friction = slowed * len(features.friction_velocity_) + len(features.friction_angle_)
    assert model[-1].n_features_in_ == len(FEATURE_NAMES) + n_friction + 4
    X, groups = protocol[list(FEATURE_NAMES)], protocol["recording"]
    expected = _compiled_is_predict(model, compiled, X, groups)
    # one recording for all rows: another velocity filter, other estimates
    merged, _, _ = compiled.run(X, np.zeros(len(X)))
    assert np.max(np.abs(merged[:, 0] - expected)) > 1e-6


def test_the_pipelines_held_samples_and_velocity_gaps(pipeline, protocol):
    model, compiled = pipeline
    features, regressor = model[0], model[-1]
    X = protocol[list(FEATURE_NAMES)].to_numpy(copy=True)
    groups = protocol["recording"].to_numpy()
    velocity = FEATURE_NAMES.index("steering_wheel_velocity")
    X[[5, 6, 7, 50, 300], velocity] = np.nan  # gaps the velocity filter bridges
    X[[9, 120], 0] = np.nan
    X[[30, 31], FEATURE_NAMES.index("yaw_rate")] = 1e120  # out of the model's range
    estimates, stds, codes = compiled.run(X, groups)
    derived = features.transform(pd.DataFrame(X, columns=FEATURE_NAMES), groups=groups)
    derived = derived.to_numpy()
    stream = FilterStream(regressor)
    expected, flags = [], []
    for row, restart in zip(derived, np.r_[True, groups[1:] != groups[:-1]], strict=True):
        if restart:
            stream.reset()
        estimate, std, flag = stream.update(row, return_std=True, return_flag=True)
        expected.append((estimate, std))
        flags.append(flag)
    assert codes[[5, 6, 7, 9, 50, 120, 300]].tolist() == [1] * 7
    assert codes[[30, 31]].tolist() == [2, 2]
    assert sum(codes != 0) == 9
    assert [f in ("non-finite", "outlier") for f in flags] == (codes != 0).tolist()
    scale = regressor.model_.standardization.output_scale
    _close(estimates[:, 0], [e for e, _ in expected], scale)
    _close(stds[:, 0], [s for _, s in expected], scale)


def test_the_driver_model_is_exported_as_the_pipeline_it_is(tmp_path):
    # make_driver_model's fit alone differs (the perturbation's penalty): its C filter gives
    # the estimates and std of its predict, and never reads the perturbation.
    data = make_driving_protocol(
        ("aggressive",),
        n_train_per_setting=1,
        n_validation=0,
        n_test=1,
        duration=8.0,
        sampling_rate=20.0,
        random_state=1,
        perturbation=0.1,
    )
    columns = list(DRIVER_MODEL_FEATURES)
    driver = make_driver_model(velocity_filter=0.05, sampling_period=0.05, random_state=0)
    driver.fit(
        data[columns],
        data["driver_torque"],
        groups=data["recording"],
        perturbation=data["steering_perturbation"],
    )
    compiled = Compiled(driver, tmp_path, name="driver")
    assert compiled.n_inputs == len(columns)
    _compiled_is_predict(driver, compiled, data[columns], data["recording"])


def test_float32_stays_close_to_predict(protocol, tmp_path):
    """Single precision: within FLOAT32_RTOL (1e-5) of ``|predict| + the output's scale``,
    4e-6 at most measured; NaN and infinite inputs held as in double precision."""
    inputs = list(FEATURE_NAMES[:6])
    model = _fit(HMMGMRRegressor(n_states=6, n_iter=15, random_state=0), protocol, inputs)
    compiled = Compiled(model, tmp_path, dtype="float32")
    assert "float alpha[6]" in compiled.paths[0].read_text()
    X, groups = protocol[inputs], protocol["recording"]
    estimates, stds, codes = compiled.run(X, groups)
    expected, expected_std = model.predict(X, groups=groups, return_std=True)
    scale = model.model_.standardization.output_scale
    assert not codes.any()
    _close(estimates[:, 0], expected, scale, FLOAT32_RTOL)
    _close(stds[:, 0], expected_std, scale, FLOAT32_RTOL)
    # held samples: those of double precision (float's range is narrower: the samples out
    # of range in double precision are held in float too, as non-finite); far samples
    # (1e6 times the data) are filtered by both, in float with float's round-off
    X = _corrupted(X, np.random.default_rng(2))
    held = Compiled(model, tmp_path, name="double").run(X, groups)
    estimates, stds, codes = compiled.run(X, groups)
    assert ((codes != 0) == (held[2] != 0)).all() and codes.any()
    assert np.isfinite(estimates).all() and np.isfinite(stds).all()


def test_float32_pipeline_is_single_precision_throughout(pipeline, protocol, tmp_path):
    """The float32 torque pipeline (derived inputs, velocity filter, read-out) builds with
    -Wdouble-promotion -Werror, calls no double-precision libm function, and stays within
    FLOAT32_RTOL of predict."""
    model, _ = pipeline
    compiled = Compiled(model, tmp_path, name="single", dtype="float32")
    source = compiled.paths[1].read_text()
    assert "double" not in source and "double" not in compiled.paths[0].read_text()
    X, groups = protocol[list(FEATURE_NAMES)], protocol["recording"]
    estimates, stds, codes = compiled.run(X, groups)
    expected, expected_std = model.predict(X, groups=groups, return_std=True)
    scale = model[-1].model_.standardization.output_scale
    assert not codes.any()
    _close(estimates[:, 0], expected, scale, FLOAT32_RTOL)
    _close(stds[:, 0], expected_std, scale, FLOAT32_RTOL)
    obj = tmp_path / "single.o"
    build = [CC, *FLOAT32_FLAGS, "-c", str(compiled.paths[1]), "-o", str(obj)]
    subprocess.run(build, check=True, capture_output=True)
    undefined = _undefined_symbols("nm", obj)
    assert not undefined & DOUBLE_LIBM, undefined
    assert "tanhf" in undefined and "expf" in undefined  # the friction input, the densities


# double-precision functions of math.h a single-precision filter must not call
DOUBLE_LIBM = frozenset(
    "exp exp2 expm1 log log2 log10 log1p tanh sinh cosh pow sqrt cbrt hypot fabs sin cos tan "  # noqa: SIM905
    "atan atan2 floor ceil fmod round lround trunc".split()
)


def _undefined_symbols(nm, obj):
    result = subprocess.run([nm, "-u", str(obj)], capture_output=True, text=True, check=True)
    return {line.split()[-1] for line in result.stdout.splitlines() if line.strip()}


ARM_GCC = shutil.which("arm-none-eabi-gcc")
CORTEX_M4F = ["-mcpu=cortex-m4", "-mthumb", "-mfloat-abi=hard", "-mfpu=fpv4-sp-d16"]


@pytest.mark.skipif(ARM_GCC is None, reason="no arm-none-eabi-gcc (Debian: gcc-arm-none-eabi)")
def test_float32_cross_compiles_for_a_cortex_m4f_without_double_routines(pipeline, tmp_path):
    """On a single-precision FPU a double operation is a software routine (``__aeabi_d*``):
    the float32 filter needs none, the float64 one does."""
    model, _ = pipeline
    symbols = {}
    for dtype in ("float32", "float64"):
        _, source = write_c(model, tmp_path / dtype, name="ecu", dtype=dtype)
        obj = tmp_path / f"{dtype}.o"
        flags = [*FLOAT32_FLAGS] if dtype == "float32" else [*FLAGS]
        command = [ARM_GCC, *flags, *CORTEX_M4F, "-c", str(source), "-o", str(obj)]
        result = subprocess.run(command, capture_output=True, text=True)
        assert result.returncode == 0, result.stderr
        symbols[dtype] = _undefined_symbols(shutil.which("arm-none-eabi-nm"), obj)
    assert not {s for s in symbols["float32"] if s.startswith("__aeabi_d")}, symbols["float32"]
    assert not symbols["float32"] & DOUBLE_LIBM
    assert {s for s in symbols["float64"] if s.startswith("__aeabi_d")}  # the check bites


def test_the_state_is_the_callers_and_the_api_is_as_documented(regressor):
    model, inputs, compiled = regressor
    header = compiled.paths[0].read_text()
    size = compiled.function("state_size", ctypes.c_size_t)()
    n_states, n_outputs = model.n_states, model.n_outputs_
    # alpha, prior, means, estimate (doubles) and the started flag
    assert size >= 8 * (2 * n_states + n_states * n_outputs + n_outputs) + 4
    for declaration in (
        "int         model_n_inputs(void);",
        "int         model_n_outputs(void);",
        "const char *model_input_name(int i);",
        "size_t      model_state_size(void);",
        "void        model_reset(model_state *state);",
        "int         model_update(model_state *state, const double *inputs,",
    ):
        assert declaration in header
    source = compiled.paths[1].read_text()
    assert "malloc" not in source and re.findall(r"#include <(\w+)\.h>", source) == [
        "math",
        "stddef",
    ]


def test_the_user_guide_program_reads_a_recording_and_prints_the_estimates(
    regressor, protocol, tmp_path
):
    model, inputs, _ = regressor
    header, source = write_c(model, tmp_path)  # the example's model name: the default
    program = tmp_path / "estimate"
    command = [CC, *FLAGS, f"-I{tmp_path}", "-o", str(program), str(EXAMPLE), str(source), "-lm"]
    result = subprocess.run(command, capture_output=True, text=True)
    assert result.returncode == 0, result.stderr
    data = protocol[["recording", *inputs]].iloc[::5]
    text = data.to_csv(index=False, float_format="%.17g")
    run = subprocess.run([str(program)], input=text, capture_output=True, text=True, check=True)
    lines = run.stdout.strip().splitlines()
    n_outputs = model.n_outputs_
    columns = [f"estimate_{o}" for o in range(n_outputs)] + [f"std_{o}" for o in range(n_outputs)]
    assert lines[0].split(",") == [*columns, "code"]
    values = np.array([[float(v) for v in line.split(",")] for line in lines[1:]])
    expected, expected_std = model.predict(data[inputs], groups=data["recording"], return_std=True)
    scale = model.model_.standardization.output_scale
    _close(values[:, :n_outputs], np.reshape(expected, (-1, n_outputs)), scale)
    _close(values[:, n_outputs:-1], np.reshape(expected_std, (-1, n_outputs)), scale)
    assert not values[:, -1].any()
    # a missing input: held, and said so
    broken = text.replace(
        text.splitlines()[3],
        text.splitlines()[3].split(",")[0] + ",nan" + "," * (len(inputs) - 1),
        1,
    )
    run = subprocess.run([str(program)], input=broken, capture_output=True, text=True, check=True)
    assert run.stdout.splitlines()[3].endswith(",1")


def test_the_user_guide_program_builds_against_the_float32_filter(protocol, tmp_path):
    inputs = list(FEATURE_NAMES[:3])
    model = _fit(HMMGMRRegressor(n_states=3, n_iter=10, random_state=0), protocol, inputs)
    _, source = write_c(model, tmp_path, dtype="float32")
    program = tmp_path / "estimate"
    command = [CC, *FLOAT32_FLAGS, f"-I{tmp_path}", "-o", str(program), str(EXAMPLE), str(source)]
    result = subprocess.run([*command, "-lm"], capture_output=True, text=True)
    assert result.returncode == 0, result.stderr
    data = protocol[["recording", *inputs]]
    text = data.to_csv(index=False, float_format="%.17g")
    run = subprocess.run([str(program)], input=text, capture_output=True, text=True, check=True)
    values = np.array([[float(v) for v in line.split(",")] for line in run.stdout.splitlines()[1:]])
    expected = model.predict(data[inputs], groups=data["recording"])
    _close(values[:, 0], expected, model.model_.standardization.output_scale, FLOAT32_RTOL)
    assert not values[:, -1].any()


def test_refused_at_export_time(protocol, tmp_path):
    inputs = list(FEATURE_NAMES[:2])
    with pytest.raises(NotFittedError, match="not fitted"):
        write_c(HMMGMRRegressor(), tmp_path)
    with pytest.raises(NotFittedError, match="not fitted"):
        write_c(make_torque_pipeline(2), tmp_path)
    marginalizing = _fit(
        HMMGMRRegressor(n_states=2, n_iter=5, missing_values="marginalize", random_state=0),
        protocol,
        inputs,
    )
    with pytest.raises(ValueError, match="missing_values='error' only.*'marginalize'"):
        write_c(marginalizing, tmp_path)
    model = _fit(HMMGMRRegressor(n_states=2, n_iter=5, random_state=0), protocol, inputs)
    scaled = Pipeline([("scale", StandardScaler()), ("hmmgmr", model)])
    with pytest.raises(ValueError, match=r"'scale' \(StandardScaler\) have no C form"):
        write_c(scaled, tmp_path)
    with pytest.raises(TypeError, match="HMMGMRRegressor"):
        write_c(StandardScaler(), tmp_path)
    with pytest.raises(TypeError, match="'name' parameter of write_c"):
        write_c(model, tmp_path, name=None)
    for name in ("", "2fast", "my-model", "_model", "modèle"):
        with pytest.raises(ValueError, match="C identifier"):
            write_c(model, tmp_path, name=name)
    with pytest.raises(ValueError, match="'float64' or 'float32'"):
        write_c(model, tmp_path, dtype="float16")
    for name in ("math", "stddef", "STDIO", "Time"):  # the file would hide <math.h>...
        with pytest.raises(ValueError, match=rf"hides the C standard header <{name.lower()}\.h>"):
            write_c(model, tmp_path, name=name)
    broken = HMMGMRRegressor.from_fitted_model(model.model_, min_log_density=0.0)
    broken.min_log_density = float("nan")  # set behind the constraints' back
    with pytest.raises(ValueError, match="'min_log_density' parameter of HMMGMRRegressor"):
        write_c(broken, tmp_path)
    assert list(tmp_path.iterdir()) == []
    alone = Pipeline([("hmmgmr", model)])
    assert [p.name for p in write_c(alone, tmp_path)] == ["skhmmgmr_model.h", "skhmmgmr_model.c"]


def _two_input_model():
    rng = np.random.default_rng(0)
    X = np.cumsum(rng.normal(size=(200, 2)), axis=0)
    return HMMGMRRegressor(n_states=2, n_iter=5, random_state=0).fit(X, X[:, 0] - X[:, 1]), X


def test_output_files_follow_the_packages_one_rule(tmp_path):
    """#51: a missing folder is created, existing files are refused unless overwrite=True,
    and a refused call writes nothing."""
    model, _ = _two_input_model()
    folder = tmp_path / "new" / "nested"
    header, source = write_c(model, folder, name="m")
    assert header == folder / "m.h" and source.read_text().startswith("/* m.c")
    with pytest.raises(FileExistsError, match=r"m\.h exists; overwrite=True to replace it"):
        write_c(model, folder, name="m")
    header.unlink()  # the source alone is enough to refuse: and the header is not written
    with pytest.raises(FileExistsError, match=r"m\.c exists"):
        write_c(model, folder, name="m")
    assert not header.exists()
    source.write_text("old")
    write_c(model, folder, name="m", overwrite=True)
    assert source.read_text().startswith("/* m.c") and header.exists()
    assert sorted(p.name for p in folder.iterdir()) == ["m.c", "m.h"]  # no temporary left
    (tmp_path / "file").write_text("")
    with pytest.raises(NotADirectoryError, match="directory"):
        write_c(model, tmp_path / "file", name="m")
    with pytest.raises(TypeError, match="'overwrite' parameter of write_c must be an instance of"):
        write_c(model, folder, name="m", overwrite="yes")


def test_a_planted_link_is_never_followed(tmp_path):
    """#51: the files are written through temporary files created exclusively at a random
    name, never through a name an attacker can predict and plant a link at."""
    model, _ = _two_input_model()
    outside = tmp_path / "outside.txt"
    outside.write_text("keep me")
    folder = tmp_path / "c"
    folder.mkdir()
    for planted in (".m.h.partial", ".m.c.partial", ".partial-m.h", ".partial-m.c"):
        (folder / planted).symlink_to(outside)
    write_c(model, folder, name="m")
    assert outside.read_text() == "keep me"
    assert (folder / "m.h").is_file() and not (folder / "m.h").is_symlink()
    assert "m_update" in (folder / "m.c").read_text()


def test_names_and_comments_that_would_break_a_pedantic_build(tmp_path):
    """#51: a feature name longer than the 4,095 characters of a C99 string literal, and
    "???/" that the comment sanitiser used to leave as the trigraph "??/" at a line wrap,
    build under -pedantic -Werror, and the names read back exactly."""
    _, X = _two_input_model()
    for first in ("a" * 5000, "w" * 60 + " ???/ tail", "??????/" * 30):
        names = [first, "yaw ??= rate ??/"]
        frame = pd.DataFrame(X, columns=names)
        model = HMMGMRRegressor(n_states=2, n_iter=5, random_state=0).fit(frame, X[:, 0])
        compiled = Compiled(model, tmp_path / str(len(first)), name="named")
        assert "??" not in compiled.paths[0].read_text()
        name = compiled.function("input_name", ctypes.c_char_p, ctypes.c_int)
        assert [name(i).decode() for i in range(2)] == names


def test_float32_refuses_parameters_single_precision_cannot_hold(tmp_path):
    """#51: a model in units beyond float's range was written with "inff" literals."""
    _, X = _two_input_model()
    model = HMMGMRRegressor(n_states=2, n_iter=5, random_state=0).fit(X * 1e39, X[:, 0])
    with pytest.raises(ValueError, match="input_center holds .*single precision cannot hold"):
        write_c(model, tmp_path, dtype="float32")
    assert list(tmp_path.iterdir()) == []
    Compiled(model, tmp_path, dtype="float64")  # double precision holds it


def test_input_names_are_escaped_c_strings(tmp_path):
    rng = np.random.default_rng(0)
    X = np.cumsum(rng.normal(size=(200, 2)), axis=0)
    names = ['angle "quoted" */ \\', "yaw rate °/s"]
    frame = pd.DataFrame(X, columns=names)
    model = HMMGMRRegressor(n_states=2, random_state=0).fit(frame, X[:, 0] - X[:, 1])
    compiled = Compiled(model, tmp_path)
    name = compiled.function("input_name", ctypes.c_char_p, ctypes.c_int)
    assert [name(i).decode("utf-8") for i in range(2)] == names
    features = SteeringFeatures(load_columns=(0,), friction_column=1, powers=(2, 5))
    pipe = Pipeline([("f", features), ("hmmgmr", HMMGMRRegressor(n_states=2, random_state=0))])
    pipe.fit(X, X[:, 0] - X[:, 1])
    compiled = Compiled(pipe, tmp_path, name="arrays")
    estimates, _, codes = compiled.run(X, np.zeros(200), std=False)
    assert not codes.any()
    _close(estimates[:, 0], pipe.predict(X), pipe[-1].model_.standardization.output_scale)
    name = compiled.function("input_name", ctypes.c_char_p, ctypes.c_int)
    assert [name(i).decode() for i in range(2)] == ["x0", "x1"]


def test_a_pipeline_ending_in_the_hierarchical_regressor(protocol, tmp_path):
    # its model_ is a flat HMM-GMR over all its states: the C filter is that of predict
    from sklearn.pipeline import make_pipeline

    from skhmmgmr import HierarchicalHMMGMRRegressor

    inputs = list(FEATURE_NAMES[:3])
    labels = np.where(protocol["steering_wheel_angle"] > 0, "left", "right")
    model = make_pipeline(
        SteeringFeatures(friction_velocity=None, load_columns=(), powers=()),
        HierarchicalHMMGMRRegressor(["left", "right"], n_states=[2, 1], random_state=0),
    )
    X, y, groups = protocol[inputs], protocol["driver_torque"], protocol["recording"]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)
        model.fit(
            X,
            y,
            hierarchicalhmmgmrregressor__groups=groups,
            hierarchicalhmmgmrregressor__manoeuvre=labels,
        )
    compiled = Compiled(model, tmp_path, name="hierarchy")
    _compiled_is_predict(model, compiled, X, groups)
