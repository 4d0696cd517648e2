"""The selection rules as the thesis states them: Table A.2 candidates, empty candidates and the
scope of the one-way ANOVAs (Appendix E.1.2-E.1.4)."""

import json
import warnings

import numpy as np
import pandas as pd
import pytest
from _protocol_data import PERIOD, make_protocol
from scipy import stats
from sklearn.model_selection import PredefinedSplit

import skhmmgmr.selection
from skhmmgmr.cli._report import report_tables, write_report
from skhmmgmr.metrics import trade_offs
from skhmmgmr.selection import candidate_subsets, compare_subsets, select_parameters
from skhmmgmr.selection._anova import accuracy_led, framework_anova

# Thesis Table A.2 ("Selection strategies"): feature relevance counts at the chosen 50/50
# trade-off over the 42 validation recordings (Table E.2 lists them), for the exhaustive
# wrapper (1) and the SFS wrapper (2). Feature names are the thesis' symbols.
THESIS_FEATURES = [
    "swa",  # steering wheel angle
    "yaw_rate",
    "rho_0",
    "e_y30",
    "e_psi10",
    "v_y",
    "e_psi30",
    "beta",
    "e_y0",
    "e_psi0",
]
EXHAUSTIVE_COUNTS = [42, 41, 24, 20, 16, 11, 4, 4, 0, 0]
SFS_COUNTS = [7, 4, 1, 21, 0, 0, 37, 1, 8, 2]
N_VALIDATION = 42

# The nine strategies of Table A.2, written out: Strict keeps counts >= 66% of 42 (28),
# Mild >= 33% (14), Liberal >= 1; every "3" row is the union of rows 1 and 2. Section VI-C
# names Strict 1 (steering wheel angle and yaw rate) and finds Strict 2 and Mild 2 inaccurate,
# i.e. without the steering wheel angle.
THESIS_CANDIDATES = {
    "Strict 1": ("swa", "yaw_rate"),
    "Mild 1": ("swa", "yaw_rate", "rho_0", "e_y30", "e_psi10"),
    "Liberal 1": ("swa", "yaw_rate", "rho_0", "e_y30", "e_psi10", "v_y", "e_psi30", "beta"),
    "Strict 2": ("e_psi30",),
    "Mild 2": ("e_y30", "e_psi30"),
    "Liberal 2": ("swa", "yaw_rate", "rho_0", "e_y30", "e_psi30", "beta", "e_y0", "e_psi0"),
    "Strict 3": ("swa", "yaw_rate", "e_psi30"),
    "Mild 3": ("swa", "yaw_rate", "rho_0", "e_y30", "e_psi10", "e_psi30"),
    "Liberal 3": tuple(THESIS_FEATURES),
}
LABELS = trade_offs(10)


def thesis_relevance():
    tables = []
    for counts in (EXHAUSTIVE_COUNTS, SFS_COUNTS):
        table = pd.DataFrame({"50/50": counts}, index=THESIS_FEATURES)
        table.attrs["n_recordings"] = N_VALIDATION
        tables.append(table)
    return tables


def as_dict(candidates):
    return dict(zip(candidates["name"], candidates["features"], strict=True))


def test_candidates_from_thesis_counts_are_table_a2():
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no candidate is empty: nothing to warn about
        candidates = candidate_subsets(
            dict(zip(("exhaustive", "forward"), thesis_relevance(), strict=True)), "50/50"
        )
    assert as_dict(candidates) == THESIS_CANDIDATES
    assert not candidates["empty"].any()
    assert list(candidates["n_features"]) == [len(f) for f in candidates["features"]]
    for strategy in ("Strict", "Mild", "Liberal"):
        union = set(THESIS_CANDIDATES[f"{strategy} 1"]) | set(THESIS_CANDIDATES[f"{strategy} 2"])
        assert set(as_dict(candidates)[f"{strategy} 3"]) == union


def test_summed_counts_rule_keeps_its_old_result():
    candidates = candidate_subsets(
        dict(zip(("exhaustive", "forward"), thesis_relevance(), strict=True)),
        "50/50",
        combined_rule="sum",
    )
    found = as_dict(candidates)
    # sources 1 and 2 do not depend on the rule
    for name in ("Strict 1", "Mild 1", "Liberal 1", "Strict 2", "Mild 2", "Liberal 2"):
        assert found[name] == THESIS_CANDIDATES[name]
    # summed counts 49, 45, 25, 41, 16, 11, 41, 5, 8, 2 of 84: none reaches 66% (55.4)
    assert found["Strict 3"] == ()
    assert found["Mild 3"] == ("swa", "yaw_rate", "e_y30", "e_psi30")
    assert found["Liberal 3"] == tuple(THESIS_FEATURES)
    assert list(candidates.loc[candidates["empty"], "name"]) == ["Strict 3"]
    assert len(candidates) == 9  # the empty candidate stays in the table


@pytest.mark.parametrize(
    "params, message",
    [
        ({"combined_rule": "intersection"}, "combined_rule"),
        ({"strict": 0.0}, "strict"),
        ({"mild": 1.5}, "mild"),
        ({"strict": True}, "strict"),
    ],
)
def test_candidate_subsets_validates_its_parameters(params, message):
    with pytest.raises(ValueError, match=message):
        candidate_subsets(
            dict(zip(("exhaustive", "forward"), thesis_relevance(), strict=True)), "50/50", **params
        )


@pytest.fixture(scope="module")
def protocol():
    return make_protocol(n_recordings=(3, 2, 1), length=120, n_features=3)


def test_compare_subsets_warns_about_empty_subsets(protocol):
    search = protocol[protocol["split"] != "test"].reset_index(drop=True)
    cv = PredefinedSplit(np.where(search["split"] == "validation", 0, -1))
    args = (search[["f0", "f1", "f2"]], search["driver_torque"], search["recording"])
    subsets = {"Strict 1": ("f0",), "Strict 3": (), "Mild 1": ("f0", "f1")}
    with pytest.warns(UserWarning, match="Strict 3"):
        scores, summary = compare_subsets(*args, subsets, cv=cv, sampling_period=PERIOD)
    assert list(summary["name"]) == ["Strict 1", "Mild 1"]
    assert set(scores["name"]) == {"Strict 1", "Mild 1"}
    with pytest.raises(ValueError, match="every subset is empty"):
        compare_subsets(*args, {"Strict 3": ()}, cv=cv, sampling_period=PERIOD)


def with_empty_candidate(monkeypatch, name="Strict 2"):
    """Make ``name`` come out empty in select_parameters, whatever the data."""
    original = skhmmgmr.selection.candidate_subsets

    def patched(*args, **kwargs):
        candidates = original(*args, **kwargs)
        row = candidates.index[candidates["name"] == name][0]
        candidates.at[row, "features"] = ()
        candidates.loc[row, ["n_features", "empty"]] = [0, True]
        return candidates

    monkeypatch.setattr(skhmmgmr.selection._framework, "candidate_subsets", patched)


def test_empty_candidate_is_warned_and_reported(protocol, monkeypatch, tmp_path):
    with_empty_candidate(monkeypatch)
    with pytest.warns(UserWarning, match="Strict 2"):
        report = select_parameters(
            protocol, k_max=2, relevance_trade_offs=["100/0", "50/50", "0/100"], progress=False
        )
    assert report.empty_candidates == ["Strict 2"]
    row = report.candidates.set_index("name").loc["Strict 2"]
    assert row["features"] == () and row["n_features"] == 0 and row["empty"]
    assert np.isnan(row["performance_score"]) and np.isnan(row["rank"])
    assert len(report.candidates) == 10  # nine candidates and the baseline
    assert "empty candidate subsets (not compared): Strict 2" in report.summary()
    assert "Strict 2" not in set(report.candidate_scores["name"])
    assert report.features != ()
    for groups in report.anova["groups"]:
        assert "Strict 2" not in groups
    tables = report_tables(report, per_driver=pd.DataFrame({"driver": ["all"]}))
    write_report(tmp_path, tables=tables, figures={}, meta={"title": "t"})
    saved = pd.read_csv(tmp_path / "candidates.csv").set_index("name")
    assert saved.loc["Strict 2", "features"] == "(empty)"
    assert bool(saved.loc["Strict 2", "empty"])
    manifest = json.loads((tmp_path / "manifest.json").read_text())
    caption = {t["name"]: t["caption"] for t in manifest["tables"]}["candidates"]
    assert "empty" in caption


def test_invalid_framework_rules_fail_before_fitting(protocol):
    with pytest.raises(ValueError, match="combined_rule"):
        select_parameters(protocol, combined_rule="both", progress=False)
    with pytest.raises(ValueError, match="35/65"):
        select_parameters(protocol, anova_trade_offs=["100/0", "35/65"], progress=False)
    with pytest.raises(ValueError, match="anova_n_strategies"):
        select_parameters(protocol, anova_n_strategies=1, progress=False)


def test_default_anova_trade_offs_are_100_0_to_40_60():
    expected = ["100/0", "90/10", "80/20", "70/30", "60/40", "50/50", "40/60"]
    assert accuracy_led(trade_offs(10)) == expected
    assert accuracy_led(trade_offs(25)) == ["100/0", "75/25", "50/50"]
    assert accuracy_led(["10/30", "40/20"]) == ["40/20"]  # shares of the summed weights


def anova_tables(seed=0):
    """Hand-made inputs of the framework's ANOVAs: 11 trade-offs, 9 strategies, 3 recordings."""
    rng = np.random.default_rng(seed)
    recordings = ["v1", "v2", "v3"]
    grid = pd.MultiIndex.from_product([LABELS, recordings], names=["trade_off", "recording"])
    best = grid.to_frame(index=False).assign(
        accuracy=rng.normal(89, 1, len(grid)), smoothness=rng.normal(3, 0.3, len(grid))
    )
    chosen = grid.to_frame(index=False).assign(
        accuracy=rng.normal(89, 1, len(grid)), smoothness=rng.normal(3, 0.3, len(grid))
    )
    # mean performance score per name; Mild 3 is Mild 1 (another feature order), the baseline
    # scores best but is no strategy, Strict 2 ranks last of the eight distinct subsets
    candidates = {
        "Strict 1": (("a", "b"), 1.0),
        "Strict 2": (("c",), 5.0),
        "Strict 3": (("a", "b", "c"), 1.2),
        "Mild 1": (("a", "b", "d"), 1.1),
        "Mild 2": (("c", "d"), 4.0),
        "Mild 3": (("d", "a", "b"), 1.1),
        "Liberal 1": (("a", "b", "c", "d", "e"), 1.3),
        "Liberal 2": (("a", "b", "c", "d", "f"), 1.5),
        "Liberal 3": (("a", "b", "c", "d", "e", "f"), 1.4),
        "Baseline": (("a", "b", "c", "d", "e", "f", "g"), 0.5),
    }
    offsets = rng.normal(0, 0.05, len(recordings))
    rows = [
        {
            "name": name,
            "subset": subset,
            "n_features": len(subset),
            "recording": rec,
            "performance_score": mean + offset,
        }
        for name, (subset, mean) in candidates.items()
        for rec, offset in zip(recordings, offsets, strict=True)
    ]
    return best, pd.DataFrame(rows), chosen, [n for n in candidates if n != "Baseline"]


def test_anova_scope_follows_appendix_e():
    best, scores, chosen, strategies = anova_tables()
    accuracy_range = ["100/0", "90/10", "80/20", "70/30", "60/40", "50/50", "40/60"]
    anova = framework_anova(
        best,
        scores,
        chosen,
        strategies=strategies,
        trade_offs=accuracy_range,
        all_trade_offs=LABELS,
    )
    rows = {
        (a.split(":")[0], m): r for (a, m), r in anova.set_index(["analysis", "metric"]).iterrows()
    }
    assert set(rows) == {
        ("feature relevance", "accuracy"),
        ("feature relevance", "smoothness"),
        ("candidate subsets", "performance_score"),
        ("state selection", "accuracy"),
        ("state selection", "smoothness"),
    }

    def expected(table, column, key, levels):
        return stats.f_oneway(*[table.loc[table[key] == lv, column] for lv in levels])

    for metric in ("accuracy", "smoothness"):
        row = rows["feature relevance", metric]
        assert row["groups"] == tuple(accuracy_range)
        assert row["F"] == pytest.approx(
            expected(best, metric, "trade_off", accuracy_range).statistic
        )
    # the seven best distinct strategies, best first: no baseline, Mild 3 (= Mild 1) once,
    # Strict 2 (the eighth) left out
    seven = ("Strict 1", "Mild 1", "Strict 3", "Liberal 1", "Liberal 3", "Liberal 2", "Mild 2")
    row = rows["candidate subsets", "performance_score"]
    assert row["groups"] == seven and row["n_groups"] == 7
    outcome = expected(scores, "performance_score", "name", seven)
    assert row["F"] == pytest.approx(outcome.statistic)
    assert row["pvalue"] == pytest.approx(outcome.pvalue)
    # state selection: accuracy over 100/0-40/60, smoothness over every trade-off
    assert rows["state selection", "accuracy"]["groups"] == tuple(accuracy_range)
    assert rows["state selection", "accuracy"]["F"] == pytest.approx(
        expected(chosen, "accuracy", "trade_off", accuracy_range).statistic
    )
    assert rows["state selection", "smoothness"]["groups"] == tuple(LABELS)
    assert rows["state selection", "smoothness"]["F"] == pytest.approx(
        expected(chosen, "smoothness", "trade_off", LABELS).statistic
    )


def test_anova_over_every_distinct_strategy():
    best, scores, chosen, strategies = anova_tables()
    anova = framework_anova(
        best,
        scores,
        chosen,
        strategies=strategies,
        trade_offs=LABELS,
        all_trade_offs=LABELS,
        n_strategies=None,
    )
    groups = anova.loc[anova["metric"] == "performance_score", "groups"].iloc[0]
    assert set(groups) == set(strategies) - {"Mild 3"}
    assert groups[-1] == "Strict 2"
