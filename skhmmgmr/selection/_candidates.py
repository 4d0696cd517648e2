"""Feature relevance and the candidate subsets built from it (thesis Section IV-C, Table A.2).

Re-exported by :mod:`skhmmgmr.selection`, where they are documented.
"""

import warnings
from collections import Counter
from collections.abc import Mapping
from numbers import Real

import numpy as np
import pandas as pd

from .._core._compat import HasMethods, Interval, StrOptions, validate_params
from .._core._docstrings import fill_shared_parameters
from ..metrics._scores import trade_offs as all_trade_offs
from ..metrics._table import TRADE_OFFS
from ._search._evaluation import check_recording_splits, evaluate_models
from ._search._score_tables import best_per_recording, labels_of, rescore_table
from ._search.base import default_estimator, input_feature_names, search_constraints

# Share of the recordings a feature must reach; Liberal: counted at least once.
STRATEGIES = {"Strict": 0.66, "Mild": 0.33, "Liberal": None}
SHARE = [Interval(Real, 0, 1, closed="right")]
# Name of the candidates built from all sources together, and the rules that form them.
COMBINED = "combined"
COMBINED_RULE = [StrOptions({"union", "sum"})]
# One trade-off: "50/50" or a pair of weights.
TRADE_OFF = [str, tuple]


@validate_params(
    {
        "results": [HasMethods(["best_subsets"]), pd.DataFrame],
        "trade_offs": [*TRADE_OFFS, None],
        "features": ["array-like", None],
    },
    prefer_skip_nested_validation=True,
)
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
            features = list(input_feature_names(results))
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


@validate_params(
    {
        "relevance": [Mapping],
        "trade_off": TRADE_OFF,
        "strict": SHARE,
        "mild": SHARE,
        "combined_rule": COMBINED_RULE,
    },
    prefer_skip_nested_validation=True,
)
def candidate_subsets(
    relevance, trade_off="50/50", *, strict=0.66, mild=0.33, combined_rule="union"
):
    """The thesis' candidate subsets from the relevance of every source (Table A.2).

    Strict keeps the features counted in at least ``strict`` of the recordings, Mild in at
    least ``mild``, Liberal at least once; each from the relevance of every source, numbered
    in the mapping's order (the thesis: exhaustive 1, forward 2). The combined subset of a
    strategy (numbered last, 3 in the thesis) is, as in the thesis' Table A.2, the union of
    the sources' subsets (``combined_rule="union"``).

    Parameters
    ----------
    relevance : mapping of str to pandas.DataFrame
        Source name -> output of :func:`feature_relevance` (``attrs["n_recordings"]`` set).
    trade_off : str, default="50/50"
        Column of the relevance tables used.
    strict, mild : float, default=0.66, 0.33
        Shares of the recordings (in (0, 1]) a feature must reach for Strict and Mild.
    combined_rule : {"union", "sum"}, default="union"
        How the combined subsets are formed. ``"union"``: the union of the sources' subsets of
        the same strategy (the thesis' Table A.2). ``"sum"``: the counts of all sources are
        added and thresholded as a share of all recordings they counted (the default of
        earlier skhmmgmr versions); with the thesis' counts it gives an empty Strict 3.

    Returns
    -------
    candidates : pandas.DataFrame
        Columns ``name`` ("Strict 1" ...), ``strategy``, ``source``, ``features`` (tuple in
        the order of the relevance rows), ``n_features`` and ``empty`` (True when no feature
        reaches the threshold; such a candidate is kept in the table, and
        :func:`compare_subsets` warns when it leaves it out).

    Examples
    --------
    >>> import pandas as pd
    >>> from skhmmgmr.selection import candidate_subsets
    >>> one = pd.DataFrame({"50/50": [4, 1, 0]}, index=["swa", "yaw_rate", "e_psi30"])
    >>> two = pd.DataFrame({"50/50": [0, 1, 4]}, index=["swa", "yaw_rate", "e_psi30"])
    >>> one.attrs["n_recordings"] = two.attrs["n_recordings"] = 4
    >>> candidates = candidate_subsets({"exhaustive": one, "forward": two})
    >>> candidates.set_index("name").loc[["Strict 1", "Strict 2", "Strict 3"], "features"].tolist()
    [('swa',), ('e_psi30',), ('swa', 'e_psi30')]
    """
    if not relevance:
        raise ValueError("relevance must be a non-empty mapping source name -> relevance table")
    label = labels_of(trade_off)[0]
    features = list(dict.fromkeys(f for table in relevance.values() for f in table.index))
    counts = {
        name: table[label].reindex(features, fill_value=0) for name, table in relevance.items()
    }
    n_recordings = {name: table.attrs["n_recordings"] for name, table in relevance.items()}
    shares = {**STRATEGIES, "Strict": strict, "Mild": mild}

    def chosen(counts, n_recordings, share):
        threshold = 1 if share is None else max(share * n_recordings, 1)
        return tuple(f for f in features if counts[f] >= threshold)

    rows = []
    sources = [*relevance, COMBINED]
    for number, source in enumerate(sources, start=1):
        for strategy, share in shares.items():
            if source != COMBINED:
                subset = chosen(counts[source], n_recordings[source], share)
            elif combined_rule == "union":
                union = {
                    f for name in relevance for f in chosen(counts[name], n_recordings[name], share)
                }
                subset = tuple(f for f in features if f in union)
            else:
                subset = chosen(sum(counts.values()), sum(n_recordings.values()), share)
            rows.append(
                {
                    "name": f"{strategy} {number}",
                    "strategy": strategy,
                    "source": source,
                    "features": subset,
                    "n_features": len(subset),
                    "empty": not subset,
                }
            )
    return pd.DataFrame(rows)


@validate_params(
    {
        "X": [pd.DataFrame],
        "y": ["array-like"],
        "groups": ["array-like"],
        "subsets": [Mapping],
        "trade_off": TRADE_OFF,
    }
    | search_constraints("cv", "estimator", "sampling_period", "n_jobs", "memory", "verbose"),
    prefer_skip_nested_validation=False,  # the estimator's own parameters are checked in fit
)
@fill_shared_parameters
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
    distinct subsets), then reported under every name. Empty subsets are left out with a
    ``UserWarning`` naming them.

    Parameters
    ----------
    X : pandas.DataFrame of shape (n_samples, n_features)
        Candidate features with their names as columns.
    y : array-like of shape (n_samples,)
        Target (driver torque).
    groups : array-like of shape (n_samples,)
        Recording id of every row (required: the comparison validates whole recordings).
    subsets : dict
        Name -> tuple of feature names; at least one must be non-empty.
    {cv}
    trade_off : str, default="50/50"
        Trade-off "accuracy/smoothness" in percent of the normalised performance score.
    {estimator}
    {sampling_period}
        Required: the comparison scores the smoothness.
    {n_jobs}
    {memory}
    {verbose}

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
    empty = [name for name, subset in subsets.items() if not len(subset)]
    if len(empty) == len(subsets):
        raise ValueError("every subset is empty: nothing to compare")
    if empty:
        warnings.warn(
            f"empty subset(s) {', '.join(map(str, empty))} left out of the comparison: no "
            "feature to fit (for a candidate subset: no feature reached its threshold)",
            UserWarning,
            stacklevel=2,
        )
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
