"""Rows that cannot win (``ce.prune``): the bound past which a running plan can no longer be an elite.

What it does: a plan's cost is its counted control steps plus a constant (eq. (2)), so it only
grows while the plan runs. Once ``keep`` plans of a batch are known to be feasible (every action
done and the goal read), the ``keep``-th smallest of their step counts bounds the batch's
``keep`` cheapest feasible plans from above: a plan still running with at least that many steps
ends with more, so it can be neither among them nor tie with one (ranking breaks cost ties by
row, ``realize.search.ce.ranking``). ``EliteBound.update`` keeps that bound as plans finish;
``Rollout.stop_hopeless`` stops the running plans at or past it. With ``keep`` = ``ce.n_elite``
(and the validation's candidate count, if larger) the elites, the refit, the best sample and the
validation candidates are those of the unpruned rollout. More feasible plans can only lower the
bound, so it is safe to use before the batch ends. As every plan starts at step 0 and a running
plan is counted every step, the plans still running when the bound first exists are all past it:
in effect a shard's rollout ends once ``keep`` of its plans are confirmed feasible: the plans
still settling then (done, goal not read yet) finished after those ``keep`` did, past the bound,
so they stop too, unread, instead of settling for nothing. The bound can only move when a goal
was read, the one time the rollout asks.
Each shard of a batch keeps its own bound (its ``keep`` best contain the batch's ``keep`` best
among its rows), so a run's numbers still do not depend on how shards are dealt to workers.
What it doesn't: stop anything itself, or apply to a robust or kNN-ranked search, where a row's
score depends on other rows or worlds (``realize.spec.run_spec.RunSpec.keep_best`` is None there).
"""

from __future__ import annotations

import torch
from torch import Tensor

__all__ = ["EliteBound"]


class EliteBound:
    """The step count at which a running plan can no longer be among the ``keep`` cheapest feasible."""

    def __init__(self, keep: int) -> None:
        if keep < 1:
            raise ValueError(f"keep must be >= 1, got {keep}")
        self.keep = keep
        self._seen = -1  # feasible plans counted at the last update
        self.bound: int | None = None

    def update(self, feasible: Tensor, steps: Tensor) -> int | None:
        """The bound for the plans known feasible now (``feasible`` (N,) bool, ``steps`` (N,)
        counted steps), or None while fewer than ``keep`` are; recomputed only when that count moved."""
        n = int(feasible.sum())
        if n != self._seen:
            self._seen = n
            if n >= self.keep:
                self.bound = int(torch.kthvalue(steps[feasible], self.keep).values)
        return self.bound
