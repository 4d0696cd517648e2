"""The thesis' parameter selection framework (Section IV, Appendix D) in one call.

:func:`select_parameters` runs, on data split into training, validation and test recordings:

1. the Spearman filter on the training recordings (top ``n_top`` features);
2. the exhaustive wrapper on those features and the forward wrapper on all candidates (one path
   per validation recording and trade-off), models with K=2;
3. feature relevance: counts of each feature in the per-recording best subsets for every
   trade-off (:func:`feature_relevance`, Fig. 4 / Table A.2);
4. candidate subsets Strict / Mild / Liberal from the exhaustive (1) and forward (2) counts,
   and their unions (3) (:func:`candidate_subsets`), compared with K=2 on the validation
   recordings (:func:`compare_subsets`); the lowest mean performance score wins;
5. state selection for that subset (:class:`~skhmmgmr.StateSelector`);
6. the final model and the all-feature baseline (same K) on the test recordings.

One-way ANOVAs (:func:`one_way_anova`) check whether the metric differences across trade-offs
and strategies are significant, in the scope of Appendix E.1.2-E.1.4 (see
:func:`select_parameters`).
"""

import time
from collections.abc import Mapping
from dataclasses import dataclass, field
from numbers import Integral, Real

import numpy as np
import pandas as pd
from sklearn.base import clone
from sklearn.model_selection import PredefinedSplit
from threadpoolctl import threadpool_limits

from .._core._compat import FiniteInterval, Interval, validate_params
from .._core._docstrings import fill_shared_parameters
from .._core._pickled import PickleVersionMixin
from .._core._schema import TARGET
from ..metrics._scores import evaluate_recordings, normalize_performance
from ..metrics._scores import trade_offs as all_trade_offs
from ..metrics._table import TRADE_OFFS
from ._anova import N_STRATEGIES, check_anova_scope, framework_anova
from ._candidates import COMBINED, COMBINED_RULE, TRADE_OFF, candidate_subsets, compare_subsets
from ._framework_data import sampling_period_of, split_recordings_table
from ._search._evaluation import shared_evaluations
from ._search._score_tables import labels_of
from ._search.base import default_estimator, search_constraints
from ._selectors._spearman import SpearmanSelector
from ._selectors._states import K_RANGE, TOL, StateSelector
from ._sources import (
    check_sources,
    fit_source,
    source_relevance,
    source_tables,
    thesis_sources,
)


@dataclass
class SelectionReport(PickleVersionMixin):
    """Everything :func:`select_parameters` found; every table is a pandas DataFrame.

    Attributes
    ----------
    features : tuple of str
        Selected feature subset.
    n_states : int
        Selected number of states K.
    trade_off : str
        Trade-off used for the choices.
    filter : DataFrame
        Spearman filter on the training recordings: ``feature``, ``spearman``, ``pvalue``,
        ``rank``, ``selected``.
    relevance : DataFrame
        Feature counts, rows (source, feature), one column per trade-off: one block per
        relevance source and a "combined" block, the sum of their counts (the combined
        candidates are unions of subsets unless ``combined_rule="sum"``).
    candidates : DataFrame
        The candidate subsets with their mean validation metrics, score and rank, plus the
        baseline (all candidates); an empty candidate stays in the table with ``empty`` True
        and no score.
    candidate_scores : DataFrame
        Per-recording scores of the candidates.
    states : DataFrame
        Per (K, validation recording) metrics, BIC and score at the trade-off.
    state_choices : DataFrame
        K chosen by both methods for every trade-off.
    bic : DataFrame
        BIC of every K on the training recordings.
    anova : DataFrame
        One-way ANOVAs in the thesis' scope (Appendix E.1.2-E.1.4): relevance across
        trade-offs, the best-ranked strategies, the chosen K across trade-offs; ``groups``
        lists the groups entered.
    test : DataFrame
        Final and baseline model on every test recording (metrics and normalised score).
    test_summary : DataFrame
        Mean test metrics per model.
    final_model, baseline_model : estimator
        Fitted on the training recordings.
    sources : dict
        Relevance source name -> fitted selector.
    timings : dict
        Wall time of every stage, seconds.
    """

    features: tuple
    n_states: int
    trade_off: str
    filter: pd.DataFrame
    relevance: pd.DataFrame
    candidates: pd.DataFrame
    candidate_scores: pd.DataFrame
    states: pd.DataFrame
    state_choices: pd.DataFrame
    bic: pd.DataFrame
    anova: pd.DataFrame
    test: pd.DataFrame
    test_summary: pd.DataFrame
    final_model: object = field(repr=False)
    baseline_model: object = field(repr=False)
    sources: dict = field(default_factory=dict, repr=False)
    timings: dict = field(default_factory=dict)

    @property
    def source_tables(self):
        """Tables of every source: ``<name>_results`` and ``<name>_paths`` when the selector
        has ``results_`` / ``paths_`` (the package's wrappers), else ``<name>_selected``."""
        tables = {}
        for name, selector in self.sources.items():
            tables.update(source_tables(name, selector))
        return tables

    @property
    def exhaustive(self):
        """Results of the ``"exhaustive"`` source (subset x validation recording), if any."""
        return self.source_tables.get("exhaustive_results")

    @property
    def forward_paths(self):
        """Every step of every path of the ``"forward"`` source, if any."""
        return self.source_tables.get("forward_paths")

    @property
    def empty_candidates(self):
        """Names of the candidate subsets that came out empty (not compared)."""
        if "empty" not in self.candidates:
            return []
        return list(self.candidates.loc[self.candidates["empty"].astype(bool), "name"])

    def summary(self):
        """A short text summary."""
        lines = [
            f"feature subset: {', '.join(self.features)}",
            f"number of states: {self.n_states} (trade-off {self.trade_off})",
        ]
        if self.empty_candidates:
            names = ", ".join(self.empty_candidates)
            lines.append(f"empty candidate subsets (not compared): {names}")
        lines += ["test set:", self.test_summary.to_string(index=False)]
        return "\n".join(lines)

    def __repr__(self):
        return (
            f"SelectionReport(features={self.features!r}, n_states={self.n_states}, "
            f"trade_off={self.trade_off!r})"
        )


def _fit_on(estimator, X, y, groups, rows, features, n_states):
    model = clone(estimator).set_params(n_states=n_states)
    with threadpool_limits(limits=1):  # see evaluate_models
        return model.fit(X.loc[rows, list(features)].to_numpy(), y[rows], groups=groups[rows])


@validate_params(
    {
        "data": [pd.DataFrame, tuple],
        "split": ["array-like", dict, None],
        "candidate_features": ["array-like", None],
        "target": [str],
        "n_top": [Interval(Integral, 1, None, closed="left")],
        "max_subset_size": [Interval(Integral, 1, None, closed="left"), None],
        "k_max": K_RANGE["k_max"],
        "trade_off": TRADE_OFF,
        "relevance_trade_offs": [*TRADE_OFFS, None],
        "combined_rule": COMBINED_RULE,
        "relevance_sources": [Mapping, None],
        "anova_trade_offs": [*TRADE_OFFS, None],
        "anova_n_strategies": [Interval(Integral, 2, None, closed="left"), None],
        "tol": TOL,
        "screening_tol": [FiniteInterval(Real, 0, None, closed="neither"), None],
        "progress": ["boolean"],
        "random_state": ["random_state"],
    }
    | search_constraints("sampling_period", "estimator", "n_jobs", "memory", "search"),
    prefer_skip_nested_validation=False,  # the estimator's own parameters are checked in fit
)
@fill_shared_parameters
def select_parameters(
    data,
    *,
    split=None,
    candidate_features=None,
    target=TARGET,
    n_top=10,
    max_subset_size=None,
    k_max=20,
    trade_off="50/50",
    relevance_trade_offs=None,
    combined_rule="union",
    relevance_sources=None,
    anova_trade_offs=None,
    anova_n_strategies=N_STRATEGIES,
    tol=0.01,
    screening_tol=None,
    sampling_period=None,
    estimator=None,
    n_jobs=None,
    memory=None,
    search="full",
    progress=True,
    random_state=0,
):
    """Run the thesis' whole parameter selection framework and test the result.

    Parameters
    ----------
    data : pandas.DataFrame or tuple (X, y, groups)
        A tidy table with columns ``recording``, ``split`` ("train", "validation", "test"),
        the candidate features and the target (the layout of :mod:`skhmmgmr.datasets`), or
        arrays with ``split`` given separately.
    split : array-like or dict, default=None
        Split of every row, or recording id -> split; default: the ``split`` column.
    candidate_features : list of str, default=None
        Default: the thesis' 18 features present in ``data``, else every numeric non-meta
        column.
    target : str, default="driver_torque"
    n_top : int, default=10
        Features kept by the filter for the exhaustive wrapper.
    max_subset_size : int, default=None
        Largest subset of the exhaustive wrapper.
    k_max : int, default=20
        Largest number of states tried.
    trade_off : str, default="50/50"
        Accuracy/smoothness trade-off of every choice.
    relevance_trade_offs : list of str, default=None
        Trade-offs mapped by the relevance (default "100/0" ... "0/100"); the forward paths are
        traced for each of them.
    combined_rule : {"union", "sum"}, default="union"
        How the combined candidates (Strict / Mild / Liberal 3) are formed; see
        :func:`candidate_subsets`. ``"union"`` is the thesis' Table A.2.
    relevance_sources : mapping of str to selector or RelevanceSource, default=None
        The selectors whose choices are counted per feature, by name, in the order their
        candidates are numbered. ``None`` means the thesis' two: ``"exhaustive"``
        (:class:`~skhmmgmr.feature_selection.ExhaustiveFeatureSelector` on the filter's top
        features, subsets up to ``max_subset_size``) and ``"forward"``
        (:class:`~skhmmgmr.feature_selection.ForwardFeatureSelector`, one path per validation
        recording and trade-off, on all candidates). Each is fitted on the training and
        validation recordings and receives the framework's parameters it has (``cv``,
        ``accuracy_weight``, ``smoothness_weight``, ``sampling_period``, ``n_jobs``,
        ``memory``, ``verbose``, ``trade_offs``, ``search``); see :class:`RelevanceSource`.
    anova_trade_offs : list of str, default=None
        Trade-offs compared by the ANOVA of the feature relevance (accuracy and smoothness of
        the best exhaustive subsets) and by the accuracy ANOVA of the state selection; each
        must be among the mapped trade-offs. ``None`` means the mapped trade-offs from "100/0"
        to "40/60" (accuracy weight at least 40%), the range of Appendix E.1.2 and E.1.4. The
        smoothness ANOVA of the state selection compares every mapped trade-off (E.1.4).
    anova_n_strategies : int or None, default=7
        Number of candidate strategies compared by the strategy ANOVA: the best-ranked
        distinct subsets (mean performance score, as the thesis' Figure E.5 sorts them; a
        subset met under several names enters once, under its first name; the baseline is no
        strategy). ``7`` is the "first seven strategies" of Appendix E.1.3; ``None``: all.
    tol : float, default=0.01
        The 1% rule of the forward selection and the state selection.
    screening_tol : float or None, default=None
        EM convergence tolerance (the estimator's ``tol``) of the models that only screen
        features: the exhaustive and forward wrappers of the default relevance sources. The
        candidate comparison, the state sweep and the final and baseline models keep the
        estimator's own tolerance. ``None``: the estimator's tolerance everywhere. A looser
        screening tolerance (e.g. ``1e-3`` against the default ``1e-4``) stops the thousands
        of screening fits earlier; see the performance page for the time it saves and the
        selections it keeps. Ignored when ``relevance_sources`` is given (their selectors
        carry their own estimators).
    {sampling_period}
        ``None``: the median time step of the ``time`` column.
    estimator : HMMGMRRegressor, default=None
        Model template; default ``HMMGMRRegressor(random_state=random_state)``.
    {n_jobs}
    {memory}
    {search}
        Here: the search of the exhaustive and forward wrappers (the default relevance sources,
        and any of the package's wrappers given as one) and of the state sweep. The
        candidate comparison and the final and baseline models are fitted in full either way.
    progress : bool, default=True
        Show progress bars.
    random_state : int, default=0
        Seed of the default estimator.

    Returns
    -------
    report : SelectionReport
    """
    if estimator is None:
        estimator = default_estimator().set_params(random_state=random_state)
    estimator = clone(estimator).set_params(n_states=2)
    period = sampling_period_of(data, sampling_period)
    X, y, groups, split = split_recordings_table(data, split, candidate_features, target)
    labels = all_trade_offs(10) if relevance_trade_offs is None else labels_of(relevance_trade_offs)
    label = labels_of(trade_off)[0]
    if label not in labels:
        labels = [*labels, label]
    anova_labels = check_anova_scope(anova_trade_offs, labels)
    if relevance_sources is None:
        screening = estimator
        if screening_tol is not None:
            screening = clone(estimator).set_params(tol=float(screening_tol))
        relevance_sources = thesis_sources(screening, max_subset_size=max_subset_size, tol=tol)
    sources = check_sources(relevance_sources)
    w1, w2 = (float(w) / 100 for w in label.split("/"))
    train = split == "train"
    searched = train | (split == "validation")
    X_s, y_s, g_s = X[searched].reset_index(drop=True), y[searched], groups[searched]
    cv = PredefinedSplit(np.where(split[searched] == "validation", 0, -1))
    common = dict(
        cv=cv,
        accuracy_weight=w1,
        smoothness_weight=w2,
        sampling_period=period,
        n_jobs=n_jobs,
        memory=memory,
        verbose=int(progress),
    )
    timings, clock = {}, time.perf_counter()

    def lap(name):
        nonlocal clock
        now = time.perf_counter()
        timings[name], clock = now - clock, now

    spearman = SpearmanSelector(k=min(n_top, X.shape[1])).fit(X[train], y[train], groups[train])
    filter_table = pd.DataFrame(
        {
            "feature": list(X.columns),
            "spearman": spearman.scores_,
            "pvalue": spearman.pvalues_,
            "rank": spearman.ranking_,
            "selected": spearman.get_support(),
        }
    ).sort_values("rank", ignore_index=True)
    top = list(filter_table.loc[filter_table["selected"], "feature"])
    lap("filter")

    # The top features in table order, as the forward step orders every subset: the subsets
    # of the top features that the forward step meets are then the exhaustive step's models.
    columns = {"all": list(X.columns), "top": [c for c in X.columns if c in top]}
    shared = {**common, "trade_offs": labels, "search": search}
    fitted, relevance_by_source = {}, {}
    with shared_evaluations():
        for name, source in sources.items():
            fitted[name] = fit_source(
                source, X_s[columns[source.features]], y_s, g_s, shared=shared
            )
            relevance_by_source[name] = source_relevance(fitted[name], labels, list(X.columns))
            lap(name)
    relevance = pd.concat(
        {**relevance_by_source, COMBINED: sum(relevance_by_source.values())},
        names=["source", "feature"],
    )
    candidates = candidate_subsets(
        relevance_by_source, label, strict=0.66, mild=0.33, combined_rule=combined_rule
    )
    named = dict(zip(candidates["name"], candidates["features"], strict=True))
    named["Baseline"] = tuple(X.columns)
    candidate_scores, candidate_summary = compare_subsets(
        X_s,
        y_s,
        g_s,
        named,
        trade_off=label,
        estimator=estimator,
        **{k: v for k, v in common.items() if k not in ("accuracy_weight", "smoothness_weight")},
    )
    baseline = {"name": "Baseline", "strategy": "Baseline", "source": "all candidates"}
    baseline.update(features=tuple(X.columns), n_features=X.shape[1], empty=False)
    candidate_summary = pd.concat([candidates, pd.DataFrame([baseline])], ignore_index=True).merge(
        candidate_summary.drop(columns="n_features"), on="name", how="left"
    )
    # the baseline is compared (and ranked) but not a candidate
    eligible = candidate_summary[candidate_summary["performance_score"].notna()].iloc[:-1]
    chosen = eligible.sort_values(["performance_score", "n_features"], kind="stable").iloc[0]
    features = tuple(chosen["features"])
    lap("relevance and candidates")

    states = StateSelector(estimator, k_max=k_max, tol=tol, refit=False, search=search, **common)
    states.fit(X_s[list(features)], y_s, g_s)
    n_states = states.n_states_
    state_scores = states.rescore(label)
    state_choices = states.choices(labels)
    lap("states")

    final = _fit_on(estimator, X, y, groups, train, features, n_states)
    baseline = _fit_on(estimator, X, y, groups, train, X.columns, n_states)
    test = split == "test"
    tables = []
    for name, model, columns in (("final", final, features), ("baseline", baseline, X.columns)):
        prediction = model.predict(X.loc[test, list(columns)].to_numpy(), groups=groups[test])
        table = evaluate_recordings(
            y[test], prediction, groups=groups[test], sampling_period=period
        )
        tables.append(table.assign(model=name))
    test_table = normalize_performance(pd.concat(tables, ignore_index=True), weights=label).merge(
        pd.concat(tables, ignore_index=True), on=["model", "recording"]
    )
    test_summary = test_table.groupby("model", sort=False, as_index=False)[
        ["rmse", "accuracy", "smoothness", "performance_score"]
    ].mean()
    test_summary["n_features"] = [len(features), X.shape[1]]
    test_summary["n_states"] = n_states
    lap("test")

    # The relevance ANOVA compares the best subsets of the first source that has them per
    # recording (the thesis: the exhaustive wrapper's).
    per_recording = [sel for sel in fitted.values() if hasattr(sel, "best_subsets")]
    best_subsets = per_recording[0].best_subsets(labels) if per_recording else None
    per_k = states.rescore(labels)
    picked = per_k.merge(state_choices[["trade_off", "n_states"]], on=["trade_off", "n_states"])
    anova = framework_anova(
        best_subsets,
        candidate_scores,
        picked,
        strategies=list(candidates["name"]),
        trade_offs=anova_labels,
        all_trade_offs=labels,
        n_strategies=anova_n_strategies,
    )
    return SelectionReport(
        features=features,
        n_states=n_states,
        trade_off=label,
        filter=filter_table,
        sources=fitted,
        relevance=relevance,
        candidates=candidate_summary,
        candidate_scores=candidate_scores,
        states=state_scores,
        state_choices=state_choices,
        bic=states.bic_,
        anova=anova,
        test=test_table,
        test_summary=test_summary,
        final_model=final,
        baseline_model=baseline,
        timings=timings,
    )
