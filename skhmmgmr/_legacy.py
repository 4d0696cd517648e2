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

# 0.1.0's private modules, by the package that holds their code now: {package: {old name
# under skhmmgmr: module name in the package}}.
_MOVES = {
    "skhmmgmr._core": {
        "_compat": "_compat",
        "_docstrings": "_docstrings",
        "_validation": "_validation",
        "_sequences": "_sequences",
        "_panel": "_panel",
        "datasets._schema": "_schema",
    },
    "skhmmgmr.datasets._simulator": {
        "datasets._driver": "_driver",
        "datasets._road": "_road",
        "datasets._sensors": "_sensors",
        "datasets._vehicle": "_vehicle",
    },
    "skhmmgmr.datasets._comma2k19": {
        "datasets._comma2k19_can": "_can",
        "datasets._fetch": "_fetch",
    },
    "skhmmgmr.datasets._recordings": {
        "datasets._resample": "_resample",
    },
    "skhmmgmr._hmm": {
        "_kernels": "_kernels",
        "_gaussian": "_gaussian",
        "_emissions": "_emissions",
        "_missing": "_missing",
        "_stale_inputs": "_stale_inputs",
        "_fused_estep": "_fused_estep",
        "_em": "_em",
        "_em_data": "_em_data",
        "_em_init": "_em_init",
        "_gmr": "_gmr",
        "_fitted": "_fitted",
        "_hmmlearn": "_hmmlearn",
    },
    "skhmmgmr.estimator": {
        "_estimator_io": "_io",
        "_prediction_inputs": "_prediction_inputs",
        "_adaptation": "_adaptation",
    },
    "skhmmgmr.metrics": {
        "_metrics_scorers": "_scorers",
        "_metrics_table": "_table",
    },
    "skhmmgmr.streaming": {
        "_stream_inputs": "_inputs",
        "_stream_adaptation": "_adaptation",
    },
    "skhmmgmr.cluster": {
        "_cluster_search": "_scatter",
        "_cluster_em": "_em",
    },
    "skhmmgmr._search": {
        "_selector_base": "base",
        "_evaluation": "_evaluation",
        "_score_tables": "_score_tables",
    },
    "skhmmgmr.feature_selection": {
        "_spearman": "_spearman",
        "_forward_paths": "_forward_paths",
    },
    "skhmmgmr.selection": {
        "_sources": "_sources",
        "_candidates": "_candidates",
        "_anova": "_anova",
        "_framework_data": "_framework_data",
    },
    "skhmmgmr.cli": {
        "_cli_files": "_files",
        "_cli_cluster": "_cluster",
        "_report": "_report",
    },
}
#: 0.1.0's private modules -> where their code is now.
MOVED_IN_0_2 = {
    f"skhmmgmr.{old}": f"{package}.{module}"
    for package, moves in _MOVES.items()
    for old, module in moves.items()
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
