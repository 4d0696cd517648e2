"""Checks a JSON document against a JSON Schema, naming the key at fault: no dependency.

The model file's rules are written once, in its JSON Schema (draft 2020-12,
``skhmmgmr/portable_schema.json``), which users validate files with; the reader checks every
file against the same schema with :func:`check_document`, so that the two never disagree and
a new key needs only its schema entry (and the lines that read and write it). ``jsonschema`` is
not needed at run time: this module implements the keywords the schema uses,
:data:`KEYWORDS` (``tests/test_portable_schema.py`` checks that the shipped schema uses no
other), with the draft's meaning and one stricter rule: a ``"number"`` is finite (JSON has no
infinite or NaN number; Python's parser reads ``1e400`` as ``inf``).

:func:`check_document` raises ``ValueError`` at the first rule broken, naming the key by its
path (``'steps[1].model.filter.input_means[0][2]'``). Keywords are checked in a fixed order, so
that the message names the most basic problem: the kind of the value, its constants, its
bounds, then for an object its required keys, its properties and its unknown keys, for an
array its size, what it must contain, its items and their uniqueness, then the subschemas
applied in place (``$ref``, ``allOf``, ``if``/``then``/``else``, ``anyOf``, ``oneOf``, ``not``).
A subschema with a ``title`` names the value by it when the value itself is wrong
(``'steps[0].name' must be a step name (text without '__')``).
"""

import math
import re

# keywords that only annotate: they never refuse a value
_ANNOTATIONS = frozenset(
    {"$schema", "$id", "$comment", "$defs", "title", "description", "default", "examples"}
)
#: Every keyword :func:`check_document` knows.
KEYWORDS = _ANNOTATIONS | {
    "$ref",
    "type",
    "const",
    "enum",
    "minimum",
    "maximum",
    "exclusiveMinimum",
    "exclusiveMaximum",
    "minLength",
    "pattern",
    "required",
    "properties",
    "additionalProperties",
    "unevaluatedProperties",
    "items",
    "minItems",
    "maxItems",
    "uniqueItems",
    "contains",
    "minContains",
    "maxContains",
    "allOf",
    "anyOf",
    "oneOf",
    "if",
    "then",
    "else",
    "not",
}

_KINDS = {
    "object": "an object",
    "array": "a list",
    "string": "text",
    "integer": "a whole number",
    "number": "a number",
    "boolean": "true or false",
    "null": "null",
}


class _Invalid(ValueError):
    """A broken rule: the path of the value and what is wrong with it (``whole``: the value
    itself, not a part of it; ``final``: a message that no ``title`` replaces)."""

    def __init__(self, path, problem, *, final=False, whole=False):
        super().__init__(path, problem)
        self.path, self.problem, self.final, self.whole = path, problem, final, whole

    def __str__(self):
        if self.problem.startswith("lacks the key"):
            return f"the model file {self.problem}"
        return f"{_where(self.path)} {self.problem}"


def _where(path):
    if not path:
        return "the file"
    text = ""
    for part in path:
        text += f"[{part}]" if isinstance(part, int) else f".{part}"
    return repr(text.lstrip("."))


def _key(path, key):
    return repr(_where((*path, key)).strip("'"))


class _Root(dict):
    """The document's schema (for ``$ref``), with the checks postponed to the end of a pass."""

    def __init__(self, schema, postponed):
        super().__init__(schema)
        self.postponed = postponed


def check_document(document, schema, *, postponed=None):
    """Check ``document`` (parsed JSON) against ``schema``; ``ValueError`` naming the key of
    the first rule broken.

    With a list ``postponed``, the uniqueness of the items of arrays (``uniqueItems``, such as
    repeated names) is not checked but appended to it as functions to call (each raising the
    same ``ValueError``), so that the caller checks them after its own cheaper checks.
    """
    try:
        _check(schema, document, (), _Root(schema, postponed))
    except _Invalid as exc:
        raise ValueError(str(exc)) from None


def is_valid(document, schema):
    """Whether ``document`` follows ``schema``."""
    return is_valid_under(schema, document, _Root(schema, None))


def _resolve(schema, root):
    """The subschema a ``$ref`` of the document's own schema names (``#`` or ``#/$defs/x``)."""
    reference = schema["$ref"]
    if not reference.startswith("#"):
        raise ValueError(f"the schema refers to {reference!r}; only local references are read")
    target = root
    for part in filter(None, reference[1:].split("/")):
        target = target[part]
    return target


def _is_kind(value, kind):
    if kind == "object":
        return isinstance(value, dict)
    if kind == "array":
        return isinstance(value, list)
    if kind == "string":
        return isinstance(value, str)
    if kind == "boolean":
        return isinstance(value, bool)
    if kind == "null":
        return value is None
    if isinstance(value, bool):
        return False
    if kind == "integer":
        return isinstance(value, int)
    return isinstance(value, int | float)  # "number"


def _finite(value):
    try:
        return math.isfinite(value)
    except OverflowError:  # an integer beyond the largest float
        return False


def _frozen(value):
    """A hashable form of a JSON value, equal for values JSON calls equal (1 and 1.0, not
    true and 1)."""
    if isinstance(value, dict):
        return ("object", frozenset((key, _frozen(item)) for key, item in value.items()))
    if isinstance(value, list):
        return ("array", tuple(_frozen(item) for item in value))
    if isinstance(value, bool):
        return ("boolean", value)
    return ("value", value)


def _equal(a, b):
    return _frozen(a) == _frozen(b)


def _check_kind(schema, value, path):
    kinds = schema["type"]
    kinds = [kinds] if isinstance(kinds, str) else kinds
    if not any(_is_kind(value, kind) for kind in kinds):
        wanted = " or ".join(_KINDS[kind] for kind in kinds)
        raise _Invalid(path, f"must be {wanted}, got {value!r:.100}")
    if isinstance(value, float | int) and not isinstance(value, bool) and not _finite(value):
        raise _Invalid(path, f"is {value!r:.30}, not a finite number", final=True)


_BOUNDS = {
    "minimum": (lambda value, bound: value >= bound, "at least"),
    "exclusiveMinimum": (lambda value, bound: value > bound, "greater than"),
    "maximum": (lambda value, bound: value <= bound, "at most"),
    "exclusiveMaximum": (lambda value, bound: value < bound, "less than"),
}


def _check_value(schema, value, path):
    """The keywords on the value itself: kind, constants, bounds, text."""
    if "type" in schema:
        _check_kind(schema, value, path)
    if "const" in schema and not _equal(value, schema["const"]):
        raise _Invalid(path, f"is {value!r:.100}, expected {schema['const']!r}")
    if "enum" in schema and not any(_equal(value, option) for option in schema["enum"]):
        raise _Invalid(path, f"is {value!r:.100}, expected one of {schema['enum']!r}")
    if _is_kind(value, "number") and not _BOUNDS.keys().isdisjoint(schema):
        if not _finite(value):
            raise _Invalid(path, f"is {value!r:.30}, not a finite number", final=True)
        for keyword, (holds, words) in _BOUNDS.items():
            if keyword in schema and not holds(value, schema[keyword]):
                raise _Invalid(path, f"must be {words} {schema[keyword]}, got {value!r}")
    if isinstance(value, str):
        if len(value) < schema.get("minLength", 0):
            raise _Invalid(path, f"must hold at least {schema['minLength']} character(s)")
        if "pattern" in schema and not re.search(schema["pattern"], value):
            raise _Invalid(path, f"is {value!r:.100}, not of the form {schema['pattern']!r}")


def _check_object(schema, value, path, root):
    """Required keys, properties and unknown keys; the keys evaluated."""
    for key in schema.get("required", ()):
        if key not in value:
            raise _Invalid(path, f"lacks the key {_key(path, key)}")
    evaluated = set()
    for key, subschema in schema.get("properties", {}).items():
        if key in value:
            _check(subschema, value[key], (*path, key), root)
            evaluated.add(key)
    if "additionalProperties" in schema:
        others = [key for key in value if key not in evaluated]
        _check_others(schema["additionalProperties"], value, others, path, root)
        evaluated.update(others)
    return evaluated


def _check_others(subschema, value, keys, path, root):
    if subschema is False and keys:
        raise _Invalid(path, f"holds the unknown key(s) {sorted(keys)}")
    if isinstance(subschema, dict):
        for key in keys:
            _check(subschema, value[key], (*path, key), root)


def _title(schema, root):
    while "$ref" in schema and "title" not in schema:
        schema = _resolve(schema, root)
    return schema.get("title", "the item described")


def _check_array(schema, value, path, root):
    """Size, containment, items and their uniqueness."""
    if len(value) < schema.get("minItems", 0):
        least = schema["minItems"]
        raise _Invalid(path, "must be a non-empty list" if least == 1 else f"needs {least} item(s)")
    if len(value) > schema.get("maxItems", math.inf):
        raise _Invalid(path, f"holds {len(value)} item(s), at most {schema['maxItems']}")
    if "contains" in schema:
        found = sum(is_valid_under(schema["contains"], item, root) for item in value)
        least, most = schema.get("minContains", 1), schema.get("maxContains", math.inf)
        if not least <= found <= most:
            count = f"exactly {least}" if least == most else f"at least {least}"
            items = "item that is" if least == 1 else "items that are"
            what = _title(schema["contains"], root)
            raise _Invalid(path, f"must hold {count} {items} {what}; it holds {found}")
    if "items" in schema:
        _check_items(schema["items"], value, path, root)
    if schema.get("uniqueItems"):
        if root.postponed is None:
            _check_unique(value, path)
        else:
            root.postponed.append(lambda: check_unique(value, path))


def check_unique(value, path):
    """``ValueError`` naming the key when items of the list ``value`` repeat (linear time)."""
    try:
        _check_unique(value, path)
    except _Invalid as exc:
        raise ValueError(str(exc)) from None


def _check_unique(value, path):
    seen, repeated = set(), []
    for item in value:
        frozen = _frozen(item)
        if frozen in seen:
            repeated.append(item)
        seen.add(frozen)
    if repeated:
        shown = sorted({repr(item) for item in repeated})[:10]
        raise _Invalid(path, f"holds [{', '.join(shown)}] more than once")


def _simple_kind(schema, root):
    """The one kind a schema asks of a value and nothing more (``{"type": "number"}``), or
    None: such items are checked in one loop."""
    while set(schema) - _ANNOTATIONS == {"$ref"}:
        schema = _resolve(schema, root)
    if set(schema) - _ANNOTATIONS == {"type"} and isinstance(schema["type"], str):
        return schema["type"]
    return None


def _check_items(items, value, path, root):
    kind = _simple_kind(items, root)
    if kind is None:
        for index, item in enumerate(value):
            _check(items, item, (*path, index), root)
        return
    for index, item in enumerate(value):
        if not _is_kind(item, kind) or (kind in ("number", "integer") and not _finite(item)):
            _check_kind({"type": kind}, item, (*path, index))


def _attempt(schema, value, path, root):
    """The keys ``schema`` evaluates of ``value``, or the ``_Invalid`` of the first rule it
    breaks: a try, every rule checked (none postponed), that decides what applies."""
    postponed, root.postponed = root.postponed, None
    try:
        return _check(schema, value, path, root)
    except _Invalid as exc:
        return exc
    finally:
        root.postponed = postponed


def is_valid_under(schema, value, root):
    """Whether ``value`` follows ``schema``, a subschema of ``root``, every rule checked."""
    return not isinstance(_attempt(schema, value, (), root), _Invalid)


def _check(schema, value, path, root):
    """Check ``value`` at ``path``; the keys of an object evaluated here (for
    ``unevaluatedProperties``)."""
    if schema is True:
        return set()
    if schema is False:
        raise _Invalid(path, f"is {value!r:.100}, where the format allows no value")
    try:
        try:
            _check_value(schema, value, path)
        except _Invalid as exc:
            exc.whole = True  # the value itself is wrong, not a part of it
            raise
        evaluated = set()
        if isinstance(value, dict):
            evaluated |= _check_object(schema, value, path, root)
        elif isinstance(value, list):
            _check_array(schema, value, path, root)
        evaluated |= _check_in_place(schema, value, path, root)
    except _Invalid as exc:
        # a value that is itself wrong (not a part of it) is named by what it must be
        if "title" in schema and exc.whole and exc.path == path and not exc.final:
            raise _Invalid(path, f"must be {schema['title']}, got {value!r:.100}") from None
        raise
    if "unevaluatedProperties" in schema and isinstance(value, dict):
        others = [key for key in value if key not in evaluated]
        _check_others(schema["unevaluatedProperties"], value, others, path, root)
        evaluated.update(others)
    return evaluated


def _check_in_place(schema, value, path, root):
    """The subschemas applied to the value itself; the keys they evaluated."""
    evaluated = set()
    if "$ref" in schema:
        evaluated |= _check(_resolve(schema, root), value, path, root)
    for subschema in schema.get("allOf", ()):
        evaluated |= _check(subschema, value, path, root)
    if "if" in schema:
        matched = _attempt(schema["if"], value, path, root)
        if isinstance(matched, _Invalid):
            if "else" in schema:
                evaluated |= _check(schema["else"], value, path, root)
        else:
            evaluated |= matched
            if "then" in schema:
                evaluated |= _check(schema["then"], value, path, root)
    for keyword in ("anyOf", "oneOf"):
        if keyword in schema:
            evaluated |= _check_alternatives(keyword, schema[keyword], value, path, root)
    if "not" in schema and is_valid_under(schema["not"], value, root):
        raise _Invalid(path, f"is {value!r:.100}, which the format does not allow", whole=True)
    return evaluated


def _check_alternatives(keyword, alternatives, value, path, root):
    """``anyOf`` (at least one) or ``oneOf`` (exactly one): the deepest error of the
    alternatives when none holds, for it names the key most precisely."""
    passed, errors = [], []
    for subschema in alternatives:
        result = _attempt(subschema, value, path, root)
        (errors if isinstance(result, _Invalid) else passed).append(result)
    if not passed:
        raise max(errors, key=lambda exc: len(exc.path))
    if keyword == "oneOf" and len(passed) > 1:
        raise _Invalid(path, f"matches {len(passed)} forms of the format, expected one")
    return set().union(*passed)
