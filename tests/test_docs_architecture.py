"""The architecture page names every module of the package, and only modules that exist."""

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PAGE = ROOT / "docs" / "architecture.rst"


def named_modules():
    return set(re.findall(r"``(skhmmgmr/[\w/]+\.py)``", PAGE.read_text()))


def test_every_module_named_on_the_architecture_page_exists():
    missing = sorted(path for path in named_modules() if not (ROOT / path).is_file())
    assert not missing, f"docs/architecture.rst names modules that do not exist: {missing}"


def test_every_module_of_the_package_is_on_the_architecture_page():
    modules = {str(p.relative_to(ROOT)) for p in (ROOT / "skhmmgmr").rglob("*.py")}
    unnamed = sorted(modules - named_modules())
    assert not unnamed, f"docs/architecture.rst does not say what these modules do: {unnamed}"


def test_the_page_is_in_the_docs_table_of_contents():
    assert "architecture" in (ROOT / "docs" / "index.rst").read_text()
