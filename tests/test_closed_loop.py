"""The driver at the wheel: ``drive`` and the lane-keeping metrics."""

import math

import numpy as np
import pandas as pd
import pytest
from numpy.testing import assert_allclose, assert_array_equal
from sklearn.linear_model import Ridge

from skhmmgmr import HMMGMRRegressor, make_torque_pipeline
from skhmmgmr.datasets import (
    FEATURE_NAMES,
    PREVIEW_FEATURES,
    drive,
    make_driving_protocol,
    make_lane_keeping,
    to_panel,
    torque_ahead,
)
from skhmmgmr.datasets._simulator._closed_loop import (
    LOG_COLUMNS,
    MAX_WHEEL_ANGLE,
    lost_control,
)
from skhmmgmr.datasets._simulator._section import Section, SectionSpec
from skhmmgmr.datasets._simulator._sensors import draw_errors, measure
from skhmmgmr.metrics import LANE_KEEPING_METRICS, lane_keeping_metrics

FEATURES = list(FEATURE_NAMES)
SEEDS = dict(random_state=5, road_random_state=7)


def defensive_section(duration, rate, seeds=(5, 7)):
    """The section a defensive human drives with the seeds of ``drive(**SEEDS)`` (or others)."""
    spec = SectionSpec(duration, 7, 100.0, rate, "highway", *seeds, None, None)
    return Section(spec, "defensive")


def _replay(torques):
    """A driver that ignores what it senses and returns ``torques`` in turn."""
    sequence = iter(torques)

    def replay(row):
        return next(sequence)

    return replay


@pytest.fixture(scope="module")
def preview_model():
    data = make_driving_protocol(("defensive",), duration=30.0, sampling_rate=50.0, random_state=0)
    train = data[data["split"] == "train"]
    return HMMGMRRegressor(n_states=3, random_state=0).fit(
        train[list(PREVIEW_FEATURES)], train["driver_torque"], groups=train["recording"]
    )


def test_a_human_style_drives_as_make_lane_keeping():
    frame = drive("novice", duration=10.0, sampling_rate=50.0, **SEEDS)
    expected = make_lane_keeping(10.0, driver="novice", sampling_rate=50.0, split="test", **SEEDS)
    pd.testing.assert_frame_equal(frame, expected)


@pytest.mark.parametrize("sensor_noise", [None, "typical"])
def test_the_closed_loop_logs_what_a_plain_run_with_the_same_torques_logs(sensor_noise):
    # A plain run of the simulator with a fixed torque sequence, measured by the batch logger
    # with the errors the seeds draw after the human's remnants.
    duration, rate = 8.0, 50.0
    rng = np.random.default_rng(3)
    torques = np.cumsum(rng.normal(0.0, 0.05, int(duration * rate)))
    section = Section(
        SectionSpec(duration, 7, 100.0, rate, "highway", 5, 7, None, None), "defensive"
    )
    log = section.simulate(lambda row, states: torques[row])
    assert_array_equal(log[:, LOG_COLUMNS.index("torque")], torques)
    clean, torque = section.features(log)
    scale = None if sensor_noise is None else 1.0
    expected, expected_torque = measure(
        clean, torque, 1.0 / rate, section.speed, scale, section.rng
    )

    frame = drive(
        _replay(torques), duration=duration, sampling_rate=rate, sensor_noise=sensor_noise, **SEEDS
    )
    assert len(frame) == len(torques)
    for name in FEATURES:
        assert_allclose(frame[name], expected[name], rtol=1e-12, atol=1e-12, err_msg=name)
    assert_allclose(frame["driver_torque"], expected_torque, rtol=0, atol=1e-12)
    assert frame.attrs["lost_control"] is None and frame.attrs["sensor_noise"] == scale


def test_every_driver_gets_the_same_sensor_errors():
    def errors(torques):
        run = dict(duration=6.0, sampling_rate=50.0, **SEEDS)
        noisy = drive(_replay(torques), **run)
        clean = drive(_replay(torques), sensor_noise=None, **run)
        return (
            noisy[["lateral_acceleration", "yaw_rate"]]
            - clean[["lateral_acceleration", "yaw_rate"]]
        ).to_numpy()

    a, b = errors(np.zeros(300)), errors(np.full(300, 0.3))
    assert_allclose(a, b, rtol=0, atol=1e-12)
    section = defensive_section(6.0, 50.0)
    drawn = draw_errors(300, 0.02, 1.0, section.rng)
    assert_allclose(a[:, 0], sum(drawn["lateral_acceleration"]), rtol=0, atol=1e-12)


def test_a_fitted_model_drives_on_what_it_senses_and_its_torque_is_its_prediction(preview_model):
    frame = drive(preview_model, duration=20.0, sampling_rate=50.0, sensor_noise=None, **SEEDS)
    assert frame["driver"].iloc[0] == "HMMGMRRegressor"
    assert frame["recording"].iloc[0] == "HMMGMRRegressor-highway-s7"
    predicted = preview_model.predict(frame[list(PREVIEW_FEATURES)])
    assert_allclose(frame["driver_torque"], predicted, rtol=0, atol=1e-12)
    # it keeps the lane the human keeps on that road
    human = lane_keeping_metrics(drive("defensive", duration=20.0, sampling_rate=50.0, **SEEDS))
    model = lane_keeping_metrics(frame)
    assert model["lateral_deviation_max"] < 1.75
    assert model["torque_rms"] == pytest.approx(human["torque_rms"], rel=0.5)


def test_a_scikit_learn_regressor_drives_one_row_at_a_time(preview_model):
    data = make_lane_keeping(60.0, sampling_rate=50.0, random_state=1)
    ridge = Ridge(1e-3).fit(data[list(PREVIEW_FEATURES)], data["driver_torque"])
    positions = [FEATURES.index(name) for name in PREVIEW_FEATURES]

    def by_hand(row):
        return row[positions] @ ridge.coef_ + ridge.intercept_

    run = dict(duration=5.0, sampling_rate=50.0, **SEEDS)
    assert_allclose(
        drive(ridge, **run)["driver_torque"], drive(by_hand, **run)["driver_torque"], atol=1e-9
    )


def test_a_driver_that_loses_control_ends_the_drive():
    with pytest.warns(UserWarning, match="lost control"):
        frame = drive(lambda row: 3.0, duration=60.0, sampling_rate=20.0, **SEEDS)
    assert 0 < len(frame) < 1200
    assert frame.attrs["lost_control"] == pytest.approx(len(frame) / 20.0)


def test_a_model_that_spins_the_wheel_away_loses_control_instead_of_diverging():
    # a positive feedback on the wheel's angle: the steering system's inverse, overdone
    angle = FEATURES.index("steering_wheel_angle")

    def diverging(row):
        return 100.0 * row[angle]

    with pytest.warns(UserWarning, match="lost control .*steering wheel at"):
        frame = drive(diverging, duration=20.0, sampling_rate=20.0, **SEEDS)
    assert 0 < len(frame) < 400
    assert frame.attrs["lost_control"] == pytest.approx(len(frame) / 20.0)
    assert "steering wheel" in frame.attrs["lost_control_reason"]
    # every logged row is finite and the wheel within the bound; the lateral deviation too
    sensed = frame[FEATURES + ["driver_torque"]].to_numpy()
    assert np.isfinite(sensed).all()
    assert np.abs(frame["steering_wheel_angle"]).max() <= MAX_WHEEL_ANGLE
    assert np.abs(frame["lateral_deviation_0m"]).max() < 10.0


def test_a_finite_but_runaway_torque_ends_the_drive_with_finite_rows():
    with pytest.warns(UserWarning, match="lost control"):
        frame = drive(lambda row: 1e300, duration=5.0, sampling_rate=20.0, **SEEDS)
    assert len(frame) == 1 and frame.attrs["lost_control"] == pytest.approx(0.05)
    assert np.isfinite(frame[FEATURES].to_numpy()).all()


def test_a_drive_that_keeps_control_has_no_reason():
    frame = drive(lambda row: 0.0, duration=2.0, sampling_rate=20.0, **SEEDS)
    assert frame.attrs["lost_control"] is None and frame.attrs["lost_control_reason"] is None


def test_the_reason_for_a_loss_of_control_names_what_went_wrong():
    calm = dict.fromkeys(("theta", "theta_d", "v", "r", "e_y", "e_psi"), 0.0)
    assert lost_control({**calm, "v": math.nan, "r": math.inf}) == "states not finite: v, r"
    assert "steering wheel at -13 rad" in lost_control({**calm, "theta": -13.0})
    assert "lateral deviation 10.5 m" in lost_control({**calm, "e_y": 10.5})
    assert lost_control({**calm, "theta_d": 1e308, "v": 1e308}).startswith("runaway")


def test_the_row_a_callable_gets_is_the_sensed_features_and_read_only():
    seen = []

    def look(row):
        seen.append(row.copy())
        with pytest.raises(ValueError, match="read-only"):
            row[0] = 1.0
        return 0.0

    frame = drive(look, duration=1.0, sampling_rate=20.0, **SEEDS)
    assert_array_equal(np.array(seen), frame[FEATURES].to_numpy())


@pytest.mark.parametrize(
    "driver, error, message",
    [
        ("racer", ValueError, "Unknown driver style"),
        (42, TypeError, "style name, a fitted model, an FMU .* or a callable"),
        (lambda row: float("nan"), ValueError, "non-finite torque"),
        (lambda row: [1.0, 2.0], ValueError, "returned 2 values"),
        # a raw float() error before, naming neither the driver nor the time
        (lambda row: "abc", ValueError, r"driver <lambda> returned 'abc' at 0.000 s; a torque"),
        (lambda row: 1 + 2j, ValueError, r"driver <lambda> returned \(1\+2j\) at 0.000 s"),
        (lambda row: np.array([0.5j]), ValueError, "a torque is a real number"),
        (lambda row: True, ValueError, "returned True at 0.000 s"),
        (lambda row: [1.0, [2.0]], ValueError, "a torque is a real number"),
    ],
)
def test_bad_drivers_are_refused_naming_the_problem(driver, error, message):
    with pytest.raises(error, match=message):
        drive(driver, duration=1.0, sampling_rate=20.0, random_state=0)


def test_a_model_must_read_sensed_features_by_name():
    rng = np.random.default_rng(0)
    X, y = rng.normal(size=(50, 2)), rng.normal(size=50)
    with pytest.raises(ValueError, match="no feature_names_in_"):
        drive(Ridge().fit(X, y), duration=1.0, sampling_rate=20.0)
    frame = pd.DataFrame(X, columns=["steering_wheel_angle", "pedal"])
    with pytest.raises(ValueError, match=r"reads \['pedal'\], which the simulator does not sense"):
        drive(Ridge().fit(frame, y), duration=1.0, sampling_rate=20.0)


def _frame(deviation, *, recording="r", period=0.5, manoeuvre=None, angle=None, torque=None):
    n = len(deviation)
    frame = pd.DataFrame(
        {
            "recording": recording,
            "time": np.arange(n) * period,
            "lateral_deviation_0m": deviation,
            "heading_deviation_0m": np.full(n, 0.01),
            "steering_wheel_angle": np.zeros(n) if angle is None else angle,
            "driver_torque": np.ones(n) if torque is None else torque,
        }
    )
    if manoeuvre is not None:
        frame["manoeuvre"] = manoeuvre
    return frame


def test_lane_keeping_metrics_of_a_hand_computed_drive():
    deviation = np.array([0.0, 0.9, 0.8, 0.9, 0.7, -0.9, -0.86, 0.0])
    torque = np.array([0.0, 1.0, 3.0, 2.0, 2.0, 0.0, 0.0, 1.0])
    deg = math.radians(1.0)
    angle = np.array([0.0, 3.0, 0.9, 0.5, 2.0, 4.0, 1.0, 1.5]) * deg
    metrics = lane_keeping_metrics(_frame(deviation, angle=angle, torque=torque))
    assert list(metrics.index) == list(LANE_KEEPING_METRICS)
    assert metrics.name == "r"
    assert metrics["lateral_deviation_rms"] == pytest.approx(np.sqrt(np.mean(deviation**2)))
    assert metrics["lateral_deviation_max"] == pytest.approx(0.9)
    # out beyond 0.85 m at rows 1, 3, 5, 6; back inside 0.75 m only at row 4 (0.7): two departures
    assert metrics["departures"] == 2
    assert metrics["time_out_of_lane"] == pytest.approx(4 * 0.5)
    assert metrics["heading_error_rms"] == pytest.approx(0.01)
    assert metrics["torque_rms"] == pytest.approx(np.sqrt(np.mean(torque**2)))
    assert metrics["torque_roughness"] == pytest.approx(np.std(np.diff(torque) / 0.5))
    # angle 0, 3 (up), 0.9 (down 2.1: reversal 1), 0.5 (lower), 2, 4 (up 3.5 from 0.5:
    # reversal 2), 1 (down 3: reversal 3), 1.5; 3 reversals in 8 rows of 0.5 s = 4 s
    assert metrics["steering_reversal_rate"] == pytest.approx(3 / (4.0 / 60.0))


def test_lane_keeping_metrics_per_recording_and_without_manoeuvres():
    first = _frame(np.array([0.0, 0.9, 0.0, 0.9]), recording="a")
    second = _frame(
        np.array([0.0, 0.9, 0.9, 0.0]),
        recording="b",
        manoeuvre=["lane_keeping", "lane_change_left", "lane_change_left", "lane_keeping"],
    )
    table = lane_keeping_metrics(pd.concat([second, first], ignore_index=True))
    assert list(table.index) == ["b", "a"]
    assert table.loc["a", "departures"] == 2 and table.loc["b", "departures"] == 0
    assert table.loc["b", "time_out_of_lane"] == 0.0
    assert table.loc["b", "lateral_deviation_max"] == pytest.approx(0.9)
    # a panel gives the same table
    panel = pd.concat([second, first]).set_index(["recording", "time"])
    pd.testing.assert_frame_equal(lane_keeping_metrics(panel), table)


def test_lane_keeping_metrics_refuse_bad_input():
    frame = _frame(np.zeros(4))
    with pytest.raises(ValueError, match=r"lacks the column\(s\) \['driver_torque'\]"):
        lane_keeping_metrics(frame.drop(columns="driver_torque"))
    bad = frame.copy()
    bad.loc[2, "lateral_deviation_0m"] = np.nan
    with pytest.raises(
        ValueError, match="lateral_deviation_0m holds NaN or infinity in recording 'r'"
    ):
        lane_keeping_metrics(bad)
    with pytest.raises(ValueError, match="vehicle_width=3.5 must be smaller"):
        lane_keeping_metrics(frame, vehicle_width=3.5)
    with pytest.raises(ValueError, match="needs the time|no 'time'"):
        lane_keeping_metrics(frame.drop(columns="time"))
    # pandas 2.0 names the class by its defining module, pandas.core.frame
    with pytest.raises(TypeError, match=r"'frame' parameter .* 'pandas\.(core\.frame\.)?DataFrame"):
        lane_keeping_metrics(frame.to_numpy())


def test_the_wide_lane_scenario_is_one_5_m_lane_of_straights_and_sinusoids():
    wide = make_lane_keeping(120.0, scenario="wide_lane", sampling_rate=20.0, random_state=2)
    narrow = make_lane_keeping(120.0, sampling_rate=20.0, random_state=2)
    assert wide.attrs["lane_width"] == 5.0 and narrow.attrs["lane_width"] == 3.5
    assert (wide["manoeuvre"] == "lane_keeping").all() and wide["crossing_time"].isna().all()
    # no radius below 300 m (curvature sensor noise aside); long straights in between
    curvature = make_lane_keeping(
        120.0, scenario="wide_lane", sampling_rate=20.0, random_state=2, sensor_noise=None
    )["road_curvature_0m"]
    assert np.abs(curvature).max() <= 1 / 300 + 1e-12
    assert (np.abs(curvature) < 1e-12).mean() > 0.2
    # the driver uses the room: a wider spread, the car's centre still in the lane
    deviation, narrow_deviation = wide["lateral_deviation_0m"], narrow["lateral_deviation_0m"]
    assert deviation.abs().max() < 2.5
    assert deviation.abs().max() > narrow_deviation.abs().max()
    assert (
        lane_keeping_metrics(wide)["departures"]
        <= lane_keeping_metrics(wide, lane_width=3.5)["departures"]
    )


def test_manoeuvre_labels_and_crossing_times_of_a_hand_made_drive():
    section = defensive_section(2.0, 10.0, seeds=(0, None))
    section.road.manoeuvres = [(100.0, 160.0, "lane_change_left"), (200.0, 230.0, "evasive")]
    s = np.arange(0.0, 300.0, 10.0)
    lateral = np.zeros_like(s)
    lateral[(s >= 100) & (s < 160)] = [0.5, 1.0, 1.7, 1.8, 3.0, 3.4]  # crosses 1.75 at s=130
    lateral[(s >= 200) & (s < 230)] = [-1.0, -1.5, -1.7]  # never crosses
    log = np.zeros((len(s), len(LOG_COLUMNS)))
    log[:, LOG_COLUMNS.index("s")], log[:, LOG_COLUMNS.index("e_y")] = s, lateral
    labels, crossing = section.manoeuvres(log)
    assert list(labels[9:17]) == ["lane_keeping"] + ["lane_change_left"] * 6 + ["lane_keeping"]
    assert list(labels[20:23]) == ["evasive"] * 3
    assert_allclose(crossing[10:16], 13 / 10.0)  # row 13 (s = 130 m) at 10 Hz
    assert np.isnan(crossing[:10]).all() and np.isnan(crossing[16:]).all()


def test_every_lane_change_of_the_human_crosses_the_marking_during_the_manoeuvre():
    frame = make_lane_keeping(
        300.0, scenario="lane_change", sampling_rate=20.0, random_state=4, sensor_noise=None
    )
    changes = frame[frame["manoeuvre"].str.startswith("lane_change")]
    assert set(changes["manoeuvre"]) == {"lane_change_left", "lane_change_right"}
    blocks = (frame["manoeuvre"] != frame["manoeuvre"].shift()).cumsum()
    for _, block in changes.groupby(blocks[changes.index]):
        crossing = block["crossing_time"].iloc[0]
        assert (block["crossing_time"] == crossing).all()
        assert block["time"].iloc[0] < crossing <= block["time"].iloc[-1]
        # the car's centre crosses there; the front axle, ahead on a heading, a little earlier
        at = frame.loc[np.isclose(frame["time"], crossing), "lateral_deviation_0m"].iloc[0]
        assert abs(abs(at) - 1.75) < 0.3


def test_a_pipeline_fitted_at_another_rate_is_refused_as_predict_refuses_it():
    # drive ran a pipeline fitted at 20 Hz (velocity filter 0.1 s) at 100 Hz without a word
    human = make_lane_keeping(20.0, sampling_rate=20.0, random_state=0)
    columns = ["steering_wheel_angle", "steering_wheel_velocity", "lateral_acceleration"]
    pipe = make_torque_pipeline(
        2, velocity_filter=0.1, sampling_period=0.05, output_smoothing=None, random_state=0
    ).fit(human[columns], human["driver_torque"])
    fast = make_lane_keeping(2.0, sampling_rate=100.0, random_state=1)
    with pytest.raises(ValueError) as predicted:
        pipe.predict(to_panel(fast)[columns])
    same_words = "but sampling_period=0.05: the velocity filter would run 5 times too fast or slow"
    assert same_words in str(predicted.value)
    for simulate, extra in ((drive, {}), (torque_ahead, {"horizons": (0.1,)})):
        with pytest.raises(ValueError) as refused:
            simulate(pipe, duration=2.0, sampling_rate=100.0, random_state=1, **extra)
        message = str(refused.value)
        assert same_words in message
        assert "sampling_rate=100" in message and "sampling_rate=20" in message
        assert "'steering_features' of TorquePipeline" in message
    # at its own rate it drives, and so does a pipeline without a velocity filter
    assert len(drive(pipe, duration=2.0, sampling_rate=20.0, random_state=1)) == 40
    unfiltered = make_torque_pipeline(2, velocity_filter=None, output_smoothing=None)
    unfiltered.fit(human[columns], human["driver_torque"])
    assert len(drive(unfiltered, duration=1.0, sampling_rate=100.0, random_state=1)) == 100
