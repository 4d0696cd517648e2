import functools
import pickle
import warnings

import numpy as np
import pandas as pd
import pytest
from numpy.testing import assert_allclose
from sklearn import config_context
from sklearn.base import BaseEstimator, RegressorMixin, clone
from sklearn.feature_selection import SequentialFeatureSelector
from sklearn.model_selection import GridSearchCV, GroupKFold, cross_validate
from sklearn.pipeline import make_pipeline
from sklearn.preprocessing import StandardScaler

from skhmmgmr.metrics import (
    AccuracyScore,
    PerformanceScore,
    SmoothnessScore,
    UngroupedScoringWarning,
    accuracy_score,
    evaluate_recordings,
    make_performance_scorers,
    normalize_performance,
    performance_score,
    rank_models,
    smoothness_score,
    trade_offs,
)

# The 4-sample recording computed by hand: SD(T) = 1, errors (0, 0, -1, 1) -> RMSE = sqrt(0.5);
# with dt = 0.5 s the estimate's derivative is (4, -2, 0) Nm/s, SD = sqrt(168 / 27).
Y_TRUE = np.array([0.0, 2.0, 0.0, 2.0])
Y_PRED = np.array([0.0, 2.0, 1.0, 1.0])
RMSE = np.sqrt(0.5)
ACCURACY = (1 - RMSE) * 100
SMOOTHNESS = np.sqrt(168 / 27)


def _running_mean_by_recording(values, groups):
    out = np.empty_like(values)
    codes = pd.factorize(np.asarray(groups), sort=False)[0]
    for code in np.unique(codes):
        rows = np.flatnonzero(codes == code)
        out[rows] = np.cumsum(values[rows]) / np.arange(1, rows.size + 1)
    return out


class RunningMeanRegressor(RegressorMixin, BaseEstimator):
    """Sequence-aware dummy: least squares, then a running mean that restarts per recording.

    Predicting two recordings as one sequence carries the running mean over the boundary and
    gives a different answer than predicting them separately.
    """

    def __init__(self, columns=None, alpha=0.0):
        self.columns = columns
        self.alpha = alpha

    def _design(self, X):
        if self.columns is not None:
            X = X[self.columns]
        X = np.asarray(X, dtype=float)
        return np.column_stack([X, np.ones(len(X))])

    def fit(self, X, y):
        A = self._design(X)
        gram = A.T @ A + self.alpha * np.eye(A.shape[1])
        self.coef_ = np.linalg.solve(gram, A.T @ np.asarray(y, dtype=float))
        self.n_features_in_ = A.shape[1] - 1
        return self

    def predict(self, X, groups=None):
        linear = self._design(X) @ self.coef_
        if groups is None:
            groups = np.zeros(len(linear))
        return _running_mean_by_recording(linear, groups)


class RunningMeanNoGroups(RunningMeanRegressor):
    """Same model whose ``predict`` does not take groups: it sees one sequence per call."""

    def predict(self, X):
        return super().predict(X)


class SpyScore(PerformanceScore):
    received = []

    def __call__(self, estimator, X, y_true, groups=None, **kwargs):
        SpyScore.received.append(groups)
        return super().__call__(estimator, X, y_true, groups=groups, **kwargs)


def _recordings(n_recordings=6, n_samples=40, seed=0):
    rng = np.random.default_rng(seed)
    X, y, groups = [], [], []
    for rec in range(n_recordings):
        x0 = np.sin(np.linspace(0, 3, n_samples) + rec) + 2.0 * rec
        x1 = rng.normal(size=n_samples)
        X.append(np.column_stack([x0, x1]))
        y.append(1.5 * x0 + 0.1 * rng.normal(size=n_samples))
        groups.append(np.full(n_samples, f"rec{rec}"))
    return np.vstack(X), np.concatenate(y), np.concatenate(groups)


def _reference_ps(estimator, X, y, groups, w1=0.5, w2=0.5, dt=0.1):
    """Plain loop: predict every recording on its own, score it, average."""
    scores = []
    for rec in pd.unique(groups):
        rows = groups == rec
        pred = estimator.predict(X[rows])
        true = y[rows]
        accuracy = (1 - np.sqrt(np.mean((pred - true) ** 2)) / np.std(true)) * 100
        smoothness = np.std(np.diff(pred) / dt)
        scores.append(w1 * abs(100 - accuracy) + w2 * abs(smoothness))
    return np.mean(scores)


# --- metric functions ------------------------------------------------------------------------


def test_hand_computed_recording():
    assert_allclose(accuracy_score(Y_TRUE, Y_PRED), ACCURACY)
    assert_allclose(smoothness_score(Y_PRED, sampling_period=0.5), SMOOTHNESS)
    assert_allclose(
        performance_score(Y_TRUE, Y_PRED, sampling_period=0.5),
        0.5 * (100 - ACCURACY) + 0.5 * SMOOTHNESS,
    )
    assert_allclose(
        performance_score(
            Y_TRUE, Y_PRED, accuracy_weight=0.3, smoothness_weight=0.7, sampling_period=0.5
        ),
        0.3 * (100 - ACCURACY) + 0.7 * SMOOTHNESS,
    )
    # accuracy only: no sampling information needed
    assert_allclose(
        performance_score(Y_TRUE, Y_PRED, accuracy_weight=1, smoothness_weight=0),
        100 - ACCURACY,
    )
    table = evaluate_recordings(Y_TRUE, Y_PRED, sampling_period=0.5)
    assert list(table.columns) == ["recording", "n_samples", "rmse", "accuracy", "smoothness"]
    assert_allclose(table.loc[0, ["rmse", "accuracy", "smoothness"]], [RMSE, ACCURACY, SMOOTHNESS])


def test_time_array_gives_uneven_steps():
    # steps (0.5, 1, 0.5) s -> derivative (4, -1, 0), SD = sqrt(14 / 3)
    time = np.array([0.0, 0.5, 1.5, 2.0])
    assert_allclose(smoothness_score(Y_PRED, time=time), np.sqrt(14 / 3))
    even = np.arange(4) * 0.5
    assert_allclose(
        smoothness_score(Y_PRED, time=even), smoothness_score(Y_PRED, sampling_period=0.5)
    )


def test_scales_divide_each_term():
    score = performance_score(
        Y_TRUE, Y_PRED, sampling_period=0.5, accuracy_scale=10.0, smoothness_scale={0: 2.0}
    )
    assert_allclose(score, 0.5 * (100 - ACCURACY) / 10 + 0.5 * SMOOTHNESS / 2)


def test_evaluate_recordings_matches_plain_loop():
    rng = np.random.default_rng(3)
    lengths = [5, 9, 2, 7]
    groups = np.repeat(["w", "x", "y", "z"], lengths)
    y_true = rng.normal(size=(sum(lengths), 2))
    y_pred = y_true + rng.normal(scale=0.5, size=y_true.shape)
    table = evaluate_recordings(y_true, y_pred, groups=groups, sampling_period=0.01)
    assert list(table.columns[:3]) == ["recording", "output", "n_samples"]
    assert len(table) == 8

    rows = []
    for rec in ["w", "x", "y", "z"]:
        t, p = y_true[groups == rec], y_pred[groups == rec]
        for out in range(2):
            rmse = np.sqrt(np.mean((t[:, out] - p[:, out]) ** 2))
            rate = np.diff(p[:, out]) / 0.01
            sd_rate = np.sqrt(np.mean((rate - rate.mean()) ** 2))
            rows.append([len(t), rmse, (1 - rmse / t[:, out].std()) * 100, sd_rate])
    assert_allclose(table[["n_samples", "rmse", "accuracy", "smoothness"]].to_numpy(), rows)

    assert_allclose(
        accuracy_score(y_true, y_pred, groups=groups, multioutput="raw_values"),
        table.groupby("output")["accuracy"].mean(),
    )
    assert_allclose(
        smoothness_score(y_pred, groups=groups, sampling_period=0.01),
        table["smoothness"].mean(),
    )
    assert_allclose(
        accuracy_score(y_true, y_pred, groups=groups, multioutput=[1, 0]),
        table.loc[table["output"] == 0, "accuracy"].mean(),
    )


def test_derivative_never_crosses_a_recording_boundary():
    first = np.array([0.0, 1.0, 2.0, 2.5])
    second = np.array([100.0, 101.0, 103.0])
    groups = np.array([0, 0, 0, 0, 1, 1, 1])
    together = smoothness_score(np.r_[first, second], groups=groups, sampling_period=0.1)
    separately = [smoothness_score(part, sampling_period=0.1) for part in (first, second)]
    assert_allclose(together, np.mean(separately))
    # the jump of 97.5 would dominate if the boundary were crossed
    assert smoothness_score(np.r_[first, second], sampling_period=0.1) > 100


def test_recordings_are_averaged_uniformly():
    groups = np.repeat(["long", "short"], [8, 3])
    rng = np.random.default_rng(0)
    y_true = rng.normal(size=11)
    y_pred = y_true + rng.normal(size=11)
    per_recording = [
        accuracy_score(y_true[groups == g], y_pred[groups == g]) for g in ("long", "short")
    ]
    assert_allclose(accuracy_score(y_true, y_pred, groups=groups), np.mean(per_recording))


def test_bad_model_has_negative_accuracy():
    y_true = np.sin(np.linspace(0, 6, 50))
    assert accuracy_score(y_true, -y_true) < 0
    assert_allclose(accuracy_score(y_true, np.full(50, y_true.mean())), 0.0, atol=1e-12)
    assert performance_score(y_true, -y_true, accuracy_weight=1, smoothness_weight=0) > 100


# --- bad input -------------------------------------------------------------------------------


def test_length_mismatch_names_the_arrays():
    with pytest.raises(ValueError, match="y_true has 4, y_pred has 3"):
        accuracy_score(Y_TRUE, Y_PRED[:3])
    with pytest.raises(ValueError, match="groups has 2"):
        accuracy_score(Y_TRUE, Y_PRED, groups=[0, 0])
    with pytest.raises(ValueError, match="time has 3"):
        smoothness_score(Y_PRED, time=[0, 1, 2])


def test_nan_names_the_recording():
    groups = ["a", "a", "b", "b"]
    with pytest.raises(ValueError, match="y_pred contains 1 NaN .* recording 'b'"):
        accuracy_score(Y_TRUE, [0.0, 1.0, np.nan, 2.0], groups=groups)
    with pytest.raises(ValueError, match="y_true .* recording 'a'"):
        evaluate_recordings([np.inf, 1, 0, 2], Y_PRED, groups=groups, sampling_period=1)


def test_constant_target_names_the_recording():
    with pytest.raises(ValueError, match="constant in recording 'flat'"):
        accuracy_score([1.0, 2.0, 3.0, 3.0], Y_PRED, groups=["ok", "ok", "flat", "flat"])


@pytest.mark.parametrize("offset", [0.3, 1e6, 1e-20])
def test_target_constant_to_round_off_names_the_recording(offset):
    # 0.1 + 0.2 != 0.3: the standard deviation is 4e-17 and the accuracy was -5e17 %
    flat = np.array([0.1 + 0.2, 0.3, 0.3, 0.1 + 0.2]) * (offset / 0.3)
    assert flat.std() > 0
    y_true = np.concatenate([Y_TRUE, flat])
    groups = ["ok"] * 4 + ["flat"] * 4
    with pytest.raises(ValueError, match=r"constant in recording 'flat' \(standard deviation"):
        accuracy_score(y_true, np.concatenate([Y_PRED, flat]), groups=groups)


@pytest.mark.parametrize("unit", [1e-13, 1e-200, 1e200])
def test_accuracy_does_not_depend_on_the_unit(unit):
    assert_allclose(accuracy_score(Y_TRUE * unit, Y_PRED * unit), ACCURACY, rtol=1e-12)


def _score_with(scorer):
    return scorer(RunningMeanRegressor().fit(Y_TRUE[:, None], Y_TRUE), Y_TRUE[:, None], Y_TRUE)


@pytest.mark.parametrize(
    "call",
    [
        lambda period: smoothness_score(Y_PRED, sampling_period=period),
        lambda period: performance_score(Y_TRUE, Y_PRED, sampling_period=period),
        lambda period: evaluate_recordings(Y_TRUE, Y_PRED, sampling_period=period),
        lambda period: _score_with(PerformanceScore(sampling_period=period)),
        lambda period: _score_with(SmoothnessScore(sampling_period=period)),
        lambda period: _score_with(
            make_performance_scorers(["50/50"], sampling_period=period)["neg_smoothness"]
        ),
    ],
)
@pytest.mark.parametrize("period", [True, np.True_, False])
def test_bool_sampling_period_is_refused(call, period):
    # True is 1 in Python arithmetic, but not a time step
    with pytest.raises(ValueError, match=r"'sampling_period' parameter of \w+ .*not a bool"):
        call(period)


def test_missing_or_bad_sampling_information():
    with pytest.raises(ValueError, match="sampling_period .* or time"):
        smoothness_score(Y_PRED)
    with pytest.raises(ValueError, match="sampling_period .* or time"):
        performance_score(Y_TRUE, Y_PRED)
    with pytest.raises(ValueError, match="not both"):
        smoothness_score(Y_PRED, sampling_period=0.1, time=np.arange(4.0))
    with pytest.raises(ValueError, match=r"'sampling_period' parameter .* range \(0.0, inf\)"):
        smoothness_score(Y_PRED, sampling_period=0)
    with pytest.raises(ValueError, match="does not increase within recording 1"):
        smoothness_score(Y_PRED, time=[0, 1, 2, 2], groups=[0, 0, 1, 1])
    with pytest.raises(ValueError, match="recording 'b' has .*1 row"):
        smoothness_score(Y_PRED, sampling_period=1, groups=["a", "a", "a", "b"])


def test_other_bad_input():
    with pytest.raises(ValueError, match="recording 0 are not contiguous"):
        accuracy_score(Y_TRUE, Y_PRED, groups=[0, 1, 1, 0])
    with pytest.raises(ValueError, match="1 output"):
        accuracy_score(Y_TRUE, np.c_[Y_PRED, Y_PRED])
    with pytest.raises(ValueError, match="both 0"):
        performance_score(Y_TRUE, Y_PRED, accuracy_weight=0, smoothness_weight=0)
    with pytest.raises(ValueError, match="smoothness_scale has no value"):
        performance_score(Y_TRUE, Y_PRED, sampling_period=1, smoothness_scale={"x": 1.0})
    with pytest.raises(ValueError, match="multioutput"):
        accuracy_score(Y_TRUE, Y_PRED, multioutput="variance_weighted")


# --- D.5 normalisation, trade-offs, ranking --------------------------------------------------


@pytest.fixture
def two_by_two():
    return pd.DataFrame(
        {
            "model": ["A", "B", "A", "B"],
            "recording": ["r1", "r1", "r2", "r2"],
            "accuracy": [90.0, 80.0, 95.0, 85.0],
            "smoothness": [2.0, 1.0, 4.0, 4.0],
        }
    )


def test_normalisation_by_hand(two_by_two):
    scores = normalize_performance(two_by_two)
    # r1: losses 10, 20 -> 1/3, 2/3; SM 2, 1 -> 2/3, 1/3
    # r2: losses 5, 15 -> 1/4, 3/4; SM 4, 4 -> 1/2, 1/2
    assert_allclose(scores["accuracy_term"], [1 / 3, 2 / 3, 1 / 4, 3 / 4])
    assert_allclose(scores["smoothness_term"], [2 / 3, 1 / 3, 1 / 2, 1 / 2])
    assert_allclose(scores["performance_score"], [0.5, 0.5, 0.375, 0.625])
    assert (scores["trade_off"] == "50/50").all()

    thirty = normalize_performance(two_by_two, weights=(0.3, 0.7))
    assert (thirty["trade_off"] == "30/70").all()
    assert_allclose(thirty["performance_score"].iloc[2:], [0.425, 0.575])


def test_trade_off_rescoring(two_by_two):
    assert trade_offs() == [f"{a}/{100 - a}" for a in range(100, -1, -10)]
    assert trade_offs(50) == ["100/0", "50/50", "0/100"]
    with pytest.raises(ValueError, match="divides 100"):
        trade_offs(30)

    all_scores = normalize_performance(two_by_two, weights=trade_offs(10))
    assert len(all_scores) == 11 * 4
    assert list(pd.unique(all_scores["trade_off"])) == trade_offs(10)
    for label in ("100/0", "70/30", "0/100"):
        alone = normalize_performance(two_by_two, weights=label)
        part = all_scores[all_scores["trade_off"] == label].reset_index(drop=True)
        pd.testing.assert_frame_equal(part, alone)
    accuracy_only = all_scores[all_scores["trade_off"] == "100/0"]
    assert_allclose(accuracy_only["performance_score"], accuracy_only["accuracy_term"])


def test_normalised_table_agrees_with_scaled_performance_score():
    rng = np.random.default_rng(1)
    groups = np.repeat(["r1", "r2"], [30, 20])
    y_true = rng.normal(size=50).cumsum()
    predictions = {
        "rough": y_true + rng.normal(scale=0.3, size=50),
        "smooth": _running_mean_by_recording(y_true, groups),
    }
    table = pd.concat(
        [
            evaluate_recordings(y_true, pred, groups=groups, sampling_period=0.1).assign(model=m)
            for m, pred in predictions.items()
        ]
    )
    scores = normalize_performance(table, weights="70/30")
    totals = table.assign(loss=(100 - table["accuracy"]).abs()).groupby("recording")
    for name, pred in predictions.items():
        direct = performance_score(
            y_true,
            pred,
            accuracy_weight=0.7,
            smoothness_weight=0.3,
            groups=groups,
            sampling_period=0.1,
            accuracy_scale=totals["loss"].sum(),
            smoothness_scale=totals["smoothness"].sum(),
        )
        from_table = scores.loc[scores["model"] == name, "performance_score"].mean()
        assert_allclose(direct, from_table)


def test_rank_models(two_by_two):
    scores = normalize_performance(two_by_two, weights=["100/0", "50/50"])
    per_recording = rank_models(scores)
    fifty = per_recording[per_recording["trade_off"] == "50/50"]
    # r1 is a tie at 50/50: both models share rank 1
    assert fifty["rank"].tolist() == [1, 1, 1, 2]
    assert fifty["model"].tolist()[2:] == ["A", "B"]

    average = rank_models(scores, average=True)
    assert list(average.columns) == ["trade_off", "model", "performance_score", "n_best", "rank"]
    row = average[(average["trade_off"] == "50/50") & (average["model"] == "A")].iloc[0]
    assert_allclose(row["performance_score"], (0.5 + 0.375) / 2)
    assert (row["n_best"], row["rank"]) == (2, 1)


def test_normalisation_errors_and_zero_sums(two_by_two):
    with pytest.raises(ValueError, match="1 of the 2 models"):
        normalize_performance(two_by_two.iloc[:3])
    with pytest.raises(ValueError, match="several rows"):
        normalize_performance(pd.concat([two_by_two, two_by_two.iloc[:1]]))
    with pytest.raises(ValueError, match="no column"):
        normalize_performance(two_by_two.drop(columns="smoothness"))
    with pytest.raises(ValueError, match="NaN .*'B', 'r2'"):
        normalize_performance(two_by_two.assign(accuracy=[90, 80, 95, np.nan]))
    with pytest.raises(ValueError, match="trade-off string"):
        normalize_performance(two_by_two, weights="fifty")
    # both weights 0 would score every model 0
    for weights in ["0/0", (0.0, 0.0), ["50/50", "0/0"]]:
        with pytest.raises(ValueError, match="'0/0'|\\(0.0, 0.0\\)"):
            normalize_performance(two_by_two, weights=weights)
    with pytest.raises(ValueError, match="both the accuracy and the smoothness weight 0"):
        make_performance_scorers(["0/0"], sampling_period=0.1)
    perfect = two_by_two.assign(accuracy=100.0)
    assert_allclose(normalize_performance(perfect)["accuracy_term"], 0.0)


# --- scorers ---------------------------------------------------------------------------------


def test_scorer_predicts_each_recording_separately():
    X, y, groups = _recordings(n_recordings=3)
    model = RunningMeanNoGroups().fit(X, y)
    scorer = PerformanceScore(sampling_period=0.1)
    expected = -_reference_ps(model, X, y, groups)
    assert_allclose(scorer(model, X, y, groups=groups), expected)
    # the same model with a groups-aware predict takes the single-call path
    aware = RunningMeanRegressor().fit(X, y)
    for mode in ("auto", "groups", "per_recording"):
        assert_allclose(
            PerformanceScore(sampling_period=0.1, predict_mode=mode)(aware, X, y, groups=groups),
            expected,
        )
    pipeline = make_pipeline(StandardScaler(), RunningMeanNoGroups()).fit(X, y)
    assert_allclose(scorer(pipeline, X, y, groups=groups), -_reference_ps(pipeline, X, y, groups))
    with pytest.warns(UngroupedScoringWarning, match="ONE recording"):
        one_sequence = scorer(model, X, y)
    assert not np.isclose(one_sequence, expected)


def test_accuracy_and_smoothness_scorers_and_sign():
    X, y, groups = _recordings(n_recordings=2)
    model = RunningMeanRegressor().fit(X, y)
    pred = model.predict(X, groups=groups)
    assert_allclose(
        AccuracyScore()(model, X, y, groups=groups), accuracy_score(y, pred, groups=groups)
    )
    assert_allclose(
        SmoothnessScore(sampling_period=0.1)(model, X, y, groups=groups),
        -smoothness_score(pred, groups=groups, sampling_period=0.1),
    )
    assert_allclose(
        PerformanceScore(0.2, 0.8, sampling_period=0.1)(model, X, y, groups=groups),
        -performance_score(
            y, pred, accuracy_weight=0.2, smoothness_weight=0.8, sampling_period=0.1, groups=groups
        ),
    )


def test_time_column():
    X, y, groups = _recordings(n_recordings=2, n_samples=10)
    frame = pd.DataFrame(X, columns=["x0", "x1"])
    frame["time"] = np.tile(np.arange(10) * 0.1, 2)
    model = RunningMeanRegressor(columns=["x0", "x1"]).fit(frame, y)
    by_time = PerformanceScore(time_column="time")(model, frame, y, groups=groups)
    by_period = PerformanceScore(sampling_period=0.1)(model, frame, y, groups=groups)
    assert_allclose(by_time, by_period)
    with pytest.raises(ValueError, match="needs X to be a pandas DataFrame"):
        PerformanceScore(time_column="time")(model, X, y, groups=groups)
    with pytest.raises(ValueError, match="no column 'clock'"):
        PerformanceScore(time_column="clock")(model, frame, y, groups=groups)


def test_scorer_parameter_errors():
    X, y, groups = _recordings(n_recordings=2, n_samples=10)
    model = RunningMeanRegressor().fit(X, y)
    with pytest.raises(ValueError, match="set sampling_period .* or time_column"):
        PerformanceScore()(model, X, y, groups=groups)
    with pytest.raises(ValueError, match="not both"):
        PerformanceScore(sampling_period=0.1, time_column="t")
    with pytest.raises(ValueError, match="predict_mode"):
        AccuracyScore(predict_mode="fast")
    with pytest.raises(TypeError, match="unexpected metadata"):
        AccuracyScore()(model, X, y, groups=groups, sample_weight=np.ones(len(y)))
    # accuracy-only trade-off needs no sampling information
    PerformanceScore(1.0, 0.0)(model, X, y, groups=groups)


def test_scorer_repr_params_clone_pickle():
    scorer = PerformanceScore(0.7, 0.3, sampling_period=0.01)
    assert (
        repr(scorer)
        == "PerformanceScore(accuracy_weight=0.7, smoothness_weight=0.3, sampling_period=0.01)"
    )
    assert repr(AccuracyScore()) == "AccuracyScore()"
    assert scorer.get_params()["accuracy_weight"] == 0.7
    cloned = clone(scorer)
    assert cloned is not scorer and repr(cloned) == repr(scorer)
    with config_context(enable_metadata_routing=True):
        scorer.set_score_request(groups="recording_id")
        restored = pickle.loads(pickle.dumps(scorer))
        assert restored.get_metadata_routing().score.requests == {"groups": "recording_id"}
        assert clone(scorer).get_metadata_routing().score.requests == {"groups": "recording_id"}
        assert PerformanceScore().get_metadata_routing().score.requests == {"groups": True}
    with pytest.raises(RuntimeError, match="metadata routing"):
        PerformanceScore().set_score_request(groups=True)
    with pytest.raises(ValueError, match="invalid parameter"):
        scorer.set_params(weight=1)


def _manual_cv_scores(estimator, X, y, groups, cv, w1=0.5, w2=0.5):
    scores, one_sequence = [], []
    for train, test in cv.split(X, y, groups):
        fitted = clone(estimator).fit(X[train], y[train])
        scores.append(-_reference_ps(fitted, X[test], y[test], groups[test], w1, w2))
        pred = fitted.predict(X[test])
        one_sequence.append(
            -performance_score(
                y[test],
                pred,
                accuracy_weight=w1,
                smoothness_weight=w2,
                groups=groups[test],
                sampling_period=0.1,
            )
        )
    return np.array(scores), np.array(one_sequence)


@pytest.mark.parametrize("estimator_class", [RunningMeanRegressor, RunningMeanNoGroups])
def test_grid_search_routes_groups_to_the_scorer(estimator_class):
    X, y, groups = _recordings()
    cv = GroupKFold(n_splits=3)
    scoring = {
        "ps": PerformanceScore(sampling_period=0.1),
        "ps_accuracy": PerformanceScore(0.9, 0.1, sampling_period=0.1),
    }
    with config_context(enable_metadata_routing=True), warnings.catch_warnings():
        warnings.simplefilter("error", UngroupedScoringWarning)
        search = GridSearchCV(
            estimator_class(),
            {"alpha": [0.0, 100.0]},
            cv=cv,
            scoring=scoring,
            refit="ps",
            error_score="raise",
        ).fit(X, y, groups=groups)

    for i, alpha in enumerate([0.0, 100.0]):
        expected, one_sequence = _manual_cv_scores(estimator_class(alpha=alpha), X, y, groups, cv)
        got = [search.cv_results_[f"split{k}_test_ps"][i] for k in range(3)]
        assert_allclose(got, expected)
        # guard: the test can tell per-recording from whole-fold prediction
        assert not np.allclose(one_sequence, expected)
    assert search.best_params_ == {"alpha": 0.0}


def test_without_routing_the_scorer_warns():
    X, y, groups = _recordings(n_recordings=4)
    with pytest.warns(UngroupedScoringWarning):
        GridSearchCV(
            RunningMeanRegressor(),
            {"alpha": [0.0]},
            cv=GroupKFold(n_splits=2),
            scoring=PerformanceScore(sampling_period=0.1),
        ).fit(X, y, groups=groups)
    with config_context(enable_metadata_routing=True), pytest.warns(UngroupedScoringWarning):
        cross_validate(
            RunningMeanRegressor(),
            X,
            y,
            cv=GroupKFold(n_splits=2),
            scoring=PerformanceScore(sampling_period=0.1).set_score_request(groups=False),
            params={"groups": groups},
        )


def test_cross_validate_with_scorer_dict():
    X, y, groups = _recordings()
    cv = GroupKFold(n_splits=3)
    scorers = make_performance_scorers(["100/0", "50/50"], sampling_period=0.1)
    assert set(scorers) == {
        "neg_performance_100/0",
        "neg_performance_50/50",
        "accuracy",
        "neg_smoothness",
    }
    with config_context(enable_metadata_routing=True):
        result = cross_validate(
            RunningMeanNoGroups(),
            X,
            y,
            cv=cv,
            scoring=scorers,
            params={"groups": groups},
            error_score="raise",
        )
    expected, _ = _manual_cv_scores(RunningMeanNoGroups(), X, y, groups, cv)
    assert_allclose(result["test_neg_performance_50/50"], expected)
    expected_accuracy, _ = _manual_cv_scores(RunningMeanNoGroups(), X, y, groups, cv, 1.0, 0.0)
    assert_allclose(result["test_neg_performance_100/0"], expected_accuracy)
    assert_allclose(result["test_accuracy"], 100 + expected_accuracy)
    assert np.all(result["test_neg_smoothness"] < 0)


def test_sequential_feature_selector_routes_groups():
    X, y, groups = _recordings()
    SpyScore.received = []
    with config_context(enable_metadata_routing=True):
        selector = SequentialFeatureSelector(
            RunningMeanNoGroups(),
            n_features_to_select=1,
            scoring=SpyScore(sampling_period=0.1),
            cv=GroupKFold(n_splits=2),
        ).fit(X, y, groups=groups)
    assert selector.get_support().tolist() == [True, False]
    assert len(SpyScore.received) == 4  # 2 candidate features x 2 folds
    for received in SpyScore.received:
        assert received is not None and len(pd.unique(received)) == 3


def test_a_scorer_predicts_a_routing_pipeline_once(monkeypatch):
    """#34: on a Pipeline the scorers fell back to one predict call per recording (24 calls on
    24 recordings), also with metadata routing on, where the Pipeline routes groups."""
    from skhmmgmr import HMMGMRRegressor, PerformanceScore

    rng = np.random.default_rng(3)
    X = np.cumsum(rng.normal(scale=0.2, size=(480, 2)), axis=0)
    y = np.tanh(X[:, 0]) + 0.1 * X[:, 1]
    groups = np.repeat(np.arange(24), 20)
    scorer = PerformanceScore(0.5, 0.5, sampling_period=0.05)
    reference = PerformanceScore(0.5, 0.5, sampling_period=0.05, predict_mode="per_recording")
    calls = []
    original = HMMGMRRegressor.predict

    @functools.wraps(original)  # keeps the signature that metadata routing reads
    def counted(self, *args, **kwargs):
        calls.append(1)
        return original(self, *args, **kwargs)

    with config_context(enable_metadata_routing=True):
        pipe = make_pipeline(StandardScaler(), HMMGMRRegressor(n_states=2, random_state=0))
        pipe.fit(X, y, groups=groups)
        monkeypatch.setattr(HMMGMRRegressor, "predict", counted)
        once = scorer(pipe, X, y, groups=groups)
        assert len(calls) == 1
        assert once == pytest.approx(reference(pipe, X, y, groups=groups), abs=1e-12)
        assert len(calls) == 1 + 24


def test_the_metric_functions_read_the_recordings_of_a_panel_index():
    """#51 item 12: evaluate_recordings read a panel as one recording (one row, the smoothness
    inflated by the jumps between recordings), although every scorer reads its index."""
    rng = np.random.default_rng(1)
    lengths = {"r1": 30, "r2": 40, "r3": 50}
    recordings = np.repeat(list(lengths), list(lengths.values()))
    time = np.concatenate([np.arange(n) * 0.05 for n in lengths.values()])
    y_true = rng.normal(size=len(time)).cumsum()
    y_pred = y_true + 0.3 * rng.normal(size=len(time))
    index = pd.MultiIndex.from_arrays([recordings, time], names=["recording", "time"])
    order = rng.permutation(len(time))  # the panel's rows in any order
    panel_true = pd.Series(y_true, index=index).iloc[order]
    table = evaluate_recordings(panel_true, y_pred[order])  # the time steps from the index
    assert sorted(table["recording"]) == list(lengths)
    table = table.set_index("recording").loc[list(lengths)]
    for rec, n in lengths.items():  # a plain loop per recording
        rows = recordings == rec
        error = y_pred[rows] - y_true[rows]
        assert table.loc[rec, "n_samples"] == n
        assert table.loc[rec, "rmse"] == pytest.approx(np.sqrt(np.mean(error**2)), rel=1e-12)
        slope = np.diff(y_pred[rows]) / 0.05
        assert table.loc[rec, "smoothness"] == pytest.approx(np.std(slope), rel=1e-9)
    # the same recordings with a sampling period, and in the other metric functions
    by_period = evaluate_recordings(panel_true, y_pred[order], sampling_period=0.05)
    assert_allclose(by_period.set_index("recording").loc[list(lengths)], table, rtol=1e-9)
    mean_smoothness = table["smoothness"].mean()
    assert smoothness_score(pd.Series(y_pred, index=index).iloc[order]) == pytest.approx(
        mean_smoothness, rel=1e-9
    )
    assert accuracy_score(panel_true, y_pred[order]) == pytest.approx(
        table["accuracy"].mean(), rel=1e-12
    )
