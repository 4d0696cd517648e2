"""Feature relevance and the candidate subsets built from it (thesis Section IV-C, Table A.2).

Re-exported by :mod:`skhmmgmr.selection`, where they are documented.
"""

import numbers
from collections import Counter

import pandas as pd

from ._search import best_per_recording, input_feature_names, labels_of, rescore_table
from .metrics import trade_offs as all_trade_offs

# Share of the recordings a feature must reach; Liberal: counted at least once.
STRATEGIES = {"Strict": 0.66, "Mild": 0.33, "Liberal": None}
SOURCES = {1: "exhaustive", 2: "forward", 3: "combined"}
COMBINED_RULES = ("union", "sum")


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


def _check_share(name, value):
    if not isinstance(value, numbers.Real) or isinstance(value, bool) or not 0 < value <= 1:
        raise ValueError(f"{name} must be a share of the recordings in (0, 1], got {value!r}")


def check_combined_rule(combined_rule):
    if combined_rule not in COMBINED_RULES:
        raise ValueError(f"combined_rule must be one of {COMBINED_RULES}, got {combined_rule!r}")


def candidate_subsets(
    exhaustive, forward, trade_off="50/50", *, strict=0.66, mild=0.33, combined_rule="union"
):
    """The thesis' nine candidate subsets from the relevance of both wrappers (Table A.2).

    Strict keeps the features counted in at least ``strict`` of the recordings, Mild in at
    least ``mild``, Liberal at least once; each from the exhaustive (1) and the forward (2)
    relevance. The combined (3) subset of a strategy is, as in the thesis' Table A.2, the
    union of its subsets 1 and 2 (``combined_rule="union"``).

    Parameters
    ----------
    exhaustive, forward : pandas.DataFrame
        Outputs of :func:`feature_relevance` (``attrs["n_recordings"]`` set).
    trade_off : str, default="50/50"
        Column of the relevance tables used.
    strict, mild : float, default=0.66, 0.33
        Shares of the recordings (in (0, 1]) a feature must reach for Strict and Mild.
    combined_rule : {"union", "sum"}, default="union"
        How the combined (3) subsets are formed. ``"union"``: the union of the exhaustive and
        forward subsets of the same strategy (the thesis' Table A.2). ``"sum"``: the counts of
        both wrappers are added and thresholded as a share of all recordings counted by both
        (the default of earlier skhmmgmr versions); with the thesis' counts it gives an empty
        Strict 3.

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
    >>> candidates = candidate_subsets(one, two)
    >>> candidates.set_index("name").loc[["Strict 1", "Strict 2", "Strict 3"], "features"].tolist()
    [('swa',), ('e_psi30',), ('swa', 'e_psi30')]
    """
    _check_share("strict", strict)
    _check_share("mild", mild)
    check_combined_rule(combined_rule)
    label = labels_of(trade_off)[0]
    features = list(dict.fromkeys([*exhaustive.index, *forward.index]))
    one = exhaustive[label].reindex(features, fill_value=0)
    two = forward[label].reindex(features, fill_value=0)
    n_one, n_two = exhaustive.attrs["n_recordings"], forward.attrs["n_recordings"]
    shares = {**STRATEGIES, "Strict": strict, "Mild": mild}

    def chosen(counts, n_recordings, share):
        threshold = 1 if share is None else max(share * n_recordings, 1)
        return tuple(f for f in features if counts[f] >= threshold)

    subsets = {}
    for strategy, share in shares.items():
        subsets[strategy, 1] = chosen(one, n_one, share)
        subsets[strategy, 2] = chosen(two, n_two, share)
        if combined_rule == "union":
            union = set(subsets[strategy, 1]) | set(subsets[strategy, 2])
            subsets[strategy, 3] = tuple(f for f in features if f in union)
        else:
            subsets[strategy, 3] = chosen(one + two, n_one + n_two, share)
    rows = [
        {
            "name": f"{strategy} {number}",
            "strategy": strategy,
            "source": SOURCES[number],
            "features": subsets[strategy, number],
            "n_features": len(subsets[strategy, number]),
            "empty": not subsets[strategy, number],
        }
        for number in SOURCES
        for strategy in shares
    ]
    return pd.DataFrame(rows)
