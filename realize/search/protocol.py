"""The ask/tell protocol between a search over plan parameters and the loop that evaluates it.

What it does:
  * ``Batch``: what ``ask()`` hands out: the samples ``Z (N, D)`` of one iteration, the
    candidate plan they belong to (``None`` for a search over one plan) and the distribution
    they were drawn from (``None`` while it is still uniform over the regions);
  * ``EvalResult``: what the evaluator (the rollout) gives back per sample: cost, feasibility
    and the scores that rank infeasible samples;
  * ``SearchReport``: the search's standing after an iteration: the leading candidate, its
    ``CEState`` and, for a search over several candidate plans, their ``HalvingDoc``;
  * ``Searcher``: the protocol (``ask`` / ``tell`` / ``done`` / ``state_dict`` /
    ``load_state_dict`` / ``report``) that ``realize.search.ce.optimizer.CrossEntropyOptimizer`` and
    ``realize.search.candidates.SuccessiveHalving`` implement; ``realize.run.loop`` drives either one
    without knowing which.
What it doesn't: sample, rank or simulate (``realize.search.ce``, ``realize.search.candidates``,
``realize.realization``), or write files (``realize.sinks``).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, Protocol, runtime_checkable

import torch
from torch import Tensor

from realize.search.ce.state import CEState, IterationRecord
from realize.run_dir.result_doc import HalvingDoc

__all__ = ["Batch", "EvalResult", "SearchReport", "Searcher"]


@dataclass
class Batch:
    """One iteration's samples. ``mean``/``std`` (D,) (or (k, D) with ``weights`` (k,) for a
    mixture) are the distribution ``Z`` was drawn from; all ``None`` for a uniform batch.
    A stitched search's segments (``realize.search.chain``) also set ``starts`` (one start
    state per row; None: the task's start) and ``capture_end`` (the rows' end states are wanted)."""

    Z: Tensor
    candidate: int | None = None
    mean: Tensor | None = None
    std: Tensor | None = None
    weights: Tensor | None = None
    starts: list[Any] | None = None
    capture_end: bool = False


@dataclass
class EvalResult:
    """What an evaluator returns for ``N`` samples.

    ``cost`` (N,) float, lower is better (NaN is treated as +inf); ``feasible`` (N,) bool;
    ``progress`` (N,) float, higher is closer to success (e.g. actions completed); ``distance``
    (N,) float, lower is closer to success (tie-break for equal progress). ``progress`` and
    ``distance`` are only used to rank infeasible samples and may be ``None``.
    ``failure_cost`` is what an infeasible sample costs for robust kNN scoring (e.g. the
    rollout's horizon); only read with ``knn_robust > 0`` and no ``CEConfig.failure_cost``.
    ``share`` (N,) (robust search, ``realize.search.ce.risk``): each sample's success share over
    its worlds; feasible samples then rank by share first, then cost. ``None``: share 1 for
    every feasible sample.
    """

    cost: Tensor
    feasible: Tensor
    progress: Tensor | None = None
    distance: Tensor | None = None
    failure_cost: float | None = None
    share: Tensor | None = None  # robust search: each sample's success share over its worlds
    stopped: Tensor | None = None  # (N,) bool, ce.prune: rows stopped as they could not be an elite
    end_states: list[Any] | None = None  # per row, its end state where feasible (asked by ``Batch.capture_end``)

    def to_cpu(self, n: int, dtype: torch.dtype) -> EvalResult:
        """Validate shapes against ``n`` and return a CPU copy in ``dtype`` (bool feasibility)."""

        def vec(t: Any, name: str, kind: torch.dtype) -> Tensor:
            if not isinstance(t, Tensor):
                t = torch.as_tensor(t)
            t = t.detach().to("cpu")
            if t.shape != (n,):
                raise ValueError(f"EvalResult.{name}: expected shape ({n},), got {tuple(t.shape)}")
            return t.to(kind)

        return EvalResult(
            cost=vec(self.cost, "cost", dtype),
            feasible=vec(self.feasible, "feasible", torch.bool),
            progress=None if self.progress is None else vec(self.progress, "progress", dtype),
            distance=None if self.distance is None else vec(self.distance, "distance", dtype),
            failure_cost=self.failure_cost,
            share=None if self.share is None else vec(self.share, "share", dtype),
            stopped=None if self.stopped is None else vec(self.stopped, "stopped", torch.bool),
            end_states=self.end_states,
        )


@dataclass
class SearchReport:
    """The search's standing. ``lead``: the leading candidate (``None`` for one plan);
    ``state``: its CE state (a copy); ``round``: the halving round and ``halving``: the
    candidates, winner and budget for the result file (both ``None`` for one plan)."""

    lead: int | None
    state: CEState
    round: int | None = None
    halving: HalvingDoc | None = None


@runtime_checkable
class Searcher(Protocol):
    """Ask/tell search: ``ask()`` the next batch (``None`` once done), evaluate it, ``tell``
    the result (returns the iteration's record). ``state_dict`` is plain JSON data that
    ``load_state_dict`` restores exactly (same samples afterwards as without the pause)."""

    @property
    def done(self) -> bool: ...

    @property
    def iterations_done(self) -> int: ...

    def ask(self) -> Batch | None: ...

    def tell(self, result: EvalResult, eval_time: float = ...) -> IterationRecord: ...

    def report(self) -> SearchReport: ...

    def state_dict(self) -> dict[str, Any]: ...

    def load_state_dict(self, d: Mapping[str, Any]) -> None: ...
