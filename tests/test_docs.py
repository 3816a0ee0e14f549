"""The docs site (``mkdocs.yml``, ``docs/``): every page is in the nav and linked from the index,
and ``mkdocs build --strict`` passes (a broken link or a page outside the nav fails it)."""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import yaml

from helpers import REPO

DOCS = REPO / "docs"


def _nav_pages() -> list[str]:
    nav = yaml.safe_load((REPO / "mkdocs.yml").read_text())["nav"]
    return [page for entry in nav for page in entry.values()]


def test_every_page_is_in_the_nav_and_linked_from_the_index() -> None:
    pages = sorted(p.name for p in DOCS.glob("*.md"))
    assert sorted(_nav_pages()) == pages
    linked = set(re.findall(r"\]\(([^)#]+\.md)", (DOCS / "index.md").read_text()))
    assert linked == set(pages) - {"index.md"}, linked


def test_mkdocs_build_strict(tmp_path: Path) -> None:
    mkdocs = Path(sys.executable).with_name("mkdocs")
    r = subprocess.run([str(mkdocs), "build", "--strict", "-d", str(tmp_path / "site")], cwd=REPO,
                       capture_output=True, text=True, timeout=300, env=dict(os.environ, NO_MKDOCS_2_WARNING="1"))
    assert r.returncode == 0, r.stdout[-3000:] + r.stderr[-3000:]
    assert "Plans and replans one task" in (tmp_path / "site" / "api" / "index.html").read_text()


# ----------------------------------------------------------------------------- section references
FENCE = re.compile(r"^(```|~~~).*?^\1[ \t]*$", re.M | re.S)
# README "X", README's "X" (a quoted name may wrap, in a comment too), the README's X section
README_QUOTED = re.compile(r"""README(?:'s)?\s+"([^"]{1,120})\"""")
README_SECTION = re.compile(r"the README's ([\w][\w ,:()-]{0,60}?) section")
DOC_LINK = re.compile(r"\]\(((?:docs/)?[\w-]*\.md)?#([^)\s]+)\)")


def _headings(text: str) -> list[str]:
    """The Markdown headings of a page (outside its fenced blocks), their text as rendered."""
    out = []
    for line in FENCE.sub("", text).splitlines():
        m = re.match(r"#{1,6}\s+(.+?)\s*#*\s*$", line)
        if m:
            h = re.sub(r"\[([^\]]*)\]\([^)]*\)", r"\1", m.group(1))     # a link: its text
            out.append(re.sub(r"`|\*\*", "", h))                           # code, bold: their text
    return out


def _anchors(text: str) -> set[str]:
    """The ids MkDocs (Python-Markdown's toc) gives a page's headings: lowercased, punctuation
    dropped, runs of spaces and hyphens one hyphen; a repeated id gets _1, _2, ..."""
    seen: dict[str, int] = {}
    for h in _headings(text):
        slug = re.sub(r"[-\s]+", "-", re.sub(r"[^\w\s-]", "", h).strip().lower())
        n = seen.get(slug, 0)
        seen[slug] = n + 1
        if n:
            seen[f"{slug}_{n}"] = 1
    return set(seen)


def _scanned_files() -> list[Path]:
    pats = ("README.md", "docs/*.md", "realize/**/*.py", "scripts/**/*.py", "configs/**/*.yaml",
            "configs/**/*.md", "Makefile")
    return sorted({p for pat in pats for p in REPO.glob(pat) if p.is_file()})


def test_section_references_name_existing_headings() -> None:
    """A README section named in the docs, the code or the configs is one README.md has (the
    topics moved to docs/: name the page there), and every link `page.md#anchor` of the docs
    (README.md: `docs/page.md#anchor`) names a heading that page has."""
    # the anchor rule on headings like the docs' own (punctuation, code, a repeat), as MkDocs renders them
    assert _anchors("# GPU\n## GPU: what was verified, and how to check it\n```bash\n# no heading\n```\n"
                    "#### Where a seed-paper run's time goes now (profiled at `1fc1637`)\n"
                    "## `experiment=tune_ce`\n# Python API\n## Python API\n") == {
        "gpu", "gpu-what-was-verified-and-how-to-check-it", "experimenttune_ce",
        "where-a-seed-paper-runs-time-goes-now-profiled-at-1fc1637", "python-api", "python-api_1"}
    readme = _headings((REPO / "README.md").read_text())
    names = set(readme) | {h.split(":")[0] for h in readme}
    anchors = {p.name: _anchors(p.read_text()) for p in DOCS.glob("*.md")}
    bad = []
    for path in _scanned_files():
        text = path.read_text()
        rel = path.relative_to(REPO)
        for m in [*README_QUOTED.finditer(text), *README_SECTION.finditer(text)]:
            name = re.sub(r"\s*\n[\s#]*", " ", m.group(1)).strip()
            if name not in names:
                bad.append(f"{rel}:{text.count(chr(10), 0, m.start()) + 1}: {m.group(0)!r} "
                           f"(README.md has no such heading)")
        if path.suffix != ".md" or not (rel.parts[0] == "docs" or str(rel) == "README.md"):
            continue
        prose = FENCE.sub(lambda f: "\n" * f.group(0).count("\n"), text)
        for m in DOC_LINK.finditer(prose):
            target, anchor = m.group(1), m.group(2)
            if rel.parts[0] != "docs" and not (target or "").startswith("docs/"):
                continue                                   # README.md's own anchors: GitHub's, not checked
            page = Path(target).name if target else rel.name
            if anchor not in anchors.get(page, set()):
                bad.append(f"{rel}:{prose.count(chr(10), 0, m.start()) + 1}: #{anchor} is no heading of docs/{page}")
    assert not bad, "\n".join(bad)
