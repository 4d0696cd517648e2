"""The package's boundaries, read from its source: who may touch what is private.

Three rules, checked by walking the abstract syntax tree of every module of the package:

- scikit-learn's private API (a ``_``-prefixed module or name) is imported by
  ``_core/_compat.py`` only, so a change in a scikit-learn release is dealt with in one place;
- no module reads another module's private state: an attribute access ``obj._name`` is allowed
  only in a module that defines ``_name`` or, for ``self._name``, in a subclass of a class whose
  module defines it (a protected hook, as scikit-learn's ``_validate_params`` is to its
  estimators); an import ``from .module import _name`` (under any alias) is never allowed, but
  from ``_core/_compat.py``, which lends scikit-learn's private names, and of a private module
  (``from . import _module``). A name a module imports from outside the package counts as
  defined there; a name imported from another module of the package does not, or the import
  would excuse itself;
- the emission model owns the form of the covariance: outside ``_hmm/_emissions.py`` (and the
  pure numerical functions of ``_hmm/_gaussian.py``) no module compares anything with a
  family's name (``"full"``, ``"tied"``...) or with a ``covariance_type``, names a family's
  class, or reads a covariance or precision field (``.covariances``, ``.full_covariances``,
  ``.precisions_chol``...): it asks the emission model's methods, so that a new family changes
  one module.

And one rule of ownership: the estimator's exporters (JSON, hmmlearn, stream) are one-line
methods that call the module owning the format.

Which layer may import which is ``tests/test_package_layers.py``'s rule.
"""

import ast
from collections import defaultdict
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "skhmmgmr"
COMPAT = PACKAGE / "_core" / "_compat.py"

# (module, private name) pairs that truly must cross a module boundary, each with its reason.
ALLOWED_PRIVATE_ACCESS: set[tuple[str, str]] = {
    # The estimator's model I/O mixin builds a fitted estimator without fit (from a JSON file,
    # an hmmlearn model or a FittedHMMGMR) and checks its parameters against the estimator
    # class's own constraints, as fit does: scikit-learn's convention for them is this name.
    ("_io.py", "_parameter_constraints"),
    # The command line checks an option that sets a model's parameter (--output-smoothing,
    # --sampling-period...) by that parameter's own constraint when it parses it, so that the
    # command line and the API refuse the same values alike, with no rule restated.
    ("_options.py", "_parameter_constraints"),
    # fit_on_cluster fits an estimator without calling its fit: it checks the estimator's
    # parameters against the class's own constraints first, as fit does.
    ("_dask.py", "_parameter_constraints"),
}


EMISSION_MODULES = {PACKAGE / "_hmm" / "_emissions.py", PACKAGE / "_hmm" / "_gaussian.py"}
FAMILY_NAMES = {"full", "tied", "diag", "spherical"}
FAMILY_CLASSES = {"FullCovariance", "TiedCovariance"}
COVARIANCE_FIELDS = {
    "covariances",
    "full_covariances",
    "precisions_chol",
    "_precisions_chol",
    "_distinct_precisions_chol",
}

# (module, what) pairs outside the emission model that may switch on the covariance form or
# read its fields, each with its reason. None today: a new one needs a reason here.
ALLOWED_COVARIANCE_FORM: dict[tuple[str, str], str] = {}


def _is_private(name):
    return name.startswith("_") and not (name.startswith("__") and name.endswith("__"))


def _modules():
    return sorted(path for path in PACKAGE.rglob("*.py"))


def _relative(path):
    return str(path.relative_to(PACKAGE))


def _trees():
    return {path: ast.parse(path.read_text(), filename=str(path)) for path in _modules()}


def _sklearn_private_imports(tree):
    """(line, text) of every import that reaches into scikit-learn's private API."""
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for alias in node.names:
                parts = alias.name.split(".")
                if parts[0] == "sklearn" and any(_is_private(p) for p in parts):
                    found.append((node.lineno, f"import {alias.name}"))
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            parts = node.module.split(".")
            if parts[0] != "sklearn":
                continue
            names = [alias.name for alias in node.names]
            if any(_is_private(p) for p in parts) or any(_is_private(n) for n in names):
                found.append((node.lineno, f"from {node.module} import {', '.join(names)}"))
    return found


def _defined_private_names(tree):
    """Private names a module defines: functions, classes, methods, attributes, globals."""
    names = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef | ast.ClassDef):
            names.add(node.name)
        elif isinstance(node, ast.Name) and isinstance(node.ctx, ast.Store):
            names.add(node.id)
        elif isinstance(node, ast.Attribute) and isinstance(node.ctx, ast.Store):
            names.add(node.attr)
        elif isinstance(node, ast.arg):
            names.add(node.arg)
        elif isinstance(node, ast.Import):
            names.update(alias.asname or alias.name.split(".")[0] for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            # from outside the package, the name it binds; from inside, only a private alias
            # (the name imported is read, not defined: _private_imports checks it)
            names.update(
                alias.asname or alias.name
                for alias in node.names
                if node.level == 0 or alias.asname
            )
    return {name for name in names if _is_private(name)}


def _private_accesses(tree):
    """(line, name, class) of every read of a private attribute.

    ``class`` is the enclosing class of a ``self._name`` (or ``Base._name``) read, else None.
    """
    found = []

    def visit(node, cls):
        if isinstance(node, ast.ClassDef):
            cls = node
        if (
            isinstance(node, ast.Attribute)
            and _is_private(node.attr)
            and not isinstance(node.ctx, ast.Store)
        ):
            bases = {b.id for b in cls.bases if isinstance(b, ast.Name)} if cls else set()
            owner = node.value.id if isinstance(node.value, ast.Name) else None
            inherited = owner in {"self", "cls"} | bases
            found.append((node.lineno, node.attr, cls if inherited else None))
        for child in ast.iter_child_nodes(node):
            visit(child, cls)

    visit(tree, None)
    return found


def _private_imports(tree):
    """(line, name, module, level) of every relative import of a private name, under any alias:
    ``from <level dots><module> import _name [as other]``."""
    return [
        (node.lineno, alias.name, node.module, node.level)
        for node in ast.walk(tree)
        if isinstance(node, ast.ImportFrom) and node.level > 0
        for alias in node.names
        if _is_private(alias.name)
    ]


def _lends(path, name, module, level):
    """Whether ``from <level dots><module> import name`` in ``path`` may import a private name:
    it comes from the compat module, or it is a module of the package."""
    if _module_path(path, module, level) == COMPAT:
        return True
    submodule = f"{module}.{name}" if module else name
    return _module_path(path, submodule, level).exists()


def _module_path(path, module, level):
    """The file a relative import ``from <level dots><module> import ...`` in ``path`` reads."""
    base = path.parent
    for _ in range(level - 1):
        base = base.parent
    target = base.joinpath(*module.split(".")) if module else base
    return (
        target.with_suffix(".py") if target.with_suffix(".py").exists() else target / "__init__.py"
    )


def _base_class_modules(path, tree, cls, trees, seen=None):
    """Modules defining the package classes ``cls`` derives from, transitively."""
    seen = set() if seen is None else seen
    imported_from = {}
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and node.level > 0:
            for alias in node.names:
                imported_from[alias.asname or alias.name] = _module_path(
                    path, node.module, node.level
                )
    local_classes = {n.name: n for n in ast.walk(tree) if isinstance(n, ast.ClassDef)}
    for base in cls.bases:
        name = base.id if isinstance(base, ast.Name) else None
        if name in local_classes and local_classes[name] is not cls:
            _base_class_modules(path, tree, local_classes[name], trees, seen)
        elif name in imported_from and imported_from[name] in trees:
            module = imported_from[name]
            if module not in seen:
                seen.add(module)
                parent = [n for n in ast.walk(trees[module]) if isinstance(n, ast.ClassDef)]
                for node in parent:
                    if node.name == name:
                        _base_class_modules(module, trees[module], node, trees, seen)
    return seen


def test_sklearn_private_api_is_imported_by_the_compat_module_only():
    trees = _trees()
    offenders = [
        f"{_relative(path)}:{line}: {text}"
        for path, tree in trees.items()
        if path != COMPAT
        for line, text in _sklearn_private_imports(tree)
    ]
    assert not offenders, "import scikit-learn's private API through _compat.py:\n" + "\n".join(
        offenders
    )
    # The compat module does what it claims: it re-exports the private names it imports.
    assert _sklearn_private_imports(trees[COMPAT]), "_compat.py imports nothing private"


def test_no_module_reads_another_modules_private_state():
    trees = _trees()
    defined_in = defaultdict(set)
    for path, tree in trees.items():
        for name in _defined_private_names(tree):
            defined_in[name].add(_relative(path))
    offenders = []
    for path, tree in trees.items():
        module = _relative(path)
        for line, name, cls in _private_accesses(tree):
            if module in defined_in[name] or (path.name, name) in ALLOWED_PRIVATE_ACCESS:
                continue
            if cls is not None:
                inherited = {_relative(m) for m in _base_class_modules(path, tree, cls, trees)}
                if inherited & defined_in[name]:
                    continue
            owners = ", ".join(sorted(defined_in[name])) or "outside the package"
            offenders.append(f"{module}:{line}: attribute {name} (defined in {owners})")
        for line, name, source, level in _private_imports(tree):
            if _lends(path, name, source, level) or (path.name, name) in ALLOWED_PRIVATE_ACCESS:
                continue
            owner = _relative(_module_path(path, source, level))
            offenders.append(f"{module}:{line}: import {name} (defined in {owner})")
    assert not offenders, "private state read across modules:\n" + "\n".join(offenders)


def _covariance_form_uses(tree):
    """(line, what) of every place that switches on the covariance form or reads its fields:
    a comparison with a family's name or with a ``covariance_type``, a ``match`` case on a
    family's name, a family's class named, a covariance or precision field read (also through
    ``getattr`` with a constant name)."""
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Compare):
            for operand in (node.left, *node.comparators):
                if isinstance(operand, ast.Constant) and operand.value in FAMILY_NAMES:
                    found.append((node.lineno, f"comparison with {operand.value!r}"))
                elif isinstance(operand, ast.Attribute) and operand.attr == "covariance_type":
                    found.append((node.lineno, "comparison with .covariance_type"))
        elif isinstance(node, ast.MatchValue):
            value = node.value
            if isinstance(value, ast.Constant) and value.value in FAMILY_NAMES:
                found.append((node.lineno, f"match case {value.value!r}"))
        elif isinstance(node, ast.Attribute) and not isinstance(node.ctx, ast.Store):
            if node.attr in COVARIANCE_FIELDS:
                found.append((node.lineno, f"read of .{node.attr}"))
            elif node.attr in FAMILY_CLASSES:
                found.append((node.lineno, f"class {node.attr}"))
        elif isinstance(node, ast.Name) and node.id in FAMILY_CLASSES:
            found.append((node.lineno, f"class {node.id}"))
        elif isinstance(node, ast.ImportFrom):
            for alias in node.names:
                if alias.name in FAMILY_CLASSES:
                    found.append((node.lineno, f"class {alias.name}"))
        elif (
            isinstance(node, ast.Call)
            and isinstance(node.func, ast.Name)
            and node.func.id in {"getattr", "hasattr"}
            and len(node.args) > 1
            and isinstance(node.args[1], ast.Constant)
            and node.args[1].value in COVARIANCE_FIELDS
        ):
            found.append((node.lineno, f"read of .{node.args[1].value}"))
    return found


def test_only_the_emission_model_knows_the_covariance_form():
    offenders = [
        f"{_relative(path)}:{line}: {what}"
        for path, tree in _trees().items()
        if path not in EMISSION_MODULES
        for line, what in _covariance_form_uses(tree)
        if (_relative(path), what) not in ALLOWED_COVARIANCE_FORM
    ]
    assert not offenders, (
        "the covariance form is switched on or read outside the emission model; ask a "
        "method of GaussianEmissions (skhmmgmr/_hmm/_emissions.py) instead:\n"
        + "\n".join(offenders)
    )


# The estimator's exporters and the module that owns each format.
EXPORTER_OWNERS = {
    "to_dict": "_hmm._portable",
    "export_json": "_hmm._portable",
    "from_dict": "_hmm._portable",
    "from_json": "_hmm._portable",
    "to_hmmlearn": "_hmm._hmmlearn",
    "from_hmmlearn": "_hmm._hmmlearn",
    "filter_stream": "streaming",
}


def test_the_estimators_exporters_are_one_line_delegations_to_their_owners():
    """``HMMGMRRegressor``'s JSON, hmmlearn and stream methods hold their docstring and one
    statement, a call of a name imported from the module that owns the format."""
    path = PACKAGE / "estimator" / "_io.py"
    tree = ast.parse(path.read_text())
    imported = {
        alias.asname or alias.name: node.module
        for node in tree.body
        if isinstance(node, ast.ImportFrom)
        for alias in node.names
    }
    methods = {
        node.name: node
        for node in ast.walk(tree)
        if isinstance(node, ast.FunctionDef) and node.name in EXPORTER_OWNERS
    }
    assert set(methods) == set(EXPORTER_OWNERS)
    for name, method in methods.items():
        body = method.body[1:] if ast.get_docstring(method) else method.body
        assert len(body) == 1 and isinstance(body[0], ast.Return | ast.Expr), name
        call = body[0].value
        assert isinstance(call, ast.Call) and isinstance(call.func, ast.Name), name
        owner = imported.get(call.func.id)
        assert owner == EXPORTER_OWNERS[name], f"{name} calls {call.func.id} of {owner}"


@pytest.mark.parametrize(
    "source, expected",
    [
        (
            'if emissions.covariance_type == "tied": pass',
            ["comparison with .covariance_type", "comparison with 'tied'"],
        ),
        ("from ._emissions import FullCovariance", ["class FullCovariance"]),
        ('x = "full" != kind', ["comparison with 'full'"]),
        ("same = a.covariance_type is b.kind", ["comparison with .covariance_type"]),
        ('match kind:\n    case "tied": pass', ["match case 'tied'"]),
        ("s = emissions.covariances", ["read of .covariances"]),
        ("s = model.data_emissions.full_covariances[0]", ["read of .full_covariances"]),
        ("p = gating.precisions_chol", ["read of .precisions_chol"]),
        ('p = getattr(gating, "precisions_chol")', ["read of .precisions_chol"]),
        ("tied = isinstance(e, TiedCovariance)", ["class TiedCovariance"]),
        # what stays allowed: a parameter's value passed on, a lookup by name, a method
        ("family = emission_family(self.covariance_type)", []),
        ('HMMGMRRegressor(covariance_type="tied")', []),
        ("s = emissions.state_covariances()", []),
        ("emissions.covariances = s", []),
        ("v = params.conditional_covariances", []),
    ],
)
def test_the_covariance_form_rule_sees_switches_and_field_reads(source, expected):
    assert [what for _, what in _covariance_form_uses(ast.parse(source))] == expected


@pytest.mark.parametrize(
    "source, expected",
    [
        ("from sklearn.base import _fit_context", 1),
        ("from sklearn.utils._param_validation import Interval", 1),
        ("import sklearn.utils._testing", 1),
        ("from sklearn.base import clone", 0),
        ("from ._em import fit_hmm", 0),
    ],
)
def test_the_sklearn_rule_recognises_private_imports(source, expected):
    assert len(_sklearn_private_imports(ast.parse(source))) == expected


def test_the_private_state_rule_sees_attribute_reads_and_imports():
    source = "est._center\nfrom .a import _b\nself._c = 1\nx.__len__\nfrom .d import _e as f"
    tree = ast.parse(source)
    assert [name for _, name, _ in _private_accesses(tree)] == ["_center"]
    assert [(name, module) for _, name, module, _ in _private_imports(tree)] == [
        ("_b", "a"),
        ("_e", "d"),
    ]


@pytest.mark.parametrize(
    "source, defined",
    [
        # an import of another module's private name does not define it, under any alias
        ("from .a import _b", set()),
        ("from .a import _b as c", set()),
        ("from .a import _b as _c", {"_c"}),
        # a private alias of a public name, and names from outside the package, are defined
        ("from .a import b as _b", {"_b"}),
        ("from sklearn.base import _fit_context", {"_fit_context"}),
        ("import numpy as _np", {"_np"}),
        ("def _f():\n    _x = 1", {"_f", "_x"}),
    ],
)
def test_an_import_of_another_modules_private_name_defines_nothing(source, defined):
    assert _defined_private_names(ast.parse(source)) == defined


def test_a_private_module_and_the_compat_modules_names_may_be_imported():
    module = PACKAGE / "estimator" / "_regressor.py"
    assert _lends(module, "_fit_context", "_core._compat", 2)
    assert _lends(PACKAGE / "__init__.py", "_version", None, 1)
    assert not _lends(module, "_private_name", "_io", 1)


def _version_tuple(text):
    parts = [int(p) for p in text.split(".")]
    return tuple(parts + [0] * (4 - len(parts)))


def test_the_oldest_constraints_are_the_lower_bounds_pyproject_claims():
    """CI's second run installs ``.ci/oldest-constraints.txt``: it must pin every runtime and
    test dependency at exactly the lower bound ``pyproject.toml`` claims."""
    import re
    import tomllib

    root = PACKAGE.parent
    project = tomllib.loads((root / "pyproject.toml").read_text())["project"]
    claimed = {}
    for requirement in project["dependencies"] + project["optional-dependencies"]["test"]:
        # an environment marker may follow (opendbc supports Python < 3.13 only)
        match = re.fullmatch(r"([A-Za-z0-9_-]+)(\[[^\]]*\])?>=([0-9.]+)(; .+)?", requirement)
        assert match, f"unexpected requirement {requirement!r}: give it a lower bound"
        claimed[match[1].lower()] = match[3]
    pinned = {}
    for line in (root / ".ci" / "oldest-constraints.txt").read_text().splitlines():
        line = line.split("#")[0].strip()
        if line:
            name, version = line.split("==")
            pinned[name.lower()] = version
    # pytest and ruff run the checks; their own newest versions are used in both runs
    for name in set(claimed) - {"pytest", "ruff"}:
        assert name in pinned, f"{name} is not pinned in .ci/oldest-constraints.txt"
        assert _version_tuple(pinned[name]) == _version_tuple(claimed[name]), (
            f"{name}: pyproject.toml claims >={claimed[name]}, CI tests {pinned[name]}"
        )


@pytest.mark.parametrize(
    "extra, why",
    [
        ("can", "the comma2k19 loader's DBC decoding"),
        ("fetch", "the range reads of comma2k19"),
        ("fmu", "the FMU export, validated and simulated by FMPy"),
    ],
)
def test_the_test_extra_holds_the_optional_extras(extra, why):
    """CI installs ``[test]``: what an extra serves is tested only if the extra is part of
    it, with the same bounds."""
    import tomllib

    extras = tomllib.loads((PACKAGE.parent / "pyproject.toml").read_text())["project"][
        "optional-dependencies"
    ]
    assert set(extras[extra]) <= set(extras["test"]), f"{why} is not tested"
