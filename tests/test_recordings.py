"""Tests of load_recordings on CSV, Parquet and DataFrame inputs."""

import numpy as np
import pandas as pd
import pytest
from numpy.testing import assert_array_equal

from skhmmgmr.datasets import load_recordings, make_lane_keeping


def _recording(n=5, rate=10.0, start=0.0, seed=0):
    rng = np.random.default_rng(seed)
    return pd.DataFrame(
        {
            "time": start + np.arange(n) / rate,
            "steering_wheel_angle": rng.normal(size=n),
            "yaw_rate": rng.normal(size=n),
            "driver_torque": rng.normal(size=n),
        }
    )


def test_one_file_per_recording_csv_and_parquet(tmp_path):
    _recording(seed=1).to_csv(tmp_path / "monday.csv", index=False)
    _recording(n=3, seed=2).to_parquet(tmp_path / "tuesday.parquet")
    frame = load_recordings([tmp_path / "monday.csv", tmp_path / "tuesday.parquet"])
    assert list(frame.columns) == [
        "recording", "driver", "setting", "split", "time",
        "steering_wheel_angle", "yaw_rate", "driver_torque",
    ]  # fmt: skip
    assert frame["recording"].tolist() == ["monday"] * 5 + ["tuesday"] * 3
    assert (frame["driver"] == "unknown").all() and (frame["split"] == "unknown").all()
    assert frame["setting"].isna().all()
    np.testing.assert_allclose(frame["yaw_rate"].iloc[5:], _recording(n=3, seed=2)["yaw_rate"])
    assert frame.attrs["units"] == {
        "time": "s",
        "steering_wheel_angle": "rad",
        "yaw_rate": "rad/s",
        "driver_torque": "Nm",
    }
    # A folder gives its files in name order.
    assert load_recordings(tmp_path).equals(frame)


def test_recording_column_custom_names_and_units():
    raw = pd.concat(
        [_recording(seed=1).assign(run=7), _recording(seed=2).assign(run=8)], ignore_index=True
    ).rename(columns={"time": "t", "driver_torque": "tau", "yaw_rate": "r"})
    raw["driver"] = "anna"
    frame = load_recordings(
        raw,
        recording="run",
        time="t",
        target="tau",
        features=["r", "steering_wheel_angle"],
        sampling_rate=10.0,
        units={"r": "rad/s", "tau": "raw"},
    )
    assert list(frame.columns[4:]) == ["time", "r", "steering_wheel_angle", "driver_torque"]
    assert frame["recording"].tolist() == ["7"] * 5 + ["8"] * 5
    assert (frame["driver"] == "anna").all()
    assert frame.attrs["units"] == {
        "time": "s",
        "r": "rad/s",
        "steering_wheel_angle": "rad",
        "driver_torque": "raw",
    }
    assert load_recordings(raw, recording="run", time="t", target="tau", features="r").shape == (
        10,
        7,
    )


def test_interleaved_recordings_are_gathered_stably():
    a, b = _recording(seed=1).assign(recording="b"), _recording(seed=2).assign(recording="a")
    raw = pd.concat([a, b]).sort_values("time", kind="stable").reset_index(drop=True)
    frame = load_recordings(raw)
    assert frame["recording"].tolist() == ["b"] * 5 + ["a"] * 5
    np.testing.assert_allclose(frame["driver_torque"].iloc[:5], a["driver_torque"])
    np.testing.assert_allclose(frame["time"].iloc[5:], b["time"])


def test_missing_columns_are_listed_with_available_ones(tmp_path):
    _recording().drop(columns="driver_torque").to_csv(tmp_path / "r1.csv", index=False)
    with pytest.raises(ValueError, match=r"r1\.csv.*\['driver_torque'\].*'yaw_rate'"):
        load_recordings(tmp_path / "r1.csv")
    with pytest.raises(ValueError, match=r"\['recording', 'lane'\]"):
        load_recordings(_recording(), features=["yaw_rate", "lane"])


def test_rows_are_sorted_by_time_within_each_recording(tmp_path):
    a, b = _recording(seed=1).assign(recording="b"), _recording(seed=2).assign(recording="a")
    raw = pd.concat([a.iloc[[3, 0, 4, 1, 2]], b.iloc[[1, 0]], a.iloc[[]], b.iloc[[4, 2, 3]]])
    raw.to_parquet(tmp_path / "shuffled.parquet")
    raw.to_csv(tmp_path / "shuffled.csv", index=False)
    expected = load_recordings(pd.concat([a, b], ignore_index=True))
    for source in (raw, tmp_path / "shuffled.parquet", tmp_path / "shuffled.csv"):
        pd.testing.assert_frame_equal(load_recordings(source), expected)


def test_duplicated_time_is_named():
    raw = _recording().assign(recording="x")
    raw.loc[2, "time"] = raw.loc[1, "time"]
    with pytest.raises(ValueError, match=r"'x'.*row 2.*repeats the time"):
        load_recordings(raw)
    shuffled = raw.iloc[[2, 0, 3, 4, 1]]  # both rows at 0.1 s, now rows 0 and 4, apart
    with pytest.raises(ValueError, match=r"'x'.*row 4, time 0\.1\).*repeats the time"):
        load_recordings(shuffled.reset_index(drop=True))


@pytest.mark.parametrize("column", ["recording", "run"])
@pytest.mark.parametrize("ids", [("7", "007"), ("1e3", "1000"), ("TRUE", "True")])
def test_recording_ids_are_read_as_text(tmp_path, ids, column):
    raw = pd.concat([_recording().assign(**{column: i}) for i in ids], ignore_index=True)
    raw.to_csv(tmp_path / "ids.csv", index=False)
    frame = load_recordings(tmp_path / "ids.csv", recording=column)
    assert frame["recording"].unique().tolist() == list(ids)


def _gzip_cut(path):
    import gzip

    data = gzip.compress(b"recording,time,x,driver_torque\n" + b"a,0,1,2\n" * 2000)
    path.write_bytes(data[: len(data) // 2])


UNREADABLE = {
    "empty.csv": (b"", "the file is empty"),
    "header.csv": (b"recording,time,x,driver_torque\n", "no data row"),
    "garbage.csv": (bytes(range(256)) * 8, "Cannot read"),
    "garbage.parquet": (b"PAR1 not really", "Cannot read"),
    "cut.csv.gz": (_gzip_cut, "Cannot read"),
    "ragged.csv": (b"recording,time,x,driver_torque\na,0,1,2\na,0.1,1,2,3\n", "fields"),
    "longer.csv": (b"time,x,driver_torque\n7,0,1,2\n7,0.1,1,2\n", "more fields"),
    "latin.csv": ("recording,time,vitesse_é\na,0,1\n".encode("latin-1"), "not UTF-8"),
}


@pytest.mark.parametrize("name", UNREADABLE)
def test_unreadable_files_are_named(tmp_path, name):
    content, message = UNREADABLE[name]
    path = tmp_path / name
    content(path) if callable(content) else path.write_bytes(content)
    with pytest.raises(ValueError, match=message) as info:
        load_recordings(path)
    assert str(path) in str(info.value)


@pytest.mark.parametrize("bad, kind", [(np.nan, "NaN"), (np.inf, "an infinite value")])
def test_non_finite_values_are_named(bad, kind):
    raw = pd.concat(
        [_recording().assign(recording="ok"), _recording().assign(recording="bad")],
        ignore_index=True,
    )
    raw.loc[8, "yaw_rate"] = bad
    raw.loc[9, "driver_torque"] = bad
    with pytest.raises(ValueError, match=rf"'yaw_rate' holds {kind}.*'bad'.*row 8, time 0\.3"):
        load_recordings(raw)


def test_non_uniform_sampling_is_refused_only_when_a_rate_is_given():
    raw = _recording(n=6).assign(recording="jittery")
    raw.loc[4:, "time"] += 0.03
    assert len(load_recordings(raw)) == 6
    with pytest.raises(ValueError, match=r"'jittery' is not sampled at 10\.0 Hz.*row 4"):
        load_recordings(raw, sampling_rate=10.0)
    with pytest.raises(ValueError, match="sampling_rate"):
        load_recordings(raw, sampling_rate=0)


def test_recording_in_two_files_and_clashing_stems(tmp_path):
    _recording().assign(recording="same").to_csv(tmp_path / "one.csv", index=False)
    _recording().assign(recording="same").to_csv(tmp_path / "two.csv", index=False)
    with pytest.raises(ValueError, match=r"'same' is in more than one source.*one\.csv.*two\.csv"):
        load_recordings(tmp_path)
    (tmp_path / "sub").mkdir()
    _recording().to_csv(tmp_path / "sub" / "one.csv", index=False)
    with pytest.raises(ValueError, match="would both be recording 'one'"):
        load_recordings([tmp_path / "one.csv", tmp_path / "sub" / "one.csv"])


def test_features_must_agree_across_files(tmp_path):
    _recording().to_csv(tmp_path / "a.csv", index=False)
    _recording().drop(columns="yaw_rate").to_csv(tmp_path / "b.csv", index=False)
    with pytest.raises(ValueError, match=r"b\.csv.*differ.*a\.csv"):
        load_recordings(tmp_path)
    frame = load_recordings(tmp_path, features=["steering_wheel_angle"])
    assert frame["recording"].unique().tolist() == ["a", "b"]


def test_bad_inputs(tmp_path):
    with pytest.raises(FileNotFoundError, match="nowhere.csv"):
        load_recordings(tmp_path / "nowhere.csv")
    (tmp_path / "notes.txt").write_text("x")
    with pytest.raises(ValueError, match="CSV"):
        load_recordings(tmp_path / "notes.txt")
    with pytest.raises(ValueError, match="no CSV or Parquet"):
        load_recordings(tmp_path)
    with pytest.raises(ValueError, match="No recordings"):
        load_recordings([])
    with pytest.raises(ValueError, match=r"\['comment'\] .* not numeric"):
        load_recordings(_recording().assign(recording="r", comment="hi"))


def test_meta_columns_are_not_features_and_recording_ids_are_required():
    raw = _recording().assign(recording="r").rename(columns={"time": "t"})
    raw["time"] = 1.0  # a stray column named like the schema's time
    frame = load_recordings(raw, time="t")
    assert list(frame.columns[5:]) == ["steering_wheel_angle", "yaw_rate", "driver_torque"]
    with pytest.raises(ValueError, match="cannot be features"):
        load_recordings(raw, time="t", features=["yaw_rate", "time"])
    raw.loc[2, "recording"] = None
    with pytest.raises(ValueError, match="'recording' of the DataFrame is empty in row 2"):
        load_recordings(raw, time="t")


def test_a_frame_of_the_simulator_written_to_a_file_loads_back_as_it_was(tmp_path):
    # The text column "manoeuvre" was taken for a feature and refused ("not numeric").
    simulated = make_lane_keeping(20.0, scenario="lane_change", sampling_rate=20.0, random_state=0)
    assert set(simulated["manoeuvre"]) > {"lane_keeping"}  # a lane change is in it
    simulated.to_csv(tmp_path / "simulated.csv", index=False)
    loaded = load_recordings(tmp_path / "simulated.csv", sampling_rate=20.0)
    assert list(loaded.columns) == list(simulated.columns)
    for name in simulated.columns:
        if name == "setting":  # a float column once in a file
            assert (loaded[name] == simulated[name]).all()
        else:
            pd.testing.assert_series_equal(loaded[name], simulated[name], check_dtype=False)
    assert loaded.attrs["units"] == simulated.attrs["units"]
    with pytest.raises(ValueError, match="meta, time or target"):
        load_recordings(tmp_path / "simulated.csv", features=["manoeuvre", "yaw_rate"])
    # on a grid, the labels are held (every sample a little early: its own), not interpolated
    jittered = simulated.assign(time=simulated["time"] - np.tile([0.0, 0.004], 200))
    jittered.to_parquet(tmp_path / "jittered.parquet")
    gridded = load_recordings(tmp_path / "jittered.parquet", sampling_rate=20.0, max_gap=0.2)
    kept = simulated.iloc[: len(gridded)]  # the grid ends at the last sample
    assert len(gridded) == 399 and gridded["manoeuvre"].tolist() == kept["manoeuvre"].tolist()
    assert_array_equal(gridded["crossing_time"], kept["crossing_time"])


def test_sources_with_and_without_the_simulators_labels_are_refused_together(tmp_path):
    simulated = make_lane_keeping(2.0, sampling_rate=10.0, random_state=0)
    simulated.to_csv(tmp_path / "a.csv", index=False)
    simulated.drop(columns=["manoeuvre", "crossing_time"]).assign(recording="b").to_csv(
        tmp_path / "b.csv", index=False
    )
    with pytest.raises(ValueError, match=r"label column\(s\) \[\]"):
        load_recordings(tmp_path)
