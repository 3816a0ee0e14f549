"""A run's copies as shards (one PhysX scene each), shards grouped per worker, results joined.

Why shards: PhysX's CPU solver does not keep the copies of one scene apart bit for bit. Once a
gripper touches its cube, a copy's result moves by ~1e-6 m when other copies of the same scene
run other plans (measured: rows 8-15 of a 16-copy scene, rows 0-7 changed, first difference at
the grasp, control step 126), so copies split over two scenes would not reproduce one scene.
The copies are therefore cut into shards of at most ``sim.shard_rows`` copies, fixed by the
config and never by the machine or the worker count; a worker holds whole shards, and any
number of workers gives the same numbers as one process.

What it does: ``RowBlock`` (copies ``first .. stop - 1`` of ``total``), ``shard_rows`` (the
shards of ``n`` copies: ``ceil(n / rows)`` contiguous blocks, sizes differing by at most one),
``group_shards`` (consecutive shards per worker), ``deal_rows`` (an ``M``-row batch dealt to the
shards in contiguous parts of near-equal size, so that a batch smaller than the copies (a
linear sample schedule, successive halving) still keeps every shard, and so every worker, busy;
a part always fits its shard) and ``join_results`` (results of consecutive parts as one, in
row order: per-plan tensors concatenated, shorter trajectories padded with their last frame).
What it doesn't: run anything (``realize.app.workers.pool``, ``.process``, ``.ray_pool``).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import torch
from torch import Tensor

from realize.realization.result import RolloutResult
from realize.world.state import SceneState

__all__ = ["RowBlock", "split_rows", "shard_rows", "group_shards", "deal_rows", "worker_parts", "worker_starts",
           "check_batch", "join_results"]


@dataclass(frozen=True)
class RowBlock:
    """Copies ``first .. stop - 1`` of a scene of ``total`` copies (one worker's scene)."""

    first: int
    stop: int
    total: int

    @property
    def size(self) -> int:
        return self.stop - self.first

    def describe(self) -> str:
        return f"rows {self.first}-{self.stop - 1} of {self.total}"


def split_rows(total: int, n: int, unit: int = 1) -> list[RowBlock]:
    """``n`` contiguous blocks covering ``0 .. total - 1``, sizes differing by at most one
    ``unit`` (each a whole number of units)."""
    if not 1 <= n <= total // unit:
        raise ValueError(f"cannot split {total} rows into {n} blocks of whole {unit}-row units")
    return [RowBlock(s.start, s.stop, total) for s in deal_rows(total, n, unit)]


def shard_rows(n: int, rows: int, unit: int = 1) -> list[RowBlock]:
    """The shards of ``n`` copies with at most ``rows`` copies each, each a whole number of
    ``unit``-copy samples (a robust search's sample fills ``unit`` = ``ce.replicas`` copies; a
    shard holds one sample at least)."""
    groups = n // unit
    return split_rows(n, -(-groups // max(1, rows // unit)), unit)


def group_shards(shards: Sequence[RowBlock], n_workers: int) -> list[list[RowBlock]]:
    """``n_workers`` groups of consecutive shards, counts differing by at most one."""
    groups = split_rows(len(shards), n_workers)
    return [list(shards[g.first:g.stop]) for g in groups]


def deal_rows(m: int, n_shards: int, unit: int = 1) -> list[slice]:
    """The rows of an ``m``-row batch each of ``n_shards`` shards realizes: contiguous, in order,
    sizes differing by at most one ``unit`` (whole units; empty where there are fewer units than
    shards). ``unit``: the copies of one sample (``ce.replicas``), which stay in one shard, each
    at its world's copy (``realize.tasks.worlds.Worlds.tile``)."""
    if m % unit:
        raise ValueError(f"a batch of {m} rows is not a whole number of {unit}-row samples")
    base, extra = divmod(m // unit, n_shards)
    out, first = [], 0
    for k in range(n_shards):
        stop = first + (base + (1 if k < extra else 0)) * unit
        out.append(slice(first, stop))
        first = stop
    return out


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
        for name in ("traj_base", "traj_ee", "traj_objects", "traj_q", "traj_action"):
            if all(getattr(p, name) is not None for p in parts):
                setattr(res, name, torch.cat([_pad_frames(getattr(p, name), frames) for p in parts]))
    return res
