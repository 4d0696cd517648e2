"""State selection of the thesis: the number of states K by the 1% rule.

The public face of the state selection of the selection family (:mod:`skhmmgmr.selection`).
"""

from .selection._selectors._states import StateSelector, select_n_states, state_choices

__all__ = ["StateSelector", "select_n_states", "state_choices"]
