"""HMMGMRRegressor inside scikit-learn's model selection, recordings kept intact."""

import numpy as np
import pytest
import sklearn
from sklearn.base import clone
from sklearn.metrics import r2_score
from sklearn.model_selection import GridSearchCV, GroupKFold, cross_validate
from sklearn.pipeline import make_pipeline
from sklearn.preprocessing import StandardScaler

from skhmmgmr import HMMGMRRegressor
from skhmmgmr.metrics import PerformanceScore, performance_score

SAMPLING_PERIOD = 0.05


def make_recordings(n_recordings=6, length=120, seed=0):
    rng = np.random.default_rng(seed)
    X, y, groups = [], [], []
    for r in range(n_recordings):
        x = np.cumsum(rng.normal(scale=0.2, size=(length, 2)), axis=0)
        torque = np.where(x[:, 0] > 0, 1.2 * x[:, 0], -0.6 * x[:, 0] + 0.4 * x[:, 1])
        X.append(x)
        y.append(torque + rng.normal(scale=0.05, size=length))
        groups += [f"rec{r}"] * length
    return np.vstack(X), np.concatenate(y), np.asarray(groups)


@pytest.fixture(scope="module")
def data():
    return make_recordings()


def scorers():
    return {
        "ps_50_50": PerformanceScore(0.5, 0.5, sampling_period=SAMPLING_PERIOD),
        "ps_100_0": PerformanceScore(1.0, 0.0, sampling_period=SAMPLING_PERIOD),
        "ps_0_100": PerformanceScore(0.0, 1.0, sampling_period=SAMPLING_PERIOD),
    }


def manual_fold_scores(pipe, X, y, groups, cv, weights, *, per_recording):
    """Fit each fold by hand; score predictions made per recording (or as one sequence)."""
    scores = []
    for train, test in cv.split(X, y, groups):
        model = clone(pipe).fit(X[train], y[train], hmmgmrregressor__groups=groups[train])
        test_groups = groups[test] if per_recording else None
        pred = model.predict(X[test], groups=test_groups)
        ps = performance_score(
            y[test],
            pred,
            accuracy_weight=weights[0],
            smoothness_weight=weights[1],
            sampling_period=SAMPLING_PERIOD,
            groups=groups[test],
        )
        scores.append(-ps)
    return np.asarray(scores)


def test_grid_search_over_states_and_trade_offs(data):
    X, y, groups = data
    pipe = make_pipeline(StandardScaler(), HMMGMRRegressor(random_state=0))
    cv = GroupKFold(n_splits=3)
    with sklearn.config_context(enable_metadata_routing=True):
        search = GridSearchCV(
            pipe,
            {"hmmgmrregressor__n_states": [1, 2, 3]},
            cv=cv,
            scoring=scorers(),
            refit="ps_50_50",
        ).fit(X, y, groups=groups)
    results = search.cv_results_
    for name in scorers():
        assert np.all(np.isfinite(results[f"mean_test_{name}"]))
    assert search.best_params_["hmmgmrregressor__n_states"] in (1, 2, 3)
    assert search.best_index_ == int(np.argmax(results["mean_test_ps_50_50"]))
    # more states fit the nonlinear gain better: accuracy-only score improves from K=1
    assert results["mean_test_ps_100_0"][2] > results["mean_test_ps_100_0"][0]
    # the refitted model was trained on all recordings
    assert search.best_estimator_[-1].n_features_in_ == 2

    # Each split's score equals a by-hand fit whose test recordings are filtered one by one;
    # a fold filtered as one sequence gives different numbers, so this fails if the search
    # ever lost the recording boundaries.
    for i, n_states in enumerate([1, 2, 3]):
        model = clone(pipe).set_params(hmmgmrregressor__n_states=n_states)
        expected = manual_fold_scores(model, X, y, groups, cv, (0.5, 0.5), per_recording=True)
        got = np.array([results[f"split{s}_test_ps_50_50"][i] for s in range(3)])
        np.testing.assert_allclose(got, expected, rtol=1e-10)
        if n_states > 1:
            as_one = manual_fold_scores(model, X, y, groups, cv, (0.5, 0.5), per_recording=False)
            assert not np.allclose(got, as_one, rtol=1e-6)


def test_cross_validate_with_routed_groups(data):
    X, y, groups = data
    pipe = make_pipeline(StandardScaler(), HMMGMRRegressor(n_states=2, random_state=0))
    cv = GroupKFold(n_splits=3)
    with sklearn.config_context(enable_metadata_routing=True):
        result = cross_validate(pipe, X, y, cv=cv, scoring=scorers(), params={"groups": groups})
    expected = manual_fold_scores(pipe, X, y, groups, cv, (1.0, 0.0), per_recording=True)
    np.testing.assert_allclose(result["test_ps_100_0"], expected, rtol=1e-10)


def test_estimator_score_is_sequence_aware_in_search(data):
    """Default scoring (R^2 from .score) also receives the fold's groups."""
    X, y, groups = data
    pipe = make_pipeline(StandardScaler(), HMMGMRRegressor(n_states=2, random_state=0))
    cv = GroupKFold(n_splits=3)
    with sklearn.config_context(enable_metadata_routing=True):
        result = cross_validate(pipe, X, y, cv=cv, params={"groups": groups})
    expected = []
    for train, test in cv.split(X, y, groups):
        model = clone(pipe).fit(X[train], y[train], hmmgmrregressor__groups=groups[train])
        # Pipeline.score drops extra params unless routing is on: compute R^2 from predict
        expected.append(r2_score(y[test], model.predict(X[test], groups=groups[test])))
    np.testing.assert_allclose(result["test_score"], expected, rtol=1e-10)
