"""The selectors of the thesis' framework, each usable alone.

The Spearman filter (``_spearman``), the exhaustive and forward wrappers (``_exhaustive``,
``_forward``, with the greedy paths of ``_forward_paths``), the state selection (``_states``)
and the scikit-learn checks they and the regressor fail by design (``_estimator_checks``).
They search through ``.._search``; the framework at the root of :mod:`skhmmgmr.selection` runs
them in turn. Private: the public faces are :mod:`skhmmgmr.feature_selection`,
:mod:`skhmmgmr.state_selection` and :mod:`skhmmgmr.utils`.
"""
