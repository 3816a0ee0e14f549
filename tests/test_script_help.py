"""Every script's ``--help`` opens with whole sentences: its docstring's first paragraph, not
the paragraph's first line cut at a line break. All scripts' help is printed in one child
process (``runpy`` of each script with ``--help``), as a user would see it."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parent.parent
# make_fabrics_fixtures.py runs in its own environment (the fabrics package and casadi)
OWN_ENVIRONMENT = {"make_fabrics_fixtures.py"}

PRINT_HELPS = r"""
import contextlib, io, json, runpy, sys
out = {}
for path in sys.argv[1:]:
    sys.argv = [path, "--help"]
    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        try:
            runpy.run_path(path, run_name="__main__")
        except SystemExit:
            pass
    out[path] = buf.getvalue()
print("HELPS" + json.dumps(out))
"""


def _description(help_text: str) -> str:
    """The paragraph after argparse's usage block: the description."""
    paragraphs = [p for p in help_text.split("\n\n") if p.strip()]
    assert len(paragraphs) >= 2 and paragraphs[0].startswith("usage:"), help_text[:300]
    return " ".join(paragraphs[1].split())


@pytest.mark.slow  # a process that imports every script (15 s on a busy 2-core host): make test keeps a
# script's argument parser in a process (tests/test_execute.py, test_script_refuses_an_unknown_family_in_one_line)
def test_script_help_descriptions_are_whole_sentences() -> None:
    scripts = sorted(str(p.relative_to(REPO)) for p in (REPO / "scripts").glob("*.py")
                     if p.name not in OWN_ENVIRONMENT)
    r = subprocess.run([sys.executable, "-c", PRINT_HELPS, *scripts], cwd=REPO, capture_output=True, text=True,
                       timeout=300)
    assert r.returncode == 0, r.stderr[-3000:]
    helps = json.loads(r.stdout.split("HELPS", 1)[1])
    cut = {}
    for path, text in helps.items():
        d = _description(text)
        if not d.endswith((".", "?", ")")):
            cut[path] = d[-60:]
    assert not cut, f"--help descriptions cut mid-sentence: {cut}"
