"""Feature relevance, candidate subsets and the one-call framework select_parameters."""

import joblib
import numpy as np
import pandas as pd
import pytest
from _protocol_data import PERIOD, make_protocol
from scipy import stats
from sklearn.model_selection import PredefinedSplit

from skhmmgmr.feature_selection import ExhaustiveFeatureSelector, ForwardFeatureSelector
from skhmmgmr.selection import (
    RelevanceSource,
    SelectionReport,
    candidate_subsets,
    feature_relevance,
    one_way_anova,
    select_parameters,
)


@pytest.fixture(scope="module")
def protocol():
    return make_protocol()


@pytest.fixture(scope="module")
def report(protocol):
    return select_parameters(protocol, k_max=3, progress=False)


def test_feature_relevance_counts(protocol):
    search = protocol[protocol["split"] != "test"]
    cv = PredefinedSplit(np.where(search["split"] == "validation", 0, -1))
    selector = ExhaustiveFeatureSelector(cv=cv, sampling_period=PERIOD)
    selector.fit(search[["f0", "f1", "f2", "f3"]], search["driver_torque"], search["recording"])
    relevance = feature_relevance(selector)
    assert list(relevance.columns) == [f"{a}/{100 - a}" for a in range(100, -1, -10)]
    assert list(relevance.index) == ["f0", "f1", "f2", "f3"]
    assert relevance.attrs["n_recordings"] == 3
    best = selector.best_subsets(list(relevance.columns))
    for label, column in relevance.items():
        # every best subset contributes each of its features once
        subsets = best.loc[best["trade_off"] == label, "subset"]
        assert column.sum() == subsets.map(len).sum()
        assert column.max() <= 3
    # the same counts from the results table and from a table of best subsets
    pd.testing.assert_frame_equal(
        feature_relevance(selector.results_, features=list(relevance.index)), relevance
    )
    pd.testing.assert_frame_equal(
        feature_relevance(best, features=list(relevance.index)), relevance
    )
    # accuracy-only relevance counts the features the torque depends on
    assert relevance.loc["f0", "100/0"] == 3


def test_candidate_subsets_are_nested():
    labels = ["50/50"]
    one = pd.DataFrame({"50/50": [10, 5, 3, 1, 0]}, index=list("abcde"))
    two = pd.DataFrame({"50/50": [0, 9, 1, 0, 2]}, index=list("abcde"))
    one.attrs["n_recordings"] = two.attrs["n_recordings"] = 10
    candidates = candidate_subsets({"exhaustive": one, "forward": two}, labels[0])
    assert list(candidates["name"]) == [
        f"{s} {n}" for n in (1, 2, 3) for s in ("Strict", "Mild", "Liberal")
    ]
    by_name = dict(zip(candidates["name"], candidates["features"], strict=True))
    assert by_name["Strict 1"] == ("a",)
    assert by_name["Mild 1"] == ("a", "b")
    assert by_name["Liberal 1"] == ("a", "b", "c", "d")
    assert by_name["Strict 2"] == ("b",)
    assert by_name["Mild 2"] == ("b",)
    assert by_name["Liberal 2"] == ("b", "c", "e")
    # combined: the union of 1 and 2
    assert by_name["Strict 3"] == ("a", "b")
    assert by_name["Mild 3"] == ("a", "b")
    assert by_name["Liberal 3"] == tuple("abcde")
    # the summed rule: counts 10, 14, 4, 1, 2 of 20 recordings
    summed = candidate_subsets({"exhaustive": one, "forward": two}, labels[0], combined_rule="sum")
    by_name_summed = dict(zip(summed["name"], summed["features"], strict=True))
    assert by_name_summed["Strict 3"] == ("b",)
    assert by_name_summed["Mild 3"] == ("a", "b")
    assert by_name_summed["Liberal 3"] == tuple("abcde")
    for names in (by_name, by_name_summed):
        for n in (1, 2, 3):
            strict, mild, liberal = (set(names[f"{s} {n}"]) for s in ("Strict", "Mild", "Liberal"))
            assert strict <= mild <= liberal


def test_one_way_anova_matches_scipy():
    table = pd.DataFrame(
        {"trade_off": ["a"] * 3 + ["b"] * 3, "accuracy": [90.0, 91, 92, 80, 85, 83]}
    )
    result = one_way_anova(table, by="trade_off", values="accuracy")
    expected = stats.f_oneway([90.0, 91, 92], [80.0, 85, 83])
    assert result["F"].iloc[0] == pytest.approx(expected.statistic)
    assert result["pvalue"].iloc[0] == pytest.approx(expected.pvalue)


def test_select_parameters_report(report):
    assert isinstance(report, SelectionReport)
    assert "f0" in report.features
    assert set(report.features) <= {"f0", "f1", "f2", "f3"}
    assert 1 <= report.n_states <= 3
    assert report.filter["feature"].iloc[0] == "f0"
    assert report.exhaustive["subset"].nunique() == 2**4 - 1
    assert set(report.relevance.index.get_level_values("source")) == {
        "exhaustive",
        "forward",
        "combined",
    }
    combined = report.relevance.loc["combined"]
    pd.testing.assert_frame_equal(
        combined, report.relevance.loc["exhaustive"] + report.relevance.loc["forward"]
    )
    assert len(report.candidates) == 9 + 1  # nine strategies and the baseline
    candidates = report.candidates[report.candidates["name"] != "Baseline"]
    chosen = candidates.dropna(subset=["rank"]).sort_values("rank").iloc[0]
    assert report.candidates["rank"].iloc[-1] >= 1  # the baseline is ranked too
    assert tuple(chosen["features"]) == report.features
    assert list(report.state_choices["n_states"][report.state_choices["trade_off"] == "50/50"]) == [
        report.n_states
    ]
    assert list(report.bic["n_states"]) == [1, 2, 3]
    assert set(report.test_summary["model"]) == {"final", "baseline"}
    assert set(report.test["recording"]) == {"test0", "test1"}
    assert report.final_model.n_features_in_ == len(report.features)
    assert report.baseline_model.n_features_in_ == 4
    assert report.final_model.n_states == report.baseline_model.n_states == report.n_states
    assert set(report.anova["analysis"].str.split(" ").str[0]) == {"feature", "candidate", "state"}
    # the thesis' scope (Appendix E.1.2-E.1.4), groups in the order entered
    thesis_range = tuple(f"{a}/{100 - a}" for a in range(100, 39, -10))
    anova = report.anova.assign(step=report.anova["analysis"].str.split(":").str[0])
    groups = anova.set_index(["step", "metric"])["groups"]
    assert groups["feature relevance", "accuracy"] == thesis_range
    assert groups["feature relevance", "smoothness"] == thesis_range
    assert groups["state selection", "accuracy"] == thesis_range
    assert groups["state selection", "smoothness"] == tuple(report.relevance.columns)
    strategies = groups["candidate subsets", "performance_score"]
    ranked = report.candidates.dropna(subset=["rank"]).query("name != 'Baseline'")
    distinct = ranked.assign(key=ranked["features"].map(frozenset)).drop_duplicates("key")
    expected = distinct.sort_values("rank")["name"].head(7)
    assert strategies == tuple(expected)
    assert "feature subset" in report.summary()


def test_select_parameters_from_arrays_and_cache(protocol, tmp_path, report):
    X = protocol[["f0", "f1", "f2", "f3"]]
    arrays = (X, protocol["driver_torque"].to_numpy(), protocol["recording"].to_numpy())
    split = dict(zip(protocol["recording"], protocol["split"], strict=False))
    params = dict(split=split, k_max=3, sampling_period=PERIOD, progress=False)
    cached = select_parameters(arrays, memory=str(tmp_path), **params)
    assert cached.features == report.features
    pd.testing.assert_frame_equal(cached.exhaustive, report.exhaustive)
    again = select_parameters(arrays, memory=joblib.Memory(tmp_path, verbose=0), **params)
    pd.testing.assert_frame_equal(again.forward_paths, cached.forward_paths)
    pd.testing.assert_frame_equal(again.states, cached.states)
    with pytest.raises(ValueError, match="split"):
        select_parameters(arrays, k_max=2, sampling_period=PERIOD, progress=False)


def test_exhaustive_search_on_a_dask_cluster(protocol):
    distributed = pytest.importorskip(
        "distributed", reason="dask.distributed is not installed (pip install 'dask[distributed]')"
    )
    search = protocol[protocol["split"] != "test"]
    X, y, groups = search[["f0", "f1", "f2"]], search["driver_torque"], search["recording"]
    cv = PredefinedSplit(np.where(search["split"] == "validation", 0, -1))
    local = ExhaustiveFeatureSelector(cv=cv, sampling_period=PERIOD).fit(X, y, groups=groups)
    with (
        distributed.LocalCluster(
            n_workers=2, threads_per_worker=1, processes=False, dashboard_address=None
        ) as cluster,
        distributed.Client(cluster),
        joblib.parallel_backend("dask"),
    ):
        remote = ExhaustiveFeatureSelector(cv=cv, sampling_period=PERIOD, n_jobs=-1)
        remote.fit(X, y, groups=groups)
    pd.testing.assert_frame_equal(remote.results_, local.results_)


def test_a_third_relevance_source_joins_without_changing_the_framework(protocol, report):
    """scikit-learn's own SequentialFeatureSelector, scored by the package's Performance Score
    on the framework's validation split, counts as a third source: its one subset is counted
    for every trade-off, it gets Strict/Mild/Liberal candidates numbered 3, the combined ones
    become number 4 (unions over the three sources), and the thesis' two sources give the same
    relevance as without it."""
    import warnings

    import sklearn
    from sklearn.feature_selection import SequentialFeatureSelector

    from skhmmgmr import HMMGMRRegressor, PerformanceScore
    from skhmmgmr.metrics import UngroupedScoringWarning

    sfs = SequentialFeatureSelector(
        HMMGMRRegressor(n_states=2, random_state=0),
        n_features_to_select=2,
        scoring=PerformanceScore(0.5, 0.5, sampling_period=PERIOD),
    )
    sources = {
        "exhaustive": RelevanceSource(ExhaustiveFeatureSelector(), features="top"),
        "forward": ForwardFeatureSelector(mode="per_recording"),
        "sequential": sfs,
    }
    # with metadata routing on, the sequential selector passes the recording ids to its scorer
    with warnings.catch_warnings(), sklearn.config_context(enable_metadata_routing=True):
        warnings.simplefilter("error", UngroupedScoringWarning)
        three = select_parameters(protocol, k_max=3, progress=False, relevance_sources=sources)
    chosen = tuple(three.sources["sequential"].get_feature_names_out())
    assert len(chosen) == 2
    sequential = three.relevance.loc["sequential"]
    assert (sequential.loc[list(chosen)] == 1).all().all()
    assert (sequential.drop(index=list(chosen)) == 0).all().all()
    for name in ("exhaustive", "forward"):
        pd.testing.assert_frame_equal(three.relevance.loc[name], report.relevance.loc[name])
    pd.testing.assert_frame_equal(
        three.relevance.loc["combined"],
        report.relevance.loc["combined"] + sequential,
    )
    candidates = three.candidates.set_index("name")
    assert candidates.loc["Strict 3", "source"] == "sequential"
    assert candidates.loc["Strict 3", "features"] == tuple(
        f for f in three.relevance.loc["sequential"].index if f in chosen
    )
    old = report.candidates.set_index("name")
    for strategy in ("Strict", "Mild", "Liberal"):
        union = set(old.loc[f"{strategy} 3", "features"]) | set(chosen)
        assert set(candidates.loc[f"{strategy} 4", "features"]) == union
        assert candidates.loc[f"{strategy} 4", "source"] == "combined"
    assert "sequential_selected" in three.source_tables
    assert {"exhaustive_results", "forward_paths"} <= set(three.source_tables)


def test_relevance_sources_are_checked(protocol):
    with pytest.raises(ValueError, match="non-empty mapping"):
        select_parameters(protocol, k_max=2, progress=False, relevance_sources={})
    with pytest.raises(ValueError, match="'combined'"):
        select_parameters(
            protocol,
            k_max=2,
            progress=False,
            relevance_sources={"combined": ForwardFeatureSelector()},
        )
    with pytest.raises(ValueError, match="'features' parameter of RelevanceSource"):
        select_parameters(
            protocol,
            k_max=2,
            progress=False,
            relevance_sources={"a": RelevanceSource(ForwardFeatureSelector(), features="some")},
        )


def test_screening_tolerance_applies_to_the_wrappers_only(protocol, report):
    screened = select_parameters(protocol, k_max=3, screening_tol=0.05, progress=False)
    for name in ("exhaustive", "forward"):
        assert screened.sources[name].estimator.tol == 0.05
        assert report.sources[name].estimator.tol == 1e-4
    assert screened.final_model.tol == screened.baseline_model.tol == 1e-4
    # the wrappers' models are those of a selector run with the loose tolerance itself
    search = protocol[protocol["split"] != "test"]
    cv = PredefinedSplit(np.where(search["split"] == "validation", 0, -1))
    loose = ExhaustiveFeatureSelector(
        screened.sources["exhaustive"].estimator, cv=cv, sampling_period=PERIOD
    ).fit(search[["f0", "f1", "f2", "f3"]], search["driver_torque"], search["recording"])
    pd.testing.assert_frame_equal(screened.exhaustive, loose.results_)
    # the state sweep keeps the strict tolerance: same subset, same state scores
    assert screened.features == report.features
    pd.testing.assert_frame_equal(screened.states, report.states)
    assert not screened.exhaustive["accuracy"].equals(report.exhaustive["accuracy"])
    for bad in (0, -1e-3, float("nan"), float("inf"), True, "1e-3"):
        with pytest.raises(ValueError, match="screening_tol"):
            select_parameters(protocol, k_max=2, screening_tol=bad, progress=False)
