"""The module map of docs/architecture.md, from the code: each package's modules with the first
paragraph of their docstrings.

What it does: walks ``realize/`` (the files git tracks, where git is there; else every ``.py``),
and prints, per package, one bullet per module: its path under ``realize/`` and its docstring's
first paragraph on one line. Paste the output under "Modules" in docs/architecture.md when a
module is added, renamed or says something new; tests/test_architecture_map.py fails while a
module of a run-layer package (``spec``, ``workers``, ``validation``, ``run``, ``repair``,
``cli``) or of ``realize/execution/`` is missing from the page.
What it doesn't: write the page (the map's prose around the list is written by hand), or read
anything but docstrings (nothing is imported).

    python scripts/module_map.py [PACKAGE ...]     # e.g. run execution; default: every package
"""

from __future__ import annotations

import argparse
import ast
import subprocess
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
PKG = REPO / "realize"


def tracked_modules() -> list[Path]:
    """The package's ``.py`` files git tracks (every one where git cannot say), sorted."""
    try:
        out = subprocess.run(["git", "ls-files", "realize"], cwd=REPO, capture_output=True, text=True,
                             check=True).stdout.split()
        files = [REPO / f for f in out if f.endswith(".py")]
    except (OSError, subprocess.CalledProcessError):
        files = list(PKG.rglob("*.py"))
    return sorted(f for f in files if f.is_file())


def first_paragraph(path: Path) -> str:
    """The module docstring's first paragraph on one line ('' without a docstring)."""
    doc = ast.get_docstring(ast.parse(path.read_text())) or ""
    return " ".join(doc.strip().split("\n\n")[0].split())


def module_map(packages: list[str] | None = None) -> str:
    """Markdown: a heading per package (``cli``, ``run``, ...), a bullet per module."""
    by_pkg: dict[str, list[Path]] = {}
    for f in tracked_modules():
        rel = f.relative_to(PKG)
        pkg = "/".join(rel.parts[:-1]) or "(top level)"
        by_pkg.setdefault(pkg, []).append(f)
    lines: list[str] = []
    for pkg in sorted(by_pkg, key=lambda p: (p != "(top level)", p)):
        if packages and not any(pkg == p or pkg.startswith(p + "/") for p in packages):
            continue
        lines.append(f"**`realize/{pkg}/`**" if pkg != "(top level)" else "**`realize/`** (top level)")
        lines.append("")
        for f in by_pkg[pkg]:
            lines.append(f"- `{f.relative_to(PKG).as_posix()}`: {first_paragraph(f)}")
        lines.append("")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=" ".join(__doc__.split("\n\n")[0].split()))
    ap.add_argument("packages", nargs="*", help="packages under realize/ (default: all)")
    args = ap.parse_args(argv)
    print(module_map(args.packages or None))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
