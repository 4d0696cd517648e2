"""SteeringFeatures and make_torque_pipeline: hand-computed derived inputs, the pipeline against
the regressor fitted on the same columns by hand, model selection over the pipeline, and the
derived inputs as ordinary features of the selection framework."""

import functools
import math
import pickle

import numpy as np
import pandas as pd
import pytest
import sklearn
import sklearn.base
from sklearn.model_selection import GridSearchCV, GroupKFold

from skhmmgmr import (
    ForwardFeatureSelector,
    HMMGMRRegressor,
    SteeringFeatures,
    make_torque_pipeline,
)
from skhmmgmr._hmm._em import PROBABILITY_FLOOR, HMMParameters, Statistics, m_step
from skhmmgmr._hmm._emissions import CovariancePrior, MomentStatistics
from skhmmgmr.datasets import FEATURE_NAMES, make_lane_keeping
from skhmmgmr.metrics import make_performance_scorers

pytestmark = pytest.mark.filterwarnings("ignore::sklearn.exceptions.ConvergenceWarning")

COLUMNS = ["steering_wheel_angle", "steering_wheel_velocity", "lateral_acceleration"]


def _frame():
    return pd.DataFrame(
        [[0.1, 0.0, 1.0], [-0.2, 0.05, -2.0], [np.nan, -1.0, 0.5]],
        columns=COLUMNS,
        index=pd.Index(["a", "b", "c"], name="row"),
    )


def test_derived_inputs_equal_a_hand_computation():
    X = _frame()
    X.attrs["units"] = {"steering_wheel_angle": "rad", "lateral_acceleration": "m/s^2"}
    out = SteeringFeatures().fit_transform(X)
    assert list(out.columns) == [
        *COLUMNS,
        "steering_friction",
        "steering_wheel_angle_signed_square",
        "steering_wheel_angle_cube",
        "lateral_acceleration_signed_square",
        "lateral_acceleration_cube",
    ]
    assert out.index.equals(X.index)
    expected = {
        "steering_friction": [0.0, math.tanh(0.5), math.tanh(-10.0)],
        "steering_wheel_angle_signed_square": [0.01, -0.04, np.nan],
        "steering_wheel_angle_cube": [0.001, -0.008, np.nan],
        "lateral_acceleration_signed_square": [1.0, -4.0, 0.25],
        "lateral_acceleration_cube": [1.0, -8.0, 0.125],
    }
    for name, values in expected.items():
        np.testing.assert_allclose(out[name], values, rtol=1e-15, err_msg=name)
    pd.testing.assert_frame_equal(out[COLUMNS], X)
    assert out.attrs["units"]["lateral_acceleration_cube"] == "(m/s^2)^3"
    assert out.attrs["units"]["steering_friction"] == "1"
    assert "units" not in X.attrs or "steering_friction" not in X.attrs["units"]


def test_options_and_arrays():
    X = _frame()
    out = SteeringFeatures(
        friction_velocity=None, load_columns=["lateral_acceleration"], powers=(4,)
    ).fit_transform(X)
    assert list(out.columns[3:]) == ["lateral_acceleration_signed_power4"]
    np.testing.assert_allclose(out.iloc[:, 3], [1.0, -16.0, 0.0625])
    values = X.to_numpy()
    transformer = SteeringFeatures(
        friction_velocity=0.5, friction_column=1, load_columns=(2,), powers=(2,)
    ).fit(values)
    array_out = transformer.transform(values)
    np.testing.assert_allclose(array_out[:, 3], np.tanh(values[:, 1] / 0.5))
    np.testing.assert_allclose(array_out[:, 4], values[:, 2] * np.abs(values[:, 2]))
    assert list(transformer.get_feature_names_out()) == [
        "x0",
        "x1",
        "x2",
        "steering_friction",
        "x2_signed_square",
    ]


def test_row_by_row_equals_whole_frame():
    """Nothing crosses a row: the transform streams."""
    X = _frame()
    transformer = SteeringFeatures().fit(X)
    whole = transformer.transform(X)
    rows = pd.concat([transformer.transform(X.iloc[[i]]) for i in range(len(X))])
    pd.testing.assert_frame_equal(rows, whole)


@pytest.mark.parametrize(
    ("params", "X", "message"),
    [
        (
            {},
            _frame().drop(columns="lateral_acceleration"),
            r"needs the column\(s\) "
            r"\['lateral_acceleration'\].*X has columns",
        ),
        ({}, _frame().to_numpy(), "X has no column names"),
        ({"friction_column": 7}, _frame(), r"needs the column\(s\) \[7\]"),
        ({"powers": (1, 2)}, _frame(), "powers must hold integers >= 2"),
        ({"powers": (2, 2)}, _frame(), "repeats a power"),
        ({"load_columns": ("lateral_acceleration",) * 2}, _frame(), "repeats a column"),
        ({"friction_velocity": 0.0}, _frame(), "'friction_velocity' parameter"),
    ],
)
def test_bad_input_is_named(params, X, message):
    with pytest.raises(ValueError, match=message):
        SteeringFeatures(**params).fit(X)


def test_transform_checks_the_columns_seen_in_fit():
    transformer = SteeringFeatures().fit(_frame())
    with pytest.raises(ValueError, match="feature names"):
        transformer.transform(_frame()[COLUMNS[::-1]])
    with pytest.raises(ValueError, match="input_features has 2 names"):
        transformer.get_feature_names_out(["a", "b"])


def test_unknown_pipeline_parameter_is_named():
    with pytest.raises(TypeError, match=r"unknown parameter\(s\) \['n_state'\]"):
        make_torque_pipeline(n_state=3)


@pytest.fixture(scope="module")
def recordings():
    frames = [
        make_lane_keeping(
            20.0, driver=style, sampling_rate=20.0, random_state=seed, recording=f"{style}-{seed}"
        )
        for seed, style in enumerate(["defensive", "aggressive", "novice", "defensive"])
    ]
    data = pd.concat(frames, ignore_index=True)
    return data[list(FEATURE_NAMES)], data["driver_torque"].to_numpy(), data["recording"]


def test_pipeline_equals_the_regressor_on_the_derived_columns(recordings):
    X, y, groups = recordings
    pipeline = make_torque_pipeline(n_states=2, random_state=0, n_iter=20)
    pipeline.fit(X, y, groups=groups)
    # the pipeline's regressor reads out the estimate by the "auto" rule (its default)
    by_hand = HMMGMRRegressor(n_states=2, random_state=0, n_iter=20, output_smoothing="auto")
    # the friction and hysteresis inputs and the plays' lead the pipeline chose ("auto"), by
    # hand
    chosen = SteeringFeatures(
        friction_velocity=pipeline[0].friction_velocity_,
        friction_angle=pipeline[0].friction_angle_,
        angle_lead=pipeline[0].angle_lead_,
    )
    derived = chosen.fit_transform(X, groups=groups)
    by_hand.fit(derived, y, groups=groups)
    np.testing.assert_array_equal(
        pipeline.predict(X, groups=groups), by_hand.predict(derived, groups=groups)
    )
    assert list(pipeline[-1].feature_names_in_) == list(derived.columns)
    again = pickle.loads(pickle.dumps(pipeline))
    np.testing.assert_array_equal(
        again.predict(X, groups=groups), pipeline.predict(X, groups=groups)
    )


def test_grid_search_over_states_with_routed_recordings(recordings):
    X, y, groups = recordings
    scorers = make_performance_scorers(["50/50"], sampling_period=0.05)
    with sklearn.config_context(enable_metadata_routing=True):
        search = GridSearchCV(
            make_torque_pipeline(random_state=0, n_iter=10),
            {"hmmgmr__n_states": [1, 2]},
            cv=GroupKFold(n_splits=2),
            scoring=scorers,
            refit="neg_performance_50/50",
        ).fit(X, y, groups=groups)
    assert search.best_params_["hmmgmr__n_states"] in (1, 2)
    # each split's score equals the pipeline fitted and scored by hand on that split
    for k in (1, 2):
        by_hand = []
        for train, test in GroupKFold(n_splits=2).split(X, y, groups):
            model = make_torque_pipeline(n_states=k, random_state=0, n_iter=10)
            model.fit(X.iloc[train], y[train], groups=groups.iloc[train])
            scorer = scorers["neg_performance_50/50"]
            with sklearn.config_context(enable_metadata_routing=True):
                by_hand.append(scorer(model, X.iloc[test], y[test], groups=groups.iloc[test]))
        index = search.cv_results_["param_hmmgmr__n_states"].tolist().index(k)
        np.testing.assert_allclose(
            search.cv_results_["mean_test_neg_performance_50/50"][index], np.mean(by_hand)
        )


def test_selection_framework_keeps_or_drops_derived_inputs():
    """A torque made of friction only: the forward selection picks the friction input first."""
    rng = np.random.default_rng(0)
    n, groups = 1200, np.repeat(["r0", "r1", "r2", "r3"], 300)
    t = np.arange(n) * 0.05
    X = pd.DataFrame(
        np.column_stack([np.sin(f * t + rng.uniform(0, 6)) for f in (0.5, 1.3, 0.8)]) * 0.3,
        columns=COLUMNS,
    )
    y = 0.3 * np.tanh(X["steering_wheel_velocity"].to_numpy() / 0.1)
    y += 0.01 * rng.normal(size=n)
    derived = SteeringFeatures().fit_transform(X)
    selector = ForwardFeatureSelector(
        HMMGMRRegressor(n_states=1),
        max_features=1,
        accuracy_weight=1.0,
        smoothness_weight=0.0,
        sampling_period=0.05,
        cv=2,
    ).fit(derived, y, groups=groups)
    assert list(selector.get_feature_names_out()) == ["steering_friction"]


def test_zero_probabilities_are_floored_and_keep_recordings_possible():
    """Counts that make a start or transition probability exactly zero give the floor."""
    n_states, n_features = 2, 1
    moments = MomentStatistics(
        np.ones(n_states),
        np.zeros((n_states, n_features)),
        np.ones((n_states, n_features, n_features)),
        np.zeros(n_features),
    )
    stats = Statistics(0.0, np.array([3.0, 0.0]), np.array([[5.0, 0.0], [1.0, 4.0]]), moments)
    previous = HMMParameters.gaussian(
        np.full(2, 0.5), np.full((2, 2), 0.5), np.zeros((2, 1)), np.ones((2, 1, 1))
    )
    params = m_step(stats, previous, prior=CovariancePrior(1e-6))
    np.testing.assert_allclose(params.startprob, [1.0, PROBABILITY_FLOOR], rtol=1e-15)
    np.testing.assert_allclose(params.transmat, [[1.0, PROBABILITY_FLOOR], [0.2, 0.8]], rtol=1e-15)
    assert params.transmat[0, 1] > 0.0 and params.startprob[1] > 0.0


def _plain_filter(values, decay):
    out, state = [], values[0]
    for value in values:
        state = decay * state + (1.0 - decay) * value
        out.append(state)
    return np.array(out)


def test_velocity_filter_restarts_at_every_recording():
    rng = np.random.default_rng(1)
    X = pd.DataFrame(rng.normal(size=(30, 3)), columns=COLUMNS)
    groups = np.repeat(["r0", "r1", "r2"], 10)
    transformer = SteeringFeatures(velocity_filter=0.02, sampling_period=0.01)
    out = transformer.fit_transform(X, groups=groups)
    decay = math.exp(-0.5)
    expected = np.concatenate(
        [
            _plain_filter(X["steering_wheel_velocity"].to_numpy()[g == groups], decay)
            for g in ("r0", "r1", "r2")
        ]
    )
    np.testing.assert_allclose(out["steering_friction"], np.tanh(expected / 0.1), rtol=1e-13)
    # the load inputs stay row by row
    np.testing.assert_allclose(
        out["lateral_acceleration_cube"], X["lateral_acceleration"].to_numpy() ** 3, rtol=1e-14
    )
    # a shuffled panel (recordings and time in the index) gives the same rows back
    panel = X.set_index(
        [
            pd.Index(groups, name="recording"),
            pd.Index(np.tile(np.arange(10) * 0.01, 3), name="time"),
        ]
    )
    shuffled = panel.sample(frac=1.0, random_state=0)
    from_panel = transformer.transform(shuffled)
    got = from_panel["steering_friction"].sort_index()
    expected_panel = out.set_index(panel.index)["steering_friction"].sort_index()
    assert got.index.equals(expected_panel.index)
    np.testing.assert_allclose(got.to_numpy(), expected_panel.to_numpy(), rtol=1e-13)


def _plain_filter_with_gaps(values, decay):
    """A plain loop: NaN rows give NaN and are skipped; the next observed value is taken in
    over the whole time since the last observed one (the first-order response to it)."""
    out, state, since = [], None, 0
    for value in values:
        since += 1
        if np.isnan(value):
            out.append(np.nan)
            continue
        if state is None:
            state = value
        else:
            lapse = decay**since
            state = lapse * state + (1.0 - lapse) * value
        since = 0
        out.append(state)
    return np.array(out)


def test_a_missing_velocity_stays_one_missing_friction_input():
    """#35: one NaN velocity used to make the friction input NaN for the rest of the
    recording."""
    rng = np.random.default_rng(3)
    X = pd.DataFrame(rng.normal(size=(200, 3)), columns=COLUMNS)
    velocity = X["steering_wheel_velocity"].to_numpy().copy()
    velocity[[0, 1, 20, 50, 51, 52, 199]] = np.nan  # missing at the start, alone, in a run
    X["steering_wheel_velocity"] = velocity
    groups = np.repeat(["a", "b"], 100)
    out = SteeringFeatures(velocity_filter=0.02, sampling_period=0.01).fit_transform(
        X, groups=groups
    )
    decay = math.exp(-0.5)
    expected = np.concatenate(
        [_plain_filter_with_gaps(velocity[g == groups], decay) for g in ("a", "b")]
    )
    friction = out["steering_friction"].to_numpy()
    np.testing.assert_array_equal(np.isnan(friction), np.isnan(velocity))
    np.testing.assert_allclose(friction, np.tanh(expected / 0.1), rtol=1e-12)
    # without a missing value the rule is the plain filter
    assert np.allclose(
        _plain_filter_with_gaps(np.arange(5.0), decay), _plain_filter(np.arange(5.0), decay)
    )


def test_velocity_filter_needs_the_sampling_period():
    with pytest.raises(ValueError, match="velocity_filter=0.02 needs sampling_period"):
        SteeringFeatures(velocity_filter=0.02).fit(_frame())


def test_recordings_reach_the_filter_through_routing(recordings):
    X, y, groups = recordings
    params = {
        "friction_velocity": 0.1,
        "velocity_filter": 0.1,
        "sampling_period": 0.05,
        "friction_angle": None,
        "slow_velocity_filter": None,
        "n_iter": 5,
        "random_state": 0,
    }
    with sklearn.config_context(enable_metadata_routing=True):
        pipeline = make_torque_pipeline(n_states=2, **params).fit(X, y, groups=groups)
        routed = pipeline.predict(X, groups=groups)
    derived = SteeringFeatures(velocity_filter=0.1, sampling_period=0.05).fit_transform(
        X, groups=groups
    )
    by_hand = HMMGMRRegressor(n_states=2, n_iter=5, random_state=0).fit(derived, y, groups=groups)
    np.testing.assert_array_equal(routed, by_hand.predict(derived, groups=groups))


def test_an_input_named_like_a_derived_one_is_refused():
    """#35: an input column named steering_friction gave duplicate columns and a narwhals
    error at fit."""
    X = _frame().assign(steering_friction=0.0)
    with pytest.raises(ValueError, match=r"X already has the column\(s\) \['steering_friction'\]"):
        SteeringFeatures().fit(X)
    assert (
        "steering_friction"
        not in SteeringFeatures(friction_velocity=None).fit_transform(X).columns[X.shape[1] :]
    )
    cube = _frame().assign(steering_wheel_angle_cube=0.0)
    with pytest.raises(ValueError, match="'steering_wheel_angle_cube'"):
        make_torque_pipeline(n_states=2).fit(cube, np.zeros(len(cube)))


def test_a_period_the_time_level_contradicts_is_refused():
    """#35: sampling_period=0.05 with a panel stepping 0.01 s was accepted (friction input off
    by up to 1.71)."""
    rng = np.random.default_rng(4)
    X = pd.DataFrame(rng.normal(size=(60, 3)), columns=COLUMNS)
    X.index = pd.MultiIndex.from_arrays(
        [np.repeat(["a", "b"], 30), np.tile(np.arange(30) * 0.01, 2)], names=["recording", "time"]
    )
    wrong = SteeringFeatures(velocity_filter=0.02, sampling_period=0.05)
    with pytest.raises(
        ValueError, match=r"steps 0.01 s \(median\) in recording 'a', but sampling_period=0.05"
    ):
        wrong.fit_transform(X)
    right = SteeringFeatures(velocity_filter=0.02, sampling_period=0.01).fit_transform(X)
    assert np.isfinite(right["steering_friction"]).all()


# --- #34: the package's pipeline hands the recordings to every step ----------------------------


def _protocol(seed=0):
    from skhmmgmr.datasets import FEATURE_NAMES, make_driving_protocol

    data = make_driving_protocol(
        ("defensive",), duration=6.0, sampling_rate=100.0, random_state=seed
    )
    return data[list(FEATURE_NAMES)], data["driver_torque"], data["recording"].to_numpy(), data


def _filtered_pipeline():
    return make_torque_pipeline(2, velocity_filter=0.02, sampling_period=0.01, random_state=0)


def test_groups_given_to_the_pipeline_reach_the_velocity_filter():
    """With routing off, hmmgmr__groups reached the regressor only and the filter ran across
    recordings (up to 0.11 Nm off, no warning)."""
    from skhmmgmr.datasets import to_panel

    X, y, groups, data = _protocol()
    with_groups = _filtered_pipeline().fit(X, y, groups=groups)
    estimate = with_groups.predict(X, groups=groups)
    panel = to_panel(data)
    from_panel = _filtered_pipeline().fit(panel[X.columns], panel["driver_torque"])
    expected = from_panel.predict(panel[X.columns])
    np.testing.assert_allclose(estimate, expected, rtol=0, atol=1e-12)
    assert with_groups.score(X, y, groups=groups) == pytest.approx(
        from_panel.score(panel[X.columns], panel["driver_torque"]), abs=1e-12
    )
    one_recording = with_groups.predict(X)
    assert np.abs(one_recording - estimate).max() > 1e-3  # the recordings matter here


def test_a_step_that_needs_the_recordings_may_not_be_left_without_them():
    X, y, groups, _ = _protocol()
    with pytest.raises(ValueError, match=r"reach the step\(s\) \['hmmgmr'\] but not \['steering_"):
        _filtered_pipeline().fit(X, y, hmmgmr__groups=groups)
    # the plays of the hysteresis inputs (the default "auto") restart at every recording too
    with pytest.raises(ValueError, match=r"reach the step\(s\) \['hmmgmr'\] but not \['steering_"):
        make_torque_pipeline(2, random_state=0).fit(X, y, hmmgmr__groups=groups)
    # without them and a velocity filter the transformer reads rows one by one: nothing is
    # refused
    make_torque_pipeline(2, friction_angle=None, random_state=0).fit(X, y, hmmgmr__groups=groups)


def test_groups_are_routed_alike_with_metadata_routing_on():
    X, y, groups, _ = _protocol()
    off = _filtered_pipeline().fit(X, y, groups=groups).predict(X, groups=groups)
    with sklearn.config_context(enable_metadata_routing=True):
        on = _filtered_pipeline().fit(X, y, groups=groups).predict(X, groups=groups)
    np.testing.assert_allclose(on, off, rtol=0, atol=1e-12)


class _RecordingCentring(sklearn.base.TransformerMixin, sklearn.base.BaseEstimator):
    """A step of another library: centres every input within each recording, with pandas
    (``unique`` and ``groupby`` refuse anything but an array or a pandas object)."""

    def fit(self, X, y=None, groups=None):
        self.recordings_ = None if groups is None else list(pd.unique(groups))
        return self

    def fit_transform(self, X, y=None, groups=None):
        return self.fit(X, y, groups).transform(X, groups)

    def transform(self, X, groups=None):
        if groups is None:
            return X
        return X - X.groupby(np.asarray(groups)).transform("mean").set_axis(X.index)


def _with_centring(step):
    pipeline = make_torque_pipeline(2, friction_angle=None, random_state=0, n_iter=10)
    pipeline.steps.insert(0, ("centring", step))
    return pipeline


def test_a_step_of_another_library_gets_no_groups_with_routing_off(recordings):
    """With routing off nobody can set a request: a step that leaves it unset gets no
    ``groups``, as from scikit-learn's Pipeline (it raised UnsetMetadataPassedError)."""
    X, y, groups = recordings
    pipeline = _with_centring(_RecordingCentring()).fit(X, y, groups=groups)
    assert pipeline[0].recordings_ is None
    plain = make_torque_pipeline(2, friction_angle=None, random_state=0, n_iter=10)
    expected = plain.fit(X, y, groups=groups).predict(X, groups=groups)
    np.testing.assert_array_equal(pipeline.predict(X, groups=groups), expected)


def test_a_step_of_another_library_gets_the_recording_ids_with_routing_on(recordings):
    X, y, groups = recordings
    shuffled = np.random.default_rng(0).permutation(pd.unique(groups))
    rows = np.concatenate([np.flatnonzero(groups == rec) for rec in shuffled])
    X, y, groups = X.iloc[rows], y[rows], groups.iloc[rows]
    with sklearn.config_context(enable_metadata_routing=True):
        step = _RecordingCentring().set_fit_request(groups=True).set_transform_request(groups=True)
        pipeline = _with_centring(step).fit(X, y, groups=groups)
        estimate = pipeline.predict(X, groups=groups)
    # the fit reads the recordings in the order of their ids, as every fit of the package
    assert pipeline[0].recordings_ == sorted(shuffled)
    centred = X - X.groupby(groups.to_numpy()).transform("mean")
    by_hand = make_torque_pipeline(2, friction_angle=None, random_state=0, n_iter=10)
    by_hand.fit(centred, y, groups=groups)
    np.testing.assert_allclose(estimate, by_hand.predict(centred, groups=groups), atol=1e-12)


def test_the_performance_score_predicts_the_pipeline_once(monkeypatch):
    """A scorer on a Pipeline fell back to one predict call per recording."""
    from skhmmgmr import PerformanceScore

    X, y, groups, _ = _protocol()
    pipe = _filtered_pipeline().fit(X, y, groups=groups)
    calls = []
    original = HMMGMRRegressor.predict

    @functools.wraps(original)  # its signature: what metadata routing reads
    def counted(self, *args, **kwargs):
        calls.append(1)
        return original(self, *args, **kwargs)

    monkeypatch.setattr(HMMGMRRegressor, "predict", counted)
    PerformanceScore(0.5, 0.5, sampling_period=0.01)(pipe, X, y, groups=groups)
    assert len(calls) == 1 and len(np.unique(groups)) > 1


# --- #36: the regressor's own methods through the pipeline ------------------------------------


def _per_recording(pipeline, X, groups, method, *args, **kwargs):
    """A plain loop: every recording through the fitted transformer alone, then the regressor's
    method on it alone; the results stacked in row order."""
    transformer, regressor = pipeline[0], pipeline[-1]
    parts = [
        getattr(regressor, method)(transformer.transform(X[groups == rec]), *args, **kwargs)
        for rec in pd.unique(groups)
    ]
    if isinstance(parts[0], tuple):
        return tuple(np.concatenate(part) for part in zip(*parts, strict=True))
    return np.concatenate(parts)


@pytest.fixture(scope="module")
def fitted_pipeline():
    X, y, groups, _ = _protocol()
    return _filtered_pipeline().fit(X, y, groups=groups)


@pytest.mark.parametrize("routing", [False, True])
@pytest.mark.parametrize(
    "method, args, kwargs",
    [
        ("predict", (), {"return_std": True}),
        ("predict_state_proba", (), {}),
        ("predict_ahead", (0,), {}),
        ("predict_ahead", (25,), {"return_std": True}),
        ("predict_ahead", (25,), {"state_output": "conditional"}),
    ],
)
def test_the_regressors_methods_through_the_pipeline(
    fitted_pipeline, routing, method, args, kwargs
):
    from sklearn.pipeline import Pipeline

    X, _, groups, _ = _protocol()
    assert isinstance(fitted_pipeline, Pipeline)
    expected = _per_recording(fitted_pipeline, X, groups, method, *args, **kwargs)
    with sklearn.config_context(enable_metadata_routing=routing):
        got = getattr(fitted_pipeline, method)(X, *args, groups=groups, **kwargs)
    for a, b in zip(
        got if isinstance(got, tuple) else (got,),
        expected if isinstance(expected, tuple) else (expected,),
        strict=True,
    ):
        np.testing.assert_allclose(a, b, rtol=0, atol=1e-12)


def test_return_std_with_routing_on_from_a_panel(fitted_pipeline):
    from skhmmgmr.datasets import to_panel

    X, _, groups, data = _protocol()
    panel = to_panel(data).sample(frac=1.0, random_state=0)
    with sklearn.config_context(enable_metadata_routing=True):
        estimate, std = fitted_pipeline.predict(panel[X.columns], return_std=True)
    by_groups = fitted_pipeline.predict(X, groups=groups, return_std=True)
    order = pd.MultiIndex.from_arrays([data["recording"], data["time"]])
    for got, expected in zip((estimate, std), by_groups, strict=True):
        got = pd.Series(got, index=panel.index).reindex(order).to_numpy()
        np.testing.assert_allclose(got, expected, rtol=0, atol=1e-12)


@pytest.mark.parametrize("routing", [False, True])
def test_adapt_through_the_pipeline_adapts_the_regressor(fitted_pipeline, routing):
    import copy

    X, y, groups, _ = _protocol()
    new = np.isin(groups, pd.unique(groups)[:4])
    X_new, y_new, groups_new = X[new], y[new] + 0.3, groups[new]
    original = fitted_pipeline[-1].model_
    pipeline = copy.deepcopy(fitted_pipeline)
    fitted = pipeline[-1].model_
    derived = pd.concat(
        [pipeline[0].transform(X_new[groups_new == rec]) for rec in pd.unique(groups_new)]
    )
    reference = copy.deepcopy(fitted_pipeline[-1]).adapt(
        derived, y_new, groups=groups_new, relevance=8.0, parameters="mv", n_iter=3
    )
    with sklearn.config_context(enable_metadata_routing=routing):
        returned = pipeline.adapt(
            X_new, y_new, groups=groups_new, relevance=8.0, parameters="mv", n_iter=3
        )
    assert returned is pipeline and pipeline[-1].model_ is not fitted
    assert fitted_pipeline[-1].model_ is original  # the copy adapted, not the original
    np.testing.assert_allclose(pipeline[-1].means_, reference.means_, rtol=0, atol=1e-10)
    np.testing.assert_allclose(pipeline[-1].covars_, reference.covars_, rtol=0, atol=1e-10)
    assert pipeline[-1].log_likelihood_ == pytest.approx(reference.log_likelihood_, abs=1e-8)
    # by default the regressor's "auto" chooses on the derived rows, as the regressor alone
    auto = copy.deepcopy(fitted_pipeline).adapt(X_new, y_new, groups=groups_new)
    alone = copy.deepcopy(fitted_pipeline[-1]).adapt(derived, y_new, groups=groups_new)
    pd.testing.assert_frame_equal(auto[-1].adaptation_, alone.adaptation_, rtol=1e-9)
    # no rows: nothing changes; rows that disagree with y are refused by the regressor
    model = pipeline[-1].model_
    assert pipeline.adapt(X.iloc[:0], y[:0]) is pipeline and pipeline[-1].model_ is model
    with pytest.raises(ValueError, match="y has 3"):
        pipeline.adapt(X.iloc[:0], y[:3])


def test_the_regressors_methods_exist_only_with_the_regressor():
    from sklearn.linear_model import Ridge

    from skhmmgmr.torque_pipeline import TorquePipeline

    pipeline = TorquePipeline([("features", SteeringFeatures()), ("ridge", Ridge())])
    for method in ("adapt", "predict_ahead", "predict_state_proba"):
        assert not hasattr(pipeline, method)
        assert hasattr(make_torque_pipeline(), method)
