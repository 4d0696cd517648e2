"""The comma2k19 loader's CAN decoding with openpilot's DBC (skhmmgmr[can]): equal to the built-in
table, the engagement columns checked against the raw frames, and the driver-only spans."""

import shutil
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from _comma2k19_data import SEGMENT, SEGMENT_NAME

from skhmmgmr.datasets import fetch_comma2k19, load_comma2k19_segment
from skhmmgmr.datasets._comma2k19 import _can as can
from skhmmgmr.datasets._comma2k19._segment import ENGAGEMENT

RAW_CAN = Path("processed_log", "CAN", "raw_can")


def _dbc_installed():
    try:
        can.dbc_decoder()
    except ImportError:
        return False
    return True


needs_dbc = pytest.mark.skipif(not _dbc_installed(), reason="skhmmgmr[can] not installed")


def _block_extra(monkeypatch):
    """Make ``import cantools`` fail, as when skhmmgmr[can] is not installed."""
    monkeypatch.setitem(sys.modules, "cantools", None)
    can.dbc_decoder.cache_clear()


@pytest.fixture
def without_extra(monkeypatch):
    _block_extra(monkeypatch)


def _raw(name, folder=SEGMENT):
    return np.load(folder / RAW_CAN / name)


def _frames(address, bus=0):
    """Times and payloads (padded to 8 bytes) of one message in the example segment."""
    selected = (_raw("address") == address) & (_raw("src") == bus)
    return _raw("t")[selected], [bytes(p).ljust(8, b"\0") for p in _raw("data")[selected]]


def _boot_times(frame, recording):
    rows = frame["recording"] == recording
    return frame.attrs["time_origin"][recording] + frame.loc[rows, "time"].to_numpy()


@pytest.fixture(scope="module")
def engaged():
    return load_comma2k19_segment(SEGMENT, engagement=True)


# --- the DBC and the table agree ------------------------------------------------------------


@needs_dbc
def test_table_is_the_dbc_definitions():
    database = can.dbc_decoder().database
    for (message, name), signal in can.TABLE.items():
        definition = database.get_message_by_name(message)
        assert definition.frame_id == signal.address
        dbc = definition.get_signal_by_name(name)
        assert dbc.byte_order == "big_endian"
        assert (dbc.start, dbc.length, dbc.is_signed) == signal[1:4]
        assert (dbc.scale, dbc.offset) == (signal.scale, signal.offset)


@needs_dbc
def test_dbc_and_table_decode_the_segment_to_the_last_bit():
    dbc, table = can.dbc_decoder(), can.TableDecoder()
    messages = {message for message, _ in can.TABLE}
    for message in messages:
        address = table.frame_id(message)
        assert dbc.frame_id(message) == address
        data = _raw("data")[(_raw("address") == address) & (_raw("src") == 0)]
        expected = table.decode(message, data)
        decoded = dbc.decode(message, data)
        assert len(data) > 1000
        for name, values in expected.items():
            np.testing.assert_array_equal(decoded[name], values, err_msg=f"{message}.{name}")


@needs_dbc
def test_loader_gives_the_same_frame_with_and_without_the_extra(monkeypatch):
    assert isinstance(can.can_decoder(), can.DbcDecoder)
    with_dbc = load_comma2k19_segment(SEGMENT, eps_torque=True)
    _block_extra(monkeypatch)
    assert isinstance(can.can_decoder(), can.TableDecoder)
    with_table = load_comma2k19_segment(SEGMENT, eps_torque=True)
    pd.testing.assert_frame_equal(with_dbc, with_table, check_exact=True)
    assert with_dbc.attrs == with_table.attrs


def test_engagement_options_need_the_extra(without_extra, tmp_path):
    for options in ({"engagement": True}, {"steering": "driver"}):
        with pytest.raises(ImportError, match=r"pip install 'skhmmgmr\[can\]'"):
            load_comma2k19_segment(tmp_path, **options)
    with pytest.raises(ImportError, match=r"skhmmgmr\[can\]"):
        can.TableDecoder().frame_id("EPS_STATUS")


def test_loader_without_the_extra_uses_the_table(without_extra):
    frame = load_comma2k19_segment(SEGMENT)
    assert len(frame) == 1200 and "cruise_active" not in frame


@pytest.mark.parametrize(
    "options, match",
    [
        ({"steering": "openpilot"}, "'steering' parameter of load_comma2k19_segment"),
        ({"steering": None}, "'steering' parameter of load_comma2k19_segment"),
        ({"min_span": -1.0}, "min_span"),
        ({"min_span": np.nan}, "min_span"),
        ({"min_span": True}, "min_span"),
    ],
)
def test_invalid_steering_options(options, match, tmp_path):
    with pytest.raises(ValueError, match=match):
        load_comma2k19_segment(tmp_path, **options)


# --- engagement columns ---------------------------------------------------------------------


@needs_dbc
def test_engagement_columns_layout(engaged):
    names = list(ENGAGEMENT)
    assert list(engaged.columns[-len(names) - 1 : -1]) == names
    assert engaged.columns[-1] == "driver_torque"
    assert engaged.attrs["units"]["openpilot_steer_command"] == "raw command units"
    for name in set(names) - {"openpilot_steer_command"}:
        assert set(np.unique(engaged[name])) <= {0.0, 1.0}
        assert engaged.attrs["units"][name] == "flag (0 or 1)"
    plain = load_comma2k19_segment(SEGMENT)
    pd.testing.assert_frame_equal(engaged.drop(columns=names), plain, check_exact=True)


def _held(times, payloads, grid, read):
    """``read`` of the last payload at or before each grid time (the first one before it)."""
    last = np.maximum(np.searchsorted(times, grid, side="right") - 1, 0)
    return np.array([read(payloads[i]) for i in last], dtype=float)


@needs_dbc
def test_engagement_columns_match_the_raw_frames(engaged):
    """Every row, decoded here bit by bit from the DBC's positions (big-endian start bit 8k+j is
    bit j of byte k)."""
    grid = _boot_times(engaged, SEGMENT_NAME)
    cruise, lka, eps = _frames(0x1D2), _frames(0x2E4, bus=128), _frames(0x262)
    torque_sensor, brake = _frames(0x260), _frames(0x224)
    expected = {
        "cruise_active": _held(*cruise, grid, lambda p: p[0] >> 5 & 1),
        "gas_pressed": _held(*cruise, grid, lambda p: 1 - (p[0] >> 4 & 1)),
        "openpilot_steer_request": _held(*lka, grid, lambda p: p[0] & 1),
        "openpilot_steer_command": _held(
            *lka, grid, lambda p: int.from_bytes(p[1:3], "big", signed=True)
        ),
        # LKA_STATE: 7 bits from bit 31 (bits 7..1 of byte 3); 5 is "active"
        "eps_lka_active": _held(*eps, grid, lambda p: p[3] >> 1 == 5),
        "steer_override": _held(*torque_sensor, grid, lambda p: p[0] & 1),
        "brake_pressed": _held(*brake, grid, lambda p: p[0] >> 5 & 1),
    }
    for name, values in expected.items():
        np.testing.assert_array_equal(engaged[name], values, err_msg=name)


@needs_dbc
def test_engagement_tells_the_story_of_the_segment(engaged):
    """Hand-read from the frames: the driver steers until openpilot engages at 9.02 s (cruise),
    9.04 s (steering request) and 9.06 s (power steering active), then openpilot steers to the
    end, but for request gaps of 10 to 90 ms; nobody brakes, the driver never overrides."""
    time = engaged["time"].to_numpy()
    before, after = time < 8.9, time > 9.2
    for name in ("cruise_active", "openpilot_steer_request", "eps_lka_active"):
        assert (engaged.loc[before, name] == 0).all()
        assert engaged.loc[after, name].mean() > 0.99
    assert (engaged.loc[after, "cruise_active"] == 1).all()
    assert (engaged[["steer_override", "brake_pressed"]] == 0).all().all()
    command = engaged["openpilot_steer_command"]
    assert (command[engaged["openpilot_steer_request"] == 0] == 0).all()
    assert 100 < command.abs().max() < 1500
    # The driver holds the accelerator before engaging, not after.
    assert engaged.loc[time < 8.5, "gas_pressed"].all()
    assert not engaged.loc[after, "gas_pressed"].any()


# --- driver-only spans ----------------------------------------------------------------------


@needs_dbc
def test_driver_keeps_only_the_rows_the_driver_steers_alone(engaged):
    driver = load_comma2k19_segment(SEGMENT, engagement=True, steering="driver")
    span = f"{SEGMENT_NAME}/span0"
    assert list(driver["recording"].unique()) == [span]
    assert (driver[["openpilot_steer_request", "eps_lka_active"]] == 0).all().all()
    # The first 9.05 s of the segment, with the values of the whole frame.
    alone = (engaged["openpilot_steer_request"] == 0) & (engaged["eps_lka_active"] == 0)
    assert alone[:181].all() and not alone[181]
    assert len(driver) == 181
    pd.testing.assert_frame_equal(
        driver.drop(columns=["recording", "time"]),
        engaged.iloc[:181].drop(columns=["recording", "time"]),
        check_exact=True,
    )
    np.testing.assert_allclose(driver["time"], np.arange(181) * 0.05, rtol=0, atol=1e-12)
    np.testing.assert_allclose(
        _boot_times(driver, span), _boot_times(engaged, SEGMENT_NAME)[:181], rtol=0, atol=1e-9
    )


@needs_dbc
def test_spans_become_separate_recordings():
    """At 100 Hz the short request gaps at 29.03 s and 34.70 s leave driver-alone rows too."""
    full = load_comma2k19_segment(SEGMENT, engagement=True, sampling_rate=100.0)
    alone = ((full["openpilot_steer_request"] == 0) & (full["eps_lka_active"] == 0)).to_numpy()
    every = load_comma2k19_segment(SEGMENT, steering="driver", min_span=0, sampling_rate=100.0)
    names = list(every["recording"].unique())
    assert names == [f"{SEGMENT_NAME}/span{k}" for k in range(len(names))]
    assert len(names) >= 3 and len(every) == alone.sum()
    boots = [_boot_times(every, name) for name in names]
    for earlier, later in zip(boots, boots[1:], strict=False):
        assert later[0] - earlier[-1] > 0.015  # at least one removed row between spans
    for name in names:
        time = every.loc[every["recording"] == name, "time"].to_numpy()
        assert time[0] == 0.0
        np.testing.assert_allclose(np.diff(time), 0.01, atol=1e-12)
    # A minimum of 50 ms (5 rows at 100 Hz) drops the shorter spans; the rest are renumbered.
    kept = load_comma2k19_segment(SEGMENT, steering="driver", min_span=0.05, sampling_rate=100.0)
    sizes = every.groupby("recording", sort=False).size().to_numpy()
    assert kept.groupby("recording", sort=False).size().tolist() == [n for n in sizes if n >= 5]
    assert set(kept["recording"]) == {f"{SEGMENT_NAME}/span{k}" for k in range(sum(sizes >= 5))}
    assert set(kept.attrs["time_origin"]) == set(kept["recording"])


@needs_dbc
def test_no_span_long_enough_gives_a_frame_without_rows():
    frame = load_comma2k19_segment(SEGMENT, steering="driver", min_span=30.0)
    assert len(frame) == 0 and frame.attrs["time_origin"] == {}
    assert list(frame.columns) == list(load_comma2k19_segment(SEGMENT).columns)


# --- segments without some messages ---------------------------------------------------------


@pytest.fixture
def copy(tmp_path):
    folder = tmp_path / "b0c9d2329ad1606b--2018-08-02--08-34-47" / "40"
    shutil.copytree(SEGMENT / "processed_log" / "CAN", folder / "processed_log" / "CAN")
    return folder


def _relabel(folder, address, bus, new_address=0x7FF):
    file = folder / RAW_CAN / "address"
    values = np.load(file)
    values[(values == address) & (_raw("src", folder) == bus)] = new_address
    with open(file, "wb") as f:
        np.save(f, values)


@needs_dbc
def test_missing_engagement_message_is_named(copy):
    _relabel(copy, 0x262, 0)
    assert len(load_comma2k19_segment(copy)) == 1200
    with pytest.raises(ValueError, match=rf"{copy}.*EPS_STATUS.*0x262.*bus 0"):
        load_comma2k19_segment(copy, engagement=True)


@needs_dbc
def test_segment_without_openpilot_commands(copy):
    """Without the frames openpilot sent, nothing requested steering: the power steering's
    state alone decides which rows the driver steers."""
    _relabel(copy, 0x2E4, 128)
    frame = load_comma2k19_segment(copy, engagement=True)
    assert (frame[["openpilot_steer_request", "openpilot_steer_command"]] == 0).all().all()
    driver = load_comma2k19_segment(copy, engagement=True, steering="driver", min_span=0)
    assert len(driver) == (frame["eps_lka_active"] == 0).sum()


# --- fetch_comma2k19 ------------------------------------------------------------------------


def test_fetch_checks_the_extra_before_downloading(without_extra, tmp_path):
    with pytest.raises(ImportError, match=r"skhmmgmr\[can\]"):
        fetch_comma2k19(data_home=tmp_path, base_url="http://127.0.0.1:9/", steering="driver")
    with pytest.raises(ValueError, match="steering"):
        fetch_comma2k19(data_home=tmp_path, base_url="http://127.0.0.1:9/", steering="car")
    assert not (tmp_path / "comma2k19").exists()
