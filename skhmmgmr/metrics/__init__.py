"""Per-recording accuracy and smoothness, the Performance Score and its scorers.

The definitions (RMSE, accuracy, smoothness, the D.5 normalisation) are in the docstring of
``skhmmgmr/metrics/_scores.py``; the scorers in ``_scorers.py``, the per-recording tables in
``_table.py``.
"""

from ._lane_keeping import LANE_KEEPING_METRICS, lane_keeping_metrics
from ._scorers import (
    AccuracyScore,
    PerformanceScore,
    SmoothnessScore,
    UngroupedScoringWarning,
    make_performance_scorers,
)
from ._scores import (
    accuracy_score,
    evaluate_recordings,
    normalize_performance,
    performance_score,
    rank_models,
    smoothness_score,
    trade_offs,
)

__all__ = [
    "AccuracyScore",
    "LANE_KEEPING_METRICS",
    "PerformanceScore",
    "SmoothnessScore",
    "UngroupedScoringWarning",
    "accuracy_score",
    "evaluate_recordings",
    "lane_keeping_metrics",
    "make_performance_scorers",
    "normalize_performance",
    "performance_score",
    "rank_models",
    "smoothness_score",
    "trade_offs",
]
