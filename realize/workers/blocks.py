"""A batch's rows dealt to a run's workers and their results joined.

What it does: ``check_batch`` (a batch fits the copies), ``worker_parts`` / ``worker_starts`` (a
batch's rows and start states cut per worker, along the shards of ``realize.scene.shards``, where
the row arithmetic and the reason for shards live) and ``join_results`` (results of consecutive
parts as one, in row order: per-plan tensors concatenated, shorter trajectories padded with
their last frame).
What it doesn't: cut the copies into shards (``realize.scene.shards``) or run anything
(``realize.workers.pool``, ``.process``, ``.ray_pool``).
"""

from __future__ import annotations

from collections.abc import Sequence

import torch
from torch import Tensor

from realize.realization.result import TRAJECTORIES, RolloutResult
from realize.scene.shards import RowBlock, deal_rows
from realize.world.state import SceneState

__all__ = ["worker_parts", "worker_starts", "check_batch", "join_results"]


def check_batch(Z: Tensor, n_envs: int) -> None:
    """Refuse a batch of more rows than the run has copies."""
    if Z.shape[0] > n_envs:
        raise ValueError(f"{Z.shape[0]} samples but the run has only {n_envs} copies (ce.n_envs)")


def _by_worker(parts: list, groups: Sequence[Sequence[RowBlock]]) -> list[list]:
    """One part per shard -> per worker (a group of consecutive shards), its shards' parts."""
    out, k = [], 0
    for g in groups:
        out.append(parts[k:k + len(g)])
        k += len(g)
    return out


def worker_parts(Z: Tensor, groups: Sequence[Sequence[RowBlock]], unit: int = 1) -> list[list[Tensor]]:
    """Per worker (a group of consecutive shards), the parts of ``Z`` its shards realize."""
    return _by_worker([Z[s] for s in deal_rows(Z.shape[0], sum(len(g) for g in groups), unit)], groups)


def worker_starts(starts: Sequence[SceneState] | None, m: int, groups: Sequence[Sequence[RowBlock]],
                  unit: int = 1) -> list[list[list[SceneState] | None]]:
    """Per worker, the start states of the rows each of its shards realizes (as ``worker_parts``
    deals an ``m``-row batch; None everywhere without ``starts``)."""
    slices = deal_rows(m, sum(len(g) for g in groups), unit)
    return _by_worker([None if starts is None else list(starts[s]) for s in slices], groups)


def _pad_frames(t: Tensor | None, frames: int) -> Tensor | None:
    """(M, T, ...) -> (M, frames, ...), the last frame repeated (a finished block holds still)."""
    if t is None or t.shape[1] == frames:
        return t
    return torch.cat([t, t[:, -1:].expand(-1, frames - t.shape[1], *t.shape[2:])], dim=1)


def join_results(parts: Sequence[RolloutResult]) -> RolloutResult:
    """The results of consecutive row blocks as one result, in row order."""
    if len(parts) == 1:
        return parts[0]
    cat = lambda name: torch.cat([getattr(p, name) for p in parts])  # noqa: E731
    res = RolloutResult(
        cost=cat("cost"), feasible=cat("feasible"), action_success=cat("action_success"), goal=cat("goal"),
        steps=cat("steps"), progress=cat("progress"), distance=cat("distance"),
        failure=[f for p in parts for f in p.failure],
        wall_time_s=max(p.wall_time_s for p in parts), sim_steps=max(p.sim_steps for p in parts),
        horizon_cost=parts[0].horizon_cost,
        stopped=None if any(p.stopped is None for p in parts) else cat("stopped"),
        end_states=None if any(p.end_states is None for p in parts) else [s for p in parts for s in p.end_states],
    )
    recorded = [p for p in parts if p.traj_t is not None]
    if len(recorded) == len(parts):
        longest = max(recorded, key=lambda p: len(p.traj_t))
        frames = len(longest.traj_t)
        res.traj_t = longest.traj_t
        for name in TRAJECTORIES:
            if all(getattr(p, name) is not None for p in parts):
                setattr(res, name, torch.cat([_pad_frames(getattr(p, name), frames) for p in parts]))
    return res
