"""Tests of the embedded lane-keeping simulator and the driving protocol."""

import ast
import dataclasses
import functools
import inspect
from collections import Counter
from pathlib import Path

import joblib
import numpy as np
import pandas as pd
import pytest

from skhmmgmr import HMMGMRRegressor
from skhmmgmr._core._schema import META_COLUMNS
from skhmmgmr.datasets import (
    CALIBRATION_BANDS,
    DRIVER_STYLES,
    FEATURE_NAMES,
    FEATURE_UNITS,
    TARGET,
    DriverParameters,
    calibration_table,
    draw_vehicle,
    drive,
    make_driving_protocol,
    make_lane_keeping,
    torque_ahead,
)
from skhmmgmr.datasets._simulator._lane_keeping import human_run
from skhmmgmr.datasets._simulator._protocol import protocol_runs, protocol_sections
from skhmmgmr.datasets._simulator._road import (
    ANGLES,
    CLOTHOID_LENGTH,
    GRID_STEP,
    SETTINGS,
    SHARP_CORNER_RADII,
    STRAIGHT_LENGTHS,
    _cumulative_trapezoid,
    make_road,
    step_curvature,
)
from skhmmgmr.datasets._simulator._section import Section, SectionSpec

SPEED = 100.0 / 3.6


@pytest.fixture(scope="module")
def corner_drive():
    """One minute of sharp corners (setting 1) in true states, shared by the physics tests."""
    return make_lane_keeping(60.0, setting=1, random_state=3, sensor_noise=None)


@pytest.fixture(scope="module")
def calibration_drives():
    """One 5-minute setting-7 section per style (speed is measured in benchmarks/)."""
    return {
        style: make_lane_keeping(300.0, driver=style, setting=7, random_state=0)
        for style in DRIVER_STYLES
    }


def test_same_seed_same_frame():
    first = make_lane_keeping(5.0, driver="novice", random_state=42)
    second = make_lane_keeping(5.0, driver="novice", random_state=42)
    pd.testing.assert_frame_equal(first, second)
    other = make_lane_keeping(5.0, driver="novice", random_state=43)
    assert not np.allclose(first[TARGET], other[TARGET])


def test_columns_units_and_sampling():
    frame = make_lane_keeping(2.0, sampling_rate=50.0, random_state=0, recording="r", split="test")
    assert list(frame.columns) == [*META_COLUMNS, *FEATURE_NAMES, TARGET]
    assert frame.shape == (100, 26)
    np.testing.assert_allclose(frame["time"], np.arange(100) / 50.0)
    assert frame.attrs["units"] == {
        "time": "s",
        "crossing_time": "s",
        **FEATURE_UNITS,
        TARGET: "Nm",
    }
    assert set(frame["recording"]) == {"r"} and set(frame["split"]) == {"test"}
    assert set(frame["driver"]) == {"defensive"} and set(frame["setting"]) == {7}
    assert np.isfinite(frame[[*FEATURE_NAMES, TARGET]].to_numpy()).all()


@pytest.mark.parametrize("setting", sorted(SETTINGS))
def test_road_elements_follow_table_b1(setting):
    road = make_road(8000.0, setting=setting, random_state=np.random.RandomState(setting))
    arcs = [e for e in road.elements if e["kind"] == "arc"]
    straights = [e for e in road.elements if e["kind"] == "straight"]
    radii = [e["radius"] for e in arcs]
    assert set(radii) <= set(SETTINGS[setting][1])
    assert all(r % 100 == 0 for r in radii)
    assert {e["angle"] for e in arcs} <= set(ANGLES)
    assert {e["length"] for e in straights} <= set(STRAIGHT_LENGTHS)
    for element in arcs:
        assert element["length"] == pytest.approx(element["radius"] * np.radians(element["angle"]))
    # balanced: counts differ by at most one (plus the unfinished last round)
    for counts in (
        Counter(e["direction"] for e in road.elements),
        Counter(radii),
        Counter(e["angle"] for e in arcs),
    ):
        assert max(counts.values()) - min(counts.values()) <= 2
    assert len(Counter(radii)) == len(SETTINGS[setting][1])


def test_road_curvature_is_continuous_and_keeps_the_heading():
    road = make_road(6000.0, setting=7, random_state=np.random.RandomState(0))
    # a linear ramp over CLOTHOID_LENGTH between at most +-1/300
    max_step = 2.0 / 300.0 * GRID_STEP / CLOTHOID_LENGTH
    assert np.abs(np.diff(road.curvature)).max() <= max_step * 1.05
    step_heading = _cumulative_trapezoid(step_curvature(road.elements, road.s.size), GRID_STEP)
    # exact wherever the step curvature is constant over the ramp length around the point
    long_elements = [e for e in road.elements[:-1] if e["length"] > CLOTHOID_LENGTH + 1.0]
    assert len(long_elements) > 10
    for element in long_elements:
        middle = int((element["start"] + element["length"] / 2) / GRID_STEP)
        assert road.heading[middle] == pytest.approx(step_heading[middle], abs=2e-3)


def test_sharp_corner_scenario_radii():
    road = make_road(4000.0, scenario="sharp_corners", random_state=np.random.RandomState(0))
    radii = {e["radius"] for e in road.elements if e["kind"] == "arc"}
    assert radii <= set(SHARP_CORNER_RADII) and min(radii) < 300


def test_slip_angle_is_lateral_velocity_over_speed(corner_drive):
    np.testing.assert_allclose(
        corner_drive["slip_angle"], corner_drive["lateral_velocity"] / SPEED, atol=1e-6
    )


def test_vehicle_physics_is_consistent(corner_drive):
    frame = corner_drive
    dt = 0.01
    yaw_rate = frame["yaw_rate"].to_numpy()
    a_y = frame["lateral_acceleration"].to_numpy()
    # in the middle of steady corners, yaw rate = speed * curvature
    steady = (frame["road_curvature_0m"].abs() > 1 / 700) & (
        (frame["road_curvature_0m"] - frame["road_curvature_30m"]).abs() < 1e-5
    )
    assert steady.sum() > 500
    ratio = yaw_rate[steady].mean() / (SPEED * frame.loc[steady, "road_curvature_0m"].mean())
    assert 0.85 < ratio < 1.15
    # lateral acceleration = speed * yaw rate + dv/dt, dominated by the first term
    assert np.corrcoef(a_y, SPEED * yaw_rate)[0, 1] > 0.98
    # derivatives come from the model and agree with the logged signals
    for signal, rate in [
        ("steering_wheel_angle", "steering_wheel_velocity"),
        ("yaw_rate", "yaw_acceleration"),
        ("roll_angle", "roll_velocity"),
        ("steering_wheel_velocity", "steering_wheel_acceleration"),
    ]:
        numeric = np.gradient(frame[signal].to_numpy(), dt)
        assert np.corrcoef(numeric, frame[rate])[0, 1] > 0.9, rate
    # the body rolls outwards (positive roll in a left turn, y to the left)
    assert np.corrcoef(frame["roll_angle"], a_y)[0, 1] > 0.9
    # steering, torque and curvature all share the sign convention
    assert np.corrcoef(frame["steering_wheel_angle"], frame["road_curvature_0m"])[0, 1] > 0.9
    assert np.corrcoef(frame[TARGET], frame["steering_wheel_angle"])[0, 1] > 0.8
    # the road ahead turns away from the vehicle heading by about curvature * distance
    heading_change = frame["heading_deviation_0m"] - frame["heading_deviation_30m"]
    assert np.corrcoef(heading_change, frame["road_curvature_10m"])[0, 1] > 0.95


def test_calibration_bands_per_style(calibration_drives):
    frames = calibration_drives
    table = calibration_table(pd.concat(frames.values()))
    assert list(table["driver"]) == list(DRIVER_STYLES)
    for style, row in table.set_index("driver").iterrows():
        for kpi, (low, high) in CALIBRATION_BANDS.items():
            assert low <= row[kpi] <= high, (style, kpi, row[kpi])
        # the vehicle centre never leaves the centre lane
        assert np.abs(frames[style]["lateral_deviation_0m"]).max() < 1.75
    # Table C.2: the aggressive driver needs less torque and angle, deviates more
    by_style = table.set_index("driver")
    assert by_style.loc["aggressive", "rms_torque"] < by_style.loc["defensive", "rms_torque"]
    assert (
        by_style.loc["aggressive", "max_steering_wheel_angle"]
        < by_style.loc["defensive", "max_steering_wheel_angle"]
    )
    # the novice corrects in jerks
    assert (
        by_style.loc["novice", "rms_steering_wheel_velocity"]
        > 1.3 * by_style.loc["defensive", "rms_steering_wheel_velocity"]
    )


def test_calibration_table_by_driver():
    frame = pd.concat(
        [
            make_lane_keeping(3.0, driver="defensive", random_state=0, recording="a"),
            make_lane_keeping(3.0, driver="defensive", random_state=1, recording="b"),
        ]
    )
    assert list(calibration_table(frame).index) == ["a", "b"]
    pooled = calibration_table(frame, by="driver")
    assert list(pooled.index) == ["defensive"]
    expected = np.sqrt(np.mean(frame[TARGET] ** 2))
    assert pooled.loc["defensive", "rms_torque"] == pytest.approx(expected)
    with pytest.raises(ValueError, match="by"):
        calibration_table(frame, by="split")


@pytest.mark.parametrize(
    "scenario, kpi",
    [
        ("sharp_corners", "rms_torque"),
        ("lane_change", "rms_lateral_deviation"),
        ("evasive", "max_torque"),
    ],
)
def test_stress_scenarios_are_harder(scenario, kpi):
    kwargs = dict(duration=120.0, driver="defensive", random_state=5)
    base = calibration_table(make_lane_keeping(scenario="highway", **kwargs))
    stress = calibration_table(make_lane_keeping(scenario=scenario, **kwargs))
    assert stress[kpi].iloc[0] > 1.2 * base[kpi].iloc[0]


def test_custom_driver_parameters():
    slow = DRIVER_STYLES["defensive"].__class__(
        **{**DRIVER_STYLES["defensive"].__dict__, "reaction_time": 0.4, "variability": 0.0}
    )
    assert isinstance(slow, DriverParameters)
    frame = make_lane_keeping(3.0, driver=slow, random_state=0)
    assert set(frame["driver"]) == {"custom"}


def test_protocol_shape_and_ids():
    frame = make_driving_protocol(
        ("defensive", "aggressive"),
        n_train_per_setting=1,
        n_validation=2,
        n_test=1,
        duration=2.0,
        sampling_rate=20.0,
        random_state=0,
        sensor_noise=None,
    )
    recordings = frame.groupby("recording", sort=False)
    assert recordings.ngroups == 2 * (6 + 2 + 1)
    assert len(frame) == recordings.ngroups * 40
    first = recordings.first()
    counts = first.groupby(["driver", "split"]).size().unstack()
    assert (counts["train"] == 6).all() and (counts["validation"] == 2).all()
    assert (counts["test"] == 1).all()
    assert set(first.loc[first["split"] == "train", "setting"]) == {1, 2, 3, 4, 5, 6}
    assert set(first.loc[first["split"] != "train", "setting"]) == {7}
    assert "defensive-train-s1-0" in first.index and "aggressive-test-s7-0" in first.index
    # contiguous, time ordered recordings
    ids = frame["recording"].to_numpy()
    assert (ids[1:] != ids[:-1]).sum() == recordings.ngroups - 1
    for _, group in recordings:
        assert group["time"].iloc[0] == 0.0 and (np.diff(group["time"]) > 0).all()
    # every driver drives the same road sections
    road = frame.set_index(["recording", "time"])["road_curvature_30m"]
    np.testing.assert_array_equal(
        road["defensive-validation-s7-1"], road["aggressive-validation-s7-1"]
    )
    assert frame.attrs["units"][TARGET] == "Nm"


def test_protocol_parallel_matches_serial():
    kwargs = dict(n_train_per_setting=1, n_validation=1, n_test=0, duration=1.0, random_state=1)
    serial = make_driving_protocol(("novice",), **kwargs)
    parallel = make_driving_protocol(("novice",), n_jobs=2, **kwargs)
    pd.testing.assert_frame_equal(serial, parallel)


def test_disk_cache(tmp_path):
    first = make_lane_keeping(2.0, random_state=7, cache=tmp_path)
    assert any(tmp_path.rglob("*.pkl"))
    second = make_lane_keeping(2.0, random_state=7, cache=joblib.Memory(tmp_path, verbose=0))
    pd.testing.assert_frame_equal(first, second)
    with pytest.raises(ValueError, match="cache"):
        make_lane_keeping(2.0, random_state=7, cache=3)


@pytest.mark.parametrize(
    "kwargs, name",
    [
        (dict(driver="reckless"), "driver"),
        (dict(setting=0), "setting"),
        (dict(setting=8), "setting"),
        (dict(setting=2.0), "setting"),
        (dict(duration=0.0), "duration"),
        (dict(duration=-5.0), "duration"),
        (dict(sampling_rate=0.0), "sampling_rate"),
        (dict(speed_kmh=-1.0), "speed_kmh"),
        (dict(scenario="city"), "scenario"),
    ],
)
def test_bad_parameters_name_the_parameter(kwargs, name):
    kwargs = {"duration": 1.0, **kwargs}
    with pytest.raises(ValueError, match=name):
        make_lane_keeping(**kwargs)


@pytest.mark.parametrize(
    "kwargs, name",
    [
        (dict(drivers=("defensive", "reckless")), "drivers"),
        (dict(drivers=()), "drivers"),
        (dict(n_validation=-1), "n_validation"),
        (dict(n_train_per_setting=1.5), "n_train_per_setting"),
        (dict(n_train_per_setting=0, n_validation=0, n_test=0), "no section"),
    ],
)
def test_bad_protocol_parameters(kwargs, name):
    with pytest.raises(ValueError, match=name):
        make_driving_protocol(duration=1.0, **kwargs)


def _run(simulate, **kwargs):
    """One call of the simulator's public function ``simulate`` with a short section."""
    kwargs = {"duration": 1.0, "sampling_rate": 20.0, "random_state": 0, **kwargs}
    if simulate == "make_lane_keeping":
        return make_lane_keeping(**kwargs)
    if simulate == "drive":
        return drive(lambda row: 0.0, **kwargs)
    return torque_ahead(_tiny_model(), horizons=(0.1,), **kwargs)


@functools.cache
def _tiny_model():
    human = make_lane_keeping(5.0, sampling_rate=20.0, random_state=0)
    return HMMGMRRegressor(n_states=2, random_state=0).fit(
        human[["lateral_deviation_0m"]], human[TARGET]
    )


SIMULATORS = ("make_lane_keeping", "drive", "torque_ahead")


@pytest.mark.parametrize("simulate", SIMULATORS)
@pytest.mark.parametrize(
    "kwargs, name",
    [
        (dict(duration=np.inf), "duration"),
        (dict(duration=10**400), "duration"),
        (dict(sampling_rate=np.inf), "sampling_rate"),
        (dict(speed_kmh=np.inf), "speed_kmh"),
        (dict(speed_kmh=1e-300), "speed_kmh"),
        (dict(duration=True), "duration"),
        (dict(setting=True), "setting"),
        (dict(sensor_noise=np.inf), "sensor_noise"),
        (dict(random_state="seed"), "random_state"),
    ],
)
def test_the_section_is_refused_up_front_naming_the_argument(simulate, kwargs, name):
    # inf made an OverflowError (duration, sampling_rate) or grew the memory until a
    # MemoryError (speed_kmh), far from the call
    with pytest.raises(ValueError, match=f"'{name}' parameter of {simulate} must be"):
        _run(simulate, **kwargs)


@pytest.mark.parametrize("simulate", SIMULATORS)
@pytest.mark.parametrize(
    "kwargs, words",
    [
        (dict(duration=1e9, sampling_rate=1.0), "1e+09 samples (2e+11 integration steps"),
        (dict(duration=1e6, sampling_rate=1000.0), "1e+09 samples"),
        (dict(duration=1e308, sampling_rate=1e300), "inf samples"),
        (dict(duration=2e4, sampling_rate=1.0, speed_kmh=200.0), "road of 1111 km"),
    ],
)
def test_a_section_too_large_for_memory_is_refused_before_any_allocation(simulate, kwargs, words):
    # make_lane_keeping(1e9, sampling_rate=1) allocated until the memory cap
    with pytest.raises(ValueError) as error:
        _run(simulate, **kwargs)
    assert words in str(error.value) and "at most" in str(error.value)


def test_the_section_specification_is_checked_once_and_frozen():
    spec = SectionSpec(10, 7, 100, 50, "highway", 0, None, "typical", 3)
    assert (spec.duration, spec.speed_kmh, spec.sampling_rate) == (10.0, 100.0, 50.0)
    assert spec.vehicle == draw_vehicle(3) and spec.sensor_noise == 1.0
    assert spec.n_samples == 500 and spec.n_sub * spec.sampling_rate >= 200.0
    assert spec.sensor_scale == draw_vehicle(3).sensor_noise
    with pytest.raises(dataclasses.FrozenInstanceError):
        spec.duration = np.inf
    with pytest.raises(ValueError, match="'scenario' parameter of SectionSpec"):
        dataclasses.replace(spec, scenario="city")


def _code_lines(function, lines):
    """Lines of code of a function: neither blank, nor a comment, nor its docstring."""
    body = function.body
    start = function.lineno
    if isinstance(body[0], ast.Expr) and isinstance(body[0].value, ast.Constant):
        docstring = range(body[0].lineno, body[0].end_lineno + 1)
    else:
        docstring = range(0)
    return sum(
        1
        for number in range(start, function.end_lineno + 1)
        if number not in docstring and lines[number - 1].strip()[:1] not in ("", "#")
    )


def test_no_simulator_function_is_over_80_lines_of_code():
    # _simulate was one function of 215 lines: the loop now calls the driver's, the steering
    # column's and the vehicle's steps, each with its module
    folder = Path(inspect.unwrap(make_lane_keeping).__code__.co_filename).parent
    sizes = {}
    for path in folder.glob("*.py"):
        text = path.read_text()
        lines = text.splitlines()
        for node in ast.walk(ast.parse(text)):
            if isinstance(node, ast.FunctionDef):
                sizes[f"{path.name}:{node.name}"] = _code_lines(node, lines)
    assert len(sizes) > 40
    assert {name: n for name, n in sizes.items() if n > 80} == {}


def _highway_spec(**spec):
    """A 20 Hz highway section of setting 7 at 100 km/h in the reference car."""
    defaults = dict(setting=7, speed_kmh=100.0, sampling_rate=20.0, scenario="highway")
    return SectionSpec(**defaults, road_random_state=None, vehicle=None, **spec)


def _law_frame(driver, sensor_noise=None, keeps=()):
    """A 6 s human run of ``driver`` (parameters) with the noise-free law's torque, and its
    section (same seeds: the remnants the human drew)."""
    spec = _highway_spec(duration=6.0, random_state=4, sensor_noise=sensor_noise)
    return human_run(spec, driver, law=keeps), Section(spec, driver)


def test_the_law_without_remnants_is_the_remnant_free_human():
    # a human without remnants drives by its law: the law's torque at the rigid column's
    # sensor is the logged torque, and the frame is the one without the law
    quiet = dataclasses.replace(
        DRIVER_STYLES["novice"], angle_remnant=0.0, torque_remnant=0.0, lane_wander=0.0
    )
    frame, _ = _law_frame(quiet)
    np.testing.assert_allclose(frame["law_torque"], frame["driver_torque"], rtol=0, atol=1e-12)
    assert np.abs(frame["driver_torque"]).max() > 0.1
    plain = make_lane_keeping(
        6.0, driver=quiet, sampling_rate=20.0, random_state=4, sensor_noise=None
    )
    pd.testing.assert_frame_equal(frame.drop(columns="law_torque"), plain, check_like=False)


def test_the_law_differs_from_the_human_by_its_torque_remnant():
    # only the torque remnant: the law sees what the human sees, so that the human's torque
    # at the wheel is the law's plus (1 + effort |law|) times the remnant at that step
    driver = dataclasses.replace(DRIVER_STYLES["defensive"], angle_remnant=0.0, lane_wander=0.0)
    frame, section = _law_frame(driver)
    p = section.parameters
    arms = p.arm_damping * frame["steering_wheel_velocity"].to_numpy()
    arms = arms + p.arm_inertia * frame["steering_wheel_acceleration"].to_numpy()
    human = frame["driver_torque"].to_numpy() + arms
    law = frame["law_torque"].to_numpy() + arms
    remnant = section.remnants[1][:: section.n_sub]
    assert np.std(remnant) > 0.01
    np.testing.assert_allclose(
        human - law, (1.0 + p.torque_remnant_effort * np.abs(law)) * remnant, atol=1e-9
    )


def test_the_law_keeping_every_remnant_is_the_human():
    frame, _ = _law_frame("novice", keeps=("angle", "torque", "wander"))
    np.testing.assert_allclose(frame["law_torque"], frame["driver_torque"], rtol=0, atol=1e-12)


def test_the_law_names_a_remnant_it_does_not_know():
    with pytest.raises(ValueError, match="law_keeps names 'tremor'"):
        _law_frame("novice", keeps=("tremor",))


def test_the_protocol_runs_are_the_protocol_recordings():
    # the recordings of protocol_runs, simulated one by one, are the protocol's frame
    frame = make_driving_protocol(
        ("novice",),
        n_train_per_setting=1,
        n_validation=0,
        n_test=1,
        duration=3.0,
        sampling_rate=20.0,
        random_state=5,
        perturbation=0.2,
        perturbed_share=0.5,
    )
    template = _highway_spec(
        duration=3.0, random_state=None, sensor_noise="typical", perturbation=0.2
    )
    runs = protocol_runs(template, ("novice",), protocol_sections(1, 0, 1), 5, 0.5)
    assert [run[2] for run in runs] == list(pd.unique(frame["recording"]))
    assert runs[1][0].perturbation == 0.2 and runs[2][0].perturbation == 0.0
    for run in (runs[1], runs[-1]):  # a perturbed training recording and the test one
        again = human_run(*run)
        recorded = frame[frame["recording"] == run[2]].reset_index(drop=True)
        pd.testing.assert_frame_equal(again, recorded, check_like=True)
