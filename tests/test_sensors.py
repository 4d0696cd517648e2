"""Tests of the sensor measurement of the lane-keeping simulator."""

import numpy as np
import pandas as pd
import pytest

from skhmmgmr.datasets import (
    CALIBRATION_BANDS,
    DRIVER_STYLES,
    FEATURE_NAMES,
    TARGET,
    calibration_table,
    make_driving_protocol,
    make_lane_keeping,
)
from skhmmgmr.datasets._simulator._sensors import (
    DERIVATIVES,
    SENSORS,
    check_sensor_noise,
    ecu_derivative,
    measure,
)

SPEED = 100.0 / 3.6
KWARGS = dict(duration=300.0, sampling_rate=20.0, random_state=11)


@pytest.fixture(scope="module")
def pair():
    """The same drive, as true states and as measured with typical sensors."""
    clean = make_lane_keeping(sensor_noise=None, **KWARGS)
    measured = make_lane_keeping(sensor_noise="typical", **KWARGS)
    return clean, measured


def _expected_rms(sensor, scale=1.0):
    return scale * np.sqrt(sensor.white**2 + sensor.drift**2 + sensor.resolution**2 / 12)


@pytest.mark.parametrize("name", sorted(SENSORS))
def test_measured_error_matches_documented_magnitude(pair, name):
    clean, measured = pair
    error = (measured[name] - clean[name]).to_numpy()
    ratio = error.std() / _expected_rms(SENSORS[name])
    # the drifts have correlation times up to 60 s: a 300 s sample estimates them loosely
    assert 0.4 < ratio < 1.6, (name, ratio)
    assert abs(error.mean()) < 3 * _expected_rms(SENSORS[name])


def test_derivatives_are_computed_from_the_measured_signals(pair):
    clean, measured = pair
    dt = 1.0 / KWARGS["sampling_rate"]
    for name, (source, time_constant) in DERIVATIVES.items():
        expected = ecu_derivative(measured[source].to_numpy(), dt, time_constant)
        np.testing.assert_allclose(measured[name], expected, err_msg=name)
        # differentiation amplifies the noise: a worse signal-to-error ratio than the source's
        source_snr = clean[source].std() / (measured[source] - clean[source]).std()
        snr = clean[name].std() / (measured[name] - clean[name]).std()
        assert snr < source_snr, name
        assert np.corrcoef(clean[name], measured[name])[0, 1] > 0.1, name
    slip = np.arctan2(measured["lateral_velocity"], SPEED)
    np.testing.assert_allclose(measured["slip_angle"], slip)


def test_no_noise_reproduces_the_true_states():
    true_states = make_lane_keeping(20.0, random_state=4, sensor_noise=None)
    frame = make_lane_keeping(20.0, random_state=4, sensor_noise="none")
    pd.testing.assert_frame_equal(frame, true_states)
    # the default measures the signals as a vehicle logs them
    default = make_lane_keeping(20.0, random_state=4)
    assert default.attrs["sensor_noise"] is not None
    assert not np.allclose(default["yaw_rate"], true_states["yaw_rate"])
    for frame in (true_states, make_lane_keeping(20.0, random_state=4, sensor_noise="none")):
        assert frame.attrs["sensor_noise"] is None
    # a zero scale keeps the ECU derivatives but no error: the closed loop is the same
    zero = make_lane_keeping(20.0, random_state=4, sensor_noise=0.0)
    direct = [*(name for name in SENSORS if name != TARGET), "slip_angle"]
    pd.testing.assert_frame_equal(zero[direct], true_states[direct])
    np.testing.assert_array_equal(zero[TARGET], true_states[TARGET])
    # first derivatives follow the true ones; the second derivatives of the steering wheel and
    # roll lose the high-frequency content of the true ones to the ECU filters
    for name, (source, _) in DERIVATIVES.items():
        if source in SENSORS:
            assert np.corrcoef(zero[name], true_states[name])[0, 1] > 0.9, name


def test_scale_factor_scales_the_errors(pair):
    clean, _ = pair
    double = make_lane_keeping(sensor_noise=2.0, **KWARGS)
    assert double.attrs["sensor_noise"] == 2.0
    for name in ("yaw_rate", "lateral_acceleration", TARGET):
        ratio = (double[name] - clean[name]).std() / _expected_rms(SENSORS[name], 2.0)
        assert 0.6 < ratio < 1.4, (name, ratio)


def test_sensors_are_causal():
    rng = np.random.RandomState(0)
    n, t = 400, 250
    columns = {name: np.cumsum(rng.standard_normal(n)) * 1e-3 for name in FEATURE_NAMES}
    torque = np.cumsum(rng.standard_normal(n)) * 1e-2
    before, torque_before = measure(columns, torque, 0.01, SPEED, 1.0, np.random.RandomState(1))
    changed = {name: values.copy() for name, values in columns.items()}
    for values in changed.values():
        values[t] += 1.0
    after, _ = measure(changed, torque, 0.01, SPEED, 1.0, np.random.RandomState(1))
    for name in FEATURE_NAMES:
        np.testing.assert_array_equal(after[name][:t], before[name][:t], err_msg=name)
        assert after[name][t] != before[name][t], name
    assert list(after) == list(FEATURE_NAMES)
    # a step in the input moves the derivative only from the step on
    step = np.r_[np.zeros(50), np.ones(50)]
    derivative = ecu_derivative(step, 0.01, 0.02)
    assert np.all(derivative[:50] == 0.0) and derivative[50] > 0


def test_same_seed_same_measurement():
    first = make_lane_keeping(5.0, driver="novice", random_state=42, sensor_noise="typical")
    second = make_lane_keeping(5.0, driver="novice", random_state=42, sensor_noise="typical")
    pd.testing.assert_frame_equal(first, second)
    other = make_lane_keeping(5.0, driver="novice", random_state=43, sensor_noise="typical")
    assert not np.allclose(first["yaw_rate"], other["yaw_rate"])


def test_calibration_bands_hold_on_measured_signals():
    frames = [
        make_lane_keeping(300.0, driver=style, random_state=0, sensor_noise="typical")
        for style in DRIVER_STYLES
    ]
    table = calibration_table(pd.concat(frames))
    for _, row in table.iterrows():
        for kpi, (low, high) in CALIBRATION_BANDS.items():
            assert low <= row[kpi] <= high, (row["driver"], kpi, row[kpi])


def test_protocol_passes_the_sensor_noise():
    kwargs = dict(n_train_per_setting=1, n_validation=1, n_test=0, duration=2.0, random_state=0)
    clean = make_driving_protocol(("defensive",), sensor_noise=None, **kwargs)
    noisy = make_driving_protocol(("defensive",), sensor_noise="typical", **kwargs)
    assert clean.attrs["sensor_noise"] is None and noisy.attrs["sensor_noise"] == 1.0
    assert not np.allclose(clean["yaw_rate"], noisy["yaw_rate"])
    np.testing.assert_allclose(clean[TARGET], noisy[TARGET], atol=0.2)


@pytest.mark.parametrize("value", ["loud", -1.0, float("nan"), True, [1.0]])
def test_bad_sensor_noise(value):
    with pytest.raises(ValueError, match="sensor_noise"):
        check_sensor_noise(value)
    with pytest.raises(ValueError, match="sensor_noise"):
        make_lane_keeping(1.0, sensor_noise=value)
    with pytest.raises(ValueError, match="sensor_noise"):
        make_driving_protocol(duration=1.0, sensor_noise=value)
