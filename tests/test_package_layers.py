"""The package's layers, read from its imports: no module imports a layer above its own.

Every top-level entry of ``skhmmgmr/`` (a subpackage or a module) sits in one layer of
:data:`LAYERS`, the lowest first. A module may import its own entry and any entry of a lower
layer; an import of an entry of its own layer or of a higher one fails the test, named with
its file and line. Every import counts: relative and absolute, at the top of a module or inside
a function. ``docs/architecture.rst`` describes the same layers.
"""

import ast
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "skhmmgmr"

#: The layers, lowest first; entries of one layer do not import each other.
LAYERS = (
    # the ground floor: shared checks, schema, recordings, the version, the loader of 0.1.0 files
    ("_core", "_version", "legacy"),
    # the HMM-GMR engine, the metrics, the datasets and the figures: each on the ground alone
    ("_hmm", "metrics", "datasets", "plotting"),
    # what reads a fitted model: the stream; the EM on a dask cluster
    ("streaming", "cluster"),
    # the scikit-learn estimator
    ("estimator",),
    # what uses the estimator: the torque pipeline; the selection family (the search over
    # recordings, the selectors, the framework)
    ("torque_pipeline", "selection"),
    # the model file of any fitted model (the regressor, the torque pipeline); the C code and
    # the FMU of a fitted regressor or torque pipeline; the public faces of the selectors and
    # of the users' checks, which live in the selection family
    ("portable", "export", "feature_selection", "state_selection", "utils"),
    # the command line and its report
    ("cli",),
    # the package's face
    ("__init__", "__main__"),
)
RANK = {entry: rank for rank, layer in enumerate(LAYERS) for entry in layer}
#: Entries that import nothing of the package, which every entry may import: the version (read
#: by the ground floor's pickles as by the model file).
LEAVES = {"_version"}
MAX_TOP_LEVEL_ENTRIES = 20
#: No module of the package is longer (its lines, docstrings and comments included): a module
#: that would grow beyond it holds two ideas, split by idea.
MAX_MODULE_LINES = 600

#: Inside a family, its private sub-folders are floors too, lowest first: a module of the
#: family imports its own sub-folder and those below it, and the rest of the family (its root,
#: the face included) stands above them all.
FAMILY_FLOORS = {
    # the search over recordings; the selectors; the framework at the root
    "selection": ("_search", "_selectors"),
}


def _entry(parts):
    """The top-level entry of a module path inside the package (``("_hmm", "_em")`` -> _hmm)."""
    return parts[0] if parts else "__init__"


def imported_paths(path, tree):
    """(line, path, text) of every import of the package in a module: ``path`` is the dotted
    path it reaches under ``skhmmgmr`` as a list (``[]`` for the package's face)."""
    parts = list(path.relative_to(PACKAGE).with_suffix("").parts)
    package = parts[:-1]  # an __init__.py's package is its folder, as any module's
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for alias in node.names:
                names = alias.name.split(".")
                if names[0] == "skhmmgmr":
                    found.append((node.lineno, names[1:], f"import {alias.name}"))
        elif isinstance(node, ast.ImportFrom):
            if node.level == 0:
                names = (node.module or "").split(".")
                if names[0] != "skhmmgmr":
                    continue
                target = names[1:]
            else:
                if node.level - 1 > len(package):
                    continue
                target = package[: len(package) - (node.level - 1)]
                target += node.module.split(".") if node.module else []
            text = f"from {'.' * node.level}{node.module or ''} import ..."
            if target:
                found.append((node.lineno, target, text))
            else:  # from the package itself: each name is an entry, or a name of the face
                for alias in node.names:
                    name = alias.name
                    exists = (PACKAGE / name).is_dir() or (PACKAGE / f"{name}.py").is_file()
                    found.append((node.lineno, [name] if exists else [], text))
    return found


def imported_entries(path, tree):
    """(line, entry, text) of every import of the package in a module, the entry it reaches."""
    return [(line, _entry(target), text) for line, target, text in imported_paths(path, tree)]


def _family_floor(family, parts):
    """The floor inside ``family`` of a module path below it (its root: above the floors)."""
    floors = FAMILY_FLOORS[family]
    return floors.index(parts[0]) if parts and parts[0] in floors else len(floors)


def _offences():
    offences = []
    for path in sorted(PACKAGE.rglob("*.py")):
        own = _entry(list(path.relative_to(PACKAGE).with_suffix("").parts))
        tree = ast.parse(path.read_text(), filename=str(path))
        for line, entry, text in imported_entries(path, tree):
            if entry == own or entry in LEAVES:
                continue
            if RANK[entry] >= RANK[own]:
                offences.append(
                    f"skhmmgmr/{path.relative_to(PACKAGE)}:{line}: {own} (layer {RANK[own]}) "
                    f"imports {entry} (layer {RANK[entry]}): {text}"
                )
    return offences


def _family_offences():
    offences = []
    for family in FAMILY_FLOORS:
        for path in sorted((PACKAGE / family).rglob("*.py")):
            own = list(path.relative_to(PACKAGE / family).with_suffix("").parts)
            tree = ast.parse(path.read_text(), filename=str(path))
            for line, target, text in imported_paths(path, tree):
                if _entry(target) != family:
                    continue
                # the face (``__init__``) is the root's
                mine, theirs = _family_floor(family, own), _family_floor(family, target[1:])
                if theirs > mine:
                    offences.append(
                        f"skhmmgmr/{path.relative_to(PACKAGE)}:{line}: floor {mine} of {family} "
                        f"imports floor {theirs}: {text}"
                    )
    return offences


def test_every_top_level_entry_has_a_layer():
    entries = {
        p.stem if p.suffix == ".py" else p.name
        for p in PACKAGE.iterdir()
        if (p.suffix == ".py" or (p / "__init__.py").is_file())
    }
    assert entries == set(RANK), (
        f"entries without a layer: {sorted(entries - set(RANK))}; "
        f"layers naming no entry: {sorted(set(RANK) - entries)}"
    )
    assert len(entries) <= MAX_TOP_LEVEL_ENTRIES


def test_no_module_is_over_the_size_of_one_idea():
    sizes = {
        str(path.relative_to(PACKAGE.parent)): len(path.read_text().splitlines())
        for path in PACKAGE.rglob("*.py")
    }
    assert len(sizes) > 100 and sizes["skhmmgmr/__init__.py"] > 0  # the rule reads the package
    over = {path: n for path, n in sorted(sizes.items()) if n > MAX_MODULE_LINES}
    assert not over, f"modules over {MAX_MODULE_LINES} lines (split them by idea): {over}"


def test_no_module_imports_its_own_layer_or_a_higher_one():
    offences = _offences()
    assert not offences, "imports that run up the layers:\n" + "\n".join(offences)


@pytest.mark.parametrize(
    "file, source, expected",
    [
        ("_hmm/_em.py", "from ._gaussian import x", "_hmm"),
        ("_hmm/_em.py", "from .._core._panel import x", "_core"),
        ("_hmm/_em.py", "def f():\n    from ..estimator import x", "estimator"),
        ("_hmm/__init__.py", "from ..metrics import x", "metrics"),
        ("_hmm/_em.py", "import skhmmgmr.cli._commands", "cli"),
        ("_hmm/_em.py", "from skhmmgmr.selection._framework import x", "selection"),
        ("cli/_report.py", "from .. import plotting", "plotting"),
        ("cli/_report.py", "from .. import __version__", "__init__"),
        ("portable.py", "from ._version import __version__", "_version"),
    ],
)
def test_the_rule_reads_every_kind_of_import(file, source, expected):
    found = imported_entries(PACKAGE / file, ast.parse(source))
    assert [entry for _, entry, _ in found] == [expected]


def test_no_module_of_a_family_imports_a_floor_of_the_family_above_its_own():
    for family, floors in FAMILY_FLOORS.items():
        assert all((PACKAGE / family / floor / "__init__.py").is_file() for floor in floors)
    offences = _family_offences()
    assert not offences, "imports that run up a family's floors:\n" + "\n".join(offences)


@pytest.mark.parametrize(
    "file, source, expected",
    [
        ("selection/_search/base.py", "from .._selectors._states import x", 1),
        ("selection/_search/base.py", "from .. import select_parameters", 2),
        ("selection/_search/base.py", "from skhmmgmr.selection._framework import x", 2),
        ("selection/_selectors/_states.py", "from .._search.base import x", 0),
        ("selection/_framework.py", "from ._selectors._states import x", 1),
    ],
)
def test_the_family_rule_reads_the_floor_an_import_reaches(file, source, expected):
    ((_, target, _),) = imported_paths(PACKAGE / file, ast.parse(source))
    assert _entry(target) == "selection"
    assert _family_floor("selection", target[1:]) == expected


def test_the_rule_reports_an_import_that_runs_up():
    tree = ast.parse("import numpy\n\ndef f():\n    from ..estimator import HMMGMRRegressor\n")
    ((line, entry, _),) = imported_entries(PACKAGE / "_hmm" / "_em.py", tree)
    assert (line, entry) == (4, "estimator") and RANK[entry] > RANK["_hmm"]


def test_the_leaves_import_nothing_of_the_package():
    for entry in LEAVES:
        path = PACKAGE / f"{entry}.py"
        assert imported_entries(path, ast.parse(path.read_text())) == [], entry
