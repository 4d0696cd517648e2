"""The thesis' parameter selection framework: ``select_parameters`` and its building blocks.

The selection family lives in this package: the search over recordings (``_search``), the
selectors (``_selectors``, public through :mod:`skhmmgmr.feature_selection`,
:mod:`skhmmgmr.state_selection` and :mod:`skhmmgmr.utils`) and, at its root, the framework
that runs them in turn.
"""

from ._candidates import candidate_subsets, compare_subsets, feature_relevance
from ._closed_loop import ClosedLoopScorer, make_closed_loop_scorer
from ._framework import SelectionReport, select_parameters
from ._search._score_tables import one_way_anova
from ._sources import RelevanceSource

__all__ = [
    "ClosedLoopScorer",
    "RelevanceSource",
    "SelectionReport",
    "candidate_subsets",
    "compare_subsets",
    "feature_relevance",
    "make_closed_loop_scorer",
    "one_way_anova",
    "select_parameters",
]
