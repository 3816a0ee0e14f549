"""A run's copies cut into shards, one PhysX scene each: the row arithmetic.

Why shards: PhysX's CPU solver does not keep the copies of one scene apart bit for bit. Once a
gripper touches its cube, a copy's result moves by ~1e-6 m when other copies of the same scene
run other plans (measured: rows 8-15 of a 16-copy scene, rows 0-7 changed, first difference at
the grasp, control step 126), so copies split over two scenes would not reproduce one scene.
The copies are therefore cut into shards of at most ``sim.shard_rows`` copies, fixed by the
config and never by the machine or the worker count; a worker holds whole shards, and any
number of workers gives the same numbers as one process.

What it does: ``RowBlock`` (copies ``first .. stop - 1`` of ``total``), ``split_rows`` (``n``
contiguous blocks), ``shard_rows`` (the shards of ``n`` copies: ``ceil(n / rows)`` contiguous
blocks, sizes differing by at most one), ``group_shards`` (consecutive shards per worker) and
``deal_rows`` (an ``M``-row batch dealt to the shards in contiguous parts of near-equal size, so
that a batch smaller than the copies (a linear sample schedule, successive halving) still keeps
every shard, and so every worker, busy; a part always fits its shard).
What it doesn't: build scenes or move tensors (``realize.workers.blocks`` deals a batch's rows
and joins the results).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

__all__ = ["RowBlock", "split_rows", "shard_rows", "group_shards", "deal_rows"]


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
