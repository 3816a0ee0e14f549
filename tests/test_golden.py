"""Results that a restructuring must not change: 5 small real runs against a committed fixture.

The fixture (``tests/fixtures/golden_runs.json``) was recorded before the restructuring of
issue #12 (``python tests/golden_runs.py``); ``seed_paper_default``, the default search with its
restores, joined it on 2026-12-06. Each run goes through the ``realize`` command as a
user would; best cost, success share per iteration, best cost per iteration and the best
parameter vector must be equal bit for bit (CPU runs are deterministic).
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from golden_runs import FIXTURE, GOLDEN_RUNS, run_golden

EXPECTED = json.loads(FIXTURE.read_text())


# make test runs the paper's algorithm (seed_task) and the default search (seed_paper_default,
# restores and two worker processes in it); make test-all every golden run
SMOKE = {"seed_task", "seed_paper_default"}


@pytest.mark.parametrize("name", [n if n in SMOKE else pytest.param(n, marks=pytest.mark.slow) for n in sorted(GOLDEN_RUNS)])
def test_results_unchanged(name: str, tmp_path: Path) -> None:
    want = EXPECTED[name]
    assert want["overrides"] == GOLDEN_RUNS[name], "the run's overrides changed: re-record the fixture on purpose"
    got = run_golden(name, tmp_path / name)
    recorded = {k: v for k, v in want.items() if k != "overrides"}
    assert sorted(got) == sorted(recorded), f"{name}: the run's keys changed (a key the fixture holds is gone?)"
    for key, value in got.items():
        assert value == recorded[key], f"{name}: {key} changed: {value!r} != {recorded[key]!r}"


def test_fixture_is_not_trivial() -> None:
    # every golden run found a feasible plan and its success share changed over iterations
    for name, want in EXPECTED.items():
        assert want["feasible"] and want["best_cost"] > 0, name
        assert len(want["best_z"]) > 3 and len(set(want["success_per_iter"])) > 1, name
