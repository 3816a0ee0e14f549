"""Robust scores: a sample's results in R perturbed worlds folded into one row the ranking reads.

What it does: ``fold_worlds`` takes the per-copy results of a batch whose sample ``i`` filled
copies ``i*R .. i*R + R - 1`` (one per world, ``realize.tasks.worlds.Worlds.tile``) and returns
per sample: its success share over the worlds, a cost (``risk = "mean"``: the mean cost of its
successful worlds; ``"cvar"``: the mean of the worst ``ceil(alpha * successes)`` of them; a
sample without a success: the mean cost of all its worlds, for the fallback order only), its
mean progress and distance, and ``feasible`` = at least one world succeeded. With the share,
``realize.search.ce.ranking.rank_samples`` orders feasible samples by share first, then cost,
as domain-randomized cross-entropy search does.
Batch-first torch, no loop over samples; R = 1 gives back the rows unchanged (share 1 or 0).
What it doesn't: draw worlds (``realize.tasks.worlds``) or run rollouts (the loop does).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import torch
from torch import Tensor

__all__ = ["WorldScores", "fold_worlds"]


@dataclass
class WorldScores:
    """Per sample (n,): what the ranking reads, folded over its R worlds."""

    cost: Tensor
    feasible: Tensor
    progress: Tensor
    distance: Tensor
    share: Tensor  # successes / R


def fold_worlds(cost: Tensor, feasible: Tensor, progress: Tensor, distance: Tensor, replicas: int,
                risk: str = "mean", alpha: float = 0.25) -> WorldScores:
    """Fold ``(n * replicas,)`` per-copy results into ``(n,)`` per-sample scores (module docstring)."""
    R = int(replicas)
    if cost.shape[0] % R:
        raise ValueError(f"{cost.shape[0]} results are not a whole number of samples of {R} worlds")
    if risk not in ("mean", "cvar"):
        raise ValueError(f"risk = {risk!r} must be 'mean' or 'cvar'")
    c = cost.reshape(-1, R).double()
    ok = (feasible.reshape(-1, R) & torch.isfinite(c))
    k = ok.sum(1)
    share = k.double() / R
    if risk == "mean":
        good = torch.where(ok, c, torch.zeros_like(c)).sum(1) / k.clamp_min(1)
    else:  # the worst ceil(alpha * k) successful costs
        worst = torch.sort(torch.where(ok, c, torch.full_like(c, -math.inf)), dim=1, descending=True).values
        take = torch.ceil(alpha * k.double()).long().clamp_min(1)
        mask = torch.arange(R)[None, :] < take[:, None]
        good = torch.where(mask & torch.isfinite(worst), worst, torch.zeros_like(worst)).sum(1) / take
    every = torch.nan_to_num(c, nan=math.inf).mean(1)
    return WorldScores(cost=torch.where(k > 0, good, every), feasible=k > 0,
                       progress=progress.reshape(-1, R).double().mean(1),
                       distance=distance.reshape(-1, R).double().mean(1), share=share)
