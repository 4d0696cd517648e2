"""Public names carry the public module users import them from, in ``__module__``.

A class or function is written in a private module (``skhmmgmr.metrics._scorers``) and
re-exported by a public face (``skhmmgmr.metrics``). Pickles, skops' trusted types, reprs and
the API reference name an object by its ``__module__``, so a face calls :func:`publish` on its
``__all__``: the rule is that a public name's ``__module__`` is the deepest public module that
exports it (``skhmmgmr.metrics.PerformanceScore``, ``skhmmgmr.estimator.HMMGMRRegressor``), and
``skhmmgmr`` for a name only the package exports (``skhmmgmr.FittedHMMGMR``). Faces deeper in
the package are imported before the package's own ``__init__`` publishes, so claiming only the
names whose ``__module__`` is still private gives the deepest one.

The cost, as for every package that sets ``__module__`` (numpy's ``set_module``): Python finds
a class's source file through its module, so ``inspect.getsource`` of a published class reads
the face and finds no definition there; functions keep their source (``__code__``).
"""

import inspect


def is_private_path(module_name):
    """Whether a dotted module path has a ``_``-prefixed part (``skhmmgmr._hmm._fitted``)."""
    return any(part.startswith("_") for part in module_name.split("."))


def publish(namespace):
    """Give the classes and functions of ``namespace["__all__"]`` the namespace's module.

    Parameters
    ----------
    namespace : dict
        A public module's ``globals()``; only names whose ``__module__`` is private are set.
    """
    module = namespace["__name__"]
    for name in namespace["__all__"]:
        value = namespace[name]
        if not (inspect.isclass(value) or inspect.isfunction(value)):
            continue
        if is_private_path(value.__module__):
            value.__module__ = module
