"""Spearman filter and the exhaustive / forward wrappers, on recordings."""

import functools
import multiprocessing
import os
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import joblib
import numpy as np
import pandas as pd
import pytest
import sklearn
from scipy import sparse, stats
from sklearn.base import clone
from sklearn.feature_selection import SelectKBest, SequentialFeatureSelector
from sklearn.model_selection import GroupKFold, PredefinedSplit
from sklearn.pipeline import make_pipeline
from threadpoolctl import threadpool_limits

import skhmmgmr
from skhmmgmr import HMMGMRRegressor, StateSelector
from skhmmgmr.feature_selection import (
    ExhaustiveFeatureSelector,
    ForwardFeatureSelector,
    SpearmanSelector,
    spearman_relevance,
)
from skhmmgmr.metrics import PerformanceScore, performance_score
from skhmmgmr.selection import compare_subsets, select_parameters
from skhmmgmr.selection._search import _evaluation
from skhmmgmr.selection._search._evaluation import shared_evaluations
from skhmmgmr.selection._selectors._forward_paths import ForwardPath

PERIOD = 0.05
FEATURES = ["f0", "f1", "f2", "f3"]


def make_recordings(n_train=4, n_validation=3, length=150, n_features=4, seed=0):
    """Torque = nonlinear map of f0 and f1 + noise; the other features are irrelevant."""
    rng = np.random.default_rng(seed)
    frames = []
    for split, n in (("train", n_train), ("validation", n_validation)):
        for r in range(n):
            x = np.cumsum(rng.normal(scale=0.15, size=(length, n_features)), axis=0)
            x -= x.mean(axis=0)
            torque = 1.5 * np.tanh(2 * x[:, 0]) + 0.8 * x[:, 1]
            frame = pd.DataFrame(x, columns=[f"f{i}" for i in range(n_features)])
            frame.insert(0, "recording", f"{split}{r}")
            frame.insert(1, "split", split)
            frame["driver_torque"] = torque + rng.normal(scale=0.05, size=length)
            frames.append(frame)
    data = pd.concat(frames, ignore_index=True)
    X = data[[c for c in data.columns if c.startswith("f")]]
    cv = PredefinedSplit(np.where(data["split"] == "validation", 0, -1))
    return X, data["driver_torque"].to_numpy(), data["recording"].to_numpy(), cv


@pytest.fixture(scope="module")
def data():
    return make_recordings()


@pytest.fixture(scope="module")
def exhaustive(data):
    X, y, groups, cv = data
    return ExhaustiveFeatureSelector(cv=cv, sampling_period=PERIOD).fit(X, y, groups=groups)


# -- filter ----------------------------------------------------------------------------------


def test_spearman_is_averaged_over_recordings(data):
    X, y, groups, _ = data
    scores, pvalues = spearman_relevance(X, y, groups=groups)
    rhos, ps = [], []
    for rec in pd.unique(groups):
        rows = groups == rec
        results = [stats.spearmanr(X.to_numpy()[rows, j], y[rows]) for j in range(X.shape[1])]
        rhos.append([abs(r.statistic) for r in results])
        ps.append([r.pvalue for r in results])
    np.testing.assert_allclose(scores, np.mean(rhos, axis=0))
    fisher = [
        stats.combine_pvalues(np.clip(column, 1e-300, 1), method="fisher").pvalue
        for column in np.asarray(ps).T
    ]
    np.testing.assert_allclose(pvalues, fisher)
    # pooled rows differ from the per-recording average
    pooled, _ = spearman_relevance(X, y)
    assert not np.allclose(pooled, scores)
    assert list(np.argsort(-scores)[:2]) == [0, 1]


def test_spearman_constant_feature_in_a_recording():
    X = np.column_stack([np.r_[np.ones(5), np.arange(5.0)], np.arange(10.0)])
    y = np.arange(10.0)
    scores, pvalues = spearman_relevance(X, y, groups=np.repeat([0, 1], 5))
    np.testing.assert_allclose(scores, [1.0, 1.0])  # the constant recording is left out
    assert np.all((pvalues >= 0) & (pvalues <= 1))


def test_spearman_in_select_k_best_and_selector(data):
    X, y, groups, _ = data
    grouped = SelectKBest(functools.partial(spearman_relevance, groups=groups), k=2).fit(X, y)
    np.testing.assert_allclose(grouped.scores_, spearman_relevance(X, y, groups=groups)[0])
    pooled = SelectKBest(spearman_relevance, k=2).fit(X, y)  # rows as one recording
    np.testing.assert_allclose(pooled.scores_, spearman_relevance(X, y)[0])

    pipe = make_pipeline(SpearmanSelector(k=2), HMMGMRRegressor(n_states=2, random_state=0))
    with sklearn.config_context(enable_metadata_routing=True):
        pipe.fit(X, y, groups=groups)
        assert pipe.predict(X, groups=groups).shape == y.shape
    selector = pipe[0]
    np.testing.assert_allclose(selector.scores_, spearman_relevance(X, y, groups=groups)[0])
    assert list(selector.get_feature_names_out()) == ["f0", "f1"]
    assert selector.pvalues_.shape == (X.shape[1],)


def test_spearman_relevance_refuses_non_finite_values_naming_them(data):
    X, y, groups, _ = data
    X = X.copy()
    X.iloc[160, 2] = np.nan  # row 10 of the second recording
    # a NaN used to drop its recording from the feature's average, silently
    with pytest.raises(ValueError, match="X contains NaN in column 'f2' of recording 'train1'"):
        spearman_relevance(X, y, groups=groups)
    y = y.copy()
    y[3] = np.inf
    with pytest.raises(ValueError, match="y contains infinity .* of recording 'train0'"):
        spearman_relevance(X.fillna(0.0), y, groups=groups)


def test_spearman_relevance_refuses_sparse_input_saying_so(data):
    X, y, groups, _ = data
    with pytest.raises(TypeError, match="sparse input for X .* X.toarray"):
        spearman_relevance(sparse.csr_matrix(X.to_numpy()), y, groups=groups)


# -- exhaustive wrapper ----------------------------------------------------------------------


def test_exhaustive_evaluates_every_subset_on_every_recording(data, exhaustive):
    X = data[0]
    results = exhaustive.results_
    n = X.shape[1]
    assert results["subset"].nunique() == 2**n - 1
    assert len(results) == (2**n - 1) * 3  # three validation recordings
    assert set(results.columns) >= {"subset", "n_features", "recording", "rmse", "accuracy"}
    assert results.groupby("subset")["recording"].nunique().eq(3).all()


def test_exhaustive_rescore_equals_direct_performance_score(data, exhaustive):
    X, y, groups, cv = data
    train, val = next(cv.split(X, y))
    table = exhaustive.results_
    scores = exhaustive.rescore("70/30")
    for subset in [("f0",), ("f0", "f1"), ("f1", "f2", "f3")]:
        model = HMMGMRRegressor(n_states=2, random_state=0)
        model.fit(X.iloc[train][list(subset)], y[train], groups=groups[train])
        prediction = model.predict(X.iloc[val][list(subset)], groups=groups[val])
        totals = table.assign(loss=(100 - table["accuracy"]).abs()).groupby("recording")
        expected = performance_score(
            y[val],
            prediction,
            accuracy_weight=0.7,
            smoothness_weight=0.3,
            sampling_period=PERIOD,
            groups=groups[val],
            accuracy_scale=totals["loss"].sum(),
            smoothness_scale=totals["smoothness"].sum(),
        )
        got = scores.loc[scores["subset"] == subset, "performance_score"].mean()
        assert got == pytest.approx(expected, rel=1e-10)


def test_exhaustive_finds_the_relevant_features(exhaustive):
    best = exhaustive.best_subsets("100/0", per_recording=False)
    assert best["subset"].iloc[0] == ("f0", "f1")
    per_recording = exhaustive.best_subsets(["100/0", "0/100"])
    assert len(per_recording) == 2 * 3
    accurate = per_recording[per_recording["trade_off"] == "100/0"]
    assert all("f0" in subset for subset in accurate["subset"])


def test_exhaustive_in_a_pipeline(data):
    X, y, groups, cv = data
    selector = ExhaustiveFeatureSelector(
        max_features=2, cv=cv, accuracy_weight=1.0, smoothness_weight=0.0, sampling_period=PERIOD
    )
    pipe = make_pipeline(selector, HMMGMRRegressor(n_states=2, random_state=0))
    with sklearn.config_context(enable_metadata_routing=True):
        pipe.fit(X, y, groups=groups)
        assert pipe.predict(X, groups=groups).shape == y.shape
    assert pipe[0].results_["n_features"].max() == 2
    assert len(pipe[0].results_["subset"].unique()) == 4 + 6
    assert list(pipe[0].get_feature_names_out()) == ["f0", "f1"]
    assert pipe[-1].n_features_in_ == 2


def test_integer_cv_needs_groups(data):
    X, y, _, _ = data
    with pytest.raises(ValueError, match="needs groups"):
        ExhaustiveFeatureSelector(cv=3, sampling_period=PERIOD).fit(X, y)
    with pytest.raises(ValueError, match="sampling_period"):
        ExhaustiveFeatureSelector(cv=3).fit(X, y)


# -- caching and parallelism -----------------------------------------------------------------

FITS = []


class CountingRegressor(HMMGMRRegressor):
    def fit(self, X, y, groups=None, time=None):
        FITS.append(X.shape[1])
        return super().fit(X, y, groups=groups, time=time)


def test_memory_cache_returns_identical_results_without_refitting(data, tmp_path):
    X, y, groups, cv = data
    estimator = CountingRegressor(n_states=2, random_state=0)
    params = dict(max_features=2, cv=cv, sampling_period=PERIOD, memory=str(tmp_path))
    FITS.clear()
    first = ExhaustiveFeatureSelector(estimator, **params).fit(X, y, groups=groups)
    assert len(FITS) == 4 + 6
    FITS.clear()
    second = ExhaustiveFeatureSelector(estimator, **params).fit(X, y, groups=groups)
    assert FITS == []
    pd.testing.assert_frame_equal(first.results_, second.results_)
    # a larger search resumes: only the new subsets are fitted
    ExhaustiveFeatureSelector(estimator, **{**params, "max_features": 3}).fit(X, y, groups=groups)
    assert len(FITS) == 4


def test_memory_cache_is_keyed_by_the_package_version(data, tmp_path, monkeypatch):
    # joblib.Memory keys by the cached function's own source and arguments only: results of
    # another skhmmgmr (or NumPy, SciPy, scikit-learn, numba) must not be served.
    X, y, groups, cv = data
    estimator = CountingRegressor(n_states=2, random_state=0)
    params = dict(max_features=1, cv=cv, sampling_period=PERIOD, memory=str(tmp_path))
    FITS.clear()
    first = ExhaustiveFeatureSelector(estimator, **params).fit(X, y, groups=groups)
    assert len(FITS) == 4
    FITS.clear()
    ExhaustiveFeatureSelector(estimator, **params).fit(X, y, groups=groups)
    assert FITS == []  # same version: served from the cache
    monkeypatch.setattr(_evaluation, "__version__", "99.0")
    again = ExhaustiveFeatureSelector(estimator, **params).fit(X, y, groups=groups)
    assert len(FITS) == 4  # another version: recomputed
    pd.testing.assert_frame_equal(first.results_, again.results_)
    monkeypatch.setattr(_evaluation, "_installed_code", lambda: {"numpy": "0.0"})
    FITS.clear()
    ExhaustiveFeatureSelector(estimator, **params).fit(X, y, groups=groups)
    assert len(FITS) == 4  # another numerical library or edited source: recomputed


def test_the_cache_key_covers_the_source_of_the_whole_package():
    # an edit of the estimator (or of any module an evaluation runs) must miss the cache
    assert Path(skhmmgmr.__file__).resolve().parent == _evaluation.PACKAGE_FOLDER
    sources = {p.name for p in _evaluation.PACKAGE_FOLDER.rglob("*.py")}
    assert {"_em.py", "_regressor.py", "_scores.py", "_evaluation.py"} <= sources


def test_shared_data_folder_is_tracked_and_removed(data, tmp_path, monkeypatch):
    # The folder of the data shared with the workers is registered with loky's resource
    # tracker while in use: if the run is killed, the tracker deletes it (see the slow test).
    from joblib.externals.loky.backend import resource_tracker

    X, y, groups, cv = data
    calls = []
    monkeypatch.setattr(resource_tracker, "register", lambda *a: calls.append(("register", *a)))
    monkeypatch.setattr(resource_tracker, "unregister", lambda *a: calls.append(("free", *a)))
    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))
    selector = ExhaustiveFeatureSelector(cv=cv, max_features=1, sampling_period=PERIOD, n_jobs=2)
    with joblib.parallel_config(backend="threading"):
        selector.fit(X, y, groups=groups)
    [(_, folder, kind), (_, freed, _)] = calls
    assert (kind, freed) == ("folder", folder)
    assert Path(folder).parent == tmp_path and not Path(folder).exists()


@pytest.mark.filterwarnings("ignore:.*tasks:UserWarning")  # joblib: cancelled tasks
def test_interrupted_parallel_search_leaves_no_folder_or_worker(data, tmp_path, monkeypatch):
    X, y, groups, cv = data

    def interrupt(results, **kwargs):
        for _ in results:
            raise KeyboardInterrupt

    monkeypatch.setattr(_evaluation, "progress_bar", interrupt)
    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))
    selector = ExhaustiveFeatureSelector(cv=cv, max_features=2, sampling_period=PERIOD, n_jobs=2)
    with pytest.raises(KeyboardInterrupt):
        selector.fit(X, y, groups=groups)
    assert list(tmp_path.iterdir()) == []
    # joblib terminates its workers on the interrupt; on a loaded machine a terminated worker
    # may take a while to exit (over 30 s twice at a load of 5 to 7): the test gives them the
    # bounded time the killed run's workers get below
    deadline = time.monotonic() + 120
    while [p for p in multiprocessing.active_children() if "Loky" in p.name]:
        assert time.monotonic() < deadline, "loky workers still running 120 s after the interrupt"
        time.sleep(0.2)


KILLED_RUN = """
import os, signal
import joblib, numpy as np
from skhmmgmr.selection._search import _evaluation
from skhmmgmr.feature_selection import ExhaustiveFeatureSelector

def die(results, **kwargs):
    for _ in results:
        os.kill(os.getpid(), signal.SIGKILL)

_evaluation.progress_bar = die
rng = np.random.default_rng(0)
X = np.cumsum(rng.normal(size=(2000, 3)), axis=0)
with joblib.parallel_config(backend="loky", idle_worker_timeout=1):
    ExhaustiveFeatureSelector(cv=2, sampling_period=0.05, n_jobs=2).fit(
        X, X.sum(axis=1), groups=np.repeat(np.arange(4), 500)
    )
"""


@pytest.mark.slow
@pytest.mark.skipif(not hasattr(signal, "SIGKILL"), reason="needs SIGKILL")
def test_killed_parallel_search_leaves_no_folder(tmp_path):
    # A run killed outright leaves its workers until their idle timeout (here 1 s, plus up to
    # 30 s in which they wait for the dead parent); then loky's resource tracker deletes the
    # shared data folder. It used to stay in the temporary directory for good.
    env = {**os.environ, "TMPDIR": str(tmp_path)}
    run = subprocess.run([sys.executable, "-c", KILLED_RUN], env=env, timeout=300, check=False)
    assert run.returncode == -signal.SIGKILL
    deadline = time.monotonic() + 120
    while list(tmp_path.glob("skhmmgmr-*")) and time.monotonic() < deadline:
        time.sleep(0.5)
    assert list(tmp_path.glob("skhmmgmr-*")) == []


def test_bool_sampling_period_is_refused_by_every_search(data):
    X, y, groups, cv = data
    for selector in (
        ExhaustiveFeatureSelector(cv=cv, sampling_period=True),
        ForwardFeatureSelector(cv=cv, sampling_period=True),
        StateSelector(cv=cv, sampling_period=True),
    ):
        with pytest.raises(ValueError, match=r"'sampling_period' parameter .*not a bool"):
            selector.fit(X, y, groups=groups)
    with pytest.raises(ValueError, match=r"'sampling_period' parameter .*not a bool"):
        compare_subsets(X, y, groups, {"a": ("f0",)}, cv=cv, sampling_period=True)
    split = np.where(pd.Series(groups).str.startswith("train"), "train", "validation")
    split[groups == "validation2"] = "test"
    with pytest.raises(ValueError, match=r"'sampling_period' parameter .*not a bool"):
        select_parameters((X, y, groups), split=split, sampling_period=True)


def test_n_jobs_gives_identical_results(data, exhaustive):
    X, y, groups, cv = data
    parallel = ExhaustiveFeatureSelector(cv=cv, max_features=2, sampling_period=PERIOD, n_jobs=2)
    parallel.fit(X, y, groups=groups)
    expected = exhaustive.results_[exhaustive.results_["n_features"] <= 2].reset_index(drop=True)
    pd.testing.assert_frame_equal(parallel.results_, expected, check_exact=True)


# -- forward wrapper -------------------------------------------------------------------------


def test_forward_path_stops_by_the_one_percent_rule():
    scores = {
        (0,): 1.0,
        (1,): 0.8,
        (2,): 0.9,
        (0, 1): 0.5,
        (1, 2): 0.6,
        (0, 1, 2): 0.496,  # 0.8% better than 0.5: not enough
    }
    path = ForwardPath(3, tol=0.01, max_features=3)
    while path.active:
        path.step(scores.__getitem__)
    assert path.selected == (1, 0)
    assert [h["accepted"] for h in path.history] == [True, True, False]
    assert path.history[-1]["gain"] == pytest.approx(0.008)

    scores[(0, 1, 2)] = 0.49  # 2% better: accepted, then no feature is left
    path = ForwardPath(3, tol=0.01, max_features=3)
    while path.active:
        path.step(scores.__getitem__)
    assert path.selected == (1, 0, 2)
    # max_features ends a path even when the gain is large
    path = ForwardPath(3, tol=0.01, max_features=1)
    while path.active:
        path.step(scores.__getitem__)
    assert path.selected == (1,)


def test_forward_selector_average_and_per_recording(data):
    X, y, groups, cv = data
    params = dict(cv=cv, accuracy_weight=1.0, smoothness_weight=0.0, sampling_period=PERIOD)
    average = ForwardFeatureSelector(**params).fit(X, y, groups=groups)
    assert set(average.subset_) >= {"f0", "f1"}
    assert list(average.paths_["path"].unique()) == ["average"]
    steps = average.paths_
    assert steps["accepted"].iloc[:-1].all()
    last = steps.iloc[-1]
    assert (not last["accepted"] and last["gain"] <= 0.01) or len(average.subset_) == 4

    per_recording = ForwardFeatureSelector(
        mode="per_recording", trade_offs=["0/100"], **params
    ).fit(X, y, groups=groups)
    paths = per_recording.paths_
    assert set(paths["trade_off"]) == {"100/0", "0/100"}
    assert paths.groupby("trade_off")["path"].nunique().eq(3).all()
    best = per_recording.best_subsets(["100/0", "0/100"])
    assert len(best) == 6
    assert all("f0" in subset for subset in best.loc[best["trade_off"] == "100/0", "subset"])
    # every distinct subset was fitted once and is kept in results_
    assert not per_recording.results_.duplicated(["subset", "recording"]).any()
    with pytest.raises(ValueError, match="no forward path"):
        per_recording.best_subsets("50/50")


def test_sklearn_sequential_feature_selector_with_routed_groups(data):
    X, y, groups, _ = data
    scorer = PerformanceScore(1.0, 0.0, sampling_period=PERIOD)
    sfs = SequentialFeatureSelector(
        HMMGMRRegressor(n_states=2, random_state=0),
        n_features_to_select=2,
        scoring=scorer,
        cv=GroupKFold(n_splits=3),
    )
    # k-means' OpenMP threads only spin on such small fits
    with sklearn.config_context(enable_metadata_routing=True), threadpool_limits(1):
        sfs.fit(X, y, groups=groups)
    assert list(sfs.get_feature_names_out()) == ["f0", "f1"]
    # the selection equals a hand-made forward step whose folds are scored per recording
    with sklearn.config_context(enable_metadata_routing=True), threadpool_limits(1):
        first = {
            j: np.mean(
                [
                    scorer(
                        clone(sfs.estimator).fit(X.iloc[tr, [j]], y[tr], groups=groups[tr]),
                        X.iloc[te, [j]],
                        y[te],
                        groups=groups[te],
                    )
                    for tr, te in GroupKFold(n_splits=3).split(X, y, groups)
                ]
            )
            for j in range(X.shape[1])
        }
    assert max(first, key=first.get) == 0


def test_shared_evaluations_reuse_subsets_across_steps_with_the_same_results(data):
    X, y, groups, cv = data
    estimator = CountingRegressor(n_states=2, random_state=0)
    params = dict(cv=cv, sampling_period=PERIOD)
    forward_params = dict(mode="per_recording", trade_offs=["0/100"], **params)
    FITS.clear()
    alone = ForwardFeatureSelector(estimator, **forward_params).fit(X, y, groups=groups)
    fits_alone = len(FITS)
    with shared_evaluations():
        first = ExhaustiveFeatureSelector(estimator, max_features=2, **params)
        first.fit(X[["f0", "f2", "f3"]], y, groups=groups)
        FITS.clear()
        shared = ForwardFeatureSelector(estimator, **forward_params).fit(X, y, groups=groups)
    known = set(first.results_["subset"])
    met = set(alone.results_["subset"])
    assert met & known  # the forward step meets subsets of the exhaustive step
    assert len(FITS) == fits_alone - len(met & known)
    pd.testing.assert_frame_equal(shared.results_, alone.results_, check_exact=True)
    pd.testing.assert_frame_equal(shared.paths_, alone.paths_)
    # another estimator, or data outside the block, is fitted again
    with shared_evaluations():
        ExhaustiveFeatureSelector(estimator, max_features=1, **params).fit(X, y, groups=groups)
        FITS.clear()
        other = clone(estimator).set_params(n_states=3)
        ExhaustiveFeatureSelector(other, max_features=1, **params).fit(X, y, groups=groups)
        assert len(FITS) == 4
    FITS.clear()
    ExhaustiveFeatureSelector(estimator, max_features=1, **params).fit(X, y, groups=groups)
    assert len(FITS) == 4


def test_models_are_fitted_longest_first_and_reported_in_their_order(data, monkeypatch):
    from skhmmgmr.selection._search import _evaluation

    X, y, groups, cv = data
    X = X.to_numpy()
    splits = _evaluation.check_recording_splits(cv, X, y, groups)
    models = [((0,), {}), ((0, 1, 2), {}), ((1,), {"n_states": 4}), ((0, 1), {}), ((2,), {})]
    estimator = HMMGMRRegressor(n_states=2, random_state=0)
    # K (D + 1)^2 + K^2 with D the subset size: 12, 36, 32, 22, 12
    assert _evaluation.longest_first(estimator, models) == [1, 2, 3, 0, 4]

    fitted = []
    real = _evaluation._fit_and_evaluate

    def recording_order(**kwargs):
        fitted.append(kwargs["columns"])
        return real(**kwargs)

    monkeypatch.setattr(_evaluation, "_fit_and_evaluate", recording_order)
    table = _evaluation.evaluate_models(
        estimator, X, y, groups, splits, models, sampling_period=PERIOD
    )
    assert fitted == [(0, 1, 2), (1,), (0, 1), (0,), (2,)]
    assert table["model"].tolist() == sorted(table["model"].tolist())
    for model_id, (columns, params) in enumerate(models):
        alone = _evaluation.evaluate_models(
            estimator, X, y, groups, splits, [(columns, params)], sampling_period=PERIOD
        )
        got = table[table["model"] == model_id].drop(columns="model").reset_index(drop=True)
        pd.testing.assert_frame_equal(got, alone.drop(columns="model"), check_exact=True)
