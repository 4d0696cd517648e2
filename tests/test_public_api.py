"""The public names: where users import them, and the module they carry (``__module__``).

The rule (``skhmmgmr/_core/_public.py``): a public class or function carries the deepest public
module that exports it (``skhmmgmr.metrics.PerformanceScore``), ``skhmmgmr`` when only the
package exports it (``skhmmgmr.FittedHMMGMR``). Pickles, joblib and skops files (and the list of
types skops asks to trust) name a class by that path, so none of them names a private module.
"""

import inspect
import json
import pickle
import re
import subprocess
import sys
from importlib import import_module
from pathlib import Path

import pytest

from skhmmgmr._core._public import is_private_path

FIXTURES = Path(__file__).resolve().parent / "fixtures"
LEGACY = json.loads((FIXTURES / "legacy_0_1_0_public_names.json").read_text())
LEGACY_MODULES = sorted(LEGACY["modules"])
# public modules added since 0.1.0
NEW_MODULES = ["skhmmgmr.export"]
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


@pytest.mark.parametrize(
    "name, value, exporters", _public_objects(), ids=lambda v: v if isinstance(v, str) else ""
)
def test_a_public_name_carries_the_deepest_public_module_that_exports_it(name, value, exporters):
    module_name = value.__module__
    assert not is_private_path(module_name), f"{name}.__module__ is private: {module_name}"
    assert getattr(import_module(module_name), value.__qualname__) is value
    assert module_name == max(exporters, key=lambda m: m.count(".")), (name, exporters)


def test_a_pickle_names_public_modules_only():
    import numpy as np

    from skhmmgmr import HMMGMRRegressor

    X = np.cumsum(np.random.default_rng(0).normal(size=(200, 2)), axis=0) / 10
    model = HMMGMRRegressor(n_states=2, n_iter=5, random_state=0).fit(X, X[:, 0])
    data = pickle.dumps(model, protocol=0)
    assert b"skhmmgmr.estimator\nHMMGMRRegressor" in data
    assert b"skhmmgmr\nFittedHMMGMR" in data
    assert pickle.loads(data).predict(X).tolist() == model.predict(X).tolist()


def test_the_old_private_modules_are_the_modules_of_today():
    from skhmmgmr._hmm import _fitted
    from skhmmgmr._legacy import MOVED_IN_0_2

    assert import_module("skhmmgmr._fitted") is _fitted
    for old, new in MOVED_IN_0_2.items():
        assert import_module(old) is import_module(new), old


def test_the_package_runs_as_a_module_and_a_script():
    result = subprocess.run(
        [sys.executable, "-m", "skhmmgmr", "--help"], capture_output=True, text=True, check=True
    )
    assert "demo" in result.stdout
    from skhmmgmr.cli import main

    assert main.__module__ == "skhmmgmr.cli"


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
