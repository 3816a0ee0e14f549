"""A robust search's rollouts: each sample in R perturbed worlds, folded back to one row per sample.

What it does: ``search_worlds(spec)`` draws the run's R = ``ce.replicas`` worlds from its task's
perturbation model (``realize.tasks.worlds.draw_worlds``, seeded by the run's seed on the search
stream), the same in every worker; the shard workers put copy ``k`` in world ``k % R``
(``shard_worlds``; or in ``spec.worlds[k]`` where a caller, validation, gives one world per copy).
``ReplicaPool`` wraps any ``RolloutPool``: a batch of n samples is rolled out as n x R copies
(sample ``i`` in copies ``i*R .. i*R + R - 1``, one per world) and folded back to n rows
(``realize.search.ce.risk.fold_worlds``): cost, feasibility, progress and distance over the
worlds, with each sample's success share (``RolloutResult.share``) and its per-world cost and
success (``world_cost``, ``world_feasible``, (n, R)); what the ranking does not read (action
successes, goal, steps, failure, trajectories) is that of the sample's first world.
What it doesn't: choose the worlds' model (the task config's ``perturbation``) or rank.
"""

from __future__ import annotations

import dataclasses
from typing import TYPE_CHECKING, Any

import numpy as np
from torch import Tensor

from realize.realization.result import TRAJECTORIES, RolloutResult
from realize.search.ce.risk import fold_worlds
from realize.tasks.worlds import SEARCH_STREAM, Worlds, draw_worlds

if TYPE_CHECKING:
    from realize.spec.run_spec import RunSpec

__all__ = ["search_worlds", "shard_worlds", "ReplicaPool", "fold_result"]


def search_worlds(spec: RunSpec) -> Worlds:
    """The R = ``ce.replicas`` worlds a robust search's samples meet."""
    return draw_worlds(spec.task.perturbation, spec.geometry.objects, spec.ce.replicas, spec.seed,
                       stream=SEARCH_STREAM)


def shard_worlds(spec: RunSpec, first: int, stop: int) -> Worlds | None:
    """The worlds of copies ``first .. stop - 1`` of a run's scene: ``spec.worlds`` (one per
    copy) where set, else a robust search's (copy ``k``: world ``k % R``), else None (the task's)."""
    if spec.worlds is not None:
        return spec.worlds.select(np.arange(first, stop))
    if spec.ce.replicas > 1:
        return search_worlds(spec).tile(stop - first, first=first)
    return None


def fold_result(res: RolloutResult, replicas: int, risk: str, alpha: float) -> RolloutResult:
    """The per-copy result of n x ``replicas`` copies as n per-sample rows (module docstring)."""
    R = replicas
    w = fold_worlds(res.cost, res.feasible, res.progress, res.distance, R, risk, alpha)
    first = slice(None, None, R)
    traj = {f: (None if getattr(res, f) is None else getattr(res, f)[first])
            for f in TRAJECTORIES}
    return dataclasses.replace(
        res, cost=w.cost.to(res.cost.dtype), feasible=w.feasible, progress=w.progress.to(res.progress.dtype),
        distance=w.distance.to(res.distance.dtype), action_success=res.action_success[first], goal=res.goal[first],
        steps=res.steps[first], failure=res.failure[::R], share=w.share,
        world_cost=res.cost.reshape(-1, R).clone(), world_feasible=res.feasible.reshape(-1, R).clone(), **traj)


class ReplicaPool:
    """A pool whose copies meet ``replicas`` worlds (copy ``k``: world ``k % replicas``); its
    ``rollout`` takes samples and returns per-sample rows (module docstring)."""

    def __init__(self, inner: Any, replicas: int, risk: str, alpha: float) -> None:
        self.inner, self.replicas, self.risk, self.alpha = inner, int(replicas), risk, float(alpha)
        self.n_envs, self.backend, self.n_workers = inner.n_envs, inner.backend, inner.n_workers
        self.kind, self.setup_time_s = inner.kind, inner.setup_time_s
        self.log_location = getattr(inner, "log_location", None)

    def rollout(self, candidate: int | None, Z: Tensor, record: bool = False) -> RolloutResult:
        res = self.inner.rollout(candidate, Z.repeat_interleave(self.replicas, dim=0), record)
        return fold_result(res, self.replicas, self.risk, self.alpha)

    def retask(self, spec: Any, tasks: Any) -> None:
        self.inner.retask(spec, tasks)

    def rebuild(self, spec: Any, tasks: Any) -> None:
        self.inner.rebuild(spec, tasks)

    def close(self) -> None:
        self.inner.close()
