"""The search over recordings shared by the selectors and the selection framework.

``base`` (``RecordingSelector``: the base class of every selector that scores models on
validation recordings), ``_evaluation`` (one model per split, scored per recording, in
parallel and cached) and ``_score_tables`` (tables of compared models). Private: the public
selectors are in :mod:`skhmmgmr.feature_selection`, :mod:`skhmmgmr.state_selection` and
:mod:`skhmmgmr.selection`.
"""
