"""Recordings in the index (the panel form): reading ids, time and the filter's row order."""

import numpy as np
import pandas as pd
import pytest

from skhmmgmr._panel import has_recording_index, read_row_order


def panel(recordings, times, values=None):
    index = pd.MultiIndex.from_arrays([recordings, times], names=["recording", "time"])
    values = np.arange(len(recordings), dtype=float) if values is None else values
    return pd.DataFrame({"x": values}, index=index)


def test_plain_input_keeps_its_arguments_and_order():
    X = np.zeros((4, 1))
    rows = read_row_order(X, groups=[1, 1, 2, 2], time=None)
    assert rows.order is None
    assert list(rows.groups) == [1, 1, 2, 2]
    assert not has_recording_index(X)


def test_shuffled_panel_is_put_in_recording_then_time_order_and_back():
    X = panel(["b", "a", "b", "a", "b"], [2.0, 0.5, 0.0, 0.0, 1.0])
    rows = read_row_order(X)
    # recordings in order of first appearance ("b" first), each sorted by time
    assert list(rows.groups) == ["b", "b", "b", "a", "a"]
    assert list(rows.time) == [0.0, 1.0, 2.0, 0.0, 0.5]
    ordered = rows.to_filter_order(X)
    assert list(ordered["x"]) == [2.0, 4.0, 0.0, 3.0, 1.0]
    assert np.array_equal(rows.to_caller_order(ordered["x"].to_numpy()), X["x"].to_numpy())
    two_d = np.column_stack([ordered["x"], -ordered["x"]])
    assert np.array_equal(rows.to_caller_order(two_d)[:, 1], -X["x"].to_numpy())


def test_ids_are_read_as_text_so_leading_zeros_stay_apart():
    X = panel(["7", "007", "7"], [0.0, 0.0, 1.0])
    rows = read_row_order(X)
    assert list(rows.groups) == ["7", "7", "007"]


def test_without_time_level_rows_of_a_recording_keep_their_relative_order():
    index = pd.Index(["a", "b", "a", "b"], name="recording")
    X = pd.Series([0.0, 1.0, 2.0, 3.0], index=index)
    rows = read_row_order(X)
    assert list(rows.to_filter_order(X)) == [0.0, 2.0, 1.0, 3.0]
    assert rows.time is None


def test_timedelta_and_datetime_levels_are_read_in_seconds():
    start = pd.Timestamp("2019-01-01")
    X = panel(["a", "a"], [start + pd.Timedelta(seconds=1.5), start])
    rows = read_row_order(X)
    assert list(rows.time) == [0.0, 1.5]
    X = panel(["a", "a"], pd.to_timedelta([0.0, 0.05], unit="s"))
    assert np.allclose(read_row_order(X).time, [0.0, 0.05])


def test_explicit_groups_must_agree_with_the_index():
    X = panel(["a", "a", "b"], [0.0, 1.0, 0.0])
    assert read_row_order(X, groups=["a", "a", "b"]).order is None
    with pytest.raises(ValueError, match="groups disagrees with the recording level.*row 2"):
        read_row_order(X, groups=["a", "a", "c"])
    with pytest.raises(ValueError, match="time disagrees with the time level.*row 1"):
        read_row_order(X, time=[0.0, 2.0, 0.0])
    with pytest.raises(ValueError, match="groups has shape"):
        read_row_order(X, groups=["a"])


def test_missing_recording_id_in_the_index_is_named():
    X = panel(["a", None, "b"], [0.0, 1.0, 0.0])
    with pytest.raises(ValueError, match="missing recording id.*row 1"):
        read_row_order(X)
