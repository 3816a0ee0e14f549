"""Rollout workers: a run's copies cut into shards (one PhysX scene each), held by this process,
local worker processes or Ray actors. ``open_pool`` is the entry point; see
``realize.app.workers.blocks`` for why the shards, not the workers, decide a run's numbers."""

from realize.app.workers.settings import WORKER_BACKENDS, WorkersSettings, physx_threads, worker_count

__all__ = ["WORKER_BACKENDS", "WorkersSettings", "physx_threads", "worker_count"]
