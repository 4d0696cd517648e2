"""Tables of compared models: performance scores per trade-off, the best model per recording or
on average, and the one-way ANOVA of the thesis."""

import warnings

import numpy as np
import pandas as pd
from scipy import stats

from ..._core._compat import validate_params
from ...metrics._scores import normalize_performance
from ...metrics._table import parse_trade_offs


def rescore_table(results, key, trade_offs):
    """D.5-normalised performance scores of ``results`` for every trade-off.

    The models compared are the distinct values of the ``key`` column; every other column of
    ``results`` is kept. No model is refitted.
    """
    codes, _ = pd.factorize(results[key])
    table = results.assign(_model=codes)
    scores = normalize_performance(table, weights=trade_offs, model="_model")
    kept = table
    merged = scores.merge(kept, on=["_model", "recording"], how="left", sort=False)
    front = ["trade_off", "accuracy_weight", "smoothness_weight"]
    rest = [c for c in kept.columns if c not in ("_model", "recording")]
    tail = ["accuracy_term", "smoothness_term", "performance_score"]
    return merged[[*front, *rest, "recording", *tail]]


def best_per_recording(scores, key, *, tie_breaker=None):
    """Row of the lowest performance score per (trade-off, recording), ties to ``tie_breaker``."""
    order = ["performance_score", tie_breaker] if tie_breaker else ["performance_score"]
    best = scores.sort_values(order, kind="stable").drop_duplicates(["trade_off", "recording"])
    position = scores.groupby(["trade_off", "recording"], sort=False).ngroup()
    return (
        best.assign(_pos=position.loc[best.index])
        .sort_values("_pos")
        .drop(columns="_pos")
        .reset_index(drop=True)
    )


def best_on_average(scores, key, *, tie_breaker=None):
    """Model with the lowest mean performance score over recordings, per trade-off."""
    columns = [key, tie_breaker] if tie_breaker else [key]
    means = scores.groupby(["trade_off", *columns], sort=False).agg(
        performance_score=("performance_score", "mean"),
        accuracy=("accuracy", "mean"),
        smoothness=("smoothness", "mean"),
    )
    means = means.reset_index()
    order = ["performance_score", tie_breaker] if tie_breaker else ["performance_score"]
    best = means.sort_values(order, kind="stable").drop_duplicates("trade_off")
    labels = list(dict.fromkeys(scores["trade_off"]))
    return best.set_index("trade_off").loc[labels].reset_index()


def labels_of(trade_offs):
    return [label for label, _, _ in parse_trade_offs(trade_offs)]


def relative_gain(previous, new):
    """Relative improvement ``(previous - new) / previous`` of a lower-is-better score."""
    if not np.isfinite(previous):
        return np.inf
    if previous <= 0:
        return 0.0
    return (previous - new) / previous


@validate_params(
    {"table": [pd.DataFrame], "by": [str], "values": [str, list, tuple]},
    prefer_skip_nested_validation=True,
)
def one_way_anova(table, *, by, values):
    """One-way ANOVA (:func:`scipy.stats.f_oneway`) of each ``values`` column across ``by``.

    Each group holds the rows (recordings) of one level of ``by``; the test asks whether the
    group means differ. Returns one row per value column: ``F``, ``pvalue``, ``n_groups`` and
    ``groups`` (tuple of the levels entered, in order of appearance).
    """
    rows = []
    for column in [values] if isinstance(values, str) else values:
        parts = [(level, g[column].to_numpy(float)) for level, g in table.groupby(by, sort=False)]
        parts = [(level, s) for level, s in parts if s.size]
        samples = [s for _, s in parts]
        statistic, pvalue = np.nan, np.nan
        if len(samples) > 1 and any(np.ptp(s) > 0 for s in samples):
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                statistic, pvalue = stats.f_oneway(*samples)
        rows.append(
            {
                "metric": column,
                "F": float(statistic),
                "pvalue": float(pvalue),
                "n_groups": len(samples),
                "groups": tuple(level for level, _ in parts),
            }
        )
    return pd.DataFrame(rows)
