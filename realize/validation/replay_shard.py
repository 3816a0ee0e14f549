"""Replay a run's best sample exactly as the run simulated it: its iteration's shard, re-run.

Why: PhysX's CPU solver does not keep the copies of one scene apart bit for bit
(``realize.scene.shards``), so the best plan replayed alone in one copy may end a step or two
off the run's cost. The run simulated its best sample in one shard of its copies, beside the
other samples of that iteration dealt to that shard. Rebuilding that shard (the same number of
copies, the same rows of ``history.npz``) repeats the run's computation, so on CPU the cost is
the run's, bit for bit.

What it does: ``find_best_row`` locates the best sample in ``history.npz`` (the iteration and
row whose ``Z`` equals ``best_z``); ``replay_shard(run, spec)`` rebuilds that row's shard with
the run's own config (``realize.validation.replay.build_replay_spec``) and returns a ``ShardReplay``.
What it doesn't: render video or capture states (``realize.validation.replay`` does, in one copy), or
replay top-k runs (their samples sit in per-candidate histories; refused with a clear line).
"""

from __future__ import annotations

import math
import time
from dataclasses import asdict, dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
import torch

from realize.run_dir.directory import BestPlan, RunDir
from realize.run_dir.names import HISTORY_FILE

if TYPE_CHECKING:
    from realize.spec.run_spec import RunSpec

__all__ = ["ShardReplay", "ShardReplayError", "find_best_row", "replay_shard"]


class ShardReplayError(ValueError):
    """The run directory lacks what an exact replay needs; the message names the file."""


@dataclass
class ShardReplay:
    """The best sample re-run in its shard: ``iteration``, ``row`` of that iteration's batch,
    the shard's copies ``first .. stop - 1`` of ``total``, and what the rollout gave."""

    iteration: int
    row: int
    shard_first: int
    shard_stop: int
    shard_total: int
    rows_in_shard: int
    cost: float
    feasible: bool
    failure: str
    steps: int
    wall_time_s: float

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)


def find_best_row(run: BestPlan) -> tuple[int, int, np.ndarray]:
    """``(iteration, row, Z of that iteration)``: where ``best_z`` was sampled (the first match)."""
    arrays = RunDir(run.run_dir).history_arrays()
    where = run.run_dir / HISTORY_FILE
    if not arrays:
        raise ShardReplayError(f"{where}: not found (an exact replay re-runs a sample's iteration from it)")
    best = np.asarray(run.best_z, dtype=np.float64)
    for i in range(int(arrays["iteration"].shape[0])):
        Z = arrays.get(f"Z_{i:03d}")
        if Z is None or Z.ndim != 2 or Z.shape[1] != best.shape[0]:
            continue
        hits = np.flatnonzero((Z.astype(np.float64) == best).all(axis=1))
        if hits.size:
            return i, int(hits[0]), Z
    raise ShardReplayError(f"{where}: no iteration holds best_z among its samples")


def replay_shard(run: BestPlan, spec: RunSpec) -> ShardReplay:
    """Re-run the shard in which the run simulated its best sample (module docstring)."""
    from realize.workers.realizers import open_realization
    from realize.scene.backends import shardable
    from realize.scene.shards import deal_rows
    from realize.workers.pool import run_shards

    if spec.halving:
        raise ShardReplayError(f"{run.run_dir}: a top-k run's samples are per candidate; an exact replay "
                               "covers single-plan runs")
    if run.backend is not None and not shardable(run.backend):
        raise ShardReplayError(f"{run.run_dir}: the run simulated on {run.backend!r}; an exact CPU replay "
                               "needs a CPU run")
    t0 = time.perf_counter()
    iteration, row, Z = find_best_row(run)
    shards = run_shards(spec)
    parts = deal_rows(Z.shape[0], len(shards))
    k = next(j for j, s in enumerate(parts) if s.start <= row < s.stop)
    block, part = shards[k], parts[k]
    rows = torch.from_numpy(np.ascontiguousarray(Z[part])).to(spec.placement.device)
    scene, (realizer,) = open_realization(spec, n_envs=block.size)
    with scene:
        res = realizer.rollout(rows)
    j = row - part.start
    cost = float(res.cost[j])
    return ShardReplay(iteration=iteration, row=row, shard_first=block.first, shard_stop=block.stop,
                       shard_total=block.total, rows_in_shard=part.stop - part.start,
                       cost=cost if math.isfinite(cost) else math.inf, feasible=bool(res.feasible[j]),
                       failure=res.failure[j], steps=int(res.steps[j]), wall_time_s=time.perf_counter() - t0)
