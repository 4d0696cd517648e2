"""Feature selection of the thesis: the Spearman filter and the exhaustive and forward wrappers."""

from ._spearman import SpearmanSelector, spearman_relevance
from ._wrappers import ExhaustiveFeatureSelector, ForwardFeatureSelector

__all__ = [
    "ExhaustiveFeatureSelector",
    "ForwardFeatureSelector",
    "SpearmanSelector",
    "spearman_relevance",
]
