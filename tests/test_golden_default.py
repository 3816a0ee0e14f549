"""The default search's golden run (``seed_paper_default``: restores, two worker processes), bit for
bit against ``tests/fixtures/golden_runs.json``: the golden run that ``make test`` keeps, in a file
of its own so that it runs beside other files. The same run with MKL told it runs on an Intel CPU
(``scripts/check_mkl_vendor.py``'s preload) must give the same bits: on an AMD host that is the
Intel host's MKL path (issue 68), checked without an Intel host."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

from golden_runs import SMOKE, check_golden
from helpers import load_script


def test_default_search_unchanged(tmp_path: Path) -> None:
    check_golden(SMOKE, tmp_path)


@pytest.mark.slow  # a second run of the golden budget (about 20 s on 2 cores)
@pytest.mark.skipif(shutil.which("cc") is None and shutil.which("gcc") is None, reason="needs a C compiler")
def test_default_search_unchanged_on_the_intel_mkl_path(tmp_path: Path) -> None:
    shim = load_script("check_mkl_vendor").build_shim(tmp_path)
    check_golden(SMOKE, tmp_path, env={"LD_PRELOAD": str(shim)})
