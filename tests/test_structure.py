"""The package's shape, checked from its source text: module size, import cycles, backend branches.

Import cycles are found on the import statements of every module in ``realize/`` and ``envs/``
(read with ``ast``, so ``if TYPE_CHECKING:`` and function-local imports count too), as a
directed graph whose strongly connected components must all be single modules (networkx).
"""

from __future__ import annotations

import ast
import re
from pathlib import Path

import networkx as nx
import pytest

REPO = Path(__file__).resolve().parent.parent
PACKAGES = ("realize", "envs")
MAX_LINES = 400
# the scene backends are the only modules that may ask which backend runs
BACKEND_MODULES = {"realize.scene.cpu_tiled", "realize.scene.gpu", "realize.scene.backends"}


def _modules() -> dict[str, Path]:
    out = {}
    for pkg in PACKAGES:
        for p in sorted((REPO / pkg).rglob("*.py")):
            rel = p.relative_to(REPO).with_suffix("")
            parts = list(rel.parts)
            if parts[-1] == "__init__":
                parts = parts[:-1]
            out[".".join(parts)] = p
    return out


def _imports(name: str, path: Path, known: set[str]) -> set[str]:
    tree = ast.parse(path.read_text())
    is_pkg = path.name == "__init__.py"
    out: set[str] = set()
    for node in ast.walk(tree):
        targets: list[str] = []
        if isinstance(node, ast.Import):
            targets = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = name.split(".")
                base = base if is_pkg else base[:-1]
                base = base[: len(base) - (node.level - 1)]
                mod = ".".join(base + ([node.module] if node.module else []))
            else:
                mod = node.module or ""
            targets = [mod] + [f"{mod}.{a.name}" for a in node.names]
        for t in targets:
            # the deepest known module the import names (``from realize.x import y`` -> realize.x)
            parts = t.split(".")
            for i in range(len(parts), 0, -1):
                cand = ".".join(parts[:i])
                if cand in known:
                    if cand != name:
                        out.add(cand)
                    break
    return out


def test_no_module_over_400_lines() -> None:
    long = {n: len(p.read_text().splitlines()) for n, p in _modules().items()}
    long = {n: k for n, k in long.items() if k > MAX_LINES}
    assert not long, f"modules over {MAX_LINES} lines: {long}"


def test_no_import_cycle() -> None:
    mods = _modules()
    g = nx.DiGraph()
    g.add_nodes_from(mods)
    for n, p in mods.items():
        for m in _imports(n, p, set(mods)):
            # a package's __init__ importing its own submodules is not a cycle of two jobs
            if not m.startswith(n + "."):
                g.add_edge(n, m)
    cycles = [sorted(c) for c in nx.strongly_connected_components(g) if len(c) > 1]
    assert not cycles, f"import cycles: {cycles}"


def test_backend_branches_only_in_backend_modules() -> None:
    pat = re.compile(r"\bbackend\s*[!=]=")
    hits = [f"{n}:{i + 1}" for n, p in _modules().items() if n not in BACKEND_MODULES
            for i, line in enumerate(p.read_text().splitlines()) if pat.search(line)]
    assert not hits, f"'backend ==' branches outside the scene backends: {hits}"


@pytest.mark.parametrize("name", sorted(_modules()))
def test_module_has_docstring(name: str) -> None:
    tree = ast.parse(_modules()[name].read_text())
    assert ast.get_docstring(tree), f"{name} has no module docstring"
