"""The torque over a horizon: ``torque_ahead`` and its rollouts of the simulator's vehicle."""

import copy
import warnings

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
    make_lane_keeping,
    torque_ahead,
)
from skhmmgmr.datasets._simulator._horizon import measured_log, rollout
from skhmmgmr.datasets._simulator._section import Section, SectionSpec
from skhmmgmr.datasets._simulator._sensors import SensorStream

RATE = 50.0
SEEDS = dict(random_state=5, road_random_state=7)
PREVIEW = list(PREVIEW_FEATURES)
FEATURES = list(FEATURE_NAMES)


@pytest.fixture(scope="module")
def preview_model():
    human = make_lane_keeping(60.0, sampling_rate=RATE, random_state=0)
    return HMMGMRRegressor(n_states=3, random_state=0).fit(human[PREVIEW], human["driver_torque"])


# A car with a torsion bar of 2 Nm/deg (its lower column is a state the log does not hold).
TORSION_BAR = {"column_stiffness": 2.0 * 180.0 / np.pi, "column_damping": 0.05}


@pytest.mark.parametrize("vehicle", [None, TORSION_BAR], ids=["rigid", "torsion-bar"])
@pytest.mark.parametrize("sensor_noise", [None, 1.0])
@pytest.mark.parametrize("start", [0, 37, 180])
def test_a_rollout_with_fixed_torques_is_a_plain_run_from_the_same_state(
    sensor_noise, start, vehicle
):
    # A plain run of the simulator with a fixed torque sequence, measured by the batch logger.
    duration, n_rows = 5.0, 40
    torques = np.cumsum(np.random.default_rng(3).normal(0.0, 0.05, int(duration * RATE)))
    spec = SectionSpec(duration, 7, 100.0, RATE, "highway", 5, 7, sensor_noise, vehicle)
    section = Section(spec, "defensive")
    column = np.empty((section.n_samples, 2))
    log = section.simulate(lambda row, states: torques[row], column_log=column)
    measured, _, errors = measured_log(section, log)
    state = log[start].copy()

    sensors = SensorStream(FEATURE_NAMES, errors, 1.0 / RATE, section.speed, sensor_noise)
    sensors.continue_from(dict(zip(FEATURE_NAMES, measured[start], strict=True)))
    sensed = []

    def replay(row, sensed_row):
        assert (sensed_row is None) == (row == 0)
        sensed.append(sensed_row)
        return torques[start + row]

    out = rollout(section, log, start, n_rows, sensors, replay, column)
    assert_allclose(out, log[start : start + n_rows], rtol=0, atol=1e-10)
    assert_allclose(np.array(sensed[1:]), measured[start + 1 : start + n_rows], rtol=0, atol=1e-10)
    assert_array_equal(log[start], state)  # the start state is read, not changed


def test_horizon_zero_is_the_models_filtered_estimate(preview_model):
    ahead = torque_ahead(
        preview_model,
        horizons=(0.0, 0.1, 1.0),
        duration=8.0,
        sampling_rate=RATE,
        start_every=3,
        return_proba=True,
        **SEEDS,
    )
    recorded = make_lane_keeping(8.0, sampling_rate=RATE, **SEEDS)
    starts = np.arange(0, len(recorded) - 50, 3)
    now = ahead[ahead["horizon"] == 0.0]
    assert_allclose(now["time"], starts / RATE)
    assert_allclose(now["estimate"], preview_model.predict(recorded[PREVIEW])[starts], atol=1e-12)
    proba = preview_model.predict_state_proba(recorded[PREVIEW])[starts]
    assert_allclose(now[[f"state_proba_{k}" for k in range(3)]], proba, atol=1e-12)
    for horizon, rows in ((0.0, 0), (0.1, 5), (1.0, 50)):
        at = ahead[ahead["horizon"] == horizon]
        assert_array_equal(at["driver_torque"], recorded["driver_torque"].to_numpy()[starts + rows])
    assert set(ahead["recording"]) == {recorded["recording"].iloc[0]}
    assert not ahead["lost_control"].any()


def test_the_rollout_from_the_first_row_is_the_model_driving_from_rest(preview_model):
    # At row 0 the human's car is at rest, as the car of a drive starts: the rollout from it
    # is the drive of the model on the same road, with the same sensor errors.
    horizons = (0.0, 0.02, 0.5, 1.0, 2.0)
    rows = (np.array(horizons) * RATE).round().astype(int)
    for sensor_noise in (None, "typical"):
        run = dict(duration=4.0, sampling_rate=RATE, sensor_noise=sensor_noise, **SEEDS)
        ahead = torque_ahead(preview_model, horizons=horizons, start_every=1000, **run)
        frame = drive(preview_model, **run)
        # the model's torques of the drive, from the sensed rows it was given
        driven = preview_model.predict(frame[PREVIEW])
        assert_allclose(ahead["estimate"], driven[rows], rtol=0, atol=1e-10)


def test_every_start_is_its_own_rollout_and_the_model_is_not_changed(preview_model):
    before = copy.deepcopy(preview_model.model_)
    run = dict(horizons=(0.2, 0.6), duration=6.0, sampling_rate=RATE, return_proba=True, **SEEDS)
    every = torque_ahead(preview_model, start_every=1, **run)
    sparse = torque_ahead(preview_model, start_every=7, **run)
    kept = np.isin(np.round(every["time"] * RATE), np.arange(0, 300, 7))
    pd.testing.assert_frame_equal(every[kept].reset_index(drop=True), sparse, rtol=0, atol=1e-12)
    recorded = make_lane_keeping(6.0, sampling_rate=RATE, **SEEDS)
    fresh = HMMGMRRegressor.from_fitted_model(before)
    assert_array_equal(preview_model.predict(recorded[PREVIEW]), fresh.predict(recorded[PREVIEW]))


def test_the_state_probabilities_stay_on_the_simplex(preview_model):
    ahead = torque_ahead(
        preview_model,
        horizons=(0.5, 2.0),
        duration=10.0,
        sampling_rate=RATE,
        start_every=4,
        return_proba=True,
        **SEEDS,
    )
    proba = ahead[[f"state_proba_{k}" for k in range(3)]].to_numpy()
    assert np.all(proba >= 0) and np.all(proba <= 1)
    assert_allclose(proba.sum(axis=1), 1.0, atol=1e-12)
    assert np.isfinite(ahead["estimate"]).all()
    # the horizon's probabilities differ from the start's: they were carried along
    assert not np.allclose(proba[ahead["horizon"] == 0.5], proba[ahead["horizon"] == 2.0])


def test_a_rollout_that_leaves_the_road_holds_its_last_estimate():
    human = make_lane_keeping(30.0, sampling_rate=RATE, random_state=0)
    y = 5.0 + 0.01 * human["driver_torque"]  # a pull to one side, which spins the wheel
    model = HMMGMRRegressor(n_states=1, random_state=0).fit(human[PREVIEW], y)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        ahead = torque_ahead(model, horizons=(0.5, 4.0), duration=8.0, sampling_rate=RATE, **SEEDS)
    far = ahead[ahead["horizon"] == 4.0]
    assert far["lost_control"].any()
    assert not ahead[ahead["horizon"] == 0.5]["lost_control"].any()
    assert np.isfinite(ahead["estimate"]).all()


@pytest.mark.parametrize(
    "horizons, message",
    [
        ((), "non-empty"),
        ("soon", "array-like"),
        ([[0.5]], "non-empty"),
        ((0.5, -0.1), ">= 0"),
        ((np.nan,), "finite"),
        ((0.51,), "whole numbers of sampling periods"),
        ((0.5, 0.5), "all differ"),
        ((8.0,), "longer"),
    ],
)
def test_bad_horizons_are_refused_naming_the_parameter(preview_model, horizons, message):
    with pytest.raises(ValueError, match="horizons") as error:
        torque_ahead(preview_model, horizons=horizons, duration=8.0, sampling_rate=RATE)
    assert message in str(error.value)


@pytest.mark.parametrize("start_every", [0, -2, 1.5, True, "1"])
def test_bad_start_every_is_refused(preview_model, start_every):
    with pytest.raises(ValueError, match="start_every"):
        torque_ahead(preview_model, duration=8.0, sampling_rate=RATE, start_every=start_every)


def test_models_that_cannot_roll_out_are_refused(preview_model):
    human = make_lane_keeping(10.0, sampling_rate=RATE, random_state=0)
    ridge = Ridge().fit(human[PREVIEW], human["driver_torque"])
    with pytest.raises(TypeError, match="'model' parameter of torque_ahead .*'filter_stream'"):
        torque_ahead(ridge, duration=8.0, sampling_rate=RATE)
    unnamed = HMMGMRRegressor(n_states=2, random_state=0).fit(
        human[PREVIEW].to_numpy(), human["driver_torque"]
    )
    with pytest.raises(ValueError, match="feature_names_in_"):
        torque_ahead(unnamed, duration=8.0, sampling_rate=RATE)
    with pytest.raises(ValueError, match="driver"):
        torque_ahead(preview_model, driver="racer", duration=8.0, sampling_rate=RATE)


def test_a_torque_pipeline_rolls_out_with_its_derived_inputs():
    human = make_lane_keeping(30.0, sampling_rate=RATE, random_state=0)
    pipe = make_torque_pipeline(2, random_state=0).fit(human[FEATURES], human["driver_torque"])
    ahead = torque_ahead(pipe, horizons=(0.0, 0.5), duration=5.0, sampling_rate=RATE, **SEEDS)
    recorded = make_lane_keeping(5.0, sampling_rate=RATE, **SEEDS)
    now = ahead[ahead["horizon"] == 0.0]
    starts = np.round(now["time"].to_numpy() * RATE).astype(int)
    assert_allclose(now["estimate"], pipe.predict(recorded[FEATURES])[starts], atol=1e-12)
    assert np.isfinite(ahead["estimate"]).all()


def test_the_rollouts_run_in_the_recordings_car(preview_model):
    # In a drawn car the recording is make_lane_keeping's in that car, and the rollout from
    # rest is the model's drive of that car.
    run = dict(duration=4.0, sampling_rate=RATE, vehicle=2, **SEEDS)
    horizons = (0.0, 0.5, 1.0)
    ahead = torque_ahead(preview_model, horizons=horizons, start_every=1000, **run)
    recorded = make_lane_keeping(**run)
    rows = (np.array(horizons) * RATE).round().astype(int)
    assert_array_equal(ahead["driver_torque"], recorded["driver_torque"].to_numpy()[rows])
    driven = preview_model.predict(drive(preview_model, **run)[PREVIEW])
    assert_allclose(ahead["estimate"], driven[rows], rtol=0, atol=1e-10)
    default_car = torque_ahead(
        preview_model, horizons=horizons, start_every=1000, **{**run, "vehicle": None}
    )
    assert not np.allclose(default_car["driver_torque"], ahead["driver_torque"])
    with pytest.raises(ValueError, match="vehicle"):
        torque_ahead(preview_model, duration=4.0, sampling_rate=RATE, vehicle={"bogus": 1.0})


def test_a_model_of_two_outputs_is_refused_naming_the_model():
    # it failed in numpy: "setting an array element with a sequence"
    human = make_lane_keeping(10.0, sampling_rate=RATE, random_state=0)
    targets = pd.DataFrame({"torque": human["driver_torque"], "twice": 2 * human["driver_torque"]})
    model = HMMGMRRegressor(n_states=2, random_state=0).fit(human[PREVIEW], targets)
    with pytest.raises(
        ValueError, match="HMMGMRRegressor returned 2 values at 0.000 s; one torque"
    ):
        torque_ahead(model, horizons=(0.1,), duration=2.0, sampling_rate=RATE)
