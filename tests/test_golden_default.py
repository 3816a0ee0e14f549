"""The default search's golden run (``seed_paper_default``: restores, two worker processes), bit for
bit against ``tests/fixtures/golden_runs.json``: the golden run that ``make
test`` keeps, in a file of its own so that it runs beside other files."""

from __future__ import annotations

from pathlib import Path

from golden_runs import SMOKE, check_golden


def test_default_search_unchanged(tmp_path: Path) -> None:
    check_golden(SMOKE, tmp_path)
