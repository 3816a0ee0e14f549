"""Open the rollout workers of a run: the one call the search loop and scripts make.

What it does: ``RolloutPool`` is what the loop talks to (``rollout(candidate, Z, record)``,
``close``, ``n_envs``, ``backend``, ``n_workers``); ``open_pool(spec, tasks, log_dir)`` cuts the
run's copies into shards (``sim.shard_rows``, CPU backend; one scene on GPU), decides the
worker count (``workers``) and opens the shards in this process (``InProcessPool``, one worker)
or in worker processes (``realize.workers.process``) or Ray actors (``realize.workers.ray_pool``);
a robust search's pool (``ce.replicas > 1``) is wrapped in ``realize.workers.replicas.ReplicaPool``.
What it doesn't: simulate (``realize.workers.worker``), or know the search.
"""

from __future__ import annotations

import logging
import multiprocessing as mp
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Protocol

from torch import Tensor

from realize.config import ConfigError
from realize.realization.result import RolloutResult
from realize.scene.shards import RowBlock, group_shards, shard_rows
from realize.workers.blocks import check_batch, worker_parts, worker_starts
from realize.spec.workers_settings import physx_threads, worker_count
from realize.workers.worker import ShardWorker

if TYPE_CHECKING:
    from realize.spec.run_spec import RunSpec
    from realize.tasks.spec import TaskSpec
    from realize.world.state import SceneState

__all__ = ["RolloutPool", "InProcessPool", "open_pool", "run_shards"]

log = logging.getLogger("realize")


class RolloutPool(Protocol):
    """Rolls out batches of a run's plans on its copies, wherever they are simulated."""

    n_envs: int
    backend: str
    n_workers: int
    kind: str
    setup_time_s: float

    def rollout(self, candidate: int | None, Z: Tensor, record: bool = False,
                starts: Sequence[SceneState] | None = None, capture_end: bool = False) -> RolloutResult: ...

    def retask(self, spec: RunSpec, tasks: Sequence[TaskSpec]) -> None: ...

    def rebuild(self, spec: RunSpec, tasks: Sequence[TaskSpec]) -> None: ...

    def close(self) -> None: ...


class InProcessPool:
    """Every shard in this process (``workers.n = 1``)."""

    kind = "in-process"
    n_workers = 1

    def __init__(self, spec: RunSpec, tasks: Sequence[TaskSpec], shards: Sequence[RowBlock],
                 physx_threads: int | None = None) -> None:
        self.worker = ShardWorker(spec, tasks, shards, physx_threads)
        self.n_envs, self.backend, self.setup_time_s = self.worker.stop, self.worker.backend, self.worker.setup_time_s

    def rollout(self, candidate: int | None, Z: Tensor, record: bool = False,
                starts: Sequence[SceneState] | None = None, capture_end: bool = False) -> RolloutResult:
        check_batch(Z, self.n_envs)
        (parts,) = worker_parts(Z, [self.worker.shards], self.worker.unit)
        (start_parts,) = worker_starts(starts, Z.shape[0], [self.worker.shards], self.worker.unit)
        return self.worker.rollout(candidate, parts, record, start_parts, capture_end)

    def retask(self, spec: RunSpec, tasks: Sequence[TaskSpec]) -> None:
        """Realize ``tasks`` from now on, on the scenes already built (``ShardWorker.retask``)."""
        self.worker.retask(spec, tasks)

    def rebuild(self, spec: RunSpec, tasks: Sequence[TaskSpec]) -> None:
        """New scenes for ``spec`` on the same shards (``ShardWorker.rebuild``)."""
        self.worker.rebuild(spec, tasks)
        self.setup_time_s = self.worker.setup_time_s

    def close(self) -> None:
        self.worker.close()

    def __enter__(self) -> InProcessPool:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def run_shards(spec: RunSpec, n_envs: int | None = None) -> list[RowBlock]:
    """The shards of a run's copies: ``sim.shard_rows`` each on the CPU backend, one otherwise."""
    from realize.scene.backends import shardable

    n = spec.ce.n_envs if n_envs is None else n_envs
    return shard_rows(n, spec.sim.shard_rows if shardable(spec.placement.backend) else n, spec.ce.replicas)


def _process_pool(spec: RunSpec, tasks: list[TaskSpec], shards: list[RowBlock], log_dir: Path | None) -> RolloutPool:
    from realize.scene.cpu_tiled import available_cores

    ws, cores = spec.workers, available_cores()
    n = worker_count(ws, len(shards), True, cores)
    if n > 1 and mp.current_process().daemon:  # e.g. a job of a process-pool launcher: no children allowed
        if ws.n is not None:
            raise ConfigError(f"workers.n = {ws.n}: this run is itself a daemonic worker process (a launcher's job), "
                              "which may not start processes; use workers.n=1 or workers.backend=ray")
        log.info("running in a daemonic process (a launcher's job): rollout workers in this process")
        n = 1
    if n == 1:
        return InProcessPool(spec, tasks, shards)
    from realize.workers.process import ProcessPool

    return ProcessPool(spec, tasks, group_shards(shards, n), physx_threads=physx_threads(spec.sim.cpu_workers, n, cores),
                       log_dir=log_dir, start_timeout_s=ws.start_timeout_s)


def _ray_pool(spec: RunSpec, tasks: list[TaskSpec], shards: list[RowBlock], log_dir: Path | None) -> RolloutPool:
    if spec.workers.n == 1 or len(shards) == 1:  # nothing to spread: no cluster needed
        return InProcessPool(spec, tasks, shards)
    from realize.workers.ray_pool import RayPool, ray_cores, ray_release

    ws = spec.workers
    cores = ray_cores(ws.ray_address)  # the cluster's CPUs (joins it, or starts a local instance)
    try:
        n = worker_count(ws, len(shards), True, cores)
    except BaseException:
        ray_release()
        raise
    if n == 1:
        ray_release()
        return InProcessPool(spec, tasks, shards)
    # the pool undoes ray_cores when it closes (or fails to open)
    return RayPool(spec, tasks, group_shards(shards, n), ws, physx_threads=physx_threads(spec.sim.cpu_workers, n, cores))


_OPENERS = {"process": _process_pool, "ray": _ray_pool}  # by workers.backend


def open_pool(spec: RunSpec, tasks: Sequence[TaskSpec] | None = None, *, log_dir: Path | None = None,
              n_envs: int | None = None) -> RolloutPool:
    """The rollout workers of ``spec`` (``ce.n_envs`` or ``n_envs`` copies) for ``tasks``
    (default ``[spec.task]``); worker logs go to ``log_dir`` (processes only). A backend whose
    copies share one scene (GPU) runs in this process."""
    from realize.scene.backends import shardable

    tasks = [spec.task] if tasks is None else list(tasks)
    shards = run_shards(spec, n_envs)
    if not shardable(spec.placement.backend):
        pool: RolloutPool = InProcessPool(spec, tasks, shards)
    else:
        pool = _OPENERS[spec.workers.backend](spec, tasks, shards, log_dir)
    if spec.ce.replicas > 1:  # robust search: each sample in ce.replicas worlds, folded back to one row
        from realize.workers.replicas import ReplicaPool

        return ReplicaPool(pool, spec.ce.replicas, spec.ce.risk, spec.ce.cvar_alpha)
    return pool
