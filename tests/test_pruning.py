"""Rows that cannot win stop (issue 35, lever 2: ``ce.prune``), on the CPU simulator.

* ``EliteBound`` against a hand-worked answer: no bound until ``keep`` plans are feasible, then
  the ``keep``-th smallest of their step counts, and it only falls as more finish;
* the same eight seed-task plans realized with and without the bound, each in a fresh scene:
  every row that was not stopped has bit-identical cost, flags and failure; every stopped row
  (running ones, and done ones still settling when the bound appeared) costs more unpruned than
  the ``keep``-th cheapest feasible plan (so it could not have been one of them); the ``keep``
  cheapest feasible rows are the same rows at the same costs; and the
  pruned batch simulates fewer steps.

* end to end: the seed-task golden run (``tests/golden_runs.py``) with ``ce.prune`` on has the
  fixture's best plan and best cost per iteration, bit for bit, and stopped some rows (here, not
  in ``test_golden.py``, so that the two files' runs can go to two test workers).
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest
import torch

from golden_runs import FIXTURE, run_golden
from helpers import FAR_SIDE, GOOD, SEED_TASK, SIDE, compose_config
from realize.spec.run_spec import build_run_spec
from realize.realization.pruning import EliteBound
from realize.realization.result import RolloutResult
from realize.realization.rollout import PlanRealizer
from realize.scene import BatchedScene

KEEP = 2
_COLS = {"t1x": 0, "t1y": 1, "t2x": 5, "t2y": 6, "ex": 10, "ey": 11}


def _vary(base: list[float], **kw: float) -> list[float]:
    z = list(base)
    for k, v in kw.items():
        z[_COLS[k]] = v
    return z


# eight plans of the seed task with different lengths: two far exits, a long detour to table 1,
# a far drop point on table 2, and one that fails at the grasp
ROWS = torch.tensor(
    [
        GOOD,
        SIDE,
        _vary(GOOD, ex=2.6, ey=0.4),
        _vary(SIDE, ex=1.8, ey=-0.4),
        FAR_SIDE,
        _vary(GOOD, t1x=-1.1, t1y=1.5),
        _vary(GOOD, t2x=-0.5, t2y=-2.2),
        _vary(SIDE, ex=2.6, ey=-0.4),
    ],
    dtype=torch.float64,
)


def test_elite_bound_is_the_kth_smallest_feasible_step_count() -> None:
    b = EliteBound(keep=2)
    steps = torch.tensor([300, 200, 500, 400])
    assert b.update(torch.tensor([False, False, False, False]), steps) is None
    assert b.update(torch.tensor([False, False, True, False]), steps) is None  # one is not enough
    assert b.update(torch.tensor([False, False, True, True]), steps) == 500  # {500, 400}: 2nd is 500
    assert b.update(torch.tensor([True, False, True, True]), steps) == 400  # {300, 400, 500}
    assert b.update(torch.tensor([True, True, True, True]), steps) == 300  # {200, 300, ...}
    with pytest.raises(ValueError, match="keep must be >= 1"):
        EliteBound(keep=0)


def _realize(keep: int | None) -> RolloutResult:
    spec = build_run_spec(compose_config(f"task_file={SEED_TASK}"))
    with BatchedScene(len(ROWS), spec.geometry_cfg, spec.sim) as scene:
        return PlanRealizer(spec.task, scene, spec.rollout, keep_best=keep).rollout(ROWS)


@pytest.fixture(scope="module")
def both(torch_single_thread: None) -> tuple[RolloutResult, RolloutResult]:
    return _realize(None), _realize(KEEP)


def test_pruned_rows_could_not_win_and_the_rest_are_unchanged(both: tuple[RolloutResult, RolloutResult]) -> None:
    full, pruned = both
    assert full.stopped is None
    stopped = pruned.stopped
    assert stopped is not None and stopped.any(), "no row was stopped: the probe lost its point"
    keep_cost = full.cost[full.feasible].sort().values[KEEP - 1]
    # a stopped row would have cost more than the keep-th cheapest feasible plan, or failed
    assert bool(((full.cost[stopped] > keep_cost) | ~full.feasible[stopped]).all())
    assert not pruned.feasible[stopped].any()
    assert all(pruned.failure[i].endswith(":stopped") for i in torch.nonzero(stopped).flatten().tolist())
    # plans done but still settling when the bound appeared stop too, their goal never read
    late = stopped & pruned.action_success.all(dim=1)
    assert late.any(), "no plan was stopped while settling: the probe lost that point"
    assert all(pruned.failure[i].endswith(":goal:stopped") for i in torch.nonzero(late).flatten().tolist())
    live = ~stopped
    assert torch.equal(pruned.cost[live], full.cost[live])
    assert torch.equal(pruned.feasible[live], full.feasible[live])
    assert [f for f, s in zip(pruned.failure, stopped.tolist()) if not s] == [
        f for f, s in zip(full.failure, stopped.tolist()) if not s
    ]
    # the keep cheapest feasible rows, and their costs, are the unpruned ones
    def top(r: RolloutResult) -> list[tuple[int, float]]:
        idx = torch.nonzero(r.feasible).flatten()
        order = idx[r.cost[idx].argsort(stable=True)][:KEEP]
        return [(int(i), float(r.cost[i])) for i in order]

    assert top(pruned) == top(full)
    assert pruned.sim_steps < full.sim_steps


@pytest.mark.slow  # a whole run or several processes: make test-all (make test keeps a smoke test)
def test_pruning_keeps_the_search(tmp_path: Path) -> None:
    """``ce.prune`` stops only rows that could not be an elite: the seed task's golden run with it
    on has the same best plan and best cost per iteration, bit for bit; only the success share
    may fall (a stopped row might have succeeded), and the run says how many it stopped."""
    want = json.loads(FIXTURE.read_text())["seed_task"]
    got = run_golden("seed_task", tmp_path / "pruned", levers=["levers=exact", "ce.prune=true", "validation=off"])
    for key in ("feasible", "best_cost", "best_cost_per_iter", "best_z"):
        assert got[key] == want[key], f"{key} changed with ce.prune: {got[key]!r} != {want[key]!r}"
    assert all(g <= w for g, w in zip(got["success_per_iter"], want["success_per_iter"]))
    doc = json.loads((tmp_path / "pruned" / "result.json").read_text())
    assert sum(doc["n_stopped_per_iter"]) > 0, "nothing was stopped: the test shows nothing"
