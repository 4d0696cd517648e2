"""One recording layout per public call: read by one parser, handed down, never parsed again."""

import ast
import copy
import pickle
import warnings
from pathlib import Path
from unittest import mock

import numpy as np
import pandas as pd
import pytest
from numpy.testing import assert_allclose, assert_array_equal

import skhmmgmr._core._panel as panel_module
import skhmmgmr._core._sequences as sequences_module
from skhmmgmr import HMMGMRRegressor, PerformanceScore, make_torque_pipeline
from skhmmgmr._core._panel import RecordingLayout, in_filter_order, read_layout, recordings_of
from skhmmgmr._core._sequences import as_recordings, median_time_step
from skhmmgmr.datasets import FEATURE_NAMES, make_driving_protocol, shift_target, to_panel

FEATURES = list(FEATURE_NAMES)


@pytest.fixture(scope="module")
def data():
    frame = make_driving_protocol(
        ("defensive",), duration=8.0, sampling_rate=20.0, random_state=3
    ).reset_index(drop=True)
    keep = frame["recording"].isin(frame["recording"].unique()[:6])
    return frame[keep].reset_index(drop=True)


class Parses:
    """Counts the parses of recordings: groups read into contiguous recordings, and a
    multi-level index read for its recording and time levels."""

    def __init__(self):
        self.groups = self.index = 0

    def __enter__(self):
        real_groups, real_index = sequences_module._contiguous_recordings, panel_module.index_levels

        def groups(*args, **kwargs):
            self.groups += 1
            return real_groups(*args, **kwargs)

        def index(X):
            if isinstance(X, pd.DataFrame | pd.Series) and X.index.nlevels > 1:
                self.index += 1
            return real_index(X)

        self._patches = [
            mock.patch.object(sequences_module, "_contiguous_recordings", groups),
            mock.patch.object(panel_module, "index_levels", index),
        ]
        for patch in self._patches:
            patch.start()
        return self

    def __exit__(self, *exc):
        for patch in self._patches:
            patch.stop()


def _count(call):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        with Parses() as parses:
            call()
    return parses.groups, parses.index


def test_every_public_call_reads_the_recordings_once(data):
    X, y, groups = data[FEATURES], data["driver_torque"], data["recording"]
    frame = to_panel(data)
    Xp, yp = frame[FEATURES], frame["driver_torque"]
    model = HMMGMRRegressor(n_states=3, random_state=0)
    scorer = PerformanceScore(sampling_period=0.05)
    pipe = make_torque_pipeline(3, velocity_filter=0.1, sampling_period=0.05, random_state=0)
    # (groups parsed, panel index parsed) per public call
    assert _count(lambda: model.fit(X, y, groups=groups)) == (1, 0)
    assert _count(lambda: model.predict(X, groups=groups)) == (1, 0)
    assert _count(lambda: model.fit(Xp, yp)) == (1, 1)
    assert _count(lambda: model.predict(Xp)) == (1, 1)
    assert _count(lambda: scorer(model, X, y, groups=groups)) == (1, 0)
    assert _count(lambda: scorer(model, Xp, yp)) == (1, 1)
    # the pipeline reads them once for its velocity filter and its regressor
    assert _count(lambda: pipe.fit(X, y, groups=groups)) == (1, 0)
    assert _count(lambda: pipe.predict(X, groups=groups)) == (1, 0)
    assert _count(lambda: pipe.predict(Xp)) == (1, 1)
    assert _count(lambda: scorer(pipe, X, y, groups=groups)) == (1, 0)
    assert _count(lambda: scorer(pipe, Xp, yp)) == (1, 1)
    assert _count(lambda: shift_target(yp, 2)) == (1, 1)


def test_the_pipeline_reads_a_shuffled_panel_once_and_answers_in_the_callers_order(data):
    frame = to_panel(data)
    shuffled = frame.sample(frac=1.0, random_state=1)
    pipe = make_torque_pipeline(3, velocity_filter=0.1, sampling_period=0.05, random_state=0)
    pipe.fit(frame[FEATURES], frame["driver_torque"])
    expected = pd.Series(pipe.predict(frame[FEATURES]), index=frame.index)
    got, std = pipe.predict(shuffled[FEATURES], return_std=True)
    assert_allclose(got, expected.loc[shuffled.index].to_numpy(), rtol=0, atol=1e-12)
    _, expected_std = pipe.predict(frame[FEATURES], return_std=True)
    expected_std = pd.Series(expected_std, index=frame.index).loc[shuffled.index]
    assert_allclose(std, expected_std.to_numpy(), rtol=0, atol=1e-12)
    # fitting the shuffled panel gives the same model (one canonical order)
    refit = make_torque_pipeline(3, velocity_filter=0.1, sampling_period=0.05, random_state=0)
    refit.fit(shuffled[FEATURES], shuffled["driver_torque"])
    assert_allclose(refit[-1].model_.gmr.coef, pipe[-1].model_.gmr.coef, rtol=0, atol=1e-10)


def test_the_handed_down_layout_is_the_groups_and_a_slice_of_it_is_refused():
    groups = np.repeat(["b", "a", "c"], [3, 2, 4])
    layout = read_layout(None, groups)
    handed = layout.handed_down()
    assert isinstance(handed, RecordingLayout) and handed.order is None
    assert handed is layout.handed_down() and handed.handed_down() is handed
    assert read_layout(None, handed) is handed
    # it stands for its recording ids wherever groups are read as an array
    assert_array_equal(np.asarray(handed), groups)
    assert len(handed) == 9 and list(handed) == groups.tolist()
    with pytest.raises(ValueError, match="read-only"):
        np.asarray(handed)[0] = "z"
    # a slice (a fold) would need a layout of its own: refused, never a silent re-parse
    for rows in (slice(0, 5), [0, 1, 2], np.arange(9) < 4):
        with pytest.raises(TypeError, match=r"not sliced.*numpy.asarray\(groups\)\[rows\]"):
            handed[rows]
    assert_array_equal(np.asarray(handed)[:5], groups[:5])  # the ids of some rows, on demand
    # a copy or a pickle is the same layout
    for other in (copy.copy(handed), copy.deepcopy(handed), pickle.loads(pickle.dumps(handed))):
        assert isinstance(other, RecordingLayout)
        assert_array_equal(np.asarray(other), groups)
        assert list(recordings_of(other, 9).ids) == ["b", "a", "c"]
    # a layout of other rows, or one in the caller's order, is refused
    with pytest.raises(ValueError, match="recordings of 9 rows but X has 8 rows"):
        read_layout(np.zeros((8, 1)), handed)
    with pytest.raises(ValueError, match="recordings of 9 rows but X has 8 rows"):
        recordings_of(handed, 8)
    reordered = read_layout(None, groups, canonical=True)
    assert reordered.order is not None
    with pytest.raises(TypeError, match="caller's row order"):
        read_layout(None, reordered)
    # a handed-down layout in first-appearance order is no canonical (fit) order
    assert read_layout(None, handed, canonical=True) is not handed
    # the recordings, read once, are those of a fresh parse; lengths are checked against it
    recordings = recordings_of(handed, len(groups), min_length=2)
    assert recordings is recordings_of(handed, len(groups))
    fresh = as_recordings(groups, len(groups))
    assert_array_equal(recordings.starts, fresh.starts)
    assert list(recordings.ids) == list(fresh.ids)
    with pytest.raises(ValueError, match="recording 'a' has n_samples=2"):
        recordings_of(handed, len(groups), min_length=3)
    with pytest.raises(ValueError, match="does not increase within recording 'a'"):
        recordings_of(handed, len(groups), time=[0, 1, 2, 0, 0, 0, 1, 2, 3])


def test_in_filter_order_runs_on_ordered_rows_and_answers_in_the_callers_order():
    index = pd.MultiIndex.from_arrays(
        [["b", "a", "b", "a", "b"], [2.0, 0.5, 0.0, 0.0, 1.0]], names=["recording", "time"]
    )
    X = pd.DataFrame({"x": [10.0, 11.0, 12.0, 13.0, 14.0]}, index=index)
    y = pd.Series([0.0, 1.0, 2.0, 3.0, 4.0], index=index).iloc[::-1]  # paired by label
    weight = np.array([5.0, 6.0, 7.0, 8.0, 9.0])  # paired by position
    seen = {}

    def run(layout, X, y, weight):
        seen.update(layout=layout, X=X["x"].tolist(), y=y.tolist(), weight=weight.tolist())
        return X["x"].to_numpy() * 2, "kept"

    doubled, other = in_filter_order(run, X, y=y, rows={"weight": weight})
    # the filter order: recording b then a (first appearance), each by time
    assert seen["X"] == [12.0, 14.0, 10.0, 13.0, 11.0]
    assert seen["y"] == [2.0, 4.0, 0.0, 3.0, 1.0]
    assert seen["weight"] == [7.0, 9.0, 5.0, 8.0, 6.0]
    assert seen["layout"].order is None and list(seen["layout"]) == ["b", "b", "b", "a", "a"]
    assert_array_equal(doubled, X["x"].to_numpy() * 2) and other == "kept"
    with pytest.raises(ValueError, match="X has 5, weight has 4"):
        in_filter_order(run, X, rows={"weight": weight[:4]})


def _read_layout_calls():
    """(file, line) of every call of read_layout in the package outside _core."""
    package = Path(__file__).resolve().parents[1] / "skhmmgmr"
    calls = []
    for path in sorted(package.rglob("*.py")):
        if "_core" in path.relative_to(package).parts:
            continue
        for node in ast.walk(ast.parse(path.read_text(), filename=str(path))):
            if isinstance(node, ast.Call):
                function = node.func
                name = function.attr if isinstance(function, ast.Attribute) else None
                name = function.id if isinstance(function, ast.Name) else name
                if name == "read_layout":
                    calls.append(f"{path.relative_to(package)}:{node.lineno}")
    return calls


def test_read_layout_is_called_from_few_places_outside_the_ground_floor():
    """The layout is read at the outermost call and handed down (in_filter_order is the one
    prologue that reads it); every other reader is a place that parses recordings again."""
    calls = _read_layout_calls()
    assert calls, "read_layout not found: the count below would say nothing"
    assert len(calls) <= 6, f"read_layout called from {len(calls)} places: {calls}"


def test_canonical_order_of_groups_moves_the_recordings_with_their_rows():
    groups = np.repeat(["r2", "r10", "r1"], [2, 3, 1])
    values = np.arange(6.0)
    layout = read_layout(None, groups, canonical=True)
    # by id as text: r1, r10, r2
    assert_array_equal(layout.to_filter_order(values), [5.0, 2.0, 3.0, 4.0, 0.0, 1.0])
    recordings = layout.recordings(6)
    assert list(recordings.ids) == ["r1", "r10", "r2"]
    assert_array_equal(recordings.starts, [0, 1, 4])
    assert_array_equal(recordings.stops, [1, 4, 6])
    fresh = as_recordings(layout.groups, 6)
    assert_array_equal(fresh.starts, recordings.starts)
    assert_array_equal(layout.to_caller_order(layout.to_filter_order(values)), values)


def test_a_scorer_gives_predict_the_rows_in_filter_order_with_their_layout(data):
    frame = to_panel(data).sample(frac=1.0, random_state=2)
    X, y = frame[FEATURES], frame["driver_torque"]
    model = HMMGMRRegressor(n_states=3, random_state=0).fit(X, y)
    seen = []
    real_predict = HMMGMRRegressor.predict

    def predict(self, X, groups=None, **kwargs):
        seen.append(groups)
        return real_predict(self, X, groups=groups, **kwargs)

    with mock.patch.object(HMMGMRRegressor, "predict", predict):
        score = PerformanceScore(sampling_period=0.05)(model, X, y)
    assert len(seen) == 1 and isinstance(seen[0], RecordingLayout)
    per_recording = []
    for rec in sorted(set(frame.index.get_level_values("recording")), key=str):
        part = frame.xs(rec, level="recording", drop_level=False).sort_index()
        per_recording.append(
            PerformanceScore(sampling_period=0.05)(model, part[FEATURES], part["driver_torque"])
        )
    assert score == pytest.approx(np.mean(per_recording), rel=1e-12)


def test_the_sampling_period_is_the_median_step_within_recordings():
    """The one inference of the sampling period (the command line's and the torque
    pipeline's), against a plain loop: steps between consecutive rows of a recording only,
    a missing time left out."""
    rng = np.random.default_rng(3)
    lengths = [5, 1, 8, 4]
    groups = np.repeat(["a", "b", "c", "d"], lengths)
    time = np.concatenate(
        [np.cumsum(rng.uniform(0.009, 0.012, n)) + 100 * i for i, n in enumerate(lengths)]
    )
    time[9] = np.nan
    steps = []
    for i in range(1, len(time)):
        if groups[i] == groups[i - 1] and not np.isnan(time[i] - time[i - 1]):
            steps.append(time[i] - time[i - 1])
    assert median_time_step(time, groups) == np.median(steps)
    assert median_time_step(time[:5]) == np.median(np.diff(time[:5]))
    assert median_time_step([0.0, np.nan], ["a", "a"]) is None
    assert median_time_step(time[5:6], groups[5:6]) is None
