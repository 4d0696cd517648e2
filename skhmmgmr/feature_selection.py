"""Feature selection of the thesis: the Spearman filter and the exhaustive and forward wrappers.

The public face of the feature selectors of the selection family (:mod:`skhmmgmr.selection`).
"""

from .selection._selectors._exhaustive import ExhaustiveFeatureSelector
from .selection._selectors._forward import ForwardFeatureSelector
from .selection._selectors._spearman import SpearmanSelector, spearman_relevance

__all__ = [
    "ExhaustiveFeatureSelector",
    "ForwardFeatureSelector",
    "SpearmanSelector",
    "spearman_relevance",
]
