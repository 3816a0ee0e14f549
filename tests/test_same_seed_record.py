"""The same-seed record (``scripts/bench_data/same_seed.json``) and its checker
(``scripts/check_same_seed.py``): the record holds whole runs of the default search, and the
checker refuses what it cannot compare in one line, before it runs anything. The full check is a
script (a run per seed takes about a minute), not a test; the golden run ``seed_paper_default``
(tests/golden_runs.py) holds the same search at a small budget in every ``make test``."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parent.parent
SCRIPT = REPO / "scripts" / "check_same_seed.py"
RECORD = REPO / "scripts" / "bench_data" / "same_seed.json"


def test_the_record_holds_the_default_search_of_five_seeds() -> None:
    doc = json.loads(RECORD.read_text())
    assert "experiment=seed_paper" in doc["overrides"] and not any(o.startswith("levers=") for o in doc["overrides"])
    assert [r["seed"] for r in doc["runs"]] == [0, 1, 2, 3, 4]
    for r in doc["runs"]:
        assert r["feasible"] and r["best_cost"] == r["best_cost_per_iter"][-1]  # the confirmation batch last and len(r["best_z"]) == 12
    assert doc["host"]["cpu"] and doc["commit"] and doc["date"]


def _check(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, str(SCRIPT), *args], cwd=REPO, capture_output=True, text=True, timeout=120)


@pytest.mark.slow  # two script processes (13 s on a busy 2-core host): make test keeps the record's check
# and a script's one-line refusal (tests/test_execute.py, test_script_refuses_an_unknown_family_in_one_line)
def test_a_seed_outside_the_record_is_refused_before_any_run(tmp_path: Path) -> None:
    p = _check("--seeds", "0,7")
    assert p.returncode == 2 and p.stderr.count("\n") == 1
    assert "seeds [7] are not in" in p.stderr and "recorded: [0, 1, 2, 3, 4]" in p.stderr
    p = _check("--file", str(tmp_path / "none.json"))
    assert p.returncode == 2 and "no record at" in p.stderr and "--record" in p.stderr
