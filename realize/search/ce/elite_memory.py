"""Elite memory (``ce.keep_elites``): the last refit's feasible elites ranked again with the next batch.

What it does: ``pooled`` appends the remembered elites (their parameters and the costs they were
simulated with, all feasible) to a batch's samples and results, so that the elites of the next
refit are the ``n_elite`` best of the batch and the memory together; ``remembered`` is the new
memory, the feasible ones among those elites. With a small batch this keeps a lucky good sample
from being forgotten after one refit: the elite set's cost can only fall from one iteration to the
next, and the distribution does not drift away from a good region because one batch missed it.
What it doesn't: simulate a remembered elite again (its cost is the one it was simulated with,
so a scene that would now give it a slightly different cost is not asked), count remembered
elites in a batch's statistics (success share, feasible count, best of the iteration), or apply
to a robust or kNN-ranked search, where a sample's score depends on its batch or its worlds
(``CrossEntropyOptimizer`` keeps no memory there).
"""

from __future__ import annotations

import torch
from torch import Tensor

from realize.search.protocol import EvalResult

__all__ = ["pooled", "remembered"]


def pooled(Z: Tensor, r: EvalResult, memory_z: Tensor | None, memory_cost: Tensor | None) -> tuple[Tensor, EvalResult]:
    """The batch ``Z`` (N, D) and its CPU result ``r`` with the ``K`` remembered elites appended
    as rows ``N .. N + K - 1`` (feasible; progress and distance those of a done plan). Without a
    memory the inputs themselves."""
    if memory_z is None or memory_cost is None or memory_cost.numel() == 0:
        return Z, r
    k = memory_cost.shape[0]

    def append(t: Tensor | None, value: float) -> Tensor | None:
        return None if t is None else torch.cat([t, t.new_full((k,), value)])

    done = float(r.progress.max()) if r.progress is not None and r.progress.numel() else 0.0
    return torch.cat([Z, memory_z.to(Z.dtype)]), EvalResult(
        cost=torch.cat([r.cost, memory_cost.to(r.cost.dtype)]),
        feasible=torch.cat([r.feasible, torch.ones(k, dtype=torch.bool)]),
        progress=append(r.progress, done),
        distance=append(r.distance, 0.0),
        failure_cost=r.failure_cost,
    )


def remembered(Z: Tensor, r: EvalResult, elite: Tensor) -> tuple[Tensor, Tensor]:
    """The next memory: the feasible rows of ``elite`` (indices into the pooled ``Z``/``r``, best
    first) as ``(z (K, D), cost (K,))`` copies."""
    keep = elite[r.feasible[elite]]
    return Z[keep].clone(), r.cost[keep].clone()
