"""FilterStream of a fitted torque pipeline: the sensed rows in, the estimates of
``pipeline.predict`` out (#36).

The references are independent of the stream's code: ``pipeline.predict`` (the batch transform
and the regressor's batch filter), the regressor's own stream fed the rows of the batch
transform, and a plain loop of the velocity filter."""

import math
import pickle
import shutil

import numpy as np
import pandas as pd
import pytest
from sklearn.exceptions import NotFittedError
from sklearn.linear_model import Ridge
from sklearn.pipeline import Pipeline, make_pipeline
from sklearn.preprocessing import StandardScaler
from test_torque_pipeline import _plain_filter_with_gaps

from skhmmgmr import FilterStream, HMMGMRRegressor, SteeringFeatures, make_torque_pipeline
from skhmmgmr.datasets import make_driving_protocol, to_panel
from skhmmgmr.streaming._derived import DerivedInputs

pytestmark = pytest.mark.filterwarnings("ignore::sklearn.exceptions.ConvergenceWarning")

COLUMNS = ["steering_wheel_angle", "steering_wheel_velocity", "lateral_acceleration", "yaw_rate"]
PERIOD = 0.01
ATOL = 1e-12


@pytest.fixture(scope="module")
def data():
    frame = make_driving_protocol(("defensive",), duration=6.0, sampling_rate=100.0, random_state=0)
    keep = frame["recording"].isin(pd.unique(frame["recording"])[:8])
    return frame[keep].reset_index(drop=True)


def _split(data):
    return data[COLUMNS], data["driver_torque"].to_numpy(), data["recording"].to_numpy()


def _pipeline(data, velocity_filter=0.02, **params):
    X, y, groups = _split(data)
    params = {"random_state": 0, "n_iter": 20, **params}
    pipeline = make_torque_pipeline(
        3, velocity_filter=velocity_filter, sampling_period=PERIOD, **params
    )
    return pipeline.fit(X, y, groups=groups)


@pytest.fixture(scope="module")
def filtered(data):
    return _pipeline(data)


def _by_recording(stream, X, groups, **update):
    """Every recording streamed row by row after a reset: estimates, stds, flags."""
    estimates, stds, flags = [], [], []
    for recording in pd.unique(groups):
        stream.reset()
        for row in np.asarray(X)[groups == recording]:
            estimate, std, flag = stream.update(row, return_std=True, return_flag=True, **update)
            estimates.append(estimate)
            stds.append(std)
            flags.append(flag)
    return np.array(estimates), np.array(stds), flags


@pytest.mark.parametrize("velocity_filter", [None, 0.02])
def test_the_stream_of_sensed_rows_equals_predict(data, velocity_filter):
    pipeline = _pipeline(data, velocity_filter)
    X, _, groups = _split(data)
    stream = pipeline.filter_stream()
    assert isinstance(stream, FilterStream) and stream.n_features_in_ == len(COLUMNS)
    estimates, stds, flags = _by_recording(stream, X, groups)
    expected, expected_std = pipeline.predict(X, groups=groups, return_std=True)
    np.testing.assert_allclose(estimates, expected, rtol=0, atol=ATOL)
    np.testing.assert_allclose(stds, expected_std, rtol=0, atol=ATOL)
    assert set(flags) <= {"ok", "restarted"}
    # the regressor's state probabilities after the last row
    last = pipeline.predict_state_proba(X, groups=groups)[-1]
    np.testing.assert_allclose(stream.state_proba_, last, rtol=0, atol=ATOL)
    if velocity_filter is not None:  # the filter matters: one recording differs from many
        with pytest.warns(UserWarning, match="ONE recording"):
            one = pipeline.predict(X)
        assert np.abs(one - expected).max() > 1e-6


def test_a_recording_that_starts_mid_curve(data, filtered):
    """The velocity filter starts at the first velocity it is given, as predict's does."""
    X, _, groups = _split(data)
    rows = X[groups == groups[0]].iloc[217:]
    assert abs(rows["steering_wheel_velocity"].iloc[0]) > 0.01
    stream = filtered.filter_stream()
    got = [stream.update(row) for row in rows.to_numpy()]
    np.testing.assert_allclose(got, filtered.predict(rows), rtol=0, atol=ATOL)
    # reset restarts both filters: the same rows give the same estimates
    again = [stream.reset().update(row) for row in rows.to_numpy()[:1]]
    again += [stream.update(row) for row in rows.to_numpy()[1:]]
    np.testing.assert_array_equal(again, got)


def test_update_batch_restarts_at_every_recording_of_a_shuffled_panel(data, filtered):
    panel = to_panel(data)
    shuffled = panel.sample(frac=1.0, random_state=3)
    X = shuffled[COLUMNS]
    expected, expected_std = filtered.predict(X, return_std=True)
    stream = filtered.filter_stream()
    got, std = stream.update_batch(X, return_std=True)
    np.testing.assert_allclose(got, expected, rtol=0, atol=ATOL)
    np.testing.assert_allclose(std, expected_std, rtol=0, atol=ATOL)
    # a recording given in two batches goes on (the velocity filter too), then the next
    ordered = panel[COLUMNS]
    recordings = pd.unique(ordered.index.get_level_values("recording"))
    first = ordered.loc[[recordings[0]]]
    second = ordered.loc[[recordings[1]]]
    stream.reset()
    parts = [stream.update_batch(first.iloc[:250]), stream.update_batch(first.iloc[250:])]
    parts.append(stream.update_batch(second))
    np.testing.assert_allclose(
        np.concatenate(parts),
        filtered.predict(pd.concat([first, second])),
        rtol=0,
        atol=ATOL,
    )
    # the rows of plain arrays are one recording until reset, as the regressor's stream
    X_plain, _, groups = _split(data)
    rows = X_plain[groups == groups[0]]
    stream.reset()
    np.testing.assert_allclose(
        stream.update_batch(rows.to_numpy()), filtered.predict(rows), rtol=0, atol=ATOL
    )


def test_a_time_level_at_another_period_is_refused_as_by_predict(data, filtered):
    panel = to_panel(data)[COLUMNS]
    slow = panel.set_axis(panel.index.set_levels(panel.index.levels[1] * 5, level="time"), axis=0)
    with pytest.raises(ValueError, match="sampling_period=0.01"):
        filtered.predict(slow)
    with pytest.raises(ValueError, match="sampling_period=0.01"):
        filtered.filter_stream().update_batch(slow)


def _regressor_stream(pipeline, X, **kwargs):
    """The regressor's own stream fed the rows of the batch transform of one recording."""
    derived = pipeline[:-1].transform(X).to_numpy()
    return derived, pipeline[-1].filter_stream(**kwargs)


@pytest.mark.parametrize(
    "column, value",
    [("steering_wheel_angle", 1e6), ("steering_wheel_velocity", 1e4), ("yaw_rate", -1e300)],
)
def test_a_held_row_still_feeds_the_velocity_filter(data, filtered, column, value):
    """Rule: a held (outlier) row is held by the regressor, but its velocity goes through
    the velocity filter as predict's transform takes it, so the derived inputs of the rows
    after it are predict's. (The far rows are held by the hold setting, the -1e300 one for
    being out of the model's range.)"""
    X, _, groups = _split(data)
    rows = X[groups == groups[1]].copy()
    held = [40, 41, 300]
    rows.iloc[held, rows.columns.get_loc(column)] = value
    stream = filtered.filter_stream(min_log_density=-1e3)
    got, flags = stream.update_batch(rows.to_numpy(), return_flag=True)
    assert [i for i, flag in enumerate(flags) if flag == "outlier"] == held
    # the regressor's stream on predict's derived rows
    derived, reference = _regressor_stream(filtered, rows, min_log_density=-1e3)
    expected, expected_flags = reference.update_batch(derived, return_flag=True)
    np.testing.assert_allclose(got, expected, rtol=0, atol=ATOL)
    assert list(flags) == list(expected_flags)
    # and, after the last held row, predict of the regressor on the other rows
    kept = pd.DataFrame(np.delete(derived, held, axis=0), columns=filtered[-1].feature_names_in_)
    after = filtered[-1].predict(kept)[held[-1] - len(held) + 1 :]
    np.testing.assert_allclose(got[held[-1] + 1 :], after, rtol=0, atol=ATOL)
    if column == "steering_wheel_velocity":  # the rule matters here
        skipped = rows.copy()
        skipped.iloc[held, rows.columns.get_loc(column)] = np.nan
        first = filtered[0].get_feature_names_out()[len(COLUMNS)]  # a friction input
        friction = filtered[:-1].transform(skipped)[first].to_numpy()
        assert np.abs(friction[302:310] - derived[302:310, len(COLUMNS)]).max() > 1e-3


def test_an_infinite_velocity_is_held_and_read_as_missing_by_the_velocity_filter(data, filtered):
    X, _, groups = _split(data)
    rows = X[groups == groups[2]].copy()
    velocity = rows.columns.get_loc("steering_wheel_velocity")
    rows.iloc[100, velocity] = np.inf
    stream = filtered.filter_stream()
    got, flags = stream.update_batch(rows.to_numpy(), return_flag=True)
    assert flags[100] == "non-finite" and np.isfinite(got).all()
    missing = rows.copy()
    missing.iloc[100, velocity] = np.nan
    derived = filtered[:-1].transform(missing).to_numpy()
    derived[100, velocity] = np.inf
    expected = filtered[-1].filter_stream().update_batch(derived)
    np.testing.assert_allclose(got, expected, rtol=0, atol=ATOL)


@pytest.mark.parametrize("missing_values", ["marginalize", "carry_forward"])
def test_missing_sensed_inputs_as_predict(data, missing_values):
    pipeline = _pipeline(data, missing_values=missing_values)
    X, _, groups = _split(data)
    rng = np.random.default_rng(5)
    values = X.to_numpy().copy()
    values[rng.random(values.shape) < 0.1] = np.nan
    starts = np.flatnonzero(np.r_[True, groups[1:] != groups[:-1]])
    values[starts[1] : starts[1] + 3, 1] = np.nan  # a recording that starts without velocity
    values[starts[2] + 50 : starts[2] + 60, 1] = np.nan  # a gap of ten rows
    values[starts[3] + 7] = np.nan  # a row with nothing observed
    X = pd.DataFrame(values, columns=COLUMNS)
    stream = pipeline.filter_stream()
    assert stream.missing_values == missing_values
    estimates, stds, flags = _by_recording(stream, X, groups)
    expected, expected_std = pipeline.predict(X, groups=groups, return_std=True)
    np.testing.assert_allclose(estimates, expected, rtol=0, atol=ATOL)
    np.testing.assert_allclose(stds, expected_std, rtol=0, atol=ATOL)
    assert "missing" in flags
    shuffled = to_panel(data.assign(**{c: X[c] for c in COLUMNS})).sample(frac=1, random_state=0)
    np.testing.assert_allclose(
        stream.update_batch(shuffled[COLUMNS]),
        pipeline.predict(shuffled[COLUMNS]),
        rtol=0,
        atol=ATOL,
    )


def test_online_adaptation_is_the_regressors_on_the_derived_rows(data, filtered):
    X, y, groups = _split(data)
    rows, targets = X[groups == groups[3]], y[groups == groups[3]] + 0.3
    stream = filtered.filter_stream(relevance=16.0, forgetting=0.999)
    got = [
        stream.update(row, target=target)
        for row, target in zip(rows.to_numpy(), targets, strict=True)
    ]
    derived, reference = _regressor_stream(filtered, rows, relevance=16.0, forgetting=0.999)
    expected = [
        reference.update(row, target=target) for row, target in zip(derived, targets, strict=True)
    ]
    np.testing.assert_allclose(got, expected, rtol=0, atol=ATOL)
    np.testing.assert_allclose(
        stream.adapted_model().emissions.means, reference.adapted_model().emissions.means, atol=ATOL
    )
    assert np.abs(np.array(got) - filtered.predict(rows)).max() > 1e-3  # it learned
    batch = filtered.filter_stream(relevance=16.0, forgetting=0.999)
    np.testing.assert_allclose(batch.update_batch(rows, y=targets), got, rtol=0, atol=ATOL)


def test_rows_by_name(data, filtered):
    X, _, groups = _split(data)
    rows = X[groups == groups[0]].iloc[:40]
    stream = filtered.filter_stream()
    np.testing.assert_array_equal(stream.feature_names_in_, COLUMNS)
    got = [stream.update(dict(reversed(list(row.items())))) for _, row in rows.iloc[:20].iterrows()]
    got += [stream.update(row) for _, row in rows.iloc[20:].iterrows()]  # Series
    np.testing.assert_allclose(got, filtered.predict(rows), rtol=0, atol=ATOL)
    with pytest.raises(ValueError, match="yaw_rate"):
        stream.update({name: 0.0 for name in COLUMNS[:3]})
    with pytest.raises(ValueError, match=r"shape \(4,\)"):
        stream.update(np.zeros(9))  # a derived row is not a sensed one


def test_any_scikit_learn_pipeline_of_the_steps_streams(data):
    X, y, groups = _split(data)
    first = SteeringFeatures(load_columns=("lateral_acceleration",), powers=(3,))
    second = SteeringFeatures(
        friction_velocity=0.2,
        velocity_filter=0.05,
        sampling_period=PERIOD,
        load_columns=("steering_wheel_angle",),
        powers=(2,),
    )
    plain = Pipeline(
        [
            ("first", first),
            ("nothing", "passthrough"),
            ("second", second),
            ("hmmgmr", HMMGMRRegressor(2, random_state=0, n_iter=10)),
        ]
    )
    with pytest.raises(ValueError, match="steering_friction"):  # both derive it
        plain.fit(X, y)
    second.set_params(friction_velocity=None)
    panel = to_panel(data)
    plain.fit(panel[COLUMNS], panel["driver_torque"])
    stream = FilterStream(plain)
    np.testing.assert_allclose(
        stream.update_batch(panel[COLUMNS]), plain.predict(panel[COLUMNS]), rtol=0, atol=ATOL
    )
    arrays = make_pipeline(
        SteeringFeatures(
            friction_column=1, load_columns=(0, 2), velocity_filter=0.02, sampling_period=PERIOD
        ),
        HMMGMRRegressor(2, random_state=0, n_iter=10),
    ).fit(X.to_numpy(), y)
    rows = X.to_numpy()[groups == groups[0]]
    stream = FilterStream(arrays)
    got = [stream.update(row) for row in rows]
    np.testing.assert_allclose(got, arrays.predict(rows), rtol=0, atol=ATOL)
    assert not hasattr(stream, "feature_names_in_")


def test_a_step_that_does_not_stream_is_refused_by_name(data):
    X, y, _ = _split(data)
    scaled = Pipeline([("scale", StandardScaler()), ("hmmgmr", HMMGMRRegressor(2, n_iter=5))])
    with pytest.raises(TypeError, match=r"step 'scale' \(StandardScaler\) cannot be streamed"):
        FilterStream(scaled.fit(X, y))
    ridge = Pipeline([("features", SteeringFeatures()), ("ridge", Ridge())]).fit(X, y)
    with pytest.raises(TypeError, match=r"last step 'ridge' \(Ridge\) is not an HMMGMRRegressor"):
        FilterStream(ridge)
    with pytest.raises(NotFittedError):
        make_torque_pipeline(2).filter_stream()


def test_a_pickled_stream_goes_on_where_it_was(data, filtered):
    X, _, groups = _split(data)
    frame = X[groups == groups[4]]
    rows = frame.to_numpy()
    stream = filtered.filter_stream()
    head = [stream.update(row) for row in rows[:100]]
    copy = pickle.loads(pickle.dumps(stream))
    tail = [stream.update(row) for row in rows[100:]]
    np.testing.assert_array_equal([copy.update(row) for row in rows[100:]], tail)
    np.testing.assert_allclose(head + tail, filtered.predict(frame), rtol=0, atol=ATOL)


def _one_velocity_filter(decay):
    """The stream settings of one velocity column, filtered, and one friction width."""
    return {
        "n_features_in": 1,
        "feature_names_in": None,
        "feature_names_out": ["x0", "steering_friction"],
        "friction_position": 0,
        "friction_velocity": 0.1,
        "filter_decay": decay,
        "sampling_period": 0.01,
        "angle_position": None,
        "friction_angle": None,
        "load_positions": [],
        "powers": [],
    }


def test_the_velocity_filter_of_the_stream_is_a_plain_loop():
    decay = math.exp(-0.5)
    settings = _one_velocity_filter(decay)
    stage = DerivedInputs(settings)
    velocity = np.random.default_rng(2).normal(scale=0.1, size=60)
    velocity[[0, 1, 10, 30, 31, 32]] = np.nan
    got = []
    for value in velocity:
        values = [float(value)]
        stage.append(values)
        got.append(values[1])
    expected = np.tanh(_plain_filter_with_gaps(velocity, decay) / 0.1)
    np.testing.assert_array_equal(np.isnan(got), np.isnan(velocity))
    np.testing.assert_allclose(got, expected, rtol=1e-13)
    stage.reset()
    values = [0.05]
    stage.append(values)
    assert values[1] == pytest.approx(math.tanh(0.5), abs=1e-15)  # starts at the value again


@pytest.mark.parametrize("layout", ["one filter's state", "decay beside its filter"])
def test_a_stream_pickled_by_an_older_release_goes_on_where_it_was(layout):
    decay = math.exp(-0.5)
    settings = _one_velocity_filter(decay)
    velocity = np.random.default_rng(3).normal(scale=0.1, size=40)
    velocity[[12, 13]] = np.nan
    stage = DerivedInputs(settings)
    for value in velocity[:15]:
        stage.append([float(value)])
    state = dict(stage.__dict__)
    if layout == "one filter's state":
        low_pass = state.pop("filter")
        del state["slow"]
        state.update(
            decay=decay, gain=1.0 - decay, filtered=low_pass.filtered, since=low_pass.since
        )
    else:
        state["decay"] = decay
    old = DerivedInputs.__new__(DerivedInputs)
    old.__setstate__(state)
    assert "decay" not in old.__dict__ and old.slow is None
    expected = np.tanh(_plain_filter_with_gaps(velocity, decay) / 0.1)[15:]
    got = []
    for value in velocity[15:]:
        values = [float(value)]
        old.append(values)
        got.append(values[1])
    np.testing.assert_allclose(got, expected, rtol=1e-13)


def _plain_play(angle, radius):
    """A plain loop of the play: the position follows the angle at most ``radius`` behind,
    from the first observed angle; a missing angle gives NaN and moves nothing."""
    out, position = [], None
    for value in angle:
        if not math.isfinite(value):
            out.append(math.nan)
            continue
        position = value if position is None else min(max(position, value - radius), value + radius)
        out.append((value - position) / radius)
    return np.array(out)


def test_the_plays_of_the_stream_and_the_transform_are_a_plain_loop():
    """The hysteresis inputs, sample by sample (the stream) and per recording (the batch
    transform), against a plain loop of the play, with missing angles; the stream restarts
    at its reset, the transform at every recording."""
    radii = (0.002, 0.01)
    rng = np.random.default_rng(3)
    angle = np.cumsum(rng.normal(scale=0.004, size=120))
    angle[[0, 7, 8, 50]] = np.nan
    groups = np.repeat(["a", "b"], 60)
    step = SteeringFeatures(friction_velocity=None, load_columns=(), friction_angle=radii)
    step.angle_column = 0
    batch = step.fit_transform(angle[:, np.newaxis], groups=groups)[:, 1:]
    stage = DerivedInputs(step.stream_settings())
    for recording in ("a", "b"):
        rows = groups == recording
        expected = np.column_stack([_plain_play(angle[rows], r) for r in radii])
        stage.reset()
        streamed = []
        for value in angle[rows]:
            values = [float(value)]
            stage.append(values)
            streamed.append(values[1:])
        np.testing.assert_array_equal(np.asarray(streamed), expected)
        np.testing.assert_array_equal(batch[rows], expected)
    assert np.nanmax(np.abs(batch)) == pytest.approx(1.0, abs=1e-12)  # a play turned over


@pytest.mark.filterwarnings("ignore:overflow encountered:RuntimeWarning")
def test_a_huge_load_is_held_as_predict_refuses_it(data, filtered, tmp_path):
    """#51: a finite load of 1e200 raised OverflowError from the derived inputs (its cube);
    the stream now holds it as the C filter does (its cube is infinite: non-finite), and a
    load of 1e60, whose cube is finite but out of the model's range, as an outlier; predict
    refuses both, naming the column."""
    X, _, groups = _split(data)
    rows = X[groups == groups[1]].iloc[:50].copy()
    angle = rows.columns.get_loc("steering_wheel_angle")
    rows.iloc[10, angle], rows.iloc[20, angle] = 1e200, 1e60
    stream = filtered.filter_stream()
    got, flags = stream.update_batch(rows.to_numpy(), return_flag=True)
    assert (flags[10], flags[20]) == ("non-finite", "outlier") and np.isfinite(got).all()
    assert got[10] == got[9] and got[20] == got[19]
    assert stream.reset().update(rows.to_numpy()[10], return_flag=True)[1] == "non-finite"
    with pytest.raises(ValueError, match="infinity in column 'steering_wheel_angle_signed_sq"):
        filtered.predict(rows.iloc[:15])
    with pytest.raises(ValueError, match="out of the model's range.*'steering_wheel_angle_cube'"):
        filtered.predict(rows.iloc[15:25])
    if shutil.which("cc"):  # the C filter holds them with the same codes
        from test_export_c import Compiled

        codes = Compiled(filtered, tmp_path).run(rows, np.zeros(len(rows)))[2]
        assert codes[[10, 20]].tolist() == [1, 2] and np.count_nonzero(codes) == 2
