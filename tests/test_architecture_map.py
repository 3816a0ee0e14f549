"""The module maps cannot go stale: every module of the run-layer packages (``spec``, ``workers``,
``validation``, ``run``, ``repair``, ``cli``) and of ``realize/execution/`` is named in
docs/architecture.md's module list, and every module of a run-layer package in that package's own
docstring map. Fast: reads text, imports nothing."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

from helpers import load_script

REPO = Path(__file__).resolve().parents[1]
PKG = REPO / "realize"
DOC = REPO / "docs" / "architecture.md"
RUN_LAYER = ["spec", "workers", "validation", "run", "repair", "cli"]


def _modules(*packages: str) -> list[Path]:
    return sorted(p for pkg in packages for p in (PKG / pkg).rglob("*.py") if "__pycache__" not in p.parts)


@pytest.mark.parametrize("package", [*RUN_LAYER, "execution"])
def test_every_module_is_on_the_architecture_page(package: str) -> None:
    text = DOC.read_text()
    missing = [p.relative_to(PKG).as_posix() for p in _modules(package)
               if f"`{p.relative_to(PKG).as_posix()}`" not in text]
    assert not missing, (f"docs/architecture.md's module list lacks {missing}: print the list with "
                         f"`python scripts/module_map.py {package}` and paste it under 'Modules'")


@pytest.mark.parametrize("package", RUN_LAYER)
def test_the_package_docstring_names_every_module(package: str) -> None:
    doc = ast.get_docstring(ast.parse((PKG / package / "__init__.py").read_text())) or ""
    names = [p.stem for p in (PKG / package).glob("*.py") if p.stem != "__init__"]
    missing = [n for n in sorted(names) if f"``{n}``" not in doc]
    assert not missing, f"realize/{package}/__init__.py's map does not name {missing}"


def test_the_module_map_script_lists_what_the_page_checks() -> None:
    """scripts/module_map.py prints a bullet per tracked module, named as the page names it."""
    text = load_script("module_map").module_map(["execution"])
    assert "**`realize/execution/`**" in text and "realize/run/" not in text
    assert "- `execution/world.py`: The execution world:" in text
