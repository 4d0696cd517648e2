"""The FMU of a fitted model (``skhmmgmr.export.write_fmu``), checked as the FMI ecosystem checks
an FMU.

Three model kinds (a regressor of two outputs with its first-order read-out, the torque
pipeline with its velocity filter and read-out, the hierarchical model), each exported for FMI
2.0 and 3.0 and compiled with the system compiler. FMPy validates every FMU (the XML schema of
the standard, the variables, the model structure) and runs it as a co-simulation with
``simulate_fmu``, one recording after another on one instance reset in between; expectations
are ``predict`` on clean recordings and :class:`~skhmmgmr.FilterStream` on held samples, to
1e-10 of the output's scale. Two instances stepped in turn give each its own recording's
estimates. Recordings are short (8 s at 20 Hz) to keep the suite fast.
"""

import ctypes
import re
import runpy
import shutil
import subprocess
import sys
import warnings
import zipfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest
from sklearn.exceptions import ConvergenceWarning

from skhmmgmr import (
    HierarchicalHMMGMRRegressor,
    HMMGMRRegressor,
    make_driver_model,
    make_torque_pipeline,
)
from skhmmgmr.datasets import (
    DRIVER_MODEL_FEATURES,
    FEATURE_NAMES,
    FEATURE_UNITS,
    PREVIEW_FEATURES,
    drive,
    make_driving_protocol,
)
from skhmmgmr.export import write_fmu
from skhmmgmr.export._fmu_description import base_units

fmpy = pytest.importorskip("fmpy")
from fmpy.fmi1 import FMICallException  # noqa: E402
from fmpy.validation import validate_fmu  # noqa: E402

CC = shutil.which("cc")
pytestmark = pytest.mark.skipif(CC is None, reason="no C compiler (cc) on this machine")
PERIOD = 0.05
RTOL = 1e-10
VERSIONS = ("2.0", "3.0")
DRIVEN = {"sampling_period": PERIOD}
STRICT = ["-std=c99", "-O2", "-Wall", "-Wextra", "-Werror", "-pedantic", "-fPIC", "-shared"]
HEADERS = Path(fmpy.__file__).parent / "c-code"
ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def protocol():
    return make_driving_protocol(
        ("defensive",),
        n_train_per_setting=1,
        n_validation=1,
        n_test=1,
        duration=8.0,
        sampling_rate=1 / PERIOD,
        random_state=0,
    )


def _fit(model, data, inputs, target):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)
        return model.fit(data[inputs], data[target], groups=data["recording"])


# kind -> (model, inputs, target, write_fmu's keywords)
def _models(protocol):
    regressor = HMMGMRRegressor(n_states=4, n_iter=10, output_smoothing=3.0, random_state=0)
    pipeline = make_torque_pipeline(
        5, velocity_filter=0.2, sampling_period=PERIOD, n_iter=10, random_state=0
    )
    hierarchical = HierarchicalHMMGMRRegressor(
        manoeuvres=2, n_states=2, start="flat", n_iter=10, refine_iter=3, random_state=0
    )
    two_outputs = ["driver_torque", "yaw_rate"]
    sensed = list(FEATURE_NAMES[:4])
    return {
        "regressor": (
            _fit(regressor, protocol, sensed, two_outputs),
            sensed,
            {"sampling_period": PERIOD, "output_names": two_outputs},
        ),
        "pipeline": (_fit(pipeline, protocol, list(FEATURE_NAMES), "driver_torque"), None, {}),
        "hierarchical": (
            _fit(hierarchical, protocol, list(PREVIEW_FEATURES), "driver_torque"),
            None,
            {"sampling_period": PERIOD},
        ),
    }


@pytest.fixture(scope="module")
def models(protocol):
    return _models(protocol)


class Exported:
    """A model and its FMU, extracted (and its binary built by FMPy when it has none)."""

    def __init__(self, kind, version, model, path, outputs=("driver_torque",)):
        self.kind, self.version, self.model, self.path = kind, version, model, path
        self.folder = Path(fmpy.extract(str(path), str(path.with_suffix(""))))
        self.description = fmpy.read_model_description(str(self.folder))
        self.inputs = [v.name for v in self.description.modelVariables if v.causality == "input"]
        assert self.inputs == list(model.feature_names_in_)
        self.outputs = list(outputs)
        self.scale = _regressor(model).model_.standardization.output_scale

    def instantiate(self, logger=None, name="instance"):
        return fmpy.instantiate_fmu(
            str(self.folder),
            self.description,
            fmi_type="CoSimulation",
            logger=logger,
            **({} if logger is None else {"debug_logging": True}),
        )

    def signal(self, rows):
        """The structured input array of FMPy: one row per sample, the time first."""
        rows = np.asarray(rows, dtype=float)
        signal = np.zeros(len(rows), dtype=[("time", float)] + [(n, float) for n in self.inputs])
        signal["time"] = np.arange(len(rows)) * PERIOD
        for i, name in enumerate(self.inputs):
            signal[name] = rows[:, i]
        return signal

    def simulate(self, X, recordings):
        """One ``simulate_fmu`` per recording on one instance, reset between recordings.

        Returns the estimates, std, status and inputs the FMU sampled of every row (the
        outputs after the step from ``t`` to ``t + h`` are those of the sample at ``t``), and
        the outputs before each recording's first step.
        """
        X, recordings = np.asarray(X, dtype=float), np.asarray(recordings)
        instance = self.instantiate()
        starts = np.flatnonzero(np.r_[True, recordings[1:] != recordings[:-1]])
        names = [*self.outputs, *(n + "_std" for n in self.outputs), "update_status"]
        runs, before = [], []
        for start, stop in zip(starts, [*starts[1:], len(X)], strict=True):
            result = fmpy.simulate_fmu(
                str(self.folder),
                model_description=self.description,
                fmu_instance=instance,
                input=self.signal(X[start:stop]),
                start_time=0.0,
                stop_time=(stop - start) * PERIOD,
                output_interval=PERIOD,
                output=[*names, *self.inputs],
            )
            assert len(result) == stop - start + 1
            table = np.column_stack([result[n] for n in [*names, *self.inputs]])
            before.append(table[0])
            runs.append(table[1:])
            instance.reset()
        instance.freeInstance()
        table, n_outputs = np.vstack(runs), len(self.outputs)
        return Run(
            table[:, :n_outputs],
            table[:, n_outputs : 2 * n_outputs],
            table[:, 2 * n_outputs].astype(int),
            table[:, 2 * n_outputs + 1 :],
            [
                (row[:n_outputs], row[n_outputs : 2 * n_outputs], row[2 * n_outputs])
                for row in before
            ],
        )


@dataclass
class Run:
    """What ``Exported.simulate`` returns."""

    estimates: np.ndarray
    stds: np.ndarray
    codes: np.ndarray
    inputs: np.ndarray  # what the FMU sampled at every step
    before: list  # (estimates, stds, status) before every recording's first step


def _regressor(model):
    return model[-1] if hasattr(model, "steps") else model


def _difference(actual, expected, scale):
    """Largest difference relative to ``|expected| + scale`` (the output's standard scale)."""
    actual = np.asarray(actual, dtype=float)
    expected = np.reshape(np.asarray(expected, dtype=float), actual.shape)
    return float(np.max(np.abs(actual - expected) / (np.abs(expected) + scale)))


def _close(exported, actual, expected):
    error = _difference(actual, expected, exported.scale)
    assert error <= RTOL, f"{exported.kind}, FMI {exported.version}: {error}"


@pytest.fixture(
    scope="module",
    params=[(k, v) for k in ("regressor", "pipeline", "hierarchical") for v in VERSIONS],
    ids=lambda p: f"{p[0]}-fmi{p[1][0]}",
)
def exported(request, models, tmp_path_factory):
    kind, version = request.param
    model, _, keywords = models[kind]
    path = tmp_path_factory.mktemp(f"{kind}{version}") / f"{kind}.fmu"
    write_fmu(model, path, fmi_version=version, **keywords)
    return Exported(kind, version, model, path, keywords.get("output_names", ["driver_torque"]))


def test_fmpy_validates_the_fmu(exported):
    assert validate_fmu(str(exported.path)) == []
    description = exported.description
    assert description.fmiVersion == exported.version
    assert description.coSimulation.canHandleVariableCommunicationStepSize is False
    assert float(description.defaultExperiment.stepSize) == PERIOD
    names = {v.name: v for v in description.modelVariables}
    for name in exported.inputs:
        assert names[name].unit == FEATURE_UNITS.get(name)
        assert names[name].variability == "continuous"
    for name in exported.outputs:
        unit = {"driver_torque": "Nm", "yaw_rate": "rad/s"}[name]
        assert names[name].unit == names[name + "_std"].unit == unit
    assert names["update_status"].type in ("Integer", "Int32")
    outputs = [u.variable.name for u in description.outputs]
    assert outputs == [*exported.outputs, *(n + "_std" for n in exported.outputs), "update_status"]
    assert all(u.dependencies == [] for u in description.outputs)


def test_the_fmu_reproduces_predict_recording_after_recording(exported, protocol):
    inputs = exported.inputs
    X, groups = protocol[inputs], protocol["recording"]
    run = exported.simulate(X, groups)
    # FMPy interpolates the signal at the communication points: the samples, to round-off
    np.testing.assert_allclose(run.inputs, X, rtol=1e-13, atol=1e-300)
    expected, expected_std = exported.model.predict(X, groups=groups, return_std=True)
    assert not run.codes.any()
    _close(exported, run.estimates, expected)
    _close(exported, run.stds, expected_std)
    # before the first step of every recording (after every reset): the prior mixture's
    prior, prior_std = _regressor(exported.model).model_.prior_output()
    for estimate, std, code in run.before:
        _close(exported, estimate, prior)
        _close(exported, std, prior_std)
        assert code == -1
    # one recording for all rows (no reset): other estimates where the filter restarts
    merged = exported.simulate(X.iloc[:320], np.zeros(320))
    assert np.max(np.abs(merged.estimates - run.estimates[:320])) > 1e-6


@pytest.mark.filterwarnings("ignore:invalid value encountered:RuntimeWarning")  # FMPy's interp.
def test_held_samples_are_those_of_the_filter_stream(exported, protocol):
    inputs = exported.inputs
    first = protocol["recording"] == protocol["recording"].iloc[0]
    X = protocol.loc[first, inputs].to_numpy(copy=True)
    X[[0, 7, 40], 0] = np.nan
    X[12, -1] = np.inf
    X[[20, 21], 0] = 1e101  # out of the model's range (its cube still finite): held, code 2
    run = exported.simulate(X, np.zeros(len(X)))
    # expected: the stream on what the FMU sampled (FMPy's interpolation of the signal spreads
    # a NaN to the neighbouring communication point at times)
    assert np.isnan(run.inputs[[0, 7, 40], 0]).all()
    stream = exported.model.filter_stream()
    expected = [stream.update(row, return_std=True, return_flag=True) for row in run.inputs]
    flags = [flag for *_, flag in expected]
    code_of = {"ok": 0, "restarted": 0, "non-finite": 1, "outlier": 2}
    assert run.codes.tolist() == [code_of[f] for f in flags]
    assert {1, 2} <= set(run.codes.tolist())
    _close(exported, run.estimates, [e for e, _, _ in expected])
    _close(exported, run.stds, [s for _, s, _ in expected])


def _step_api(exported, instance):
    """(set inputs, do a step, read the estimates) of an instance, by FMI version."""
    variables = {v.name: v.valueReference for v in exported.description.modelVariables}
    inputs = [variables[n] for n in exported.inputs]
    outputs = [variables[n] for n in exported.outputs]
    if exported.version == "2.0":
        instance.setupExperiment(startTime=0.0)
        instance.enterInitializationMode()
        instance.exitInitializationMode()
        return (
            lambda row: instance.setReal(inputs, list(row)),
            lambda t: instance.doStep(currentCommunicationPoint=t, communicationStepSize=PERIOD),
            lambda: instance.getReal(outputs),
        )
    instance.enterInitializationMode(startTime=0.0)
    instance.exitInitializationMode()
    return (
        lambda row: instance.setFloat64(inputs, list(row)),
        lambda t: instance.doStep(currentCommunicationPoint=t, communicationStepSize=PERIOD),
        lambda: instance.getFloat64(outputs),
    )


def test_two_instances_side_by_side_are_independent(exported, protocol):
    inputs = exported.inputs
    recordings = protocol["recording"].unique()[:2]
    rows = [protocol.loc[protocol["recording"] == r, inputs] for r in recordings]
    instances = [exported.instantiate(), exported.instantiate()]
    apis = [_step_api(exported, instance) for instance in instances]
    results = [[], []]
    for t in range(len(rows[0])):  # in turn: a step of the first, then one of the second
        for which, (set_inputs, do_step, read) in enumerate(apis):
            set_inputs(rows[which].iloc[t])
            do_step(t * PERIOD)
            results[which].append(read())
    for which, instance in enumerate(instances):
        instance.terminate()
        instance.freeInstance()
        expected = exported.model.predict(rows[which])
        _close(exported, results[which], expected)


def test_a_step_of_another_size_is_refused_and_logged(exported, protocol):
    messages = []

    if exported.version == "2.0":

        def logger(environment, name, status, category, message):
            messages.append((status, category.decode(), message.decode()))
    else:

        def logger(environment, status, category, message):
            messages.append((status, category.decode(), message.decode()))

    instance = exported.instantiate(logger=logger)
    set_inputs, _, read = _step_api(exported, instance)
    set_inputs(protocol[exported.inputs].to_numpy()[0])
    before = read()
    for size in (2 * PERIOD, PERIOD / 10):
        with pytest.raises(FMICallException, match="failed with status 3"):
            instance.doStep(currentCommunicationPoint=0.0, communicationStepSize=size)
        status, category, text = messages[-1]
        assert status == 3 and category == "logStatusError"  # fmi2Error, fmi3Error
        assert f"a step of {size!r} s is refused" in text
        assert f"sampling period, {PERIOD!r} s" in text
        assert read() == before  # nothing changed
    # a step of the period within the master's rounding of the time is taken
    instance.doStep(currentCommunicationPoint=0.0, communicationStepSize=PERIOD * (1 + 1e-12))
    assert read() != before
    instance.terminate()
    instance.freeInstance()


def test_the_binary_exports_every_function_of_the_fmi_headers_and_nothing_else(exported):
    major = exported.version[0]
    header = (HEADERS / f"fmi{major}Functions.h").read_text()
    declared = set(re.findall(rf"FMI{major}_Export\s+(fmi{major}\w+)TYPE\s+fmi{major}\w+;", header))
    assert len(declared) == {"2": 44, "3": 75}[major]
    name = exported.description.coSimulation.modelIdentifier
    platform = fmpy.platform if exported.version == "2.0" else fmpy.platform_tuple
    binary = exported.folder / "binaries" / platform / f"{name}{fmpy.sharedLibraryExtension}"
    library = ctypes.CDLL(str(binary))
    assert all(hasattr(library, function) for function in declared)
    nm = shutil.which("nm")
    if nm is not None:
        listed = subprocess.run([nm, "-D", "--defined-only", str(binary)], capture_output=True)
        exported_names = {line.split()[-1] for line in listed.stdout.decode().splitlines()}
        assert exported_names == declared


def test_the_sources_build_warning_free_with_strict_flags(exported, tmp_path):
    sources = sorted((exported.folder / "sources").glob("*.c"))
    assert [p.name for p in sources] == sorted(f.name for f in sources)
    assert not list((exported.folder / "sources").glob("fmi*.h"))  # the importer's headers
    command = [CC, *STRICT, f"-I{HEADERS}", f"-I{exported.folder / 'sources'}"]
    command += ["-o", str(tmp_path / "strict.so"), *map(str, sources), "-lm"]
    result = subprocess.run(command, capture_output=True, text=True)
    assert result.returncode == 0, result.stderr


def test_fmi3_source_code_fmu_builds_from_its_build_description(models, protocol, tmp_path):
    build = pytest.importorskip("fmpy.build")
    if shutil.which("cmake") is None:
        pytest.skip("no cmake")
    model = models["pipeline"][0]
    path = write_fmu(model, tmp_path / "sources.fmu", fmi_version="3.0", binary=False)
    assert validate_fmu(str(path)) == []
    with zipfile.ZipFile(path) as archive:
        assert not [n for n in archive.namelist() if n.startswith("binaries/")]
        assert "sources/buildDescription.xml" in archive.namelist()
    exported = Exported("pipeline built by FMPy", "3.0", model, path)
    (tmp_path / "build").mkdir()
    build.build_platform_binary(exported.folder, build_dir=tmp_path / "build")
    rows = protocol["recording"] == protocol["recording"].iloc[0]
    X = protocol.loc[rows, exported.inputs]
    _close(exported, exported.simulate(X, np.zeros(len(X))).estimates, model.predict(X))


def test_the_same_model_gives_the_same_fmu(models, tmp_path):
    model, _, keywords = models["regressor"]
    first = write_fmu(model, tmp_path / "a.fmu", name="same", binary=False, **keywords)
    second = write_fmu(model, tmp_path / "b.fmu", name="same", binary=False, **keywords)
    assert first.read_bytes() == second.read_bytes()
    other = write_fmu(model, tmp_path / "c.fmu", binary=False, fmi_version="3.0", **keywords)
    token = re.compile(rb'(?:guid|instantiationToken)="(\{[-0-9a-f]+\})"')
    with zipfile.ZipFile(first) as a, zipfile.ZipFile(other) as c:
        assert token.search(a.read("modelDescription.xml")).group(1) != token.search(
            c.read("modelDescription.xml")
        ).group(1)
        assert a.namelist()[0] == "modelDescription.xml"


def test_units_given_complete_and_override_the_schemas(models, tmp_path):
    model, _, keywords = models["regressor"]
    units = {"driver_torque": "N.m", "steering_wheel_angle": "deg"}  # "deg": not readable
    path = write_fmu(model, tmp_path / "u.fmu", binary=False, units=units, **keywords)
    assert validate_fmu(str(path)) == []
    description = fmpy.read_model_description(str(path))
    declared = {v.name: v.unit for v in description.modelVariables}
    assert declared["driver_torque"] == declared["driver_torque_std"] == "N.m"
    assert declared["steering_wheel_angle"] is None  # a unit without base units: none
    assert declared["steering_wheel_velocity"] == "rad/s"  # the schema's
    definitions = {u.name: u.baseUnit for u in description.unitDefinitions}
    assert (definitions["N.m"].kg, definitions["N.m"].m, definitions["N.m"].s) == (1, 2, -2)


def test_refused_with_a_clear_error(models, tmp_path, monkeypatch):
    model, _, keywords = models["regressor"]
    pipeline = models["pipeline"][0]
    with pytest.raises(ValueError, match="sampling_period="):
        write_fmu(model, tmp_path / "m.fmu")
    with pytest.raises(ValueError, match="is not the period the model's SteeringFeatures"):
        write_fmu(pipeline, tmp_path / "m.fmu", sampling_period=0.01)
    for bad in (0, -1.0, float("nan"), float("inf"), "0.01", True):
        with pytest.raises(ValueError, match="'sampling_period' parameter of write_fmu"):
            write_fmu(model, tmp_path / "m.fmu", sampling_period=bad)
    for bad in ("1.0", 2.0):
        with pytest.raises(
            ValueError, match="'fmi_version' parameter of write_fmu must be a str among"
        ):
            write_fmu(model, tmp_path / "m.fmu", fmi_version=bad, **keywords)
    with pytest.raises(ValueError, match=r"\.fmu file"):
        write_fmu(model, tmp_path / "m.zip", **keywords)
    with pytest.raises(ValueError, match="2 non-empty name"):
        write_fmu(model, tmp_path / "m.fmu", sampling_period=PERIOD, output_names=["torque"])
    with pytest.raises(ValueError, match="two variables named 'yaw_std'"):
        write_fmu(
            model, tmp_path / "m.fmu", sampling_period=PERIOD, output_names=["yaw", "yaw_std"]
        )
    with pytest.raises(ValueError, match="two variables named 'steering_wheel_angle'"):
        write_fmu(
            model,
            tmp_path / "m.fmu",
            sampling_period=PERIOD,
            output_names=["steering_wheel_angle", "yaw_rate"],
        )
    with pytest.raises(ValueError, match=r"units names \['torque'\], which are neither"):
        write_fmu(model, tmp_path / "m.fmu", units={"torque": "Nm"}, **keywords)
    with pytest.raises(ValueError, match="C identifier"):
        write_fmu(model, tmp_path / "m.fmu", name="my-model", **keywords)
    (tmp_path / "taken.fmu").write_bytes(b"")
    with pytest.raises(FileExistsError, match="overwrite=True"):
        write_fmu(model, tmp_path / "taken.fmu", **keywords)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["taken.fmu"]
    # no compiler, no FMPy: said, and nothing written
    monkeypatch.setattr(shutil, "which", lambda name: None)
    with pytest.raises(RuntimeError, match="no 'cc' on the PATH.*binary=False"):
        write_fmu(model, tmp_path / "m.fmu", **keywords)
    monkeypatch.undo()
    monkeypatch.setattr("importlib.util.find_spec", lambda name: None)
    with pytest.raises(ImportError, match=r"pip install 'skhmmgmr\[fmu\]'"):
        write_fmu(model, tmp_path / "m.fmu", **keywords)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["taken.fmu"]
    # the stem as the model identifier
    path = write_fmu(model, tmp_path / "2-fast driver.fmu", binary=False, **keywords)
    with zipfile.ZipFile(path) as archive:
        assert "sources/fmu_2_fast_driver.c" in archive.namelist()


@pytest.mark.parametrize(
    "unit, expected",
    [
        ("rad", {"rad": 1}),
        ("rad/s^2", {"rad": 1, "s": -2}),
        ("1/m", {"m": -1}),
        ("Nm", {"kg": 1, "m": 2, "s": -2}),
        ("N.m/rad", {"kg": 1, "m": 2, "s": -2, "rad": -1}),
        ("m/s/s", None),
        ("furlong", None),
        ("", None),
    ],
)
def test_unit_texts_are_read_into_base_units(unit, expected):
    assert base_units(unit) == expected


def test_every_unit_of_the_schema_is_declared():
    assert all(base_units(unit) for unit in [*FEATURE_UNITS.values(), "Nm"])


def test_the_user_guide_example_runs_and_reproduces_predict(capsys, monkeypatch, tmp_path):
    monkeypatch.chdir(tmp_path)
    runpy.run_path(str(ROOT / "docs" / "user_guide" / "fmu_example.py"), run_name="__main__")
    printed = capsys.readouterr().out
    match = re.fullmatch(r"400 steps; largest difference from predict: (\S+) Nm\n", printed)
    assert match and float(match.group(1)) < 1e-9, printed
    assert list(tmp_path.iterdir()) == []  # the FMU was written in a temporary folder


# -- the FMU at the wheel of the simulator ----------------------------------------------------


@pytest.fixture(scope="module")
def preview_model(protocol):
    """A model of what the driver sees of the road, with its read-out: it keeps the lane."""
    model = HMMGMRRegressor(n_states=3, n_iter=10, output_smoothing=2.0, random_state=0)
    return _fit(model, protocol, list(PREVIEW_FEATURES), "driver_torque")


@pytest.mark.parametrize("version", VERSIONS)
def test_the_fmu_drives_as_the_model_it_was_written_from(preview_model, version, tmp_path):
    path = write_fmu(preview_model, tmp_path / "preview.fmu", fmi_version=version, **DRIVEN)
    settings = {"duration": 20.0, "sampling_rate": 1 / PERIOD, "random_state": 1}
    by_model = drive(preview_model, **settings)
    by_fmu = drive(path if version == "2.0" else str(path), **settings)
    assert by_model.attrs["lost_control"] is None and by_fmu.attrs["lost_control"] is None
    assert by_fmu["driver"].iloc[0] == "preview.fmu"
    assert by_fmu["recording"].iloc[0] == "preview.fmu-highway-s7"
    columns = [*FEATURE_NAMES, "driver_torque"]
    assert by_fmu.shape == by_model.shape
    np.testing.assert_allclose(by_fmu[columns], by_model[columns], rtol=1e-9, atol=1e-12)
    assert list(tmp_path.iterdir()) == [path]  # the extracted FMU removed


def test_the_pipelines_fmu_drives_as_the_pipeline(models, tmp_path):
    """The velocity filter and the read-out in the loop."""
    model = models["pipeline"][0]
    path = write_fmu(model, tmp_path / "pipeline.fmu")
    settings = {"duration": 6.0, "sampling_rate": 1 / PERIOD, "random_state": 1}
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        by_model, by_fmu = drive(model, **settings), drive(path, **settings)
    assert by_fmu.attrs["lost_control"] == by_model.attrs["lost_control"]
    assert len(caught) == 2 * (by_model.attrs["lost_control"] is not None)
    columns = [*FEATURE_NAMES, "driver_torque"]
    np.testing.assert_allclose(by_fmu[columns], by_model[columns], rtol=1e-9, atol=1e-12)


@pytest.fixture(scope="module")
def driver_model():
    """A driver model fitted on a perturbation experiment, and a test recording without one."""
    data = make_driving_protocol(
        ("defensive",),
        n_train_per_setting=1,
        n_validation=0,
        n_test=1,
        duration=8.0,
        sampling_rate=1 / PERIOD,
        random_state=0,
        perturbation=0.1,
    )
    train, test = data[data["split"] == "train"], data[data["split"] == "test"]
    inputs = list(DRIVER_MODEL_FEATURES)
    model = make_driver_model(velocity_filter=0.05, sampling_period=PERIOD, random_state=0)
    model.fit(
        train[inputs],
        train["driver_torque"],
        groups=train["recording"],
        perturbation=train["steering_perturbation"],
    )
    return model, test


@pytest.mark.parametrize("version", VERSIONS)
def test_the_driver_models_fmu_is_valid_and_reproduces_predict(driver_model, version, tmp_path):
    """The FMU of #46's last item: the driver model's (no perturbation among its inputs)."""
    model, test = driver_model
    path = write_fmu(model, tmp_path / "driver.fmu", fmi_version=version)
    assert validate_fmu(str(path)) == []
    exported = Exported("driver", version, model, path)
    assert exported.inputs == list(DRIVER_MODEL_FEATURES)
    X, groups = test[exported.inputs], test["recording"]
    run = exported.simulate(X, groups)
    expected, expected_std = model.predict(X, groups=groups, return_std=True)
    assert not run.codes.any()
    _close(exported, run.estimates, expected)
    _close(exported, run.stds, expected_std)


def test_drive_refuses_an_fmu_it_cannot_run(preview_model, protocol, tmp_path, monkeypatch):
    path = write_fmu(preview_model, tmp_path / "fast.fmu", sampling_period=0.01)
    with pytest.raises(ValueError, match=r"steps every 0.01 s .* sampling_rate=100.0"):
        drive(path, duration=2.0, sampling_rate=1 / PERIOD)
    renamed = protocol.rename(columns={"road_curvature_0m": "curvature"})
    inputs = ["curvature", *PREVIEW_FEATURES[3:]]
    unsensed = _fit(HMMGMRRegressor(n_states=2, n_iter=3), renamed, inputs, "driver_torque")
    other = write_fmu(unsensed, tmp_path / "other.fmu", sampling_period=PERIOD)
    with pytest.raises(ValueError, match=r"reads \['curvature'\], which the simulator does not"):
        drive(other, duration=2.0, sampling_rate=1 / PERIOD)
    with pytest.raises(FileNotFoundError, match="missing.fmu"):
        drive(tmp_path / "missing.fmu", duration=2.0, sampling_rate=1 / PERIOD)
    monkeypatch.setitem(sys.modules, "fmpy", None)
    with pytest.raises(ImportError, match=r"pip install 'skhmmgmr\[fmu\]'"):
        drive(str(path), duration=2.0, sampling_rate=100.0)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["fast.fmu", "other.fmu"]


# -- the command line -------------------------------------------------------------------------


def test_export_fmu_command_writes_the_fmu_of_a_model_file(protocol, tmp_path, capsys):
    from skhmmgmr.cli import main
    from skhmmgmr.portable import load

    data, model = tmp_path / "drives.csv", tmp_path / "model.json"
    inputs = list(PREVIEW_FEATURES[:3])
    protocol[["recording", "time", *inputs, "yaw_rate"]].to_csv(data, index=False)
    argv = ["--quiet", "fit", str(data), "--target", "yaw_rate", "--features", *inputs]
    assert main([*argv, "--n-states", "2", "--output", str(model)]) == 0
    path = tmp_path / "yaw model.fmu"
    assert main(["--quiet", "export-fmu", str(model), str(path), "--fmi-version", "3.0"]) == 0
    assert validate_fmu(str(path)) == []
    description = fmpy.read_model_description(str(path))
    assert description.fmiVersion == "3.0"
    assert description.coSimulation.modelIdentifier == "yaw_model"
    assert float(description.defaultExperiment.stepSize) == pytest.approx(PERIOD, rel=1e-12)
    outputs = {v.name: v.unit for v in description.modelVariables if v.causality == "output"}
    assert outputs == {"yaw_rate": "rad/s", "yaw_rate_std": "rad/s", "update_status": None}
    fitted = load(model)
    first = protocol[protocol["recording"] == protocol["recording"].iloc[0]]
    exported = Exported("command line", "3.0", fitted, path, ["yaw_rate"])
    _close(
        exported,
        exported.simulate(first[inputs], np.zeros(len(first))).estimates,
        fitted.predict(first[inputs]),
    )
    # refused: an existing file, a model without a sampling period, no FMPy
    assert main(["export-fmu", str(model), str(path)]) == 2
    assert "exists; pass --overwrite" in capsys.readouterr().err
    assert main(["--quiet", "export-fmu", str(model), str(path), "--overwrite"]) == 0
    argv = ["fit", str(data), "--target", "yaw_rate", "--features", *inputs, "--time", "none"]
    untimed = tmp_path / "untimed.json"
    assert main([*argv, "--n-states", "2", "--output", str(untimed), "--quiet"]) == 0
    assert main(["export-fmu", str(untimed), str(tmp_path / "u.fmu")]) == 2
    assert "pass sampling_period=" in capsys.readouterr().err
    argv = ["--quiet", "export-fmu", str(untimed), str(tmp_path / "u.fmu")]
    assert main([*argv, "--sampling-period", "0.05", "--sources-only"]) == 0
    assert validate_fmu(str(tmp_path / "u.fmu")) == []
