"""The public names: where users import them, and where their code is.

A public class or function is written in a module (often private, ``_``-prefixed) and
re-exported by a public face; it keeps the ``__module__`` of the module that defines it, as
scikit-learn's do, so that ``inspect.getsource``, the API reference's source links and an
editor's go-to-definition find it. Nothing rewrites ``__module__``, and ``import skhmmgmr``
installs no import hook: the files of 0.1.0 load through ``skhmmgmr.legacy``
(``tests/test_legacy_files.py``).
"""

import ast
import inspect
import json
import pickle
import re
import subprocess
import sys
from importlib import import_module
from pathlib import Path

import pytest

FIXTURES = Path(__file__).resolve().parent / "fixtures"
PACKAGE = Path(__file__).resolve().parents[1] / "skhmmgmr"
LEGACY = json.loads((FIXTURES / "legacy_0_1_0_public_names.json").read_text())
LEGACY_MODULES = sorted(LEGACY["modules"])
# public modules added since 0.1.0
NEW_MODULES = ["skhmmgmr.export", "skhmmgmr.legacy"]
PUBLIC_MODULES = sorted([*LEGACY_MODULES, *NEW_MODULES])


def _exported(module_name):
    module = import_module(module_name)
    return {name: getattr(module, name) for name in module.__all__}


def _public_objects():
    """(name, object, public modules that export it) of every class and function exported."""
    found = {}
    for module_name in PUBLIC_MODULES:
        for name, value in _exported(module_name).items():
            if inspect.isclass(value) or inspect.isfunction(value):
                found.setdefault(id(value), (name, value, []))[2].append(module_name)
    return sorted(found.values(), key=lambda item: (item[2][0], item[0]))


@pytest.mark.parametrize("module_name", LEGACY_MODULES)
def test_every_0_1_0_public_name_is_still_imported_from_the_same_module(module_name):
    module = import_module(module_name)
    missing = [name for name in LEGACY["modules"][module_name] if not hasattr(module, name)]
    assert not missing, f"{module_name} lost {missing}"
    assert set(LEGACY["modules"][module_name]) <= set(module.__all__)


def test_every_public_module_lists_its_names():
    for module_name in PUBLIC_MODULES:
        module = import_module(module_name)
        assert hasattr(module, "__all__"), module_name
        assert sorted(set(module.__all__)) == sorted(module.__all__), module_name


def test_the_source_of_every_public_class_and_function_is_found():
    """#50: 17 of 20 public classes raised OSError in ``inspect.getsource`` while their
    ``__module__`` named the face that re-exports them."""
    objects = _public_objects()
    assert len(objects) > 70  # every class and function of every public module
    failed = []
    for name, value, exporters in objects:
        try:
            source = inspect.getsource(value)
        except (OSError, TypeError) as exc:
            failed.append(f"{exporters[0]}.{name}: {exc}")
            continue
        # the module it names defines it, and its source is that definition
        module = import_module(value.__module__)
        assert getattr(module, value.__qualname__) is value, name
        assert re.search(rf"(class|def) {re.escape(value.__name__)}\b", source), name
        assert inspect.getsourcefile(inspect.unwrap(value)) == inspect.getsourcefile(module)
    assert not failed, "\n".join(failed)


def test_the_docs_find_the_definition_of_every_public_class_and_function():
    """The API reference's "[source]" links: Sphinx's viewcode reads the definitions of a
    module with its own parser, which gives up on the whole module when a decorator holds a
    dict unpacked with ``**`` (Sphinx 9.0): every name of that module lost its link."""
    pycode = pytest.importorskip("sphinx.pycode")
    missing = []
    for name, value, exporters in _public_objects():
        try:
            tags = pycode.ModuleAnalyzer.for_module(value.__module__).find_tags()
        except pycode.PycodeError as exc:
            missing.append(f"{exporters[0]}.{name}: {exc}")
            continue
        if value.__qualname__ not in tags:
            missing.append(f"{exporters[0]}.{name}: no definition in {value.__module__}")
    assert not missing, "\n".join(missing)


def test_no_module_of_the_package_rewrites_module_names():
    writes = []
    for path in sorted(PACKAGE.rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text())):
            targets = node.targets if isinstance(node, ast.Assign) else []
            if any(isinstance(t, ast.Attribute) and t.attr == "__module__" for t in targets):
                writes.append(f"{path.relative_to(PACKAGE)}:{node.lineno}")
            if (
                isinstance(node, ast.Call)
                and isinstance(node.func, ast.Name)
                and node.func.id == "setattr"
                and len(node.args) > 1
                and isinstance(node.args[1], ast.Constant)
                and node.args[1].value == "__module__"
            ):
                writes.append(f"{path.relative_to(PACKAGE)}:{node.lineno}")
    assert not writes, writes


def test_importing_the_package_leaves_the_import_system_alone():
    """#50: ``import skhmmgmr`` put a finder of 39 old module names first in
    ``sys.meta_path``."""
    code = (
        "import sys\n"
        "before = list(sys.meta_path), list(sys.path_hooks)\n"
        "import skhmmgmr, skhmmgmr.portable, skhmmgmr.legacy, skhmmgmr.cli\n"
        "assert (list(sys.meta_path), list(sys.path_hooks)) == before, sys.meta_path\n"
        "assert 'skhmmgmr._fitted' not in sys.modules\n"
    )
    subprocess.run([sys.executable, "-c", code], check=True)


def test_a_pickle_names_the_modules_that_define_its_classes():
    import numpy as np

    from skhmmgmr import HMMGMRRegressor

    X = np.cumsum(np.random.default_rng(0).normal(size=(200, 2)), axis=0) / 10
    model = HMMGMRRegressor(n_states=2, n_iter=5, random_state=0).fit(X, X[:, 0])
    data = pickle.dumps(model, protocol=0)
    assert b"skhmmgmr.estimator._regressor\nHMMGMRRegressor" in data
    assert b"skhmmgmr._hmm._fitted\nFittedHMMGMR" in data
    assert pickle.loads(data).predict(X).tolist() == model.predict(X).tolist()


def test_the_table_of_0_1_0_modules_names_modules_of_today():
    from skhmmgmr.legacy import MOVED_IN_0_2

    assert len(MOVED_IN_0_2) == 46  # 39 moved into subpackages, 7 by the datasets families
    for old, new in MOVED_IN_0_2.items():
        assert import_module(new).__name__ == new, old
        assert old not in sys.modules, old


def test_the_package_runs_as_a_module_and_a_script():
    result = subprocess.run(
        [sys.executable, "-m", "skhmmgmr", "--help"], capture_output=True, text=True, check=True
    )
    assert "demo" in result.stdout
    from skhmmgmr.cli import main

    assert main.__module__.startswith("skhmmgmr.cli.")


def _documented():
    """The names the API reference lists, as full dotted paths."""
    text = (Path(__file__).resolve().parents[1] / "docs" / "api.rst").read_text()
    return {f"skhmmgmr.{name}" for name in re.findall(r"^   ([\w.]+)$", text, re.MULTILINE)}


def _written_in_a_private_module():
    """Names of the classes and functions defined at the top of a private module's source."""
    import ast

    names = set()
    for path in (Path(__file__).resolve().parents[1] / "skhmmgmr").rglob("_*.py"):
        if path.name != "__init__.py":
            tree = ast.parse(path.read_text())
            names |= {
                node.name for node in tree.body if isinstance(node, ast.ClassDef | ast.FunctionDef)
            }
    return names


def test_every_public_name_written_in_a_private_module_is_in_the_api_reference():
    # Users import these from a face, the only place they can find them; the command line's
    # functions are documented as the command (user guide), not as an API.
    documented, private = _documented(), _written_in_a_private_module()
    missing = [
        f"{exporters[0]}.{name}"
        for name, _, exporters in _public_objects()
        if name in private
        and not {f"{module}.{name}" for module in exporters} & documented
        and exporters != ["skhmmgmr.cli"]
    ]
    assert not missing, f"docs/api.rst does not list {missing}"


def test_the_benchmarks_import_names_that_exist():
    # The benchmarks run by hand, not in the suite: their imports of the package are checked here.
    import ast

    missing = []
    for path in sorted((Path(__file__).resolve().parents[1] / "benchmarks").glob("*.py")):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ImportFrom) and (node.module or "").startswith("skhmmgmr"):
                module = import_module(node.module)
                missing += [
                    f"{path.name}:{node.lineno}: {node.module}.{alias.name}"
                    for alias in node.names
                    if not hasattr(module, alias.name)
                ]
    assert not missing, "imports of names that do not exist:\n" + "\n".join(missing)
