"""State selection: the 1% rule on validation recordings, BIC, and the GridSearchCV route."""

import warnings

import numpy as np
import pandas as pd
import pytest
import sklearn
from sklearn.exceptions import NotFittedError
from sklearn.model_selection import GridSearchCV, GroupKFold, PredefinedSplit
from threadpoolctl import threadpool_limits

from skhmmgmr import HMMGMRRegressor
from skhmmgmr.metrics import make_performance_scorers
from skhmmgmr.state_selection import StateSelector, select_n_states, state_choices

PERIOD = 0.05


def make_recordings(n_train=4, n_validation=3, length=150, seed=0):
    """One input, torque a piecewise-linear (regime-dependent) map of it."""
    rng = np.random.default_rng(seed)
    X, y, groups, split = [], [], [], []
    for name, n in (("train", n_train), ("validation", n_validation)):
        for r in range(n):
            x = np.cumsum(rng.normal(scale=0.15, size=(length, 1)), axis=0)
            X.append(x - x.mean())
            y.append(np.where(X[-1][:, 0] > 0, 2.0, -0.5) * X[-1][:, 0])
            y[-1] = y[-1] + rng.normal(scale=0.05, size=length)
            groups += [f"{name}{r}"] * length
            split += [name] * length
    split = np.asarray(split)
    cv = PredefinedSplit(np.where(split == "validation", 0, -1))
    return np.vstack(X), np.concatenate(y), np.asarray(groups), cv


@pytest.fixture(scope="module")
def data():
    return make_recordings()


def table(per_recording):
    """Tidy score table from {recording: [PS of K=1, 2, ...]}."""
    return pd.DataFrame(
        [
            {"n_states": k + 1, "recording": rec, "performance_score": ps}
            for rec, values in per_recording.items()
            for k, ps in enumerate(values)
        ]
    )


def test_state_choices_rule_on_a_hand_made_table():
    scores = table(
        {
            # alone: 1 -> 2 gains 50%, 2 -> 3 gains 0.5%: K=2 although K=4 is far better
            "a": [1.0, 0.5, 0.4975, 0.2],
            # 1 -> 2 gains 0.5%: K=1
            "b": [1.0, 0.995, 0.5, 0.4],
            # gains 20%, 25%, 33%: K=4
            "c": [1.0, 0.8, 0.6, 0.4],
        }
    )
    choices = state_choices(scores)
    # means: 1.0, 0.765 (23.5%), 0.5325 (30.4%), 0.333 (37%): K grows to 4
    assert choices["n_states_average"].iloc[0] == 4
    assert choices["n_states_per_recording_mean"].iloc[0] == pytest.approx(7 / 3)
    assert choices["n_states_per_recording"].iloc[0] == 2
    assert choices["n_states"].iloc[0] == 2  # the minimum of both methods
    assert "trade_off" not in choices.columns

    # the average stops where its gain falls to 1% or less
    plateau = table({"a": [1.0, 0.6, 0.595, 0.3], "b": [1.0, 0.6, 0.595, 0.3]})
    assert state_choices(plateau)["n_states_average"].iloc[0] == 2
    assert state_choices(plateau, tol=0.001)["n_states_average"].iloc[0] == 4
    # the per-recording mean is rounded half up
    half = table({"a": [1.0, 0.5, 0.5], "b": [1.0, 0.5, 0.25]})
    assert state_choices(half)["n_states_per_recording"].iloc[0] == 3  # mean 2.5
    # one row per trade-off
    two = pd.concat([scores.assign(trade_off="50/50"), plateau.assign(trade_off="0/100")])
    assert list(state_choices(two)["trade_off"]) == ["50/50", "0/100"]


def test_state_selector(data):
    X, y, groups, cv = data
    selector = StateSelector(
        k_max=3, cv=cv, accuracy_weight=1.0, smoothness_weight=0.0, sampling_period=PERIOD
    )
    selector.fit(X, y, groups=groups)
    assert selector.results_["n_states"].unique().tolist() == [1, 2, 3]
    assert len(selector.results_) == 3 * 3
    assert list(selector.bic_["n_states"]) == [1, 2, 3]
    assert selector.n_states_bic_ in (1, 2, 3)
    # the regime change needs more than one state for accuracy
    assert selector.n_states_ >= 2
    assert selector.best_estimator_.n_states == selector.n_states_
    assert selector.predict(X, groups=groups).shape == y.shape
    choices = selector.choices(["100/0", "0/100"])
    assert list(choices["trade_off"]) == ["100/0", "0/100"]
    expected = state_choices(selector.rescore("100/0"))
    assert choices["n_states"].iloc[0] == expected["n_states"].iloc[0] == selector.n_states_
    # BIC matches the estimator's own on the training recordings
    train = np.flatnonzero(~np.isin(groups, ["validation0", "validation1", "validation2"]))
    model = HMMGMRRegressor(n_states=2, random_state=0).fit(X[train], y[train], groups[train])
    assert selector.bic_["bic"].iloc[1] == pytest.approx(
        model.bic(X[train], y[train], groups[train])
    )


def test_select_n_states_function(data):
    X, y, groups, cv = data
    scores, choices = select_n_states(
        X, y, groups, k_max=2, cv=cv, trade_offs=["100/0", "50/50"], sampling_period=PERIOD
    )
    assert len(choices) == 2
    assert set(scores.columns) >= {"trade_off", "n_states", "recording", "bic", "performance_score"}
    assert len(scores) == 2 * 2 * 3


def test_grid_search_over_states_and_trade_offs(data):
    """The plain scikit-learn route: GridSearchCV over n_states with multi-metric scoring."""
    X, y, groups, _ = data
    scoring = make_performance_scorers(["100/0", "50/50"], sampling_period=PERIOD)
    with sklearn.config_context(enable_metadata_routing=True), threadpool_limits(1):
        search = GridSearchCV(
            HMMGMRRegressor(random_state=0),
            {"n_states": [1, 2, 3]},
            cv=GroupKFold(n_splits=3),
            scoring=scoring,
            refit="neg_performance_50/50",
        ).fit(X, y, groups=groups)
    results = search.cv_results_
    for name in scoring:
        assert np.all(np.isfinite(results[f"mean_test_{name}"]))
    # accuracy-only: more states fit the two regimes better
    assert (
        results["mean_test_neg_performance_100/0"][1]
        > results["mean_test_neg_performance_100/0"][0]
    )
    assert search.best_params_["n_states"] in (1, 2, 3)


def test_predict_after_fit_without_refit_says_why(data):
    X, y, groups, cv = data
    selector = StateSelector(k_max=2, cv=cv, sampling_period=PERIOD).fit(X, y, groups=groups)
    assert hasattr(selector, "best_estimator_")
    selector.set_params(refit=False).fit(X, y, groups=groups)
    # the estimator refitted by the first fit is gone: it would predict with a stale K
    assert not hasattr(selector, "best_estimator_")
    with pytest.raises(NotFittedError, match="fitted with refit=False"):
        selector.predict(X, groups=groups)


def test_the_refitted_estimator_knows_the_feature_names(data):
    X, y, groups, cv = data
    X = pd.DataFrame(X, columns=["speed"])
    selector = StateSelector(k_max=2, cv=cv, sampling_period=PERIOD).fit(X, y, groups=groups)
    assert list(selector.best_estimator_.feature_names_in_) == ["speed"]
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no "X has feature names, but ... fitted without"
        selector.predict(X, groups=groups)
    with pytest.warns(UserWarning, match="X does not have valid feature names"):
        selector.predict(X.to_numpy(), groups=groups)
