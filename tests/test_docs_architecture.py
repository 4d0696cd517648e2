"""The architecture page: its sections are the package's subpackages, in the order of the layers.

Every module of the package is named on the page, in the section of the top-level entry (a
subpackage or a module of ``skhmmgmr/``) that holds it; every entry has its section; the
sections come in the order of ``tests/test_package_layers.py``'s layers, lowest first, and the
drawing of the floors shows those layers.
"""

import re
from pathlib import Path

from test_package_layers import LAYERS, RANK

ROOT = Path(__file__).resolve().parents[1]
PAGE = ROOT / "docs" / "architecture.rst"
MODULE = re.compile(r"``(skhmmgmr/[\w/]+\.py)``")
HEADING = re.compile(r"^``skhmmgmr/(\w+)(?:/|\.py)``: .+\n-+$", re.MULTILINE)
FLOOR = re.compile(r"^   floor +(\d+) ", re.MULTILINE)
ENTRY = re.compile(r"(?:skhmmgmr/)?(\w+)(?:/|\.py)")


def named_modules():
    return set(MODULE.findall(PAGE.read_text()))


def sections():
    """(entry, text) of every section headed by a top-level entry of the package."""
    text = PAGE.read_text()
    found = list(HEADING.finditer(text))
    ends = [m.start() for m in found[1:]] + [text.find("\nWhere to add")]
    return [(m.group(1), text[m.end() : end]) for m, end in zip(found, ends, strict=True)]


def _entry_of(module_path):
    parts = Path(module_path).relative_to("skhmmgmr").with_suffix("").parts
    return parts[0]


def test_every_module_named_on_the_architecture_page_exists():
    missing = sorted(path for path in named_modules() if not (ROOT / path).is_file())
    assert not missing, f"docs/architecture.rst names modules that do not exist: {missing}"


def test_every_module_of_the_package_is_on_the_architecture_page():
    modules = {str(p.relative_to(ROOT)) for p in (ROOT / "skhmmgmr").rglob("*.py")}
    unnamed = sorted(modules - named_modules())
    assert not unnamed, f"docs/architecture.rst does not say what these modules do: {unnamed}"


def test_the_sections_are_the_subpackages_in_the_order_of_the_layers():
    entries = [entry for entry, _ in sections()]
    # _version and legacy are on the ground floor and said in _core's section
    assert set(entries) == set(RANK) - {"_version", "legacy", "__main__"}
    ranks = [RANK[entry] for entry in entries]
    assert ranks == sorted(ranks), f"sections out of the layers' order: {entries}"
    for entry, text in sections():
        for module in MODULE.findall(text):
            if _entry_of(module) not in {"_version", "legacy", "__main__"}:
                assert _entry_of(module) == entry, f"{module} is named in the {entry} section"


def drawn_floors():
    """{floor: entries} of the drawing of the floors (its first code block): the entries of a
    floor are those its lines name (folders ``name/``, modules ``name.py``), the lines that
    follow a ``floor N`` line included."""
    text = PAGE.read_text()
    start = text.index(".. code-block:: text")
    block = text[start : text.index("\n\n", text.index("floor", start))]
    floors, current = {}, None
    for line in block.splitlines():
        found = FLOOR.match(line)
        if found:
            current = int(found.group(1))
            floors[current] = set()
        if current is not None:
            floors[current].update(ENTRY.findall(line))
    return floors


def test_the_drawing_of_the_floors_is_the_layers_of_the_layers_test():
    assert drawn_floors() == {floor: set(layer) for floor, layer in enumerate(LAYERS)}


def test_the_page_is_in_the_docs_table_of_contents():
    assert "architecture" in (ROOT / "docs" / "index.rst").read_text()
