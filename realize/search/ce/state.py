"""What a cross-entropy search keeps: its state (for resuming), one record per iteration, the result.

What it does:
  * ``CEState``: the distribution, the best sample so far and the generator state; it
    round-trips through plain JSON (``to_dict``/``from_dict``; inf/NaN as the strings
    ``"inf"``/``"nan"``, the RNG state as a byte list) so a resumed run draws exactly the samples
    the uninterrupted one would have;
  * ``IterationRecord``: one iteration, all tensors on the CPU, and its ``summary()``
    (``realize.run_dir.summaries.IterationSummary``: what the checkpoint and result keep);
  * ``CEResult``: the outcome of ``CrossEntropyOptimizer.run``.
What it doesn't: sample, rank or refit (``realize.search.ce.optimizer``), or write files
(``realize.sinks``).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import torch
from torch import Tensor

from realize.run_dir.summaries import IterationSummary

__all__ = ["CEState", "IterationRecord", "CEResult", "WarmDistribution"]


def _t2l(t: Tensor | None) -> list | None:
    return None if t is None else t.detach().cpu().tolist()


def _f2j(x: float) -> float | str:
    """JSON has no inf/nan: encode them as strings."""
    return x if math.isfinite(x) else str(x)


def _clone(v: Tensor | None) -> Tensor | None:
    return None if v is None else v.clone()


@dataclass
class CEState:
    """Everything needed to continue a run: the distribution, the best so far and the RNG.

    ``iteration`` counts completed iterations (the next one to run). ``mean``/``std`` are
    ``None`` while the distribution is still the uniform one over the regions. ``best_*`` is the
    best sample of all completed iterations (feasible first; see ``rank_samples``).
    ``init_mean``/``init_std`` are the moments of the last uniform batch (the "previous"
    distribution for the first smoothed refit). With ``n_modes = k > 1`` ``mean``/``std`` are
    ``(k, D)`` and ``weights`` ``(k,)`` holds the mixture weights; it is ``None`` otherwise (and
    left out of ``to_dict``, so single-mode checkpoints read as before).
    """

    iteration: int
    rng_state: Tensor
    mean: Tensor | None = None
    std: Tensor | None = None
    init_mean: Tensor | None = None
    init_std: Tensor | None = None
    best_z: Tensor | None = None
    best_cost: float = math.inf
    best_feasible: bool = False
    best_progress: float = -math.inf
    best_distance: float = math.inf
    best_iteration: int = -1
    best_share: float = 1.0  # robust search: the best sample's success share over its worlds
    converged: bool = False
    weights: Tensor | None = None
    # the elites' mean cost of every iteration so far (NaN where they were not all feasible): the
    # stopping rule's memory (``CEConfig.patience``)
    elite_costs: list[float] = field(default_factory=list)
    # ce.keep_elites: the last refit's feasible elites and the costs they were simulated with
    # (``realize.search.ce.elite_memory``); None without the memory (and then not in ``to_dict``)
    memory_z: Tensor | None = None
    memory_cost: Tensor | None = None

    def to_dict(self) -> dict[str, Any]:
        """Plain-JSON form (lists, numbers, strings for inf/nan; the RNG state as a byte list)."""
        d = {
            "iteration": self.iteration,
            "rng_state": self.rng_state.to(torch.uint8).tolist(),
            "mean": _t2l(self.mean),
            "std": _t2l(self.std),
            "init_mean": _t2l(self.init_mean),
            "init_std": _t2l(self.init_std),
            "best_z": _t2l(self.best_z),
            "best_cost": _f2j(self.best_cost),
            "best_feasible": self.best_feasible,
            "best_progress": _f2j(self.best_progress),
            "best_distance": _f2j(self.best_distance),
            "best_iteration": self.best_iteration,
            "best_share": _f2j(self.best_share),
            "converged": self.converged,
            "elite_costs": [_f2j(c) for c in self.elite_costs],
        }
        if self.weights is not None:
            d["weights"] = _t2l(self.weights)
        if self.memory_cost is not None:
            d["memory_z"], d["memory_cost"] = _t2l(self.memory_z), [_f2j(c) for c in self.memory_cost.tolist()]
        return d

    @classmethod
    def from_dict(cls, d: Mapping[str, Any], dtype: torch.dtype = torch.float64) -> CEState:
        def t(v: Any) -> Tensor | None:
            return None if v is None else torch.tensor(v, dtype=dtype)

        return cls(
            iteration=int(d["iteration"]),
            rng_state=torch.tensor(d["rng_state"], dtype=torch.uint8),
            mean=t(d.get("mean")),
            std=t(d.get("std")),
            init_mean=t(d.get("init_mean")),
            init_std=t(d.get("init_std")),
            best_z=t(d.get("best_z")),
            best_cost=float(d.get("best_cost", math.inf)),
            best_feasible=bool(d.get("best_feasible", False)),
            best_progress=float(d.get("best_progress", -math.inf)),
            best_distance=float(d.get("best_distance", math.inf)),
            best_iteration=int(d.get("best_iteration", -1)),
            best_share=float(d.get("best_share", 1.0)),
            converged=bool(d.get("converged", False)),
            weights=t(d.get("weights")),
            elite_costs=[float(c) for c in d.get("elite_costs", [])],
            memory_z=t(d.get("memory_z")),
            memory_cost=None if d.get("memory_cost") is None else torch.tensor([float(c) for c in d["memory_cost"]],
                                                                                  dtype=dtype),
        )

    def copy(self) -> CEState:
        return CEState(
            iteration=self.iteration,
            rng_state=self.rng_state.clone(),
            mean=_clone(self.mean),
            std=_clone(self.std),
            init_mean=_clone(self.init_mean),
            init_std=_clone(self.init_std),
            best_z=_clone(self.best_z),
            best_cost=self.best_cost,
            best_feasible=self.best_feasible,
            best_progress=self.best_progress,
            best_distance=self.best_distance,
            best_iteration=self.best_iteration,
            best_share=self.best_share,
            converged=self.converged,
            weights=_clone(self.weights),
            elite_costs=list(self.elite_costs),
            memory_z=_clone(self.memory_z),
            memory_cost=_clone(self.memory_cost),
        )


@dataclass
class WarmDistribution:
    """Where a warm-started search begins instead of uniform sampling (``realize.search.warm_start``
    builds it from an earlier run): ``mean``/``std`` ``(D,)``, or ``(k, D)`` with ``weights``
    ``(k,)`` for a k-mode mixture (k = ``ce.n_modes``), and the share of iteration 0's batch
    that is still drawn uniformly over the regions (later iterations use ``ce.uniform_share``)."""

    mean: Tensor
    std: Tensor
    weights: Tensor | None = None
    uniform_share: float = 0.0


@dataclass
class IterationRecord:
    """One CE iteration, all tensors on the CPU.

    ``Z`` (N, D) the samples (``None`` when ``keep_samples`` is off); ``cost``/``feasible``/
    ``progress``/``distance`` (N,) the evaluation; ``elite_idx`` the rows used for the refit, best first
    (or, when the distribution was kept, the feasible rows); ``mean``/``std`` (D,) the
    distribution *after* this iteration's update (``None`` while still uniform);
    ``sampled_from`` is ``"uniform"``, ``"gaussian"``, ``"warm"`` (iteration 0 of a warm start) or
    ``"given"`` (rows chosen elsewhere: ``CrossEntropyOptimizer.give``); ``refit`` says what happened:
    ``"elite"`` (>= n_elite feasible), ``"fallback_progress"``, ``"feasible_only"`` or ``"kept"``.
    ``best_cost`` is the best feasible cost of all iterations so far (inf if none; never
    increases); ``iteration_best_cost`` the best feasible cost of this batch. Elite cost stats
    are over the feasible elites (NaN if none). Times in seconds.

    With ``n_modes > 1`` ``mean``/``std`` are ``(k, D)`` and ``weights`` ``(k,)`` (else
    ``None``). ``best_idx`` is the batch's best single sample (feasible by cost, else the
    fallback order), which with ``knn_robust`` need not be ``elite_idx[0]``; ``robust_cost`` (N,)
    is the kNN score used to rank the feasible elites (``None`` when ``knn_robust`` is 0).
    ``n_envs`` is the batch size (``CEConfig.samples_at(iteration)``). A robust search
    (``ce.replicas > 1``) keeps each sample's success share over its worlds in ``share`` (N,),
    and ``success_share`` is then the share of successful copies (their mean).
    """

    iteration: int
    n_envs: int
    Z: Tensor | None
    cost: Tensor
    feasible: Tensor
    progress: Tensor | None
    distance: Tensor | None
    elite_idx: Tensor
    sampled_from: str
    refit: str
    mean: Tensor | None
    std: Tensor | None
    n_feasible: int
    success_share: float
    best_cost: float
    iteration_best_cost: float
    elite_cost_min: float
    elite_cost_mean: float
    elite_cost_max: float
    eval_time: float
    wall_time: float
    converged: bool
    weights: Tensor | None = None
    best_idx: int = -1
    robust_cost: Tensor | None = None
    share: Tensor | None = None  # robust search: each sample's success share over its worlds
    n_stopped: int | None = None  # ce.prune: rows stopped as they could not be an elite (None: off)
    n_screened: int | None = None  # ce.screen: draws rejected before simulation (None: off)
    screened_Z: Tensor | None = None  # ce.screen: those draws (k, D), not simulated
    # ce.keep_elites: elites of the refit that came from the memory (elite_idx lists the batch's;
    # the elite cost stats cover both). None: no memory
    n_remembered: int | None = None

    def summary(self, candidate: int | None = None) -> IterationSummary:
        """This iteration's numbers without the per-sample tensors (``result.json``'s series and
        the checkpoint's records are made of these); ``candidate``: its plan in a top-k run."""
        return IterationSummary(
            iteration=self.iteration,
            n_envs=self.n_envs,
            sampled_from=self.sampled_from,
            refit=self.refit,
            n_feasible=self.n_feasible,
            success_share=self.success_share,
            best_cost=self.best_cost,
            iteration_best_cost=self.iteration_best_cost,
            elite_cost_min=self.elite_cost_min,
            elite_cost_mean=self.elite_cost_mean,
            elite_cost_max=self.elite_cost_max,
            n_elite=int(self.elite_idx.numel()) + (self.n_remembered or 0),
            mean=_t2l(self.mean),
            std=_t2l(self.std),
            eval_time=self.eval_time,
            wall_time=self.wall_time,
            converged=self.converged,
            weights=_t2l(self.weights),
            candidate=candidate,
            n_stopped=self.n_stopped,
            n_screened=self.n_screened,
        )


@dataclass
class CEResult:
    """Outcome of a run: the best sample of all iterations, the final distribution, history.

    ``best_z`` (D,) with ``best_params`` its per-parameter split; ``best_feasible`` is False
    only when no sample was ever feasible (then ``best_z`` is the top-ranked infeasible one).
    ``history`` holds the iterations run by *this* call (a resumed run starts at its
    ``state.iteration``). ``mean``/``std``/``weights`` as in ``CEState``.
    """

    best_z: Tensor
    best_params: dict[str, Tensor]
    best_cost: float
    best_feasible: bool
    best_iteration: int
    mean: Tensor | None
    std: Tensor | None
    converged: bool
    history: list[IterationRecord] = field(default_factory=list)
    state: CEState | None = None
    weights: Tensor | None = None
