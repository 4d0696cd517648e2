"""The selection's two searches: ``search="full"`` (every model from its own start until EM
converges, the path of earlier versions) and ``search="fast"`` (subsets screened from the
marginal of a joint model, the state sweep grown by splitting a state, the K the 1% rule reads
fitted in full)."""

import numpy as np
import pandas as pd
import pytest
from _protocol_data import PERIOD, make_protocol
from scipy.stats import multivariate_normal
from sklearn.base import clone
from sklearn.model_selection import PredefinedSplit

from skhmmgmr import HMMGMRRegressor, StateSelector
from skhmmgmr.feature_selection import ExhaustiveFeatureSelector, ForwardFeatureSelector
from skhmmgmr.metrics import evaluate_recordings
from skhmmgmr.selection import select_parameters
from skhmmgmr.selection._search import _screening, base
from skhmmgmr.selection._search._score_tables import rescore_table
from skhmmgmr.selection._selectors._states import read_by_the_rule, state_choices

FEATURES = ["f0", "f1", "f2", "f3"]


@pytest.fixture(scope="module")
def searched():
    protocol = make_protocol(n_recordings=(4, 3, 2), length=150, n_features=4, seed=0)
    search = protocol[protocol["split"] != "test"].reset_index(drop=True)
    cv = PredefinedSplit(np.where(search["split"] == "validation", 0, -1))
    return search[FEATURES], search["driver_torque"].to_numpy(), search["recording"], cv


def _plain_loop(X, y, groups, cv, subsets, estimator):
    """Accuracy and smoothness of every subset's model on every validation recording: a
    fit on the training rows, a prediction per validation recording."""
    train, val = next(cv.split(X, y))
    rows = []
    for subset in subsets:
        model = clone(estimator).fit(
            X.iloc[train][list(subset)].to_numpy(), y[train], groups=groups.iloc[train]
        )
        prediction = model.predict(X.iloc[val][list(subset)].to_numpy(), groups=groups.iloc[val])
        table = evaluate_recordings(
            y[val], prediction, groups=groups.iloc[val], sampling_period=PERIOD
        )
        rows.append(table.assign(subset=[subset] * len(table)))
    return pd.concat(rows, ignore_index=True)


def test_the_full_search_is_the_plain_loop_and_never_screens(searched, monkeypatch):
    X, y, groups, cv = searched

    def refuse(*args, **kwargs):
        raise AssertionError("the full search built a fast search")

    monkeypatch.setattr(base, "FastSearch", refuse)
    selector = ExhaustiveFeatureSelector(
        cv=cv, sampling_period=PERIOD, max_features=2, search="full"
    ).fit(X, y, groups=groups)
    assert "screened" not in selector.results_
    subsets = [("f0",), ("f1", "f3"), ("f0", "f1")]
    estimator = HMMGMRRegressor(n_states=2, random_state=0)  # the selectors' default
    reference = _plain_loop(X, y, groups, cv, subsets, estimator)
    merged = selector.results_.merge(reference, on=["subset", "recording"], suffixes=("", "_r"))
    assert len(merged) == len(reference)
    np.testing.assert_allclose(merged["accuracy"], merged["accuracy_r"], rtol=1e-9)
    np.testing.assert_allclose(merged["smoothness"], merged["smoothness_r"], rtol=1e-9)


def test_the_fast_state_sweep_chooses_the_k_of_the_full_sweep(searched):
    X, y, groups, cv = searched
    kwargs = dict(k_max=8, cv=cv, sampling_period=PERIOD, refit=False)
    full = StateSelector(search="full", **kwargs).fit(X[["f0", "f1"]], y, groups=groups)
    fast = StateSelector(search="fast", **kwargs).fit(X[["f0", "f1"]], y, groups=groups)
    assert fast.n_states_ == full.n_states_
    # the K that the rule reads are fitted as the full sweep fits them, to the bit (and
    # those an earlier reading of screened scores asked for)
    read = read_by_the_rule(rescore_table(full.results_, "n_states", "50/50"), 0.01)
    exact = fast.results_[~fast.results_["screened"]]
    assert set(read) <= set(exact["n_states"])
    columns = ["n_states", "recording", "accuracy", "smoothness", "bic"]
    pd.testing.assert_frame_equal(
        exact[columns].reset_index(drop=True),
        full.results_[full.results_["n_states"].isin(exact["n_states"])][columns].reset_index(
            drop=True
        ),
    )
    # the others come from the chain of splits
    screened = set(fast.results_.loc[fast.results_["screened"], "n_states"])
    assert screened and screened == set(range(1, 9)) - set(exact["n_states"])


def test_the_rule_reads_a_prefix_that_settles_its_choice():
    # whatever the scores past the prefix read, the choice of K stays the same
    rng = np.random.default_rng(0)
    ks = np.arange(1, 9)
    for _ in range(200):
        n_recordings = int(rng.integers(1, 5))
        drops = rng.choice([0.2, 0.05, 0.003], size=(n_recordings, len(ks)), p=[0.4, 0.3, 0.3])
        values = np.cumprod(1.0 - drops, axis=1)
        scores = pd.DataFrame(
            [
                {"n_states": k, "recording": f"r{r}", "performance_score": values[r, i]}
                for r in range(n_recordings)
                for i, k in enumerate(ks)
            ]
        )
        read = read_by_the_rule(scores, 0.01)
        assert read == list(ks[: len(read)])
        choice = state_choices(scores)["n_states"].iloc[0]
        unread = ~scores["n_states"].isin(read)
        for _ in range(5):
            changed = scores.copy()
            changed.loc[unread, "performance_score"] = rng.uniform(0.01, 2.0, unread.sum())
            assert state_choices(changed)["n_states"].iloc[0] == choice


def test_the_fast_exhaustive_search_keeps_the_relevant_features(searched, monkeypatch):
    # The torque depends on f0 and f1. Both searches keep them; on these short recordings
    # a K=2 model has several optima, and the fast search's subset may hold one more feature
    # than the full search's (its screened models sit in the joint model's optimum).
    X, y, groups, cv = searched
    kwargs = dict(cv=cv, sampling_period=PERIOD)
    full = ExhaustiveFeatureSelector(search="full", **kwargs).fit(X, y, groups=groups)
    fast = ExhaustiveFeatureSelector(search="fast", **kwargs).fit(X, y, groups=groups)
    assert {"f0", "f1"} <= set(fast.subset_) and {"f0", "f1"} <= set(full.subset_)
    merged = fast.results_.merge(full.results_, on=["subset", "recording"], suffixes=("", "_f"))
    assert len(merged) == len(full.results_)
    # the joint model (all features) is the full search's model; the others start from it
    joint = merged[merged["n_features"] == len(FEATURES)]
    assert not joint["screened"].any()
    np.testing.assert_array_equal(joint["accuracy"], joint["accuracy_f"])
    assert merged.loc[merged["n_features"] < len(FEATURES), "screened"].all()
    # with a bound on the screening's error, what it confirms is fitted as the full search
    # fits it, to the bit, and the rest stays screened
    monkeypatch.setattr(_screening, "SCREENING_ERROR", 0.005)
    fast = ExhaustiveFeatureSelector(search="fast", **kwargs).fit(X, y, groups=groups)
    merged = fast.results_.merge(full.results_, on=["subset", "recording"], suffixes=("", "_f"))
    exact = merged[~merged["screened"]]
    assert len(exact) > len(joint)
    np.testing.assert_array_equal(exact["accuracy"], exact["accuracy_f"])
    np.testing.assert_array_equal(exact["smoothness"], exact["smoothness_f"])
    assert merged["screened"].any()


def test_the_fast_forward_search_starts_from_the_full_search_first_step(searched, monkeypatch):
    X, y, groups, cv = searched
    kwargs = dict(cv=cv, sampling_period=PERIOD, trade_offs=["100/0"])
    full = ForwardFeatureSelector(search="full", **kwargs).fit(X, y, groups=groups)
    fast = ForwardFeatureSelector(search="fast", **kwargs).fit(X, y, groups=groups)
    assert {"f0", "f1"} <= set(fast.subset_) and {"f0", "f1"} <= set(full.subset_)
    # both paths take the same feature first
    first = [p[p["accepted"]]["feature"].iloc[0] for p in (full.paths_, fast.paths_)]
    assert first[0] == first[1]
    # the single features (the scales of every score) are fitted in full, to the bit; the
    # other subsets below the joint model are screened
    results = fast.results_
    singles = results[results["n_features"] == 1]
    assert not singles["screened"].any()
    merged = singles.merge(full.results_, on=["subset", "recording"], suffixes=("", "_f"))
    assert len(merged) == len(singles) == len(FEATURES) * results["recording"].nunique()
    np.testing.assert_array_equal(merged["accuracy"], merged["accuracy_f"])
    np.testing.assert_array_equal(merged["smoothness"], merged["smoothness_f"])
    assert results.loc[results["n_features"].between(2, len(FEATURES) - 1), "screened"].all()
    monkeypatch.setattr(_screening, "SCREENING_ERROR", 0.005)
    fast = ForwardFeatureSelector(search="fast", **kwargs).fit(X, y, groups=groups)
    # the single features (the scales) and what the confirmed paths read are fitted as the
    # full search fits them, to the bit, and read once in the table
    results = fast.results_
    assert not results.duplicated(["subset", "recording"]).any()
    exact = results[~results["screened"]]
    assert {(f,) for f in FEATURES} < set(exact["subset"])
    # (of those the full paths visited too)
    merged = exact.merge(full.results_, on=["subset", "recording"], suffixes=("", "_f"))
    assert {(f,) for f in FEATURES} <= set(merged["subset"])
    np.testing.assert_array_equal(merged["accuracy"], merged["accuracy_f"])
    np.testing.assert_array_equal(merged["smoothness"], merged["smoothness_f"])


def test_an_estimator_the_fast_search_does_not_serve_is_searched_in_full(searched):
    X, y, groups, cv = searched
    estimator = HMMGMRRegressor(output_smoothing=0.5, random_state=0)
    kwargs = dict(cv=cv, sampling_period=PERIOD, max_features=2)
    tables = [
        ExhaustiveFeatureSelector(estimator, search=search, **kwargs)
        .fit(X, y, groups=groups)
        .results_
        for search in ("full", "fast")
    ]
    pd.testing.assert_frame_equal(tables[0], tables[1])


def test_an_unknown_search_is_refused_by_name(searched):
    X, y, groups, cv = searched
    with pytest.raises(ValueError, match="'search' parameter"):
        StateSelector(k_max=2, cv=cv, sampling_period=PERIOD, search="quick").fit(
            X, y, groups=groups
        )
    protocol = make_protocol(n_recordings=(2, 2, 1), length=60, n_features=2)
    with pytest.raises(ValueError, match="'search' parameter"):
        select_parameters(protocol, k_max=2, search="quick", progress=False)


def test_the_framework_searches_fast_and_fits_what_it_compares_in_full():
    protocol = make_protocol(n_recordings=(4, 3, 2), length=150, n_features=4, seed=1)
    fast = select_parameters(protocol, k_max=6, progress=False, search="fast")
    assert fast.sources["exhaustive"].search == fast.sources["forward"].search == "fast"
    assert fast.exhaustive["screened"].any() and fast.states["screened"].any()
    assert {"f0", "f1"} <= set(fast.features)
    # the final model is fitted as the full search fits it, on the training recordings
    train = protocol[protocol["split"] == "train"]
    final = HMMGMRRegressor(n_states=fast.n_states, random_state=0).fit(
        train[list(fast.features)].to_numpy(),
        train["driver_torque"].to_numpy(),
        groups=train["recording"],
    )
    np.testing.assert_array_equal(fast.final_model.means_, final.means_)


def _marginal_prediction(model, dims, X, groups):
    """Causal GMR estimate of the HMM of a fitted ``model`` over the columns ``dims`` (the
    inputs, then the target) alone: a plain-loop forward recursion on every recording."""
    means, covs = model.means_[:, dims], model.covars_[:, dims][:, :, dims]
    n_inputs, n_states = len(dims) - 1, len(model.startprob_)
    estimates = np.empty(len(X))
    for recording in pd.unique(groups):
        rows = np.flatnonzero(np.asarray(groups) == recording)
        alpha = None
        for t in rows:
            x = X[t]
            b = np.array(
                [
                    multivariate_normal(means[k, :n_inputs], covs[k, :n_inputs, :n_inputs]).pdf(x)
                    for k in range(n_states)
                ]
            )
            alpha = model.startprob_ * b if alpha is None else (alpha @ model.transmat_) * b
            alpha = alpha / alpha.sum()
            conditional = [
                means[k, n_inputs]
                + covs[k, n_inputs, :n_inputs]
                @ np.linalg.solve(covs[k, :n_inputs, :n_inputs], x - means[k, :n_inputs])
                for k in range(n_states)
            ]
            estimates[t] = alpha @ np.array(conditional)
    return estimates


def test_a_screened_subset_is_the_joint_model_marginal_scored_as_a_fitted_model(searched):
    # with no EM iteration (the default), a subset's model is the marginal of the joint model
    # over its columns and the target, and it is scored as the full search scores a fit
    X, y, groups, cv = searched
    assert _screening.EXHAUSTIVE_ITERATIONS == 0
    fast = ExhaustiveFeatureSelector(search="fast", cv=cv, sampling_period=PERIOD).fit(
        X, y, groups=groups
    )
    train, val = next(cv.split(X, y))
    joint = HMMGMRRegressor(n_states=2, random_state=0).fit(
        X.iloc[train].to_numpy(), y[train], groups=groups.iloc[train]
    )
    for subset in [("f0",), ("f1", "f3"), ("f0", "f1", "f2")]:
        dims = [FEATURES.index(f) for f in subset] + [len(FEATURES)]
        prediction = _marginal_prediction(
            joint, dims, X.iloc[val][list(subset)].to_numpy(), groups.iloc[val]
        )
        expected = evaluate_recordings(
            y[val], prediction, groups=groups.iloc[val], sampling_period=PERIOD
        )
        screened = fast.results_[fast.results_["subset"] == subset]
        assert screened["screened"].all()
        merged = screened.merge(expected, on="recording", suffixes=("", "_r"))
        assert len(merged) == len(expected)
        np.testing.assert_allclose(merged["accuracy"], merged["accuracy_r"], rtol=1e-8)
        np.testing.assert_allclose(merged["smoothness"], merged["smoothness_r"], rtol=1e-8)


@pytest.mark.parametrize("iterations", [0, 3])
def test_with_one_state_a_screened_subset_is_the_full_search_fit(searched, monkeypatch, iterations):
    # one state: the joint Gaussian's marginal is the maximum-likelihood Gaussian of the
    # subset's columns and the target, the optimum EM reaches from any start and never leaves
    X, y, groups, cv = searched
    monkeypatch.setattr(_screening, "EXHAUSTIVE_ITERATIONS", iterations)
    estimator = HMMGMRRegressor(n_states=1, random_state=0)
    kwargs = dict(cv=cv, sampling_period=PERIOD)
    full = ExhaustiveFeatureSelector(estimator, search="full", **kwargs).fit(X, y, groups=groups)
    fast = ExhaustiveFeatureSelector(estimator, search="fast", **kwargs).fit(X, y, groups=groups)
    merged = fast.results_.merge(full.results_, on=["subset", "recording"], suffixes=("", "_f"))
    assert len(merged) == len(full.results_) and merged["screened"].sum() > 0
    np.testing.assert_allclose(merged["accuracy"], merged["accuracy_f"], rtol=1e-9)
    np.testing.assert_allclose(merged["smoothness"], merged["smoothness_f"], rtol=1e-9)
    assert fast.subset_ == full.subset_


def test_the_framework_forward_step_reads_no_screen_of_other_iterations(monkeypatch):
    # with the exhaustive wrapper's subsets screened with another number of EM iterations
    # than the forward wrapper's, the forward step of the framework reads none of the
    # exhaustive step's screens: it is the forward wrapper fitted alone
    monkeypatch.setattr(_screening, "SUBSET_ITERATIONS", _screening.EXHAUSTIVE_ITERATIONS + 1)
    protocol = make_protocol(n_recordings=(4, 3, 2), length=150, n_features=4, seed=1)
    report = select_parameters(protocol, k_max=2, progress=False, search="fast")
    searched = protocol[protocol["split"] != "test"].reset_index(drop=True)
    alone = clone(report.sources["forward"]).fit(
        searched[FEATURES], searched["driver_torque"].to_numpy(), groups=searched["recording"]
    )
    columns = ["subset", "recording", "accuracy", "smoothness", "screened"]
    ordered = [
        t.sort_values(["subset", "recording"])[columns].reset_index(drop=True)
        for t in (report.sources["forward"].results_, alone.results_)
    ]
    pd.testing.assert_frame_equal(ordered[0], ordered[1])
