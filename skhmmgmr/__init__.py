"""skhmmgmr: Hidden Markov Model + Gaussian Mixture Regression for scikit-learn."""

__version__ = "0.1.0.dev0"

from . import datasets, feature_selection, metrics, selection, state_selection
from .estimator import HMMGMRRegressor
from .feature_selection import (
    ExhaustiveFeatureSelector,
    ForwardFeatureSelector,
    SpearmanSelector,
    spearman_relevance,
)
from .metrics import AccuracyScore, PerformanceScore, SmoothnessScore
from .selection import SelectionReport, select_parameters
from .state_selection import StateSelector
from .streaming import FilterStream

__all__ = [
    "AccuracyScore",
    "ExhaustiveFeatureSelector",
    "FilterStream",
    "ForwardFeatureSelector",
    "HMMGMRRegressor",
    "PerformanceScore",
    "SelectionReport",
    "SmoothnessScore",
    "SpearmanSelector",
    "StateSelector",
    "__version__",
    "datasets",
    "feature_selection",
    "metrics",
    "select_parameters",
    "selection",
    "spearman_relevance",
    "state_selection",
]
