"""Tests of the tidy-frame builder and of the loaders that go through it."""

import numpy as np
import pandas as pd
import pytest

from skhmmgmr.datasets import (
    load_comma2k19_segment,
    load_recordings,
    make_lane_keeping,
)
from skhmmgmr.datasets._frame import concat_frames, tidy_frame
from skhmmgmr.datasets._simulator import _lane_keeping

# --- the builder on hand-made columns ---------------------------------------------------------


def _columns(**changes):
    """Two recordings "7" and "007" of 3 rows each, columns deliberately out of order."""
    columns = {
        "driver_torque": [0.1, 0.2, 0.3, -0.1, -0.2, -0.3],
        "yaw_rate": [1, 2, 3, 4, 5, 6],
        "time": [0.0, 0.1, 0.2, 0.0, 0.1, 0.2],
        "split": "train",
        "recording": ["7", "7", "7", "007", "007", "007"],
        "lane_width": [3.5] * 6,
    }
    columns.update(changes)
    return columns


def _message(excinfo):
    return str(excinfo.value)


def test_column_order_dtypes_and_defaults():
    frame = tidy_frame(_columns())
    assert list(frame.columns) == [
        "recording", "driver", "setting", "split", "time", "yaw_rate", "lane_width",
        "driver_torque",
    ]  # fmt: skip
    assert frame["recording"].tolist() == ["7", "7", "7", "007", "007", "007"]
    assert frame["recording"].nunique() == 2
    for name in ("recording", "driver", "split"):
        assert pd.api.types.is_string_dtype(frame[name])
        assert all(type(v) is str for v in frame[name])
    assert frame["driver"].tolist() == ["unknown"] * 6
    assert frame["split"].tolist() == ["train"] * 6
    assert frame["setting"].isna().all()
    for name in ("time", "yaw_rate", "lane_width", "driver_torque"):
        assert frame[name].dtype == np.float64
    assert frame["yaw_rate"].tolist() == [1.0, 2.0, 3.0, 4.0, 5.0, 6.0]
    assert frame.attrs == {
        "units": {"time": "s", "yaw_rate": "rad/s", "lane_width": "unknown", "driver_torque": "Nm"}
    }


def test_numeric_ids_become_text_and_settings_keep_their_dtype():
    frame = tidy_frame(
        {"recording": np.array([7, 7, 8]), "setting": np.array([3, 3, 5]), "time": [0, 1, 0]},
        units={"time": "ms", "absent": "m"},
        attrs={"origin": "hand"},
    )
    assert frame["recording"].tolist() == ["7", "7", "8"]
    assert frame["setting"].dtype == np.int64
    assert frame.attrs == {"units": {"time": "ms"}, "origin": "hand"}
    # A pandas Series keeps its values, whatever its index.
    series = pd.Series([1.0, 2.0], index=[10, 20])
    assert tidy_frame({"recording": "a", "x": series})["x"].tolist() == [1.0, 2.0]


@pytest.mark.parametrize("bad, kind", [(np.nan, "NaN"), (-np.inf, "an infinite value")])
def test_non_finite_value_names_column_recording_and_first_row(bad, kind):
    torque = [0.1, 0.2, 0.3, -0.1, bad, bad]
    yaw_rate = [1, 2, 3, 4, 5, bad]
    with pytest.raises(ValueError) as excinfo:
        tidy_frame(_columns(driver_torque=torque, yaw_rate=yaw_rate))
    assert _message(excinfo) == (
        f"The column 'driver_torque' holds {kind} in recording '007' (row 4, time 0.1); "
        "3 non-finite value(s) in all. Fill or drop them first."
    )


def test_source_and_row_numbers_are_named():
    with pytest.raises(ValueError) as excinfo:
        tidy_frame(
            _columns(lane_width=[3.5, np.nan, 3.5, 3.5, 3.5, 3.5]),
            source="file 'a.csv'",
            row=[10, 11, 12, 0, 1, 2],
        )
    assert "recording '7' (file 'a.csv', row 11, time 0.1)" in _message(excinfo)


@pytest.mark.parametrize(
    "time, problem, previous",
    [
        ([0.0, 0.1, 0.2, 0.0, 0.1, 0.05], "goes back in time", "0.1"),
        ([0.0, 0.1, 0.2, 0.0, 0.1, 0.1], "repeats the time of row 4", "0.1"),
    ],
)
def test_time_must_increase_within_each_recording(time, problem, previous):
    with pytest.raises(ValueError) as excinfo:
        tidy_frame(_columns(time=time))
    assert _message(excinfo) == (
        f"The row of recording '007' (row 5, time {time[5]}) {problem} (previous time "
        f"{previous}). Rows of a recording must have strictly increasing times."
    )


def test_time_restarts_between_recordings_and_is_optional():
    assert len(tidy_frame(_columns(time=[5.0, 6.0, 7.0, 0.0, 1.0, 2.0]))) == 6
    frame = tidy_frame({"recording": ["a", "a"], "driver_torque": [1.0, 2.0]})
    assert list(frame.columns) == ["recording", "driver", "setting", "split", "driver_torque"]
    assert frame.attrs["units"] == {"driver_torque": "Nm"}


def test_rows_of_a_recording_must_be_contiguous():
    recording = ["7", "7", "007", "007", "7", "007"]
    with pytest.raises(ValueError, match=r"recording .7. \(row 4, time 0\.1\) comes after rows"):
        tidy_frame(_columns(recording=recording, time=[0, 1, 0, 1, 0.1, 2]))


@pytest.mark.parametrize("column", ["recording", "driver", "split"])
def test_empty_ids_are_refused(column):
    values = ["a", "a", None, "b", "b", "b"] if column == "recording" else ["x"] * 6
    if column != "recording":
        values[2] = np.nan
    with pytest.raises(ValueError, match=rf"The column '{column}' is empty in .*row 2, time 0\.2"):
        tidy_frame(_columns(**{column: values}))


def test_sampling_rate_is_checked_when_given():
    time = [0.0, 0.1, 0.2, 0.0, 0.1, 0.25]
    assert len(tidy_frame(_columns(time=time))) == 6
    with pytest.raises(ValueError, match=r"'007' is not sampled at 10\.0 Hz: the row of .*row 5"):
        tidy_frame(_columns(time=time), sampling_rate=10.0)


def test_malformed_columns():
    with pytest.raises(ValueError, match="needs a 'recording' column"):
        tidy_frame({"time": [0.0]})
    with pytest.raises(ValueError, match="different lengths"):
        tidy_frame({"recording": "a", "time": [0.0, 1.0], "x": [1.0]})
    with pytest.raises(ValueError, match="every column is a scalar"):
        tidy_frame({"recording": "a", "x": 1.0})
    with pytest.raises(ValueError, match="'x' is not numeric"):
        tidy_frame({"recording": "a", "x": ["left", "right"]})


def test_concat_frames_refuses_a_recording_in_two_frames():
    first = tidy_frame(_columns())
    second = tidy_frame(_columns(recording=["8"] * 3 + ["9"] * 3))
    joined = concat_frames([first, second], attrs={"source": "hand"})
    assert joined["recording"].tolist() == ["7"] * 3 + ["007"] * 3 + ["8"] * 3 + ["9"] * 3
    assert joined.index.tolist() == list(range(12))
    assert joined.attrs == {"units": first.attrs["units"], "source": "hand"}
    third = tidy_frame(_columns(recording=["9"] * 3 + ["10"] * 3))
    with pytest.raises(ValueError, match="The recording '9' is in frames 1 and 2"):
        concat_frames([first, second, third])
    other_units = tidy_frame(_columns(recording=["8"] * 3 + ["9"] * 3), units={"yaw_rate": "deg/s"})
    with pytest.raises(ValueError, match="different units"):
        concat_frames([first, other_units])
    with pytest.raises(ValueError, match="columns"):
        concat_frames([first, second.drop(columns="lane_width")])


# --- every loader goes through the builder ----------------------------------------------------


def _nan_message(column, recording, where, count):
    return (
        f"The column {column!r} holds NaN in recording {recording!r} ({where}); "
        f"{count} non-finite value(s) in all. Fill or drop them first."
    )


def test_simulator_goes_through_the_builder(monkeypatch):
    measure = _lane_keeping.measure

    def corrupted(*args):
        features, torque = measure(*args)
        features["yaw_rate"][3] = np.nan
        return features, torque

    monkeypatch.setattr(_lane_keeping, "measure", corrupted)
    with pytest.raises(ValueError) as excinfo:
        make_lane_keeping(0.1, recording="r", random_state=0)
    assert _message(excinfo) == _nan_message("yaw_rate", "r", "row 3, time 0.03", 1)


def test_recordings_go_through_the_builder(tmp_path):
    raw = pd.DataFrame(
        {"recording": "r", "time": np.arange(10) / 100.0, "yaw_rate": 0.0, "driver_torque": 0.0}
    )
    raw.loc[3, "yaw_rate"] = np.nan
    with pytest.raises(ValueError) as excinfo:
        load_recordings(raw)
    assert _message(excinfo) == _nan_message("yaw_rate", "r", "the DataFrame, row 3, time 0.03", 1)
    with pytest.raises(ValueError) as direct:
        tidy_frame(raw, source="the DataFrame")
    assert _message(direct) == _message(excinfo)

    raw = raw.fillna(0.0)
    raw.loc[4, "time"] = 0.03
    with pytest.raises(ValueError) as excinfo:
        load_recordings(raw)
    with pytest.raises(ValueError) as direct:
        tidy_frame(raw, source="the DataFrame")
    assert "'r' (the DataFrame, row 4, time 0.03) repeats the time" in _message(excinfo)
    assert _message(direct) == _message(excinfo)


def test_csv_recording_ids_are_read_as_text(tmp_path):
    raw = pd.DataFrame(
        {
            "recording": ["007", "007", "7", "7"],
            "driver": ["01", "01", "1", "1"],
            "time": [0.0, 0.1, 0.0, 0.1],
            "driver_torque": [0.1, 0.2, 0.3, 0.4],
        }
    )
    raw.to_csv(tmp_path / "runs.csv", index=False)
    frame = load_recordings(tmp_path / "runs.csv")
    assert frame["recording"].tolist() == ["007", "007", "7", "7"]
    assert frame["driver"].tolist() == ["01", "01", "1", "1"]
    raw.loc[2, "driver"] = None
    raw.to_csv(tmp_path / "runs.csv", index=False)
    with pytest.raises(ValueError, match=r"'driver' is empty in recording '7' \(file .*row 2,"):
        load_recordings(tmp_path / "runs.csv")


def _save(path, array):
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "wb") as f:  # comma2k19 files are .npy files without the suffix
        np.save(f, array)


def _fake_segment(folder, speed):
    """A 2-second comma2k19 segment: zero CAN payloads at 50 Hz, speed at 100 Hz."""
    can_times = np.linspace(0.0, 2.0, 101)
    addresses = (0x260, 0x24, 0x25)
    raw_can = folder / "processed_log" / "CAN" / "raw_can"
    _save(raw_can / "t", np.tile(can_times, len(addresses)))
    _save(raw_can / "address", np.repeat(addresses, can_times.size))
    _save(raw_can / "src", np.zeros(can_times.size * len(addresses), dtype=np.uint8))
    _save(raw_can / "data", np.zeros(can_times.size * len(addresses), dtype="S8"))
    _save(folder / "processed_log" / "CAN" / "speed" / "t", np.linspace(0.0, 2.0, 201))
    _save(folder / "processed_log" / "CAN" / "speed" / "value", np.full((201, 1), speed))
    return folder


def test_comma2k19_goes_through_the_builder(tmp_path):
    frame = load_comma2k19_segment(_fake_segment(tmp_path / "ok", 20.0), recording="seg")
    assert list(frame.columns[:5]) == ["recording", "driver", "setting", "split", "time"]
    assert frame.columns[-1] == "driver_torque"
    assert frame["recording"].tolist() == ["seg"] * 41
    assert frame["split"].tolist() == ["unknown"] * 41 and frame["setting"].isna().all()
    assert frame.attrs["units"]["speed"] == "m/s"
    assert frame.attrs["time_origin"] == {"seg": 0.0}

    with pytest.raises(ValueError) as excinfo:
        load_comma2k19_segment(_fake_segment(tmp_path / "bad", np.nan), recording="seg")
    assert _message(excinfo) == _nan_message("speed", "seg", "row 0, time 0", 41)


def test_a_tidy_frame_keeps_the_manoeuvre_and_its_crossing_time():
    frame = tidy_frame(
        {
            "recording": "r",
            "time": [0.0, 0.1, 0.2],
            "manoeuvre": ["lane_keeping", "evasive", "evasive"],
            "crossing_time": [np.nan, 0.2, 0.2],
            "yaw_rate": [0.0, 0.1, 0.2],
        }
    )
    assert list(frame.columns) == [
        "recording",
        "driver",
        "setting",
        "split",
        "time",
        "manoeuvre",
        "crossing_time",
        "yaw_rate",
    ]
    assert frame.attrs["units"] == {"time": "s", "crossing_time": "s", "yaw_rate": "rad/s"}
    with pytest.raises(ValueError, match="'manoeuvre' is empty"):
        tidy_frame({"recording": "r", "manoeuvre": [None, "evasive"], "yaw_rate": [0.0, 1.0]})
    with pytest.raises(ValueError, match="crossing_time"):
        tidy_frame({"recording": "r", "crossing_time": [np.inf, 1.0], "yaw_rate": [0.0, 1.0]})
