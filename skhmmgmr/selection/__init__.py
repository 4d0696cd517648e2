"""The thesis' parameter selection framework: ``select_parameters`` and its building blocks."""

from .._search._score_tables import one_way_anova
from ._candidates import candidate_subsets, compare_subsets, feature_relevance
from ._framework import SelectionReport, select_parameters
from ._sources import RelevanceSource

__all__ = [
    "RelevanceSource",
    "SelectionReport",
    "candidate_subsets",
    "compare_subsets",
    "feature_relevance",
    "one_way_anova",
    "select_parameters",
]
