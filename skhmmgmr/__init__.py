"""skhmmgmr: Hidden Markov Model + Gaussian Mixture Regression for scikit-learn."""

from . import (
    cluster,
    datasets,
    export,
    feature_selection,
    metrics,
    selection,
    state_selection,
    utils,
)
from ._core._pickled import InconsistentVersionWarning
from ._hmm._fitted import FittedHMMGMR, Standardization
from ._version import __version__
from .estimator import HierarchicalHMMGMRRegressor, HMMGMRRegressor
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
from .torque_pipeline import SteeringFeatures, make_driver_model, make_torque_pipeline

__all__ = [
    "AccuracyScore",
    "ExhaustiveFeatureSelector",
    "FilterStream",
    "FittedHMMGMR",
    "ForwardFeatureSelector",
    "HMMGMRRegressor",
    "HierarchicalHMMGMRRegressor",
    "InconsistentVersionWarning",
    "PerformanceScore",
    "SelectionReport",
    "SmoothnessScore",
    "SpearmanSelector",
    "Standardization",
    "StateSelector",
    "SteeringFeatures",
    "__version__",
    "cluster",
    "datasets",
    "export",
    "feature_selection",
    "make_driver_model",
    "make_torque_pipeline",
    "metrics",
    "select_parameters",
    "selection",
    "spearman_relevance",
    "state_selection",
    "utils",
]
