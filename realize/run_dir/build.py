"""Pure builders of the run documents from what a search loop has in hand.

What it does:
  * ``RunInfo``: how the run was set up (segments, the iteration it resumed from, the scene's
    backend and copies, setup time); the loop fills it in as it learns it;
  * ``result_doc(...)`` -> ``ResultDoc`` from the CE state (``realize.search.ce.state.CEState``,
    or ``None`` before the first iteration), the ``IterationSummary`` list, the task
    (``realize.tasks.spec.TaskSpec``) and the run's identity (iterations, seed, config, directory);
  * ``halving_doc(sh, top_k)`` -> ``HalvingDoc`` from a ``realize.search.candidates.SuccessiveHalving``;
  * ``failure_doc(message, config)`` -> ``FailureDoc``; ``package_versions()``.
The inputs are read by attribute (duck typing, described by the protocols below), so this
module imports neither the optimizer nor the task code.
What it doesn't: write files (``realize.run_dir.directory.RunDir``), or run anything.
"""

from __future__ import annotations

import importlib.metadata
import math
import os
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Protocol

from realize.reproducible import PINNED, in_force
from realize.run_dir.jsonio import json_safe
from realize.run_dir.result_doc import EliteStats, FailureDoc, HalvingDoc, PlanRef, ResultDoc
from realize.run_dir.summaries import IterationSummary, best_params

__all__ = ["RunInfo", "SearchState", "TaskInfo", "result_doc", "halving_doc", "failure_doc", "package_versions"]


class SearchState(Protocol):
    """What ``result_doc`` reads of the search state (``realize.search.ce.state.CEState``)."""

    best_z: Any  # (D,) tensor or None
    best_cost: float
    best_feasible: bool
    best_iteration: int
    converged: bool
    mean: Any  # (D,) / (k, D) tensor or None
    std: Any
    weights: Any  # (k,) tensor or None


class TaskInfo(Protocol):
    """What ``result_doc`` reads of the task (``realize.tasks.spec.TaskSpec``)."""

    name: str
    source: str
    layout: Any  # realize.tasks.regions.ParamLayout

    def describe(self) -> str: ...


@dataclass
class RunInfo:
    """How a run was set up: ``segments`` (how often it started: 1, +1 per resume),
    ``resumed_from_iteration`` (None: not resumed), the scene's ``backend`` and copy count
    ``n_envs``, ``setup_time_s`` (None until the scene is built) and the rollout ``workers``."""

    segments: int = 1
    resumed_from_iteration: int | None = None
    backend: str | None = None
    n_envs: int | None = None
    setup_time_s: float | None = None
    workers: int = 1  # rollout workers (realize.workers); never changes the numbers
    warm_start: dict[str, Any] | None = None  # the earlier run the search started from (realize.search.warm_start)


def package_versions() -> dict[str, str | None]:
    """Versions of the packages that decide a run's numbers, the CPU math paths pinned by
    ``realize.reproducible`` (they decide its last bits) and, as ``cpu_math.LIB``, the kernels
    each loaded library runs (``realize.reproducible.in_force``)."""
    out: dict[str, str | None] = {}
    for name in ("realize", "torch", "mani_skill", "sapien", "numpy", "hydra-core", "rerun-sdk"):
        try:
            out[name] = importlib.metadata.version(name)
        except importlib.metadata.PackageNotFoundError:
            out[name] = None
    for key in PINNED:
        out[key] = os.environ.get(key)
    for lib, kernels in in_force().items():  # what each library runs, read back from it
        out[f"cpu_math.{lib}"] = kernels
    return out


def _list(t: Any) -> list[Any] | None:
    return None if t is None else t.tolist()


def result_doc(
    *,
    status: str,
    state: SearchState | None,
    summaries: Sequence[IterationSummary],
    task: TaskInfo,
    iterations: int,
    seed: int,
    config: dict[str, Any],
    run_dir: Path | str,
    wall_time_s: float,
    error: str | None = None,
    info: RunInfo | None = None,
    halving: HalvingDoc | None = None,
) -> ResultDoc:
    """The result document of a run (single plan, or the leading candidate of a top-k run with
    ``halving``): ``state`` searched over ``task``'s parameters and produced ``summaries``
    (one per completed iteration, in order)."""
    info = info if info is not None else RunInfo()
    has_best = state is not None and state.best_z is not None
    feasible = bool(state.best_feasible) if state is not None else False
    return ResultDoc(
        status=status,
        error=error,
        feasible=feasible,
        best_cost=float(state.best_cost) if state is not None and feasible else math.inf,
        best_iteration=state.best_iteration if has_best else None,
        best_params=best_params(task.layout, state.best_z) if has_best else None,
        best_z=state.best_z.tolist() if has_best else None,
        columns=list(task.layout.column_names),
        iterations_done=len(summaries),
        iterations=iterations,
        converged=bool(state.converged) if state is not None else False,
        success_per_iter=[r.success_share for r in summaries],
        best_cost_per_iter=[r.best_cost for r in summaries],
        iteration_best_cost_per_iter=[r.iteration_best_cost for r in summaries],
        n_envs_per_iter=[r.n_envs for r in summaries],
        n_feasible_per_iter=[r.n_feasible for r in summaries],
        n_stopped_per_iter=(None if all(r.n_stopped is None for r in summaries)
                            else [r.n_stopped or 0 for r in summaries]),
        n_screened_per_iter=(None if all(r.n_screened is None for r in summaries)
                             else [r.n_screened or 0 for r in summaries]),
        elite_per_iter=[EliteStats(r.n_elite, r.refit, r.elite_cost_min, r.elite_cost_mean, r.elite_cost_max)
                        for r in summaries],
        iteration_time_s=[r.wall_time for r in summaries],
        final_mean=None if state is None else _list(state.mean),
        final_std=None if state is None else _list(state.std),
        final_weights=None if state is None else _list(state.weights),
        wall_time_s=wall_time_s,
        seed=seed,
        task_name=task.name,
        task_source=task.source,
        plan=task.describe(),
        config=config,
        versions=package_versions(),
        run_dir=str(run_dir),
        segments=info.segments,
        resumed_from_iteration=info.resumed_from_iteration,
        backend=info.backend,
        n_envs=info.n_envs,
        setup_time_s=math.nan if info.setup_time_s is None else info.setup_time_s,
        workers=info.workers,
        warm_start=info.warm_start,
        halving=halving,
    )


def halving_doc(sh: Any, top_k: int) -> HalvingDoc:
    """The top-k part of the result from a ``realize.search.candidates.SuccessiveHalving`` ``sh``:
    its leader (the winner once decided), winner, budget, spending and every candidate's
    ``Candidate.summary()``."""
    lead, win = sh.leader, sh.winner
    return HalvingDoc(
        top_k=top_k,
        leader=PlanRef(lead, sh.candidates[lead].spec.plan),
        winner=None if win is None else PlanRef(win, sh.candidates[win].spec.plan),
        budget=sh.budget.to_dict(),
        spent_iterations=sh.spent_iterations,
        spent_samples=sh.spent_samples,
        halving_round=min(sh.round, sh.budget.n_rounds),
        candidates=[c.summary() for c in sh.candidates],
    )


def failure_doc(message: str, config: Any = None) -> FailureDoc:
    """The document of a run that failed before simulating (``config``: as far as it was read)."""
    return FailureDoc(error=message, config=json_safe(config), versions=package_versions())
