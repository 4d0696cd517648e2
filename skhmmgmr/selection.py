"""The thesis' parameter selection framework (Section IV, Appendix D) in one call.

:func:`select_parameters` runs, on data split into training, validation and test recordings:

1. the Spearman filter on the training recordings (top ``n_top`` features);
2. the exhaustive wrapper on those features and the forward wrapper on all candidates (one path
   per validation recording and trade-off), models with K=2;
3. feature relevance: counts of each feature in the per-recording best subsets for every
   trade-off (:func:`feature_relevance`, Fig. 4 / Table A.2);
4. candidate subsets Strict / Mild / Liberal from the exhaustive (1), forward (2) and combined (3)
   counts (:func:`candidate_subsets`), compared with K=2 on the validation recordings
   (:func:`compare_subsets`); the lowest mean performance score wins;
5. state selection for that subset (:class:`~skhmmgmr.state_selection.StateSelector`);
6. the final model and the all-feature baseline (same K) on the test recordings.

One-way ANOVAs (:func:`one_way_anova`) check whether the metric differences across trade-offs
and strategies are significant, as in Appendix E.
"""

import time
from collections import Counter
from dataclasses import dataclass, field

import numpy as np
import pandas as pd
from sklearn.base import clone
from sklearn.model_selection import PredefinedSplit
from threadpoolctl import threadpool_limits

from ._search import (
    best_per_recording,
    check_recording_splits,
    default_estimator,
    evaluate_models,
    labels_of,
    one_way_anova,
    rescore_table,
    sampling_period_of,
    shared_evaluations,
    split_recordings_table,
)
from .datasets._schema import TARGET
from .feature_selection import ExhaustiveFeatureSelector, ForwardFeatureSelector, SpearmanSelector
from .metrics import evaluate_recordings, normalize_performance
from .metrics import trade_offs as all_trade_offs
from .state_selection import StateSelector

__all__ = [
    "SelectionReport",
    "candidate_subsets",
    "compare_subsets",
    "feature_relevance",
    "one_way_anova",
    "select_parameters",
]

STRATEGIES = {"Strict": 0.66, "Mild": 0.33, "Liberal": None}
SOURCES = {1: "exhaustive", 2: "forward", 3: "combined"}


def feature_relevance(results, trade_offs=None, *, features=None):
    """Count every feature in the per-recording best subsets, for every trade-off.

    For each trade-off and each validation recording the best subset (lowest performance
    score) is taken and its features are counted: the thesis' feature relevance (Fig. 4,
    Table A.2). The largest possible count is the number of validation recordings.

    Parameters
    ----------
    results : fitted selector or pandas.DataFrame
        A fitted :class:`~skhmmgmr.feature_selection.ExhaustiveFeatureSelector` or
        :class:`~skhmmgmr.feature_selection.ForwardFeatureSelector` (its per-recording paths),
        an exhaustive ``results_`` table (re-scored here), or a table of best subsets with
        columns ``trade_off``, ``recording`` and ``subset``.
    trade_offs : list of str, default=None
        Trade-offs; ``None`` means "100/0" to "0/100" in steps of 10%.
    features : list of str, default=None
        Row order (and features with zero count); default: the selector's features or the
        features met in the subsets.

    Returns
    -------
    relevance : pandas.DataFrame
        Counts, one row per feature and one column per trade-off;
        ``relevance.attrs["n_recordings"]`` holds the number of recordings counted.

    Examples
    --------
    >>> import pandas as pd
    >>> from skhmmgmr.selection import feature_relevance
    >>> best = pd.DataFrame({
    ...     "trade_off": ["50/50", "50/50"], "recording": [1, 2],
    ...     "subset": [("swa", "yaw_rate"), ("swa",)],
    ... })
    >>> feature_relevance(best, ["50/50"])
    trade_off  50/50
    swa            2
    yaw_rate       1
    """
    labels = all_trade_offs(10) if trade_offs is None else labels_of(trade_offs)
    if hasattr(results, "best_subsets"):
        best = results.best_subsets(labels)
        if features is None:
            features = list(results._names())
    elif "trade_off" in results.columns:
        best = results[results["trade_off"].isin(labels)]
    else:
        best = best_per_recording(
            rescore_table(results, "subset", labels), "subset", tie_breaker="n_features"
        )
    if features is None:
        features = list(dict.fromkeys(f for subset in best["subset"] for f in subset))
    counts = pd.DataFrame(0, index=pd.Index(features, name="feature"), columns=labels)
    for label, block in best.groupby("trade_off", sort=False):
        counted = Counter(f for subset in block["subset"] for f in subset)
        counts[label] = [counted.get(f, 0) for f in features]
    counts.columns.name = "trade_off"
    counts.index.name = None
    counts.attrs["n_recordings"] = int(best.groupby("trade_off")["recording"].nunique().max())
    return counts


def candidate_subsets(exhaustive, forward, trade_off="50/50", *, strict=0.66, mild=0.33):
    """The thesis' nine candidate subsets from the relevance of both wrappers (Table A.2).

    Strict keeps the features counted in at least ``strict`` of the recordings, Mild in at
    least ``mild``, Liberal at least once; each from the exhaustive (1), forward (2) and
    combined (3, counts added, shares of the summed recordings) relevance.

    Parameters
    ----------
    exhaustive, forward : pandas.DataFrame
        Outputs of :func:`feature_relevance` (``attrs["n_recordings"]`` set).
    trade_off : str, default="50/50"
    strict, mild : float, default=0.66, 0.33

    Returns
    -------
    candidates : pandas.DataFrame
        Columns ``name`` ("Strict 1" ...), ``strategy``, ``source``, ``features`` (tuple,
        maybe empty), ``n_features``.
    """
    label = labels_of(trade_off)[0]
    features = list(dict.fromkeys([*exhaustive.index, *forward.index]))
    one = exhaustive[label].reindex(features, fill_value=0)
    two = forward[label].reindex(features, fill_value=0)
    n_one, n_two = exhaustive.attrs["n_recordings"], forward.attrs["n_recordings"]
    sources = {1: (one, n_one), 2: (two, n_two), 3: (one + two, n_one + n_two)}
    rows = []
    for number, (counts, n_recordings) in sources.items():
        for strategy, share in {**STRATEGIES, "Strict": strict, "Mild": mild}.items():
            threshold = 1 if share is None else share * n_recordings
            chosen = tuple(f for f in features if counts[f] >= max(threshold, 1))
            rows.append(
                {
                    "name": f"{strategy} {number}",
                    "strategy": strategy,
                    "source": SOURCES[number],
                    "features": chosen,
                    "n_features": len(chosen),
                }
            )
    return pd.DataFrame(rows)


def compare_subsets(
    X,
    y,
    groups,
    subsets,
    *,
    cv,
    trade_off="50/50",
    estimator=None,
    sampling_period=None,
    n_jobs=None,
    memory=None,
    verbose=0,
):
    """Fit one model per named feature subset and compare them on the validation recordings.

    Equal subsets are fitted once and compared as one model (D.5 normalisation over the
    distinct subsets), then reported under every name; empty subsets are left out.

    Parameters
    ----------
    X : pandas.DataFrame of shape (n_samples, n_features)
        Candidate features with their names as columns.
    y, groups : array-like of shape (n_samples,)
    subsets : dict
        Name -> tuple of feature names.
    cv : splitter
        Training/validation split(s), as in the selectors.
    trade_off : str, default="50/50"
    estimator, sampling_period, n_jobs, memory, verbose
        As in the selectors.

    Returns
    -------
    scores : pandas.DataFrame
        One row per (name, recording) with metrics and normalised ``performance_score``.
    summary : pandas.DataFrame
        One row per name: mean ``accuracy``, ``smoothness``, ``performance_score`` and
        ``rank`` (1 = best; ties to fewer features).
    """
    names = list(X.columns)
    values = X.to_numpy(dtype=float)
    y, groups = np.asarray(y, dtype=float), np.asarray(groups)
    splits = check_recording_splits(cv, values, y, groups)
    distinct = list(dict.fromkeys(tuple(s) for s in subsets.values() if len(s)))
    table = evaluate_models(
        default_estimator() if estimator is None else estimator,
        values,
        y,
        groups,
        splits,
        [(tuple(names.index(f) for f in subset), {}) for subset in distinct],
        sampling_period=sampling_period,
        n_jobs=n_jobs,
        memory=memory,
        verbose=verbose,
        desc="candidate subsets",
    )
    table.insert(1, "subset", [distinct[i] for i in table["model"]])
    table.insert(2, "n_features", table["subset"].map(len))
    scored = rescore_table(table.drop(columns="model"), "subset", trade_off)
    frames = [
        scored[scored["subset"] == tuple(subset)].assign(name=name)
        for name, subset in subsets.items()
        if len(subset)
    ]
    scores = pd.concat(frames, ignore_index=True)
    summary = scores.groupby(["name", "n_features"], sort=False, as_index=False).agg(
        accuracy=("accuracy", "mean"),
        smoothness=("smoothness", "mean"),
        performance_score=("performance_score", "mean"),
    )
    order = summary.sort_values(["performance_score", "n_features"], kind="stable").index
    summary.loc[order, "rank"] = np.arange(1, len(order) + 1)
    summary["rank"] = summary["rank"].astype(int)
    return scores, summary


@dataclass
class SelectionReport:
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
    exhaustive : DataFrame
        Exhaustive wrapper results (subset x validation recording).
    forward_paths : DataFrame
        Every step of every forward path (per validation recording and trade-off).
    relevance : DataFrame
        Feature counts, rows (source, feature), one column per trade-off.
    candidates : DataFrame
        The candidate subsets with their mean validation metrics, score and rank, plus the
        baseline (all candidates).
    candidate_scores : DataFrame
        Per-recording scores of the candidates.
    states : DataFrame
        Per (K, validation recording) metrics, BIC and score at the trade-off.
    state_choices : DataFrame
        K chosen by both methods for every trade-off.
    bic : DataFrame
        BIC of every K on the training recordings.
    anova : DataFrame
        One-way ANOVAs: relevance across trade-offs, strategies, states across trade-offs.
    test : DataFrame
        Final and baseline model on every test recording (metrics and normalised score).
    test_summary : DataFrame
        Mean test metrics per model.
    final_model, baseline_model : estimator
        Fitted on the training recordings.
    timings : dict
        Wall time of every stage, seconds.
    """

    features: tuple
    n_states: int
    trade_off: str
    filter: pd.DataFrame
    exhaustive: pd.DataFrame
    forward_paths: pd.DataFrame
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
    timings: dict = field(default_factory=dict)

    def summary(self):
        """A short text summary."""
        lines = [
            f"feature subset: {', '.join(self.features)}",
            f"number of states: {self.n_states} (trade-off {self.trade_off})",
            "test set:",
            self.test_summary.to_string(index=False),
        ]
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
    tol=0.01,
    sampling_period=None,
    estimator=None,
    n_jobs=None,
    memory=None,
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
    tol : float, default=0.01
        The 1% rule of the forward selection and the state selection.
    sampling_period : float, default=None
        Seconds between rows; default: the median time step of the ``time`` column.
    estimator : HMMGMRRegressor, default=None
        Model template; default ``HMMGMRRegressor(random_state=random_state)``.
    n_jobs : int, default=None
        Parallel fits (joblib; a surrounding ``joblib.parallel_backend("dask")`` runs them on a
        dask cluster).
    memory : str or joblib.Memory, default=None
        Cache of every fit and evaluation: rerunning resumes where it stopped.
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
    w1, w2 = (float(w) / 100 for w in label.split("/"))
    train = split == "train"
    search = train | (split == "validation")
    X_s, y_s, g_s = X[search].reset_index(drop=True), y[search], groups[search]
    cv = PredefinedSplit(np.where(split[search] == "validation", 0, -1))
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
    with shared_evaluations():
        exhaustive = ExhaustiveFeatureSelector(estimator, max_features=max_subset_size, **common)
        exhaustive.fit(X_s[[c for c in X.columns if c in top]], y_s, g_s)
        lap("exhaustive")
        forward = ForwardFeatureSelector(
            estimator, mode="per_recording", tol=tol, trade_offs=labels, **common
        )
        forward.fit(X_s, y_s, g_s)
        lap("forward")

    relevance_one = feature_relevance(exhaustive, labels, features=list(X.columns))
    relevance_two = feature_relevance(forward, labels, features=list(X.columns))
    relevance = pd.concat(
        {
            "exhaustive": relevance_one,
            "forward": relevance_two,
            "combined": relevance_one + relevance_two,
        },
        names=["source", "feature"],
    )
    candidates = candidate_subsets(relevance_one, relevance_two, label, strict=0.66, mild=0.33)
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
    baseline.update(features=tuple(X.columns), n_features=X.shape[1])
    candidate_summary = pd.concat([candidates, pd.DataFrame([baseline])], ignore_index=True).merge(
        candidate_summary.drop(columns="n_features"), on="name", how="left"
    )
    # the baseline is compared (and ranked) but not a candidate
    eligible = candidate_summary[candidate_summary["performance_score"].notna()].iloc[:-1]
    chosen = eligible.sort_values(["performance_score", "n_features"], kind="stable").iloc[0]
    features = tuple(chosen["features"])
    lap("relevance and candidates")

    states = StateSelector(estimator, k_max=k_max, tol=tol, refit=False, **common)
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

    best_exhaustive = exhaustive.best_subsets(labels)
    per_k = states.rescore(labels)
    picked = per_k.merge(state_choices[["trade_off", "n_states"]], on=["trade_off", "n_states"])
    anova = pd.concat(
        [
            one_way_anova(
                best_exhaustive, by="trade_off", values=["accuracy", "smoothness"]
            ).assign(analysis="feature relevance (best subsets across trade-offs)"),
            one_way_anova(candidate_scores, by="name", values="performance_score").assign(
                analysis="candidate subsets (across strategies)"
            ),
            one_way_anova(picked, by="trade_off", values=["accuracy", "smoothness"]).assign(
                analysis="state selection (chosen K across trade-offs)"
            ),
        ],
        ignore_index=True,
    )
    return SelectionReport(
        features=features,
        n_states=n_states,
        trade_off=label,
        filter=filter_table,
        exhaustive=exhaustive.results_,
        forward_paths=forward.paths_,
        relevance=relevance,
        candidates=candidate_summary,
        candidate_scores=candidate_scores,
        states=state_scores,
        state_choices=state_choices,
        bic=states.bic_,
        anova=anova[["analysis", "metric", "F", "pvalue", "n_groups"]],
        test=test_table,
        test_summary=test_summary,
        final_model=final,
        baseline_model=baseline,
        timings=timings,
    )
