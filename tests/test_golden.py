"""Results that a restructuring must not change: 5 small real runs against a committed fixture.

The fixture (``tests/fixtures/golden_runs.json``) was recorded before the restructuring of
issue #12 (``python tests/golden_runs.py``); ``seed_paper_default``, the default search with its
restores, joined it on 2026-12-06. Each run goes through the ``realize`` command as a
user would; best cost, success share per iteration, best cost per iteration and the best
parameter vector must be equal bit for bit (CPU runs are deterministic). ``make test`` runs
``seed_paper_default`` (``test_golden_default.py``); ``make test-slow`` the other four.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from golden_runs import EXPECTED, GOLDEN_RUNS, SMOKE, check_golden


@pytest.mark.slow
@pytest.mark.parametrize("name", sorted(set(GOLDEN_RUNS) - {SMOKE}))
def test_results_unchanged(name: str, tmp_path: Path) -> None:
    check_golden(name, tmp_path)


def test_fixture_is_not_trivial() -> None:
    # every golden run found a feasible plan and its success share changed over iterations
    for name, want in EXPECTED.items():
        assert want["feasible"] and want["best_cost"] > 0, name
        assert len(want["best_z"]) > 3 and len(set(want["success_per_iter"])) > 1, name
