"""The framework's one-way ANOVAs in the thesis' scope (Appendix E.1.2-E.1.4).

- Feature relevance (E.1.2): accuracy and smoothness of the per-recording best exhaustive
  subsets, across the trade-offs from 100/0 to 40/60.
- Candidate subsets (E.1.3): performance score of the first seven strategies of the thesis'
  Figure E.5, which sorts them on their mean score; a subset met under several names is one
  model and enters once.
- State selection (E.1.4): accuracy of the chosen K across the trade-offs from 100/0 to 40/60,
  smoothness across every trade-off.
"""

import pandas as pd

from ..metrics._table import parse_trade_offs
from ._search._score_tables import labels_of, one_way_anova

# "100/0 to 40/60": the trade-offs giving accuracy at least this share of the weight
LOWEST_ACCURACY_SHARE = 0.4
N_STRATEGIES = 7
ANALYSES = {
    "relevance": "feature relevance: best exhaustive subsets across trade-offs (E.1.2)",
    "strategies": "candidate subsets: best-ranked distinct strategies (E.1.3)",
    "states": "state selection: chosen K across trade-offs (E.1.4)",
}


def accuracy_led(labels, lowest=LOWEST_ACCURACY_SHARE):
    """The trade-offs of ``labels`` from 100/0 down to 40/60 (accuracy share >= ``lowest``)."""
    return [
        label
        for label, w1, w2 in parse_trade_offs(labels)
        if w1 + w2 > 0 and w1 / (w1 + w2) >= lowest - 1e-9
    ]


def check_anova_scope(anova_trade_offs, labels):
    """The trade-offs the ANOVAs of :func:`~skhmmgmr.select_parameters` compare, checked to
    be among the mapped ``labels``."""
    if anova_trade_offs is None:
        chosen = accuracy_led(labels)
    else:
        chosen = labels_of(anova_trade_offs)
        missing = [label for label in chosen if label not in labels]
        if missing:
            raise ValueError(
                f"anova_trade_offs {missing} are not among the mapped trade-offs {labels}; "
                "add them to relevance_trade_offs"
            )
    return chosen


def _in_order(table, column, levels):
    """Rows of ``table`` whose ``column`` is in ``levels``, grouped in the order of ``levels``."""
    parts = [table[table[column] == level] for level in levels]
    return pd.concat(parts, ignore_index=True) if parts else table.iloc[:0]


def strategy_ranking(scores, strategies, n_strategies=N_STRATEGIES):
    """Names of the best-ranked distinct candidate subsets, best first.

    A subset met under several names is kept under its first name in ``strategies`` (the
    thesis' order). Subsets are ranked on their mean performance score over the recordings,
    ties to fewer features; the first ``n_strategies`` are returned (all when None).
    """
    first = {}
    for name in strategies:
        rows = scores[scores["name"] == name]
        if len(rows):
            first.setdefault(frozenset(rows["subset"].iloc[0]), name)
    distinct = scores[scores["name"].isin(list(first.values()))]
    means = distinct.groupby("name", sort=False).agg(
        performance_score=("performance_score", "mean"), n_features=("n_features", "first")
    )
    means = means.loc[list(first.values())]
    order = list(means.sort_values(["performance_score", "n_features"], kind="stable").index)
    return order if n_strategies is None else order[:n_strategies]


def framework_anova(
    best_subsets,
    candidate_scores,
    chosen_states,
    *,
    strategies,
    trade_offs,
    all_trade_offs,
    n_strategies=N_STRATEGIES,
):
    """The three ANOVAs of Appendix E.1 in one table.

    Parameters
    ----------
    best_subsets : pandas.DataFrame or None
        Best exhaustive subset per (``trade_off``, ``recording``), with ``accuracy`` and
        ``smoothness``; None (no source gives subsets per recording) leaves the relevance
        ANOVA out.
    candidate_scores : pandas.DataFrame
        Per (``name``, ``recording``) scores of the candidates (:func:`compare_subsets`), with
        ``subset``, ``n_features`` and ``performance_score``.
    chosen_states : pandas.DataFrame
        Metrics per (``trade_off``, ``recording``) of the K chosen for that trade-off.
    strategies : list of str
        Candidate names in the thesis' order; other names (the baseline) are left out.
    trade_offs : list of str
        Trade-offs of the relevance ANOVA (both metrics) and of the state selection's accuracy.
    all_trade_offs : list of str
        Trade-offs of the state selection's smoothness.
    n_strategies : int or None, default=7
        Best-ranked distinct strategies compared; None: all.

    Returns
    -------
    anova : pandas.DataFrame
        Columns ``analysis``, ``metric``, ``F``, ``pvalue``, ``n_groups`` and ``groups``.
    """
    ranked = strategy_ranking(candidate_scores, strategies, n_strategies)
    tables = (
        []
        if best_subsets is None
        else [
            one_way_anova(
                _in_order(best_subsets, "trade_off", trade_offs),
                by="trade_off",
                values=["accuracy", "smoothness"],
            ).assign(analysis=ANALYSES["relevance"])
        ]
    )
    tables += [
        one_way_anova(
            _in_order(candidate_scores, "name", ranked), by="name", values="performance_score"
        ).assign(analysis=ANALYSES["strategies"]),
        one_way_anova(
            _in_order(chosen_states, "trade_off", trade_offs), by="trade_off", values="accuracy"
        ).assign(analysis=ANALYSES["states"]),
        one_way_anova(
            _in_order(chosen_states, "trade_off", all_trade_offs),
            by="trade_off",
            values="smoothness",
        ).assign(analysis=ANALYSES["states"]),
    ]
    anova = pd.concat(tables, ignore_index=True)
    return anova[["analysis", "metric", "F", "pvalue", "n_groups", "groups"]]
