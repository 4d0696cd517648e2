"""Tests of the comma2k19 segment loader and of the big-endian CAN signal decoder."""

import shutil

import numpy as np
import pytest
from _comma2k19_data import SEGMENT, SEGMENT_NAME

from skhmmgmr.datasets import FEATURE_UNITS, TARGET, load_comma2k19_segment
from skhmmgmr.datasets._comma2k19._can import decode_big_endian_signal

WHEELBASE = 2.65
STEERING_RATIO = 16.88


def encode_big_endian(value, start_bit, length):
    """Write a raw value into an 8-byte payload bit by bit, walking the DBC numbering."""
    payload = bytearray(8)
    bit = start_bit
    for i in range(length):
        if (value >> (length - 1 - i)) & 1:
            payload[bit // 8] |= 1 << (bit % 8)
        # Next less significant bit: down within the byte, then to bit 7 of the next byte.
        bit = bit - 1 if bit % 8 else bit + 15
    return bytes(payload)


# --- decoder on hand-built frames -----------------------------------------------------------


@pytest.mark.parametrize(
    "payload, start_bit, length, signed, scale, offset, expected",
    [
        (b"\x00\xff\xfe", 15, 16, True, 1.0, 0.0, -2.0),  # STEER_TORQUE_DRIVER
        (b"\x00\x00\x64", 15, 16, True, 1.0, 0.0, 100.0),
        (b"\x0f\xfd", 3, 12, True, 1.5, 0.0, -4.5),  # STEER_ANGLE, raw -3
        (b"\x00\x03", 3, 12, True, 1.5, 0.0, 4.5),
        (b"\x01\xfe", 1, 10, False, 0.244, -125.0, 510 * 0.244 - 125.0),  # YAW_RATE
        (b"\x00\x00\x00\x00\xe0", 39, 4, True, 0.1, 0.0, -0.2),  # STEER_FRACTION
        (b"\x00\x00\x00\x00\x00\x00\x00\x80", 63, 1, False, 1.0, 0.0, 1.0),
    ],
)
def test_decode_known_frames(payload, start_bit, length, signed, scale, offset, expected):
    value = decode_big_endian_signal(
        np.array([payload], dtype="S8"),
        start_bit,
        length,
        signed=signed,
        scale=scale,
        offset=offset,
    )
    np.testing.assert_allclose(value, [expected])


@pytest.mark.parametrize(
    "start_bit, length, signed",
    [
        (15, 16, True),
        (47, 16, True),
        (1, 10, False),
        (33, 10, False),
        (3, 12, True),
        (7, 1, False),
        (39, 4, True),
        (35, 12, True),
        (7, 32, False),
        (20, 20, True),
    ],
)
def test_decode_matches_bitwise_encoder(start_bit, length, signed):
    rng = np.random.default_rng(start_bit * 100 + length)
    raw = rng.integers(0, 1 << length, size=50)
    frames = np.array([encode_big_endian(int(r), start_bit, length) for r in raw], dtype="S8")
    expected = np.where(signed & (raw >= 1 << (length - 1)), raw - (1 << length), raw)
    decoded = decode_big_endian_signal(frames, start_bit, length, signed=signed)
    np.testing.assert_array_equal(decoded, expected)
    # The same frames as rows of bytes, and as a list of byte strings.
    as_rows = np.frombuffer(frames.tobytes(), dtype=np.uint8).reshape(-1, 8)
    np.testing.assert_array_equal(
        decode_big_endian_signal(as_rows, start_bit, length, signed=signed), expected
    )
    as_list = [bytes(f) for f in frames]
    np.testing.assert_array_equal(
        decode_big_endian_signal(as_list, start_bit, length, signed=signed), expected
    )


def test_decode_ignores_other_bits_and_pads_short_payloads():
    frame = bytearray(b"\xff" * 8)
    frame[1:3] = b"\x12\x34"
    assert decode_big_endian_signal([bytes(frame)], 15, 16)[0] == 0x1234
    assert decode_big_endian_signal([b"\x00\x12"], 15, 16)[0] == 0x1200


def test_decode_rejects_bad_signals_and_payloads():
    with pytest.raises(ValueError, match="does not fit"):
        decode_big_endian_signal([b"\x00"], 56, 2)
    with pytest.raises(ValueError, match="Invalid signal"):
        decode_big_endian_signal([b"\x00"], 64, 1)
    with pytest.raises(ValueError, match="at most 8 bytes"):
        decode_big_endian_signal(np.array([b"123456789"]), 7, 8)


# --- loader on the real segment -------------------------------------------------------------


@pytest.fixture(scope="module")
def segment():
    return load_comma2k19_segment(SEGMENT)


def _raw_can(name):
    return np.load(SEGMENT / "processed_log" / "CAN" / "raw_can" / name)


def _grid_times(frame):
    return frame.attrs["time_origin"][SEGMENT_NAME] + frame["time"].to_numpy()


def test_segment_layout_and_units(segment):
    features = [
        "steering_wheel_angle",
        "steering_wheel_velocity",
        "steering_wheel_acceleration",
        "lateral_acceleration",
        "yaw_rate",
        "yaw_acceleration",
        "speed",
    ]
    assert list(segment.columns) == [
        "recording",
        "driver",
        "setting",
        "split",
        "time",
        *features,
        TARGET,
    ]
    assert (segment["recording"] == SEGMENT_NAME).all()
    assert (segment["driver"] == "comma2k19").all()
    assert segment["setting"].isna().all()
    assert (segment["split"] == "unknown").all()
    units = segment.attrs["units"]
    assert units[TARGET] == "raw sensor units"
    assert units["speed"] == "m/s" and units["time"] == "s"
    for name in features[:-1]:
        assert units[name] == FEATURE_UNITS[name]
    assert not segment.drop(columns="setting").isna().any().any()
    assert np.isfinite(segment.iloc[:, 4:].to_numpy(dtype=float)).all()


def test_segment_time_grid_is_uniform(segment):
    time = segment["time"].to_numpy()
    assert time[0] == 0.0
    np.testing.assert_allclose(np.diff(time), 0.05, atol=1e-9)
    assert 59.0 < time[-1] < 60.0
    half = load_comma2k19_segment(SEGMENT, sampling_rate=10.0, recording="r")
    np.testing.assert_allclose(np.diff(half["time"]), 0.1, atol=1e-9)
    assert (half["recording"] == "r").all()
    assert abs(len(half) - len(segment) / 2) <= 1


def test_steering_angle_agrees_with_processed_signal(segment):
    folder = SEGMENT / "processed_log" / "CAN" / "steering_angle"
    reference = np.deg2rad(
        np.interp(_grid_times(segment), np.load(folder / "t"), np.load(folder / "value"))
    )
    angle = segment["steering_wheel_angle"].to_numpy()
    assert np.corrcoef(angle, reference)[0, 1] > 0.99
    # Measured: identical to rounding (STEER_ANGLE + STEER_FRACTION is the processed signal).
    assert np.median(np.abs(angle - reference)) < np.deg2rad(0.05)
    assert np.max(np.abs(angle - reference)) < np.deg2rad(0.2)


def test_speed_agrees_with_wheel_speeds_decoded_from_can(segment):
    selected = (_raw_can("address") == 0xAA) & (_raw_can("src") == 0)
    data = _raw_can("data")[selected]
    wheels = [
        decode_big_endian_signal(data, b, 16, scale=0.01, offset=-67.67) for b in (7, 23, 39, 55)
    ]
    reference = np.interp(
        _grid_times(segment), _raw_can("t")[selected], np.mean(wheels, axis=0) / 3.6
    )
    speed = segment["speed"].to_numpy()
    assert np.corrcoef(speed, reference)[0, 1] > 0.99
    assert np.median(np.abs(speed - reference)) < 0.05
    assert speed.min() > 5.0 and speed.max() < 40.0


def test_vehicle_motion_is_consistent(segment):
    speed = segment["speed"].to_numpy()
    yaw_rate = segment["yaw_rate"].to_numpy()
    angle = segment["steering_wheel_angle"].to_numpy()
    assert np.abs(angle).max() < 0.5 and np.abs(yaw_rate).max() < 0.2
    assert np.abs(segment[TARGET]).max() < 1000

    # Kinematic (single-track) yaw rate: same sign when the car clearly turns.
    kinematic = speed * angle / STEERING_RATIO / WHEELBASE
    assert np.corrcoef(yaw_rate, kinematic)[0, 1] > 0.6
    turning = np.abs(kinematic) > 0.01
    assert turning.sum() > 20
    assert np.mean(np.sign(yaw_rate[turning]) == np.sign(kinematic[turning])) > 0.75

    # The phone gyro (device frame forward, right, down) turns the other way round its z axis.
    imu = SEGMENT / "processed_log" / "IMU" / "gyro"
    gyro_down = np.interp(_grid_times(segment), np.load(imu / "t"), np.load(imu / "value")[:, 2])
    assert np.corrcoef(yaw_rate, -gyro_down)[0, 1] > 0.6

    # Lateral acceleration is positive to the left, like speed * yaw rate.
    smooth = np.ones(20) / 20
    lateral = np.convolve(segment["lateral_acceleration"], smooth, mode="valid")
    centripetal = np.convolve(speed * yaw_rate, smooth, mode="valid")
    assert np.corrcoef(lateral, centripetal)[0, 1] > 0.6


def test_derivatives_are_consistent(segment):
    rate = segment["steering_wheel_velocity"].to_numpy()
    acceleration = segment["steering_wheel_acceleration"].to_numpy()
    assert np.corrcoef(np.gradient(rate, 0.05), acceleration)[0, 1] > 0.7
    yaw_acceleration = segment["yaw_acceleration"].to_numpy()
    assert np.corrcoef(np.gradient(segment["yaw_rate"], 0.05), yaw_acceleration)[0, 1] > 0.5
    # The decoded rate is the rate of the decoded angle (loosely: both are coarse).
    angle_rate = np.gradient(segment["steering_wheel_angle"], 0.05)
    assert np.corrcoef(angle_rate, rate)[0, 1] > 0.3


def test_eps_torque_is_optional():
    frame = load_comma2k19_segment(SEGMENT, eps_torque=True)
    assert list(frame.columns[-2:]) == ["eps_torque", TARGET]
    assert frame.attrs["units"]["eps_torque"] == "raw sensor units"


def test_missing_folder_is_named(tmp_path):
    with pytest.raises(FileNotFoundError, match="no_such_segment"):
        load_comma2k19_segment(tmp_path / "no_such_segment")


def test_missing_file_is_named(tmp_path):
    copy = tmp_path / "route" / "40"
    shutil.copytree(SEGMENT, copy)
    (copy / "processed_log" / "CAN" / "raw_can" / "data").unlink()
    with pytest.raises(FileNotFoundError, match=r"raw_can/data"):
        load_comma2k19_segment(copy)


def test_segment_without_toyota_frames_is_refused(tmp_path):
    copy = tmp_path / "route" / "40"
    shutil.copytree(SEGMENT, copy)
    address_file = copy / "processed_log" / "CAN" / "raw_can" / "address"
    address = np.load(address_file)
    address[address == 0x260] = 0x7FF
    with open(address_file, "wb") as f:
        np.save(f, address)
    with pytest.raises(ValueError, match="STEER_TORQUE_SENSOR"):
        load_comma2k19_segment(copy)


@pytest.mark.parametrize("rate", [0, -1.0, np.inf, "20", True])
def test_invalid_sampling_rate(rate, tmp_path):
    with pytest.raises(ValueError, match="sampling_rate"):
        load_comma2k19_segment(tmp_path, sampling_rate=rate)
