"""Ranking a batch and choosing its elites; the single-normal refit and the kNN-robust score.

What it does:
  * ``rank_samples``: feasible rows by cost first (a robust search's: by success share over
    its worlds, then cost), then infeasible rows by (progress desc, distance asc, cost asc), stable; ``sort_key`` is the same order for one sample;
  * ``robust_order``: with ``knn_robust = k > 0`` feasible rows are re-ranked by the mean cost
    of their ``k`` nearest samples (``knn_mean``, in the normalised space; an infeasible
    neighbour counts as the failure cost), infeasible rows keep the fallback order;
  * ``choose_elites``: the elite rows and what the refit does (``CEConfig.fallback``);
  * ``elite_weights`` / ``fit_normal``: the (optionally rank-weighted) elite mean and
    population std.
Everything is batch-first torch on the CPU, deterministic (no random draws here).
What it doesn't: sample, keep state or fit mixtures (``realize.search.ce.optimizer``,
``realize.search.ce.mixture``).
"""

from __future__ import annotations

import math

import torch
from torch import Tensor

from realize.search.ce.config import CEConfig
from realize.search.protocol import EvalResult

__all__ = ["rank_samples", "sort_key", "stable_argsort", "knn_mean", "robust_cost", "robust_order",
           "choose_elites", "elite_weights", "fit_normal"]


def stable_argsort(key: Tensor, order: Tensor) -> Tensor:
    """``order`` re-sorted by ``key`` ascending; equal keys keep their order in ``order``."""
    return order[torch.sort(key[order], stable=True).indices]


def rank_samples(
    cost: Tensor, feasible: Tensor, progress: Tensor | None = None, distance: Tensor | None = None,
    share: Tensor | None = None,
) -> Tensor:
    """Indices ``(N,)`` best first: feasible rows by (share desc, cost asc), then infeasible rows
    by (progress desc, distance asc, cost asc). Ties keep the original order (stable).
    ``share`` (robust search's success share over worlds; ``None``: every feasible row 1)."""
    n = cost.shape[0]
    c = torch.nan_to_num(cost, nan=math.inf)
    zero = torch.zeros_like(c)
    p = zero if progress is None else torch.where(feasible, zero, -torch.nan_to_num(progress, nan=-math.inf))
    d = zero if distance is None else torch.where(feasible, zero, torch.nan_to_num(distance, nan=math.inf))
    keys = [c, d, p]
    if share is not None:
        keys.append(torch.where(feasible, -share.to(c), zero))
    order = torch.arange(n)
    for key in (*keys, (~feasible).to(torch.int8)):  # least significant first
        order = stable_argsort(key, order)
    return order


def sort_key(feasible: bool, cost: float, progress: float, distance: float, share: float = 1.0) -> tuple[float, ...]:
    """Scalar lexicographic key matching ``rank_samples`` (smaller is better)."""
    c = math.inf if math.isnan(cost) else cost
    if feasible:
        return (0.0, -share, 0.0, 0.0, c)
    p = -math.inf if math.isnan(progress) else progress
    d = math.inf if math.isnan(distance) else distance
    return (1.0, 0.0, -p, d, c)


def knn_mean(X: Tensor, values: Tensor, k: int) -> Tensor:
    """``(N,)``: the mean of ``values`` over each row's ``k`` nearest rows of ``X (N, D)``,
    the row itself always included (its own distance is set below every other)."""
    n = X.shape[0]
    k = min(k, n)
    d = torch.cdist(X, X)
    d.diagonal().fill_(-1.0)
    idx = torch.topk(d, k, dim=1, largest=False, sorted=True).indices  # (N, k)
    return values[idx].mean(1)


def robust_cost(Xn: Tensor, r: EvalResult, cfg: CEConfig) -> Tensor:
    """``(N,)`` mean cost of each row's ``cfg.knn_robust`` nearest rows of ``Xn`` (the batch in
    the normalised space, itself included); infeasible or non-finite costs count as the failure
    cost (only needed when there are any)."""
    ok = r.feasible & torch.isfinite(r.cost)
    fail = cfg.failure_cost if cfg.failure_cost is not None else r.failure_cost
    if fail is None or not math.isfinite(float(fail)):
        if not bool(ok.all()):
            raise ValueError(
                f"ce.knn_robust = {cfg.knn_robust} needs the cost of a failed plan: set ce.failure_cost "
                "or return EvalResult.failure_cost from the evaluator"
            )
        fail = 0.0  # unused
    c = torch.where(ok, r.cost, torch.full_like(r.cost, float(fail)))
    return knn_mean(Xn, c, cfg.knn_robust)


def robust_order(order: Tensor, robust: Tensor, feasible: Tensor) -> Tensor:
    """Feasible rows by their neighbourhood cost, infeasible rows keep the order of ``order``."""
    key = torch.where(feasible, robust, torch.zeros_like(robust))
    return stable_argsort((~feasible).to(torch.int8), stable_argsort(key, order))


def choose_elites(order: Tensor, n_feasible: int, cfg: CEConfig) -> tuple[Tensor, str]:
    """The elite rows (best first) and the refit: ``"elite"`` (>= n_elite feasible),
    ``"fallback_progress"``, ``"feasible_only"`` or ``"kept"`` (the distribution stays; the
    returned rows are then the feasible ones)."""
    if n_feasible >= cfg.n_elite:
        return order[: cfg.n_elite], "elite"
    if cfg.fallback == "progress":
        return order[: cfg.n_elite], "fallback_progress"
    if cfg.fallback == "feasible_only" and n_feasible >= cfg.min_feasible_refit:
        return order[:n_feasible], "feasible_only"
    return order[:n_feasible], "kept"


def elite_weights(k: int, rank_weighted: bool, dtype: torch.dtype) -> Tensor:
    """``(k,)`` normalised weights of the elites (best first): equal, or the CMA-ES log
    weights ``w_i ~ log(k + 1/2) - log(i)``, i = 1..k, with ``rank_weighted``."""
    if rank_weighted and k > 1:
        i = torch.arange(1, k + 1, dtype=dtype)
        w = math.log(k + 0.5) - torch.log(i)
    else:
        w = torch.ones(k, dtype=dtype)
    return w / w.sum()


def fit_normal(Ze: Tensor, w: Tensor) -> tuple[Tensor, Tensor]:
    """Weighted mean and population std of the elite rows ``Ze (m, D)`` (weights ``w (m,)``)."""
    mean = (w[:, None] * Ze).sum(0)
    var = (w[:, None] * (Ze - mean) ** 2).sum(0)
    return mean, var.sqrt()
