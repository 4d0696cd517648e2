"""Where the modules of 0.1.0 went, so that files naming them still load.

skhmmgmr 0.1.0 kept its modules in one flat folder (``skhmmgmr._fitted``,
``skhmmgmr._emissions``...); they now live in subpackages by layer. A pickle, a joblib or a
skops file names every object it holds by its module, and those written by 0.1.0 name the old
private modules. :func:`install` puts a finder first in ``sys.meta_path`` that answers an
import of one of the old names, a fixed list, with the module that holds its code now: the
same module object, so that the classes a 0.1.0 file names are the classes of today. First,
so that no other finder (an editable install's) serves a stale file of an old name; it
answers no other name. Portable JSON files name no module and need none of this.
"""

import importlib
import importlib.abc
import importlib.util
import sys

#: 0.1.0's private modules -> where their code is now.
MOVED_IN_0_2 = {
    "skhmmgmr._compat": "skhmmgmr._core._compat",
    "skhmmgmr._docstrings": "skhmmgmr._core._docstrings",
    "skhmmgmr._validation": "skhmmgmr._core._validation",
    "skhmmgmr._sequences": "skhmmgmr._core._sequences",
    "skhmmgmr._panel": "skhmmgmr._core._panel",
    "skhmmgmr.datasets._schema": "skhmmgmr._core._schema",
    "skhmmgmr._kernels": "skhmmgmr._hmm._kernels",
    "skhmmgmr._gaussian": "skhmmgmr._hmm._gaussian",
    "skhmmgmr._emissions": "skhmmgmr._hmm._emissions",
    "skhmmgmr._missing": "skhmmgmr._hmm._missing",
    "skhmmgmr._stale_inputs": "skhmmgmr._hmm._stale_inputs",
    "skhmmgmr._fused_estep": "skhmmgmr._hmm._fused_estep",
    "skhmmgmr._em": "skhmmgmr._hmm._em",
    "skhmmgmr._em_data": "skhmmgmr._hmm._em_data",
    "skhmmgmr._em_init": "skhmmgmr._hmm._em_init",
    "skhmmgmr._gmr": "skhmmgmr._hmm._gmr",
    "skhmmgmr._fitted": "skhmmgmr._hmm._fitted",
    "skhmmgmr._hmmlearn": "skhmmgmr._hmm._hmmlearn",
    "skhmmgmr._estimator_io": "skhmmgmr.estimator._io",
    "skhmmgmr._prediction_inputs": "skhmmgmr.estimator._prediction_inputs",
    "skhmmgmr._adaptation": "skhmmgmr.estimator._adaptation",
    "skhmmgmr._metrics_scorers": "skhmmgmr.metrics._scorers",
    "skhmmgmr._metrics_table": "skhmmgmr.metrics._table",
    "skhmmgmr._stream_inputs": "skhmmgmr.streaming._inputs",
    "skhmmgmr._stream_adaptation": "skhmmgmr.streaming._adaptation",
    "skhmmgmr._cluster_search": "skhmmgmr.cluster._scatter",
    "skhmmgmr._cluster_em": "skhmmgmr.cluster._em",
    "skhmmgmr._selector_base": "skhmmgmr._search.base",
    "skhmmgmr._evaluation": "skhmmgmr._search._evaluation",
    "skhmmgmr._score_tables": "skhmmgmr._search._score_tables",
    "skhmmgmr._spearman": "skhmmgmr.feature_selection._spearman",
    "skhmmgmr._forward_paths": "skhmmgmr.feature_selection._forward_paths",
    "skhmmgmr._sources": "skhmmgmr.selection._sources",
    "skhmmgmr._candidates": "skhmmgmr.selection._candidates",
    "skhmmgmr._anova": "skhmmgmr.selection._anova",
    "skhmmgmr._framework_data": "skhmmgmr.selection._framework_data",
    "skhmmgmr._cli_files": "skhmmgmr.cli._files",
    "skhmmgmr._cli_cluster": "skhmmgmr.cli._cluster",
    "skhmmgmr._report": "skhmmgmr.cli._report",
}


class _Alias(importlib.abc.Loader):
    """Loads an old name as the module that holds its code now."""

    def __init__(self, target):
        self.target = target

    def create_module(self, spec):
        return None

    def exec_module(self, module):
        # The import system returns what sys.modules holds under the name after this call:
        # the module of today, not the empty one made for the old name.
        sys.modules[module.__name__] = importlib.import_module(self.target)


class MovedModuleFinder(importlib.abc.MetaPathFinder):
    """Finds the modules of :data:`MOVED_IN_0_2` under their 0.1.0 names."""

    def find_spec(self, fullname, path=None, target=None):
        if fullname not in MOVED_IN_0_2:
            return None
        return importlib.util.spec_from_loader(fullname, _Alias(MOVED_IN_0_2[fullname]))


def install():
    """Put one :class:`MovedModuleFinder` first in ``sys.meta_path`` (once)."""
    if not any(isinstance(finder, MovedModuleFinder) for finder in sys.meta_path):
        sys.meta_path.insert(0, MovedModuleFinder())
