"""skhmmgmr: Hidden Markov Model + Gaussian Mixture Regression for scikit-learn."""

__version__ = "0.1.0.dev0"

from . import datasets, metrics
from .estimator import HMMGMRRegressor
from .metrics import AccuracyScore, PerformanceScore, SmoothnessScore
from .streaming import FilterStream

__all__ = [
    "AccuracyScore",
    "FilterStream",
    "HMMGMRRegressor",
    "PerformanceScore",
    "SmoothnessScore",
    "__version__",
    "datasets",
    "metrics",
]
