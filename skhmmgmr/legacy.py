"""Loading the pickles and skops files that skhmmgmr 0.1.0 wrote.

skhmmgmr 0.1.0 kept its private modules in one flat folder; a pickle or a skops file names
every object by its module, so a file of 0.1.0 names modules that no longer exist
(``skhmmgmr._fitted``, ``skhmmgmr._emissions``...). :func:`load_pickle` and :func:`load_skops`
read such a file, resolving each old name to the module that holds its code now: the objects
are those of today. Nothing changes on ``import skhmmgmr``; ``pickle.load`` and
``skops.io.load`` keep their own behaviour.

Files written since load with ``pickle``, ``joblib`` or ``skops.io`` directly, and warn with
:class:`~skhmmgmr.InconsistentVersionWarning` when another version of skhmmgmr wrote them. The
file that lasts across releases is the model file of :func:`skhmmgmr.portable.save`.

The old names are a fixed table, :data:`MOVED_IN_0_2` (data only, read by these loaders): a
module that moves again adds its old names there. Portable JSON files name no module and need
none of this.

Examples
--------
>>> import io, pickle
>>> from skhmmgmr import legacy
>>> legacy.load_pickle(io.BytesIO(pickle.dumps({"n_states": 3})))
{'n_states': 3}
"""

import io
import json
import os
import pickle
import zipfile

__all__ = ["LegacyUnpickler", "load_pickle", "load_skops", "untrusted_skops_types"]

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
    "skhmmgmr.selection._search": {
        "_selector_base": "base",
        "_evaluation": "_evaluation",
        "_score_tables": "_score_tables",
    },
    "skhmmgmr.selection._selectors": {
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


_SKOPS_SCHEMA = "schema.json"


def _current_type_name(name):
    """A type's dotted name (``module.qualname``) with a 0.1.0 module replaced by today's."""
    for old, new in MOVED_IN_0_2.items():
        if name.startswith(old + "."):
            return new + name[len(old) :]
    return name


class LegacyUnpickler(pickle.Unpickler):
    """A :class:`pickle.Unpickler` that finds the classes of 0.1.0's modules where they are now.

    Use it as :class:`pickle.Unpickler` (``LegacyUnpickler(file).load()``), for example to read a
    pickle inside another stream; :func:`load_pickle` reads a whole file.

    Examples
    --------
    >>> import io
    >>> from skhmmgmr.legacy import LegacyUnpickler
    >>> reference = b"cskhmmgmr._fitted\\nFittedHMMGMR\\n."  # a class as 0.1.0 named it
    >>> LegacyUnpickler(io.BytesIO(reference)).load().__module__
    'skhmmgmr._hmm._fitted'
    """

    def find_class(self, module, name):
        return super().find_class(MOVED_IN_0_2.get(module, module), name)


def load_pickle(file):
    """Load a pickle written by skhmmgmr 0.1.0 (or later).

    Parameters
    ----------
    file : str, path-like or binary file object
        The pickle (``pickle.dump``'s output).

    Returns
    -------
    obj : object
        What the file holds, with the classes of today.

    Warns
    -----
    InconsistentVersionWarning
        For every object of the package written by another version (the objects of 0.1.0
        carry no version: "0.1.0 or earlier").

    Notes
    -----
    Loading a pickle runs code that the file names: load only files you trust. A joblib file
    is not a plain pickle; load it with ``joblib.load`` in skhmmgmr 0.1.0 and save its models
    with :func:`skhmmgmr.portable.save`.

    Examples
    --------
    >>> import io, pickle
    >>> from skhmmgmr.legacy import load_pickle
    >>> load_pickle(io.BytesIO(pickle.dumps([1, 2])))
    [1, 2]
    """
    if hasattr(file, "read"):
        return LegacyUnpickler(file).load()
    with open(_checked_path(file), "rb") as opened:
        return LegacyUnpickler(opened).load()


def _checked_path(file):
    """``file`` if it names a file; ``open`` would take an int as a file descriptor."""
    if not isinstance(file, str | bytes | os.PathLike):
        raise TypeError(
            "file must be a path (str or path-like) or a binary file object; "
            f"got {type(file).__name__}."
        )
    return file


def _renamed_nodes(node):
    """The skops schema ``node`` with every 0.1.0 module in ``__module__`` replaced."""
    if isinstance(node, list):
        return [_renamed_nodes(item) for item in node]
    if not isinstance(node, dict):
        return node
    renamed = {key: _renamed_nodes(value) for key, value in node.items()}
    module = renamed.get("__module__")
    if isinstance(module, str):
        renamed["__module__"] = MOVED_IN_0_2.get(module, module)
    return renamed


def _current_skops_bytes(file):
    """The bytes of the skops file ``file`` with its schema naming today's modules."""
    if hasattr(file, "read"):
        data = file.read()
    else:
        with open(_checked_path(file), "rb") as opened:
            data = opened.read()
    renamed = io.BytesIO()
    with (
        zipfile.ZipFile(io.BytesIO(data)) as source,
        zipfile.ZipFile(renamed, "w", compression=zipfile.ZIP_DEFLATED) as target,
    ):
        if _SKOPS_SCHEMA not in source.namelist():
            raise ValueError(f"{file} is not a skops file: it holds no {_SKOPS_SCHEMA}")
        for member in source.infolist():
            content = source.read(member)
            if member.filename == _SKOPS_SCHEMA:
                schema = _renamed_nodes(json.loads(content))
                content = json.dumps(schema).encode("utf-8")
            target.writestr(member, content)
    return renamed.getvalue()


def _skops_io():
    try:
        import skops.io
    except ImportError as exc:  # an optional dependency
        raise ImportError("loading a skops file needs skops: pip install skops") from exc
    return skops.io


def untrusted_skops_types(file):
    """The types of a skops file of skhmmgmr 0.1.0 that skops does not trust by default.

    Parameters
    ----------
    file : str, path-like or binary file object

    Returns
    -------
    types : list of str
        Dotted names with today's modules (``skhmmgmr._hmm._fitted.FittedHMMGMR`` for 0.1.0's
        ``skhmmgmr._fitted.FittedHMMGMR``): check them, then pass them to :func:`load_skops`.

    Examples
    --------
    >>> import io, pytest
    >>> sio = pytest.importorskip("skops.io")
    >>> from skhmmgmr import HMMGMRRegressor
    >>> from skhmmgmr.legacy import untrusted_skops_types
    >>> untrusted_skops_types(io.BytesIO(sio.dumps(HMMGMRRegressor())))
    ['skhmmgmr.estimator._regressor.HMMGMRRegressor']
    """
    return _skops_io().get_untrusted_types(data=_current_skops_bytes(file))


def load_skops(file, *, trusted=None):
    """Load a skops file written by skhmmgmr 0.1.0 (or later).

    Parameters
    ----------
    file : str, path-like or binary file object
        The file of ``skops.io.dump``.
    trusted : list of str, default=None
        The types to trust beyond skops' defaults, as :func:`untrusted_skops_types` lists them
        (0.1.0's names, as ``skops.io.get_untrusted_types`` lists them for the file, are taken
        too); skops refuses a file holding any other type.

    Returns
    -------
    obj : object
        What the file holds, with the classes of today.

    Warns
    -----
    InconsistentVersionWarning
        For every object of the package written by another version.

    Examples
    --------
    >>> import io, pytest
    >>> sio = pytest.importorskip("skops.io")
    >>> from skhmmgmr import HMMGMRRegressor
    >>> from skhmmgmr.legacy import load_skops, untrusted_skops_types
    >>> file = io.BytesIO(sio.dumps(HMMGMRRegressor(n_states=3)))
    >>> trusted = untrusted_skops_types(file)
    >>> _ = file.seek(0)
    >>> load_skops(file, trusted=trusted).n_states
    3
    """
    trusted = None if trusted is None else [_current_type_name(name) for name in trusted]
    return _skops_io().loads(_current_skops_bytes(file), trusted=trusted)
