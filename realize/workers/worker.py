"""What one rollout worker holds and does, whatever runs it (this process, a local process, a
Ray actor): the scenes of consecutive shards of a run's copies.

What it does: ``ShardWorker`` builds, once, one batched scene and one plan realizer per task
for each of its shards (``realize.workers.blocks``), with the given PhysX thread count;
``rollout`` realizes one part of a batch per shard (``realize.scene.shards.deal_rows``),
shard after shard, and returns their ``RolloutResult`` joined, on the CPU. A robust search's
shards (``ce.replicas`` = R > 1) put copy ``k`` in world ``k % R`` of the run's worlds
(``realize.workers.replicas.shard_worlds``; every shard a whole number of samples), a
validation's in the world it gives each copy (``RunSpec.worlds``). A shard's scene and controllers see only that shard's rows, so a
row's numbers are the same in whichever worker its shard sits.
What it doesn't: talk to the search or to other workers (``realize.workers.process``,
``realize.workers.ray_pool``), or choose the shards (``realize.workers.blocks``).
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

from torch import Tensor

from realize.realization.result import RolloutResult
from realize.scene.shards import RowBlock
from realize.workers.blocks import join_results

if TYPE_CHECKING:
    from realize.spec.run_spec import RunSpec
    from realize.tasks.spec import TaskSpec
    from realize.world.state import SceneState

__all__ = ["ShardWorker", "worker_spec"]


def worker_spec(spec: RunSpec, physx_threads: int | None) -> RunSpec:
    """``spec`` with ``physx_threads`` PhysX threads per scene (None, or ``sim.cpu_workers``
    set by the user, the one key for them: as it is)."""
    if physx_threads is None or spec.sim.cpu_workers is not None:
        return spec
    return dataclasses.replace(spec, sim=dataclasses.replace(spec.sim, cpu_workers=physx_threads))


class ShardWorker:
    """The scenes of consecutive shards and a realizer per task on each (module docstring)."""

    def __init__(self, spec: RunSpec, tasks: Sequence[TaskSpec], shards: Sequence[RowBlock],
                 physx_threads: int | None = None) -> None:
        from realize.workers.realizers import open_realization
        from realize.workers.replicas import shard_worlds

        t0 = time.perf_counter()
        self.physx_threads = physx_threads
        self.shards = list(shards)
        self.first, self.stop = self.shards[0].first, self.shards[-1].stop
        wspec = worker_spec(spec, physx_threads)
        self.unit = spec.ce.replicas  # a robust search's sample fills this many copies, one per world
        self.scenes: list[Any] = []
        self.realizers: list[list[Any]] = []
        try:
            for shard in self.shards:
                scene, realizers = open_realization(wspec, tasks, n_envs=shard.size,
                                                    worlds=shard_worlds(spec, shard.first, shard.stop))
                self.scenes.append(scene)
                self.realizers.append(realizers)
        except BaseException:
            self.close()
            raise
        self.backend = self.scenes[0].backend
        self.setup_time_s = time.perf_counter() - t0

    def retask(self, spec: RunSpec, tasks: Sequence[TaskSpec]) -> None:
        """New realizers for ``tasks`` (and ``spec``'s start state, controller settings and seed)
        on the scenes already built: a replan of the same world keeps its scenes. The caller
        checks that ``spec``'s scene is the one these scenes were built for
        (``realize.run.planner``)."""
        from realize.realization.rollout import PlanRealizer

        wspec = worker_spec(spec, self.physx_threads)
        self.realizers = [[PlanRealizer.from_spec(wspec, t, scene) for t in tasks] for scene in self.scenes]
        self.unit = spec.ce.replicas

    def rebuild(self, spec: RunSpec, tasks: Sequence[TaskSpec]) -> None:
        """Close the scenes and build them again for ``spec`` (a world whose static layout
        changed: a table moved, a new obstacle), the same shards; the process stays."""
        shards, threads = self.shards, self.physx_threads
        self.close()
        self.__init__(spec, tasks, shards, threads)  # type: ignore[misc]

    def describe(self) -> str:
        return f"rows {self.first}-{self.stop - 1} ({len(self.shards)} shard(s))"

    def rollout(self, candidate: int | None, parts: Sequence[Tensor], record: bool = False,
                starts: Sequence[list[SceneState] | None] | None = None, capture_end: bool = False) -> RolloutResult:
        """Realize ``parts[k]`` (rows of a batch, maybe none) in shard ``k`` of this worker, from
        ``starts[k]`` (one state per row) where given (``PlanRealizer.rollout``)."""
        if len(parts) != len(self.shards) or (starts is not None and len(starts) != len(parts)):
            raise ValueError(f"{len(parts)} parts for {len(self.shards)} shards")
        t0 = time.perf_counter()
        starts = [None] * len(parts) if starts is None else starts
        results = [realizers[0 if candidate is None else candidate].rollout(Z, record, s, capture_end)
                   for Z, s, realizers in zip(parts, starts, self.realizers) if Z.shape[0]]
        res = join_results(results)
        res.wall_time_s = time.perf_counter() - t0
        return res

    def close(self) -> None:
        for scene in self.scenes:
            scene.close()
        self.scenes = []
