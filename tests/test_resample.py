"""Tests of resample_recordings and of load_recordings(max_gap=...), against hand-computed grids."""

import warnings

import numpy as np
import pandas as pd
import pytest

from skhmmgmr.datasets import load_recordings, make_lane_keeping, resample_recordings


def _log():
    """Two recordings: 'drive7' jittered, with a short gap (0.197 -> 0.5) and a long one."""
    return pd.DataFrame(
        {
            "recording": ["drive7"] * 8 + ["other"] * 3,
            "time": [0.0, 0.102, 0.197, 0.5, 0.6, 2.0, 2.099, 2.2, 0.0, 0.1, 0.25],
            "x": [1.0, 2.0, 0.0, 3.0, 4.0, -1.0, 5.0, 7.0, 0.0, 3.0, 6.0],
            "flag": [0, 0, 1, 1, 0, 1, 1, 0, 0, 1, 1],
        }
    )


def test_hand_computed_grid_short_gap_interpolated_long_gap_split():
    out = resample_recordings(_log(), 10.0, max_gap=0.35)
    assert list(out.columns) == ["recording", "time", "x", "flag"]
    assert out["recording"].tolist() == ["drive7/0"] * 7 + ["drive7/1"] * 3 + ["other"] * 3
    np.testing.assert_allclose(
        out["time"], [0.0, 0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 2.0, 2.1, 2.2, 0.0, 0.1, 0.2], atol=1e-12
    )
    # Between samples (t_i, x_i) and (t_j, x_j): x_i + (t - t_i) / (t_j - t_i) * (x_j - x_i).
    expected = [
        1.0, 1 + 50 / 51,                           # 0.1 in (0, 0.102)
        3 / 101, 103 / 101, 203 / 101,              # 0.2, 0.3, 0.4 in the gap (0.197, 0.5)
        3.0, 4.0,                                   # on samples
        -1.0, 5 + 2 / 101, 7.0,                     # second piece, 2.1 in (2.099, 2.2)
        0.0, 3.0, 5.0,                              # 0.2 in (0.1, 0.25); 0.3 > 0.25 not made
    ]  # fmt: skip
    np.testing.assert_allclose(out["x"], expected, rtol=0, atol=1e-12)
    # The integer flag is held: the value of the latest sample at or before the grid time.
    assert out["flag"].dtype == np.int64
    assert out["flag"].tolist() == [0, 0, 1, 1, 1, 1, 0, 1, 1, 0, 0, 1, 1]


def test_missing_samples_stay_missing():
    log = _log()
    log.loc[3, "x"] = np.nan  # t = 0.5
    out = resample_recordings(log, 10.0, max_gap=0.35)
    # 0.2 to 0.4 would need the sample at 0.5, and 0.5 is it; 0.1 and 0.6 do not.
    assert np.isnan(out["x"]).tolist()[:7] == [False, False, True, True, True, True, False]
    assert not np.isnan(out["x"].iloc[7:]).any()


@pytest.mark.parametrize("start, rate", [(0.0, 10.0), (12.345, 100.0), (1000.0, 20.0)])
def test_a_recording_on_the_grid_comes_back_unchanged(start, rate):
    rng = np.random.default_rng(0)
    n = 50
    frame = pd.DataFrame(
        {
            "recording": np.repeat(["a", "b"], n),
            # another rounding than the grid's start + k / rate
            "time": np.tile(start + np.arange(n) * (1 / rate), 2),
            "x": rng.normal(size=2 * n),
            "flag": rng.integers(0, 3, size=2 * n),
        }
    )
    frame.loc[[3, 77], "x"] = np.nan
    out = resample_recordings(frame, rate, max_gap=1.5 / rate)
    pd.testing.assert_frame_equal(out, frame, check_exact=False, rtol=0, atol=1e-12)


def test_a_tidy_frame_on_the_grid_comes_back_unchanged_with_its_attrs():
    frame = make_lane_keeping(2.0, sampling_rate=20.0, random_state=0, recording="sim")
    out = resample_recordings(frame, 20.0, max_gap=0.1)
    pd.testing.assert_frame_equal(out, frame, check_exact=False, rtol=0, atol=1e-12)
    assert out.attrs == frame.attrs


def test_piece_ids_numbered_in_time_order_before_min_length_drops():
    frame = pd.DataFrame(
        {
            "run": [7, 7, 7, 7, 7, 7, 8, 8],
            "t": [0.0, 0.1, 0.2, 5.0, 9.0, 9.1, 0.0, 0.1],
            "x": np.arange(8.0),
        }
    )
    out = resample_recordings(frame, 10.0, max_gap=1.0, recording="run", time="t")
    assert out["run"].tolist() == ["7/0"] * 3 + ["7/1"] + ["7/2"] * 2 + ["8"] * 2
    with pytest.warns(UserWarning, match=r"dropped 1 piece.*min_length=2.*'7/1' \(5 to 5 s, 1"):
        short = resample_recordings(
            frame, 10.0, max_gap=1.0, recording="run", time="t", min_length=2
        )
    assert short["run"].tolist() == ["7/0"] * 3 + ["7/2"] * 2 + ["8"] * 2
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        resample_recordings(frame, 10.0, max_gap=np.inf, recording="run", time="t", min_length=2)
    # With max_gap=inf nothing splits: the 4.8 s step is interpolated.
    whole = resample_recordings(frame, 10.0, max_gap=np.inf, recording="run", time="t")
    assert set(whole["run"]) == {"7", "8"} and (whole["run"] == "7").sum() == 92


def test_a_piece_may_not_take_the_id_of_another_recording():
    frame = pd.DataFrame({"recording": ["a", "a", "a/1"], "time": [0.0, 5.0, 0.0], "x": 0.0})
    with pytest.raises(ValueError, match=r"'a'.*'a/1', which is already a recording"):
        resample_recordings(frame, 10.0, max_gap=1.0)


def test_hold_and_meta_columns_keep_the_previous_value():
    frame = pd.DataFrame(
        {
            "recording": "r",
            "split": "train",
            "setting": [1.0, 1.0, 2.0],
            "time": [0.0, 0.15, 0.3],
            "brake": [0.0, 1.0, 1.0],
            "label": pd.Categorical(["a", "b", "b"]),
        }
    )
    out = resample_recordings(frame, 10.0, max_gap=0.2, hold=["brake"])
    assert out["brake"].tolist() == [0.0, 0.0, 1.0, 1.0]  # linear would give 0.667 at 0.1
    assert out["setting"].tolist() == [1.0, 1.0, 1.0, 2.0]
    assert out["label"].dtype == "category" and out["label"].tolist() == ["a", "a", "b", "b"]
    assert (out["split"] == "train").all()


@pytest.mark.parametrize(
    "times, message",
    [
        ([0.0, 0.2, 0.1], r"'b' \(row 4, time 0\.1\) goes back in time"),
        ([0.0, 0.1, 0.1], r"'b' \(row 4, time 0\.1\) repeats the time of row 3"),
        ([0.0, np.nan, 0.2], r"'time' holds NaN in recording 'b' \(row 3"),
    ],
)
def test_unsorted_repeated_and_missing_times_name_recording_and_row(times, message):
    frame = pd.DataFrame({"recording": ["a", "a", "b", "b", "b"], "time": [0, 0.1, *times]})
    frame["x"] = 1.0
    with pytest.raises(ValueError, match=message):
        resample_recordings(frame, 10.0, max_gap=0.5)


def test_bad_arguments_are_named():
    frame = _log()
    for rate in (0, -10.0, np.nan, True, "10"):
        with pytest.raises(ValueError, match="'sampling_rate' parameter of resample_recordings"):
            resample_recordings(frame, rate, max_gap=1.0)
    for gap in (0.05, 0, -1.0):
        with pytest.raises(ValueError, match=r"max_gap must be at least one sampling period"):
            resample_recordings(frame, 10.0, max_gap=gap)
    for gap in ("1 s", np.nan, True):
        with pytest.raises(ValueError, match="'max_gap' parameter of resample_recordings"):
            resample_recordings(frame, 10.0, max_gap=gap)
    for length in (0, 2.0, True):
        with pytest.raises(ValueError, match="'min_length' parameter of resample_recordings"):
            resample_recordings(frame, 10.0, max_gap=1.0, min_length=length)
    with pytest.raises(ValueError, match=r"lacks the column\(s\) \['t'\]"):
        resample_recordings(frame, 10.0, max_gap=1.0, time="t")
    with pytest.raises(ValueError, match="rows of a recording must be contiguous"):
        resample_recordings(frame.iloc[[0, 8, 1]], 10.0, max_gap=1.0)
    with pytest.raises(TypeError, match="DataFrame"):
        resample_recordings(frame.to_numpy(), 10.0, max_gap=1.0)


def test_load_recordings_resamples_a_csv_with_gaps_on_request(tmp_path):
    raw = pd.DataFrame(
        {
            "time": [0.0, 0.098, 0.3, 0.401, 3.0, 3.1],  # short gap 0.098 -> 0.3, long 0.401 -> 3
            "yaw_rate": [0.0, 0.098, 0.3, 0.401, 3.0, 3.1],
            "turn_signal": [0, 0, 1, 1, 0, 0],
            "driver_torque": [1.0, 1.0, 1.0, 1.0, 2.0, 2.0],
        }
    )
    raw.to_csv(tmp_path / "drive7.csv", index=False)
    # By default the rate is only checked, as before.
    with pytest.raises(ValueError, match=r"'drive7' is not sampled at 10\.0 Hz"):
        load_recordings(tmp_path / "drive7.csv", sampling_rate=10.0)
    frame = load_recordings(tmp_path / "drive7.csv", sampling_rate=10.0, max_gap=0.25)
    assert frame["recording"].tolist() == ["drive7/0"] * 5 + ["drive7/1"] * 2
    np.testing.assert_allclose(frame["time"], [0.0, 0.1, 0.2, 0.3, 0.4, 3.0, 3.1], atol=1e-12)
    np.testing.assert_allclose(frame["yaw_rate"], frame["time"], atol=1e-12)  # a linear signal
    assert frame["turn_signal"].tolist() == [0.0, 0.0, 0.0, 1.0, 1.0, 0.0, 0.0]  # held
    assert frame.attrs["units"]["yaw_rate"] == "rad/s"
    with pytest.raises(ValueError, match="max_gap needs sampling_rate"):
        load_recordings(tmp_path / "drive7.csv", max_gap=0.25)
    with pytest.raises(ValueError, match="max_gap must be at least one sampling period"):
        load_recordings(tmp_path / "drive7.csv", sampling_rate=10.0, max_gap=0.01)


def test_load_recordings_keeps_missing_values_on_request_and_drops_short_pieces(tmp_path):
    raw = pd.DataFrame(
        {
            "time": [0.0, 0.1, 0.2, 0.3, 0.4, 2.0, 3.0, 3.1, 3.2],  # two long gaps
            "yaw_rate": [0.0, 0.1, np.nan, 0.3, 0.4, 2.0, 3.0, 3.1, 3.2],
            "driver_torque": [1.0, np.nan, 1.0, 1.0, 1.0, 2.0, 2.0, 2.0, 2.0],
        }
    )
    raw.to_csv(tmp_path / "drive7.csv", index=False)
    with pytest.raises(
        ValueError, match=r"'driver_torque' holds NaN in recording 'drive7' \(.*row 1"
    ):
        load_recordings(tmp_path / "drive7.csv")
    frame = load_recordings(tmp_path / "drive7.csv", allow_missing=True)
    np.testing.assert_array_equal(frame["yaw_rate"], raw["yaw_rate"])
    np.testing.assert_array_equal(frame["driver_torque"], raw["driver_torque"])
    with pytest.warns(UserWarning, match="dropped 1 piece.*shorter than min_length=2"):
        frame = load_recordings(
            tmp_path / "drive7.csv",
            sampling_rate=10.0,
            max_gap=0.25,
            min_length=2,
            allow_missing=True,
        )
    # the 1-sample piece at 2.0 s is dropped; the missing sample stays missing on the grid
    assert frame["recording"].tolist() == ["drive7/0"] * 5 + ["drive7/2"] * 3
    np.testing.assert_allclose(frame["time"], [0.0, 0.1, 0.2, 0.3, 0.4, 3.0, 3.1, 3.2], atol=1e-9)
    assert np.isnan(frame["yaw_rate"].iloc[2]) and np.isnan(frame["driver_torque"].iloc[1])
    assert not frame["yaw_rate"].drop(index=2).isna().any()
    raw.loc[4, "yaw_rate"] = np.inf
    raw.to_csv(tmp_path / "drive7.csv", index=False)
    with pytest.raises(ValueError, match="'yaw_rate' holds an infinite value"):
        load_recordings(tmp_path / "drive7.csv", allow_missing=True)
    raw.loc[4, ["yaw_rate", "time"]] = [0.4, np.nan]
    raw.to_csv(tmp_path / "drive7.csv", index=False)
    with pytest.raises(ValueError, match="'time' holds NaN"):
        load_recordings(tmp_path / "drive7.csv", allow_missing=True)


# --- bounded grids (#35) ----------------------------------------------------------------------


def test_a_grid_far_denser_than_the_samples_is_refused_before_it_is_built():
    """Two samples five million seconds apart would give 1e8 grid rows (1 GB per column)."""
    raw = pd.DataFrame({"recording": "r", "time": [0.0, 5e6], "x": [1.0, 2.0]})
    with pytest.raises(ValueError, match=r"recording 'r' would take 1e\+08 grid rows.*2 sample"):
        resample_recordings(raw, 20.0, max_gap=np.inf)
    # the same samples split at the gap are two one-row pieces
    split = resample_recordings(raw, 20.0, max_gap=1.0)
    assert list(split["recording"]) == ["r/0", "r/1"]


def test_the_grid_bound_leaves_a_hundredfold_upsampling_alone():
    raw = pd.DataFrame({"recording": "r", "time": np.arange(500) * 0.1, "x": np.arange(500.0)})
    dense = resample_recordings(raw, 1000.0, max_gap=1.0)
    assert len(dense) == 49_901  # 49.9 s at 1 kHz, both ends included
    np.testing.assert_allclose(dense["x"], dense["time"] * 10.0, atol=1e-9)


def test_the_largest_offending_recording_is_named():
    raw = pd.DataFrame(
        {
            "recording": ["ok"] * 3 + ["long"] * 2 + ["longer"] * 2,
            "time": [0.0, 0.1, 0.2, 0.0, 1e5, 0.0, 1e6],
            "x": np.arange(7.0),
        }
    )
    with pytest.raises(ValueError, match="'longer' would take 2e\\+07"):
        resample_recordings(raw, 20.0, max_gap=np.inf)


@pytest.mark.parametrize("rate", [1e12, 1000.5, np.float32(5e3)])
def test_a_rate_above_the_bound_is_refused_everywhere(rate, tmp_path):
    raw = pd.DataFrame({"recording": "r", "time": [0.0, 0.1], "steering_wheel_angle": [0.0, 1.0]})
    raw["driver_torque"] = 0.0
    with pytest.raises(ValueError, match="sampling_rate must be at most 1000 Hz"):
        resample_recordings(raw, rate, max_gap=1.0)
    with pytest.raises(ValueError, match="sampling_rate must be at most 1000 Hz"):
        load_recordings(raw, target="driver_torque", sampling_rate=rate, max_gap=1.0)
