"""Tools that never pass ``groups`` on, fed the panel form (recordings in the index).

Issue #24, item 3. ``cross_val_predict``, ``cross_validate`` (built-in and package scorers),
``permutation_importance``, successive halving and MAPIE's conformal regressors get an X whose
index holds the recording and the time of every row, and no extra argument (routing off). Each
case must give what the same computation gives by hand with explicit ``groups`` on plain rows.
"""

import warnings
from contextlib import contextmanager

import numpy as np
import pandas as pd
import pytest
from mapie.regression import CrossConformalRegressor, SplitConformalRegressor
from sklearn.experimental import enable_halving_search_cv  # noqa: F401
from sklearn.inspection import permutation_importance
from sklearn.metrics import get_scorer, mean_squared_error, r2_score
from sklearn.model_selection import (
    GridSearchCV,
    GroupKFold,
    HalvingGridSearchCV,
    cross_val_predict,
    cross_validate,
)

from skhmmgmr import AccuracyScore, HMMGMRRegressor, PerformanceScore
from skhmmgmr.datasets import make_lane_keeping, to_panel
from skhmmgmr.metrics import UngroupedScoringWarning

FEATURES = ["steering_wheel_angle", "yaw_rate", "heading_deviation_10m"]
TARGET = "driver_torque"
DRIVERS = ["defensive", "aggressive", "novice"]
SAMPLING_PERIOD = 0.05  # 20 Hz
TOL = 1e-9


@pytest.fixture(scope="module")
def frame():
    """Nine recordings of 12 s at 20 Hz (240 rows each), tidy: recording and time columns."""
    frames = [
        make_lane_keeping(
            12.0,
            setting=1 + i % 7,
            driver=DRIVERS[i % 3],
            sampling_rate=1 / SAMPLING_PERIOD,
            random_state=i,
            recording=f"drive{i}",
        )
        for i in range(9)
    ]
    return pd.concat(frames, ignore_index=True)


@pytest.fixture(scope="module")
def panel(frame):
    return to_panel(frame)


def new_model(n_states=2):
    return HMMGMRRegressor(n_states=n_states, random_state=0)


def plain(frame, rows=slice(None)):
    """(X, y, groups) of ``rows`` without recordings in the index: groups are explicit."""
    part = frame.iloc[rows] if isinstance(rows, slice) else frame[rows]
    part = part.reset_index(drop=True)
    return part[FEATURES], part[TARGET].to_numpy(), part["recording"].to_numpy()


def recordings_of(X):
    return X.index.get_level_values("recording")


def grouped_folds(frame, cv):
    """Per fold (train, test, model fitted with groups, grouped predictions of the test rows)."""
    X, y, groups = plain(frame)
    folds = []
    for train, test in cv.split(X, y, groups):
        model = new_model().fit(X.iloc[train], y[train], groups=groups[train])
        folds.append((train, test, model, model.predict(X.iloc[test], groups=groups[test])))
    return folds


@contextmanager
def no_one_recording_warning():
    """Warnings of rows scored or filtered as ONE recording become errors."""
    with warnings.catch_warnings():
        warnings.simplefilter("error", UngroupedScoringWarning)
        warnings.filterwarnings("error", message=".*filtered as ONE recording")
        yield


def max_diff(a, b):
    return float(np.max(np.abs(np.asarray(a, dtype=float) - np.asarray(b, dtype=float))))


def test_fit_on_a_shuffled_panel_gives_the_same_model(panel):
    # the initialization reads the rows in order: a shuffle must not change the recordings'
    # order, so fit takes them in order of their ids, each in time order
    ordered = new_model().fit(panel[FEATURES], panel[TARGET])
    rows = np.random.default_rng(2).permutation(len(panel))
    shuffled = new_model().fit(panel[FEATURES].iloc[rows], panel[TARGET].iloc[rows])
    assert max_diff(shuffled.means_, ordered.means_) <= 1e-12


# --------------------------------------------------------------------------------------------
# 1. cross_val_predict
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize("shuffled", [False, True], ids=["in-order", "shuffled"])
def test_cross_val_predict_on_a_panel_equals_the_grouped_loop(frame, panel, shuffled):
    cv = GroupKFold(n_splits=3)
    expected = np.empty(len(frame))
    for _, test, _, y_pred in grouped_folds(frame, cv):
        expected[test] = y_pred
    rows = np.random.default_rng(0).permutation(len(panel)) if shuffled else np.arange(len(panel))
    X, y = panel[FEATURES].iloc[rows], panel[TARGET].iloc[rows]
    # groups only feed the splitter; fit and predict read the recordings from the index
    with no_one_recording_warning():
        y_pred = cross_val_predict(new_model(), X, y, cv=cv, groups=recordings_of(X))
    # a shuffle changes neither the folds (GroupKFold assigns whole recordings) nor the fitted
    # models (fit takes an indexed X's recordings in order of their ids, each in time order)
    assert max_diff(y_pred, expected[rows]) <= TOL


# --------------------------------------------------------------------------------------------
# 2. cross_validate
# --------------------------------------------------------------------------------------------


def test_cross_validate_built_in_scorers_score_grouped_predictions(frame, panel):
    cv = GroupKFold(n_splits=3)
    X, y = panel[FEATURES], panel[TARGET]
    results = cross_validate(
        new_model(),
        X,
        y,
        groups=recordings_of(X),
        cv=cv,
        scoring=["r2", "neg_mean_squared_error"],
        error_score="raise",
    )
    y_true = frame[TARGET].to_numpy()
    folds = grouped_folds(frame, cv)
    r2 = [r2_score(y_true[test], y_pred) for _, test, _, y_pred in folds]
    mse = [-mean_squared_error(y_true[test], y_pred) for _, test, _, y_pred in folds]
    assert max_diff(results["test_r2"], r2) <= TOL
    assert max_diff(results["test_neg_mean_squared_error"], mse) <= TOL


def test_cross_validate_package_scorer_reads_the_recordings_from_the_index(frame, panel):
    cv = GroupKFold(n_splits=3)
    scorer = PerformanceScore(sampling_period=SAMPLING_PERIOD)
    X, y = panel[FEATURES], panel[TARGET]
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        results = cross_validate(
            new_model(), X, y, groups=recordings_of(X), cv=cv, scoring=scorer, error_score="raise"
        )
    X_plain, y_plain, groups = plain(frame)
    expected = [
        scorer(model, X_plain.iloc[test], y_plain[test], groups=groups[test])
        for _, test, model, _ in grouped_folds(frame, cv)
    ]
    assert max_diff(results["test_score"], expected) <= TOL


# --------------------------------------------------------------------------------------------
# 3. permutation_importance
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "scoring",
    [PerformanceScore(sampling_period=SAMPLING_PERIOD), AccuracyScore(), "r2"],
    ids=["performance", "accuracy", "r2"],
)
def test_permutation_importance_scores_the_recordings_of_the_index(frame, panel, scoring):
    train = np.asarray(recordings_of(panel).isin([f"drive{i}" for i in range(6)]))
    model = new_model().fit(panel.loc[train, FEATURES], panel.loc[train, TARGET])
    rows = np.random.default_rng(1).permutation(int((~train).sum()))  # any row order will do
    X_test, y_test = panel.loc[~train, FEATURES].iloc[rows], panel.loc[~train, TARGET].iloc[rows]
    scorer = get_scorer(scoring)
    calls = []

    def recorded(estimator, X, y):
        calls.append(scorer(estimator, X, y))
        return calls[-1]

    with no_one_recording_warning():
        result = permutation_importance(
            model, X_test, y_test, scoring=recorded, n_repeats=1, random_state=0
        )
    X_plain, y_plain, groups = plain(frame, ~train)
    if isinstance(scoring, str):
        expected = r2_score(y_plain, model.predict(X_plain, groups=groups))
    else:
        expected = scoring(model, X_plain, y_plain, groups=groups)
    # the first call is the baseline: the unpermuted score, per recording
    assert abs(calls[0] - expected) <= TOL
    assert np.all(np.isfinite(result.importances))
    assert max_diff(result.importances_mean, calls[0] - np.array(calls[1:])) <= TOL
    # the steering wheel angle leads the torque: permuting it must cost the most
    assert np.argmax(result.importances_mean) == 0


# --------------------------------------------------------------------------------------------
# 4. Successive halving
# --------------------------------------------------------------------------------------------


def halving_last_iteration(X, y):
    """{n_states: mean test score} of the last iteration of a halving search on all rows."""
    n_rows = len(y)
    search = HalvingGridSearchCV(
        new_model(),
        {"n_states": [1, 2]},
        cv=GroupKFold(n_splits=3),
        resource="n_samples",
        # iteration 0: both candidates on half of the rows; iteration 1: the best on all rows
        min_resources=n_rows // 2,
        max_resources=n_rows,
        factor=2,
        random_state=0,
    )
    search.fit(X, y, groups=recordings_of(X))
    results = pd.DataFrame(search.cv_results_)
    last = results[results["iter"] == results["iter"].max()]
    assert (last["n_resources"] == n_rows).all()
    return {p["n_states"]: s for p, s in zip(last["params"], last["mean_test_score"], strict=True)}


def test_halving_search_on_all_rows_equals_the_grid_search(panel):
    X, y = panel[FEATURES], panel[TARGET]
    grid = GridSearchCV(new_model(), {"n_states": [1, 2]}, cv=GroupKFold(n_splits=3))
    grid.fit(X, y, groups=recordings_of(X))
    grid_scores = {
        p["n_states"]: s
        for p, s in zip(
            grid.cv_results_["params"], grid.cv_results_["mean_test_score"], strict=True
        )
    }
    with no_one_recording_warning():
        halving = halving_last_iteration(X, y)
    # Note: even on all rows, the halving splitter draws each training and test fold with
    # sklearn.utils.resample(replace=False), a permutation of the rows: the rows of every
    # recording come shuffled. The "time" level of the index is what puts them back in time
    # order (and fit takes the recordings in order of their ids), so the fold models and
    # scores equal the grid search's on the same folds.
    assert halving, "no candidate reached the last iteration"
    for n_states, score in halving.items():
        assert abs(score - grid_scores[n_states]) <= TOL
    # without the time level the shuffled rows are filtered out of time order: other scores
    by_recording = X.reset_index(level="time", drop=True), y.reset_index(level="time", drop=True)
    for n_states, score in halving_last_iteration(*by_recording).items():
        assert abs(score - grid_scores[n_states]) > 1e-6


# --------------------------------------------------------------------------------------------
# 5. MAPIE's conformal regressors
# --------------------------------------------------------------------------------------------

CONFIDENCE = 0.9


def split_recordings(panel):
    """Boolean rows of 3 training, 3 conformalization and 3 test recordings."""
    number = recordings_of(panel).str.removeprefix("drive").astype(int).to_numpy()
    return number < 3, (number >= 3) & (number < 6), number >= 6


def coverage(y_true, intervals):
    low, high = intervals[:, 0, 0], intervals[:, 1, 0]
    return float(np.mean((y_true >= low) & (y_true <= high)))


# MAPIE checks that a prefit model is fitted by predicting one plain row of zeros
@pytest.mark.filterwarnings("ignore:X does not have valid feature names:UserWarning")
def test_split_conformal_regressor_predicts_per_recording(frame, panel):
    train, calibration, test = split_recordings(panel)
    model = new_model().fit(panel.loc[train, FEATURES], panel.loc[train, TARGET])
    with no_one_recording_warning():
        mapie = SplitConformalRegressor(model, confidence_level=CONFIDENCE, prefit=True)
        mapie.conformalize(panel.loc[calibration, FEATURES], panel.loc[calibration, TARGET])
        y_pred, intervals = mapie.predict_interval(panel.loc[test, FEATURES])
    X_test, y_test, groups_test = plain(frame, test)
    assert max_diff(y_pred, model.predict(X_test, groups=groups_test)) <= TOL
    # the conformity scores are the residuals of the grouped predictions
    X_cal, y_cal, groups_cal = plain(frame, calibration)
    residuals = np.abs(y_cal - model.predict(X_cal, groups=groups_cal))
    assert max_diff(np.sort(mapie._mapie_regressor.conformity_scores_), np.sort(residuals)) <= TOL
    assert np.all(intervals[:, 0, 0] <= y_pred) and np.all(y_pred <= intervals[:, 1, 0])
    covered = coverage(y_test, intervals)
    assert 0.75 <= covered <= 1.0, f"coverage {covered:.3f} at confidence {CONFIDENCE}"


def test_cross_conformal_regressor_folds_are_fitted_and_predicted_per_recording(frame, panel):
    _, _, test = split_recordings(panel)
    development = ~test
    X_dev, y_dev = panel.loc[development, FEATURES], panel.loc[development, TARGET]
    cv = GroupKFold(n_splits=3)
    mapie = CrossConformalRegressor(new_model(), confidence_level=CONFIDENCE, cv=cv)
    with no_one_recording_warning():
        mapie.fit_conformalize(X_dev, y_dev, groups=recordings_of(X_dev))
        y_mean, intervals = mapie.predict_interval(panel.loc[test, FEATURES])
        # 2nd argument: aggregate_predictions, renamed aggregate_point_predictions in MAPIE
        # 1.6; None predicts with the model fitted on all development recordings
        y_full = mapie.predict(panel.loc[test, FEATURES], None)
    # the fold models are those fitted by hand with groups on the same folds
    folds = grouped_folds(frame[development], cv)
    ensemble = mapie._mapie_regressor.estimator_
    assert len(ensemble.estimators_) == len(folds) == 3
    X_test, y_test, groups_test = plain(frame, test)
    fold_predictions = []
    for fitted, (_, _, model, _) in zip(ensemble.estimators_, folds, strict=True):
        fold_predictions.append(fitted.predict(X_test, groups=groups_test))
        assert max_diff(fold_predictions[-1], model.predict(X_test, groups=groups_test)) <= TOL
    # conformity scores: residuals of the out-of-fold grouped predictions
    residuals = np.empty(int(development.sum()))
    X_dev_plain, y_dev_plain, groups_dev = plain(frame, development)
    for _, fold_test, _, y_pred in folds:
        residuals[fold_test] = np.abs(y_dev_plain[fold_test] - y_pred)
    assert max_diff(mapie._mapie_regressor.conformity_scores_, residuals) <= TOL
    # "mean": each fold model weighted by the conformalization rows it predicted
    weights = np.array([len(fold_test) for _, fold_test, _, _ in folds], dtype=float)
    expected_mean = np.column_stack(fold_predictions) @ (weights / weights.sum())
    assert max_diff(y_mean, expected_mean) <= TOL
    full = new_model().fit(X_dev_plain, y_dev_plain, groups=groups_dev)
    assert max_diff(y_full, full.predict(X_test, groups=groups_test)) <= TOL
    covered = coverage(y_test, intervals)
    assert 0.75 <= covered <= 1.0, f"coverage {covered:.3f} at confidence {CONFIDENCE}"
