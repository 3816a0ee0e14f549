"""The small runs whose results must not change when code is restructured (bit for bit on CPU).

``GOLDEN_RUNS`` names each run by its command-line overrides; ``run_golden(name, dir)`` runs one
through the ``realize`` command (a subprocess, as a user would) and returns the numbers kept in
``tests/fixtures/golden_runs.json``. ``python tests/golden_runs.py`` re-records that fixture:
only do that when a change is *meant* to change results, and say so in the commit message.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import Any

from helpers import REPO, realize_cli
from realize.run_dir.history import batch_digests

FIXTURE = REPO / "tests" / "fixtures" / "golden_runs.json"
_QUIET = ["device=cpu", "logging.rerun=false", "logging.progress=false"]
# the paper's algorithm: the fixture's numbers predate the speed levers (configs/levers/), and a
# run with them off must give them bit for bit
EXACT = ["levers=exact"]

GOLDEN_RUNS: dict[str, list[str]] = {
    # the seed task (pick and place), plain CE
    "seed_task": ["ce.n_envs=12", "ce.n_elite=3", "ce.iterations=2", "seed=3"],
    # the move-and-push scene and template
    "push_task": ["experiment=move_and_push", "ce.n_envs=12", "ce.n_elite=3", "ce.iterations=2", "seed=1"],
    # successive halving over the planner's two best plans (carry or push)
    "top_k": ["experiment=carry_or_push", "task.planner.top_k=2", "ce.n_envs=8", "ce.n_elite=2",
              "ce.iterations=3", "seed=0"],
    # a two-mode mixture with kNN-robust ranking
    "mixture_ce": ["ce.n_envs=12", "ce.n_elite=4", "ce.iterations=3", "ce.n_modes=2", "ce.knn_robust=3",
                   "seed=5"],
    # the default search (experiment=seed_paper, levers=stitched) at a small budget: 2 rounds
    # (prefix, prefix, suffix from restored states, confirmation) in two worker processes on a
    # 2-core host (12 copies in 6-copy shards); restores are history-free, so it holds on any host.
    # Its batch digests part on MKL's vendor branch (MKL_CBWR=AVX2 on an Intel and an AMD CPU):
    # the golden run that catches a kernel a host picks for itself
    "seed_paper_default": ["experiment=seed_paper", "ce.n_envs=12", "stitch.n_prefix=8", "ce.n_elite=3",
                           "ce.iterations=2", "sim.shard_rows=6", "validation=off", "seed=0"],
}
# runs with their preset's own levers, not EXACT
PRESET_LEVERS: dict[str, list[str]] = {"seed_paper_default": []}
KEYS = ("feasible", "best_cost", "success_per_iter", "best_cost_per_iter", "best_z")
EXPECTED: dict[str, Any] = json.loads(FIXTURE.read_text()) if FIXTURE.exists() else {}
# make test runs the default search (restores and two worker processes in it), in a file of its own
# (test_golden_default.py) so that another worker runs beside it; make test-all every golden run
SMOKE = "seed_paper_default"


def run_golden(name: str, run_dir: Path, levers: list[str] | None = None,
               env: dict[str, str] | None = None) -> dict[str, Any]:
    """Run ``GOLDEN_RUNS[name]`` into ``run_dir`` with ``levers`` (default: ``PRESET_LEVERS[name]``
    where it has one, else ``EXACT``, every speed lever off) and ``env`` added to the environment;
    the compared numbers of its result.json."""
    levers = PRESET_LEVERS.get(name, EXACT) if levers is None else levers
    p = realize_cli(*GOLDEN_RUNS[name], *levers, *_QUIET, f"hydra.run.dir={run_dir}", cwd=REPO, timeout=900, env=env)
    if p.returncode != 0:
        raise RuntimeError(f"golden run {name} failed ({p.returncode}):\n{p.stdout[-2000:]}\n{p.stderr[-4000:]}")
    doc = json.loads((run_dir / "result.json").read_text())
    out = {k: doc.get(k) for k in KEYS}
    # every row's cost and final distance, not only the best: the last bits a host's kernels move
    # show here first (issue 68: an Intel and an AMD host agreed in every key above at this budget)
    out["batch_digests"] = batch_digests(run_dir)
    if "candidates" in doc:
        out["winner"] = doc.get("winner")
        out["candidates"] = [{"plan": c.get("plan"), "best_cost": c.get("best_cost")} for c in doc["candidates"]]
    return out


def check_golden(name: str, tmp_path: Path, env: dict[str, str] | None = None) -> None:
    """Run the golden run ``name`` (``env`` added to its environment) and compare its numbers with
    the fixture's, bit for bit."""
    want = EXPECTED[name]
    assert want["overrides"] == GOLDEN_RUNS[name], "the run's overrides changed: re-record the fixture on purpose"
    got = run_golden(name, tmp_path / name, env=env)
    recorded = {k: v for k, v in want.items() if k != "overrides"}
    assert sorted(got) == sorted(recorded), f"{name}: the run's keys changed (a key the fixture holds is gone?)"
    for key, value in got.items():
        assert value == recorded[key], f"{name}: {key} changed: {value!r} != {recorded[key]!r}"


if __name__ == "__main__":  # pragma: no cover - re-records the fixture
    import tempfile

    names = sys.argv[1:] or list(GOLDEN_RUNS)
    data = json.loads(FIXTURE.read_text()) if FIXTURE.exists() else {}
    with tempfile.TemporaryDirectory() as tmp:
        for n in names:
            data[n] = {"overrides": GOLDEN_RUNS[n], **run_golden(n, Path(tmp) / n)}
            print(n, data[n]["best_cost"], data[n]["success_per_iter"], flush=True)
    FIXTURE.write_text(json.dumps(data, indent=1) + "\n")
