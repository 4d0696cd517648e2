"""Recordings in the index (the panel form): reading ids, time and the filter's row order."""

import pickle
import warnings

import numpy as np
import pandas as pd
import pytest

from skhmmgmr._core._panel import has_recording_index, read_layout


def panel(recordings, times, values=None):
    index = pd.MultiIndex.from_arrays([recordings, times], names=["recording", "time"])
    values = np.arange(len(recordings), dtype=float) if values is None else values
    return pd.DataFrame({"x": values}, index=index)


def test_plain_input_keeps_its_arguments_and_order():
    X = np.zeros((4, 1))
    rows = read_layout(X, groups=[1, 1, 2, 2], time=None)
    assert rows.order is None
    assert list(rows.groups) == [1, 1, 2, 2]
    assert not has_recording_index(X)


def test_shuffled_panel_is_put_in_recording_then_time_order_and_back():
    X = panel(["b", "a", "b", "a", "b"], [2.0, 0.5, 0.0, 0.0, 1.0])
    rows = read_layout(X)
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
    rows = read_layout(X)
    assert list(rows.groups) == ["7", "7", "007"]


def test_without_time_level_rows_of_a_recording_keep_their_relative_order():
    index = pd.Index(["a", "b", "a", "b"], name="recording")
    X = pd.Series([0.0, 1.0, 2.0, 3.0], index=index)
    rows = read_layout(X)
    assert list(rows.to_filter_order(X)) == [0.0, 2.0, 1.0, 3.0]
    assert rows.time is None


def test_timedelta_and_datetime_levels_are_read_in_seconds():
    start = pd.Timestamp("2019-01-01")
    X = panel(["a", "a"], [start + pd.Timedelta(seconds=1.5), start])
    rows = read_layout(X)
    assert list(rows.time) == [0.0, 1.5]
    X = panel(["a", "a"], pd.to_timedelta([0.0, 0.05], unit="s"))
    assert np.allclose(read_layout(X).time, [0.0, 0.05])


def test_explicit_groups_must_agree_with_the_index():
    X = panel(["a", "a", "b"], [0.0, 1.0, 0.0])
    assert read_layout(X, groups=["a", "a", "b"]).order is None
    with pytest.raises(ValueError, match="groups disagrees with the recording level.*row 2"):
        read_layout(X, groups=["a", "a", "c"])
    with pytest.raises(ValueError, match="time disagrees with the time level.*row 1"):
        read_layout(X, time=[0.0, 2.0, 0.0])
    with pytest.raises(ValueError, match="groups has shape"):
        read_layout(X, groups=["a"])


def test_missing_recording_id_in_the_index_is_named():
    X = panel(["a", None, "b"], [0.0, 1.0, 0.0])
    with pytest.raises(ValueError, match="missing recording id.*row 1"):
        read_layout(X)


# --------------------------------------------------------------------------------------------
# The estimator reads the panel form
# --------------------------------------------------------------------------------------------

from sklearn.model_selection import GroupKFold  # noqa: E402

from skhmmgmr import ExhaustiveFeatureSelector, HMMGMRRegressor, PerformanceScore  # noqa: E402
from skhmmgmr.datasets import make_lane_keeping, to_panel  # noqa: E402

FEATURES = ["steering_wheel_angle", "yaw_rate"]


@pytest.fixture(scope="module")
def drives():
    frames = [
        make_lane_keeping(
            12.0, setting=1 + i, sampling_rate=20.0, random_state=i, recording=f"r{i}"
        )
        for i in range(4)
    ]
    frame = pd.concat(frames, ignore_index=True)
    model = HMMGMRRegressor(n_states=2, random_state=0)
    model.fit(frame[FEATURES], frame["driver_torque"], groups=frame["recording"])
    return frame, to_panel(frame), model


def test_fit_on_the_panel_equals_fit_with_groups(drives):
    frame, panel_frame, model = drives
    on_panel = HMMGMRRegressor(n_states=2, random_state=0)
    on_panel.fit(panel_frame[FEATURES], panel_frame["driver_torque"])
    assert np.allclose(on_panel.means_, model.means_, rtol=0, atol=1e-10)
    assert on_panel.longest_recording_ == model.longest_recording_ == 240


def test_shuffled_panel_predicts_every_row_as_the_grouped_call_does(drives):
    frame, panel_frame, model = drives
    expected, expected_std = model.predict(
        frame[FEATURES], groups=frame["recording"], return_std=True
    )
    expected_alpha = model.predict_state_proba(frame[FEATURES], groups=frame["recording"])
    shuffle = np.random.default_rng(0).permutation(len(panel_frame))
    shuffled = panel_frame.iloc[shuffle]
    y_pred, y_std = model.predict(shuffled[FEATURES], return_std=True)
    assert np.allclose(y_pred, expected[shuffle], rtol=0, atol=1e-12)
    assert np.allclose(y_std, expected_std[shuffle], rtol=0, atol=1e-12)
    alpha = model.predict_state_proba(shuffled[FEATURES])
    assert np.allclose(alpha, expected_alpha[shuffle], rtol=0, atol=1e-12)
    grouped_ll = model.log_likelihood(
        frame[FEATURES], frame["driver_torque"], groups=frame["recording"]
    )
    panel_ll = model.log_likelihood(shuffled[FEATURES], shuffled["driver_torque"])
    assert panel_ll == pytest.approx(grouped_ll, rel=1e-12)


def test_groups_given_with_a_panel_must_agree(drives):
    _, panel_frame, model = drives
    wrong = np.where(panel_frame.index.get_level_values("recording") == "r1", "r2", "r1")
    with pytest.raises(ValueError, match="groups disagrees with the recording level"):
        model.predict(panel_frame[FEATURES], groups=wrong)


def test_many_ungrouped_rows_warn_that_they_are_one_recording(drives):
    frame, _, model = drives
    with pytest.warns(UserWarning, match="filtered as ONE recording.*longest training"):
        model.predict(frame[FEATURES])
    with pytest.warns(UserWarning, match="filtered as ONE recording.*longest training"):
        model.log_likelihood(frame[FEATURES], frame["driver_torque"])
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        model.predict(frame[FEATURES].iloc[:240])
        model.predict(frame[FEATURES], groups=frame["recording"])


def test_filter_stream_restarts_at_every_recording_of_an_indexed_batch(drives):
    frame, panel_frame, model = drives
    expected = model.predict(frame[FEATURES], groups=frame["recording"])
    shuffle = np.random.default_rng(1).permutation(len(panel_frame))
    stream = model.filter_stream()
    estimates = stream.update_batch(panel_frame[FEATURES].iloc[shuffle])
    assert np.allclose(estimates, expected[shuffle], rtol=0, atol=1e-12)
    # in two batches cut inside a recording: the second goes on with the same recording
    stream.reset()
    first = stream.update_batch(panel_frame[FEATURES].iloc[:300])
    assert stream.recording_ == "r1"
    second = stream.update_batch(panel_frame[FEATURES].iloc[300:])
    assert np.allclose(np.concatenate([first, second]), expected, rtol=0, atol=1e-12)


def test_scorers_read_recordings_and_time_from_a_shuffled_panel(drives):
    frame, panel_frame, model = drives
    grouped = PerformanceScore(sampling_period=0.05)(
        model, frame[FEATURES], frame["driver_torque"], groups=frame["recording"]
    )
    shuffle = np.random.default_rng(2).permutation(len(panel_frame))
    shuffled = panel_frame.iloc[shuffle]
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no UngroupedScoringWarning
        on_panel = PerformanceScore(sampling_period=0.05)(
            model, shuffled[FEATURES], shuffled["driver_torque"]
        )
        # the time step from the index's time level when no sampling_period is given
        from_index_time = PerformanceScore()(model, shuffled[FEATURES], shuffled["driver_torque"])
    assert on_panel == pytest.approx(grouped, rel=1e-12)
    assert from_index_time == pytest.approx(grouped, rel=1e-9)


def test_a_selector_fitted_on_the_panel_equals_one_fitted_with_groups(drives):
    frame, panel_frame, _ = drives
    features = [*FEATURES, "heading_deviation_10m"]
    cv = GroupKFold(2)
    grouped = ExhaustiveFeatureSelector(cv=cv, sampling_period=0.05, max_features=2)
    grouped.fit(frame[features], frame["driver_torque"], groups=frame["recording"])
    shuffle = np.random.default_rng(3).permutation(len(panel_frame))
    shuffled = panel_frame.iloc[shuffle]
    on_panel = ExhaustiveFeatureSelector(cv=cv, sampling_period=0.05, max_features=2)
    on_panel.fit(shuffled[features], shuffled["driver_torque"])
    pd.testing.assert_frame_equal(on_panel.results_, grouped.results_)
    assert list(on_panel.get_feature_names_out()) == list(grouped.get_feature_names_out())


# --- #35: a y with an index is paired with X's rows by label, or refused ----------------------


def _shuffled_panel(seed=0):
    rng = np.random.default_rng(seed)
    n = 240
    X = pd.DataFrame(np.cumsum(rng.normal(scale=0.3, size=(n, 2)), axis=0), columns=["a", "b"])
    y = pd.Series(np.tanh(X["a"]) - 0.5 * X["b"] + rng.normal(scale=0.05, size=n), name="y")
    index = pd.MultiIndex.from_arrays(
        [np.repeat(["r0", "r1", "r2", "r3"], 60), np.tile(np.arange(60) * 0.05, 4)],
        names=["recording", "time"],
    )
    X.index = y.index = index
    return X, y


def test_fit_adapt_and_streams_pair_y_with_x_by_label():
    """y's labels in another order were paired by position (fitted means 3.1 apart)."""
    from skhmmgmr import HMMGMRRegressor

    X, y = _shuffled_panel()
    other_order = y.sample(frac=1.0, random_state=1)
    params = {"n_states": 2, "random_state": 0}
    same = HMMGMRRegressor(**params).fit(X, y)
    shuffled = HMMGMRRegressor(**params).fit(X, other_order)
    np.testing.assert_allclose(shuffled.means_, same.means_, rtol=0, atol=1e-10)
    assert shuffled.score(X, other_order) == pytest.approx(same.score(X, y), abs=1e-12)
    adapted = pickle.loads(pickle.dumps(same)).adapt(X, y + 0.3)
    shuffled_adapted = pickle.loads(pickle.dumps(same)).adapt(X, other_order + 0.3)
    np.testing.assert_allclose(shuffled_adapted.means_, adapted.means_, rtol=0, atol=1e-10)
    stream = same.filter_stream(relevance=8.0)
    first = stream.update_batch(X, y=y)
    second = same.filter_stream(relevance=8.0).update_batch(X, y=other_order)
    np.testing.assert_allclose(second, first, rtol=0, atol=1e-12)


@pytest.mark.parametrize("change", ["other labels", "fewer rows", "plain index"])
def test_a_y_whose_index_is_not_xs_is_refused(change):
    from skhmmgmr import HMMGMRRegressor

    X, y = _shuffled_panel()
    if change == "other labels":
        y = y.rename(index={"r3": "r9"}, level="recording")
    elif change == "fewer rows":
        y = y.iloc[:-1]
    else:
        y = y.reset_index(drop=True)
    # fewer rows: the one check of every per-row argument names both lengths first
    message = "X has 240, y has 239" if change == "fewer rows" else "y is a pandas object whose"
    with pytest.raises(ValueError, match=message):
        HMMGMRRegressor(n_states=2, random_state=0).fit(X, y)
    # an array pairs by position, as scikit-learn does
    HMMGMRRegressor(n_states=2, random_state=0).fit(X, np.asarray(_shuffled_panel()[1]))


# --- #34: sktime's level names are read; an index of other names is refused -------------------


def _renamed(frame, names):
    out = frame.copy()
    out.index = out.index.set_names(names)
    return out


@pytest.mark.parametrize(
    "names", [["instances", "timepoints"], ["recording", "timepoints"], ["instances", "time"]]
)
def test_sktime_level_names_are_read_like_the_packages(names):
    """A panel with sktime's names was one recording (0.06 Nm off; 0.11 shuffled), and
    recording + timepoints ignored the time level."""
    from skhmmgmr import HMMGMRRegressor

    X, y = _shuffled_panel(3)
    model = HMMGMRRegressor(n_states=2, random_state=0).fit(X, y)
    expected = model.predict(X)
    other = _renamed(X, names)
    np.testing.assert_allclose(model.predict(other), expected, rtol=0, atol=1e-12)
    shuffled = other.sample(frac=1.0, random_state=2)
    got = pd.Series(model.predict(shuffled), index=shuffled.index).reindex(other.index)
    np.testing.assert_allclose(got.to_numpy(), expected, rtol=0, atol=1e-12)
    refitted = HMMGMRRegressor(n_states=2, random_state=0).fit(shuffled, _renamed(y, names))
    np.testing.assert_allclose(refitted.means_, model.means_, rtol=0, atol=1e-10)


@pytest.mark.parametrize(
    "names, message",
    [
        (["run", "t"], r"the levels \['run', 't'\], none of which holds the recording ids"),
        ([None, None], r"the levels \[None, None\], none of which"),
    ],
)
def test_a_two_level_index_that_is_no_panel_is_refused(names, message):
    from skhmmgmr import HMMGMRRegressor

    X, y = _shuffled_panel(4)
    with pytest.raises(ValueError, match=message):
        HMMGMRRegressor(n_states=2, random_state=0).fit(_renamed(X, names), np.asarray(y))


def test_two_levels_for_the_recordings_are_refused():
    X, _ = _shuffled_panel(5)
    X = X.set_index(pd.Index(X.index.get_level_values(0), name="instances"), append=True)
    with pytest.raises(ValueError, match="both a 'recording' and a 'instances' level"):
        read_layout(X)


def test_one_canonical_order_for_a_panel_and_for_arrays_with_groups():
    """#34: the same rows fitted as a panel and as arrays with groups, the recordings in another
    order, gave different models (predictions 0.006 apart; means up to 16.5 apart)."""
    from skhmmgmr import HMMGMRRegressor

    X, y = _shuffled_panel(6)
    params = {"n_states": 3, "random_state": 0}
    reference = HMMGMRRegressor(**params).fit(X.sample(frac=1.0, random_state=0), y)
    ids = X.index.get_level_values("recording").to_numpy()
    for order in (["r0", "r1", "r2", "r3"], ["r3", "r1", "r0", "r2"], ["r2", "r3", "r1", "r0"]):
        rows = np.concatenate([np.flatnonzero(ids == rec) for rec in order])
        arrays = HMMGMRRegressor(**params).fit(
            X.to_numpy()[rows], y.to_numpy()[rows], groups=ids[rows]
        )
        np.testing.assert_allclose(arrays.means_, reference.means_, rtol=0, atol=1e-10)
        np.testing.assert_allclose(arrays.transmat_, reference.transmat_, rtol=0, atol=1e-10)
    # scattered recordings are still refused, naming one
    scattered = np.tile(["a", "b"], len(ids) // 2)
    with pytest.raises(ValueError, match="'a'"):
        HMMGMRRegressor(**params).fit(X.to_numpy(), y.to_numpy(), groups=scattered)


def test_many_rows_fitted_as_one_recording_without_saying_so_warn():
    """#34: nothing said that a long fit without recordings was one recording."""
    from skhmmgmr import HMMGMRRegressor
    from skhmmgmr.estimator._prediction_inputs import ONE_RECORDING_ROWS

    rng = np.random.default_rng(7)
    n = ONE_RECORDING_ROWS + 1
    X = np.cumsum(rng.normal(scale=0.1, size=(n, 1)), axis=0)
    y = np.tanh(X[:, 0])
    params = {"n_states": 1, "random_state": 0, "n_iter": 2}
    with pytest.warns(UserWarning, match=r"ONE recording.*groups=.*'recording' level.*say so"):
        HMMGMRRegressor(**params).fit(X, y)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        HMMGMRRegressor(**params).fit(X, y, groups=np.zeros(n))  # said so
        HMMGMRRegressor(**params).fit(X[:ONE_RECORDING_ROWS], y[:ONE_RECORDING_ROWS])
