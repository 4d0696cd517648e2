"""One recording layout per public call: read by one parser, handed down, never parsed again."""

import pickle
import warnings
from unittest import mock

import numpy as np
import pandas as pd
import pytest
from numpy.testing import assert_allclose, assert_array_equal

import skhmmgmr._core._panel as panel_module
import skhmmgmr._core._sequences as sequences_module
from skhmmgmr import HMMGMRRegressor, PerformanceScore, make_torque_pipeline
from skhmmgmr._core._panel import RecordingIds, read_layout, recordings_of
from skhmmgmr._core._sequences import as_recordings
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


def test_handed_down_ids_carry_the_layout_and_nothing_else_does():
    groups = np.repeat(["b", "a", "c"], [3, 2, 4])
    layout = read_layout(None, groups)
    ids = layout.handed_down()
    assert isinstance(ids, RecordingIds)
    assert ids is layout.handed_down()  # one handed-down object per layout
    assert_array_equal(np.asarray(ids), groups)
    assert read_layout(None, ids) is ids._layout
    with pytest.raises(ValueError, match="read-only"):
        ids[0] = "z"
    # a slice (a fold of a cross-validation), a copy or a pickle carries no layout
    for other in (ids[:5], ids[[0, 1, 2]], ids.copy(), pickle.loads(pickle.dumps(ids))):
        assert getattr(other, "_layout", None) is None
        assert read_layout(None, other)._recordings is None
    # a handed-down layout in first-appearance order is no canonical (fit) order
    assert read_layout(None, ids, canonical=True) is not ids._layout
    # the recordings, read once, are those of a fresh parse; lengths are checked against it
    recordings = recordings_of(ids, len(groups), min_length=2)
    assert recordings is recordings_of(ids, len(groups))
    fresh = as_recordings(groups, len(groups))
    assert_array_equal(recordings.starts, fresh.starts)
    assert list(recordings.ids) == list(fresh.ids)
    with pytest.raises(ValueError, match="has 9 entries but X has 8 rows"):
        recordings_of(ids, 8)
    with pytest.raises(ValueError, match="recording 'a' has n_samples=2"):
        recordings_of(ids, len(groups), min_length=3)
    with pytest.raises(ValueError, match="does not increase within recording 'a'"):
        recordings_of(ids, len(groups), time=[0, 1, 2, 0, 0, 0, 1, 2, 3])


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
    assert len(seen) == 1 and isinstance(seen[0], RecordingIds)
    per_recording = []
    for rec in sorted(set(frame.index.get_level_values("recording")), key=str):
        part = frame.xs(rec, level="recording", drop_level=False).sort_index()
        per_recording.append(
            PerformanceScore(sampling_period=0.05)(model, part[FEATURES], part["driver_torque"])
        )
    assert score == pytest.approx(np.mean(per_recording), rel=1e-12)
