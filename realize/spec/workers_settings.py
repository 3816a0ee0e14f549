"""The ``workers`` config group: how many rollout workers a run uses, and where they run.

What it does: ``WorkersSettings`` (the Hydra ``workers`` group, checked like every group),
``worker_count`` (the workers a run gets: ``n``, or for ``n: null`` one per shard up to the
core count; never more than the shards, since a worker holds whole shards) and
``physx_threads`` (each worker's PhysX CPU threads, so that the workers together use the cores
once).
What it doesn't: start anything (``realize.workers.pool``), or decide the shards
(``sim.shard_rows``, ``realize.scene.shards``): the numbers of a run depend on the shards,
never on the workers.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

from realize.config import ConfigError, Settings, setting

__all__ = ["WorkersSettings", "WORKER_BACKENDS", "worker_count", "physx_threads"]

WORKER_BACKENDS = ("process", "ray")


@dataclass
class WorkersSettings(Settings):
    """Rollout workers (the Hydra ``workers`` group: this class's defaults are its one option,
    ``realize.spec.hydra_edge.register_schema``). Every field is a config key."""

    config_key: ClassVar[str] = "workers"

    n: int | None = setting(None, ge=1)  # None: min(cores, shards)
    backend: str = setting("process", choices=WORKER_BACKENDS)  # process (local) | ray (actors; pip install -e '.[ray]')
    ray_address: str | None = None  # ray backend: "auto", "host:port", or None (start a local Ray instance)
    start_timeout_s: float = setting(600.0, gt=0)  # a worker that has not built its scenes by then fails


def worker_count(settings: WorkersSettings, n_shards: int, shardable: bool, cores: int) -> int:
    """The rollout workers for ``n_shards`` shards with ``cores`` cores (for Ray: the cluster's
    CPUs); ``shardable``: the simulator backend's copies may sit in several scenes
    (``realize.scene.backends.shardable``). Raises ``ConfigError`` where ``n`` cannot work."""
    if not shardable:
        if settings.n not in (None, 1):
            raise ConfigError(f"workers.n = {settings.n}: workers split the CPU backend's shards; the "
                              f"GPU backend holds every copy in one scene (use workers.n=1)")
        return 1
    if settings.n is not None:
        if settings.n > n_shards:
            raise ConfigError(f"workers.n = {settings.n} is more than the {n_shards} shard(s) of this run (a worker "
                              f"holds whole shards: ce.n_envs copies in shards of sim.shard_rows); lower "
                              f"sim.shard_rows to cut the copies into more shards (this changes the run's numbers)")
        return settings.n
    return max(1, min(cores, n_shards))


def physx_threads(cpu_workers: int | None, n_workers: int, cores: int) -> int | None:
    """PhysX CPU threads of one worker's scenes: ``sim.cpu_workers`` (the one key for them),
    else (several workers) its share of the cores: 0, PhysX on the calling thread, when the
    share is one core or less; None for one worker (the scene's own rule)."""
    if cpu_workers is not None:
        return cpu_workers
    if n_workers == 1:
        return None
    share = cores // n_workers
    return 0 if share <= 1 else min(share, 8)
