"""Stitched segments on a run's workers: the plan cut in two, realized side by side, confirmed whole.

What it does:
  * ``split_task(task, split)``: the prefix task (actions ``0 .. split - 1``, no goal, no final
    cost: its cost counts its own control steps), the suffix task (``realize.tasks.suffix``:
    actions ``split ..``, the goal and the final cost) and the full layout's columns of each; a
    parameter both segments bind (a plan that comes back to a region) is one ``ConfigError``;
  * ``default_split(task)``: the action after the plan's first grasp (the seed's example);
  * ``stitched_search(spec, stitch)``: opens the run's workers with the three tasks (whole plan,
    prefix, suffix), runs ``realize.search.stitched.StitchedSearch`` on them (the prefix's rows
    capture their end states, ``PlanRealizer.rollout(capture_end=True)``; the suffix's rows each
    start from one, ``starts``; the confirmation realizes whole plans) and returns its result;
  * ``validate_plan(spec, result)``: the cheapest confirmed plans in the validation's perturbed
    worlds, and the one a run's validation would return (``realize.app.candidate_validation``).
On a CPU host the two segments run as two calls on the same workers, one after the other: each
worker realizes its shards one after another anyway, so a batch holding both segments would cost
the same.
What it doesn't: write a run directory or a checkpoint (a research lever measured by
``scripts/bench_stitch.py``, not a run mode yet), or run a robust, kNN-ranked, top-k or replan
search (refused).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import torch
from torch import Tensor

from realize.app.run_config import RunSpec
from realize.config import ConfigError
from realize.search.protocol import EvalResult
from realize.search.stitched import StitchConfig, StitchedIteration, StitchedResult, StitchedSearch
from realize.tasks.goal_spec import GoalSpec
from realize.tasks.spec import TaskSpec, task_for_plan
from realize.tasks.suffix import part_columns, task_suffix

__all__ = ["split_task", "default_split", "stitched_search", "validate_plan", "SEGMENTS"]

SEGMENTS = ("full", "prefix", "suffix")  # the pool's candidate index of each segment's task


def split_task(task: TaskSpec, split: int) -> tuple[TaskSpec, TaskSpec, list[int], list[int]]:
    """(prefix task, suffix task, prefix columns, suffix columns) of ``task`` cut before ``split``."""
    n = task.n_actions
    if isinstance(split, bool) or not isinstance(split, int) or not 1 <= split < n:
        actions = "; ".join(f"{i}: {a}" for i, a in enumerate(task.plan))
        raise ConfigError(f"stitch.split = {split!r} is invalid: the second segment's first action, 1 .. {n - 1} "
                          f"({actions})")
    prefix = task_for_plan(dataclasses.replace(task, goal=GoalSpec(), final_cost=0.0), task.plan[:split])
    prefix.name = f"{task.name}[:{split}]"
    suffix = task_suffix(task, split, key="stitch.split")
    shared = sorted(set(prefix.layout.names) & set(suffix.layout.names))
    if shared:
        raise ConfigError(f"stitch.split = {split}: parameters {shared} are bound on both sides of the cut; "
                          "cut where no parameter (or goal region) is used on both sides")
    return prefix, suffix, part_columns(task, prefix), part_columns(task, suffix)


def default_split(task: TaskSpec) -> int:
    """The action after the plan's first grasp; a ``ConfigError`` where none is followed by another."""
    for i, a in enumerate(task.plan[:-1]):
        if a.template == "grasp":
            return i + 1
    raise ConfigError(f"stitch.split: the plan of {task.source} has no grasp followed by another action; give "
                      "the second segment's first action (0-based)")


def _check(spec: RunSpec) -> None:
    ce = spec.ce
    for bad, what in ((ce.replicas > 1, "a robust search (ce.replicas > 1)"),
                      (ce.knn_robust > 0, "a kNN-ranked search (ce.knn_robust > 0)"),
                      (spec.halving, "several candidate plans (task.planner.top_k > 1)"),
                      (spec.replan is not None, "a replan (replan_from)")):
        if bad:
            raise ConfigError(f"stitched segments cannot run {what}")


def stitched_search(spec: RunSpec, stitch: StitchConfig, split: int | None = None, *, log_dir: Path | None = None,
                    on_iteration: Callable[[StitchedIteration], None] | None = None) -> tuple[StitchedResult, float]:
    """The stitched search of ``spec``'s task on its workers: (result, the workers' setup seconds)."""
    from realize.app.workers.pool import open_pool

    _check(spec)
    k = default_split(spec.task) if split is None else split
    prefix, suffix, pcols, scols = split_task(spec.task, k)
    pool = open_pool(spec, [spec.task, prefix, suffix], log_dir=log_dir,
                     n_envs=max(stitch.n_prefix, stitch.n_suffix, stitch.confirm))

    steps = {"row": 0, "batch": 0}

    def evaluate(segment: str, Z: Tensor, starts: Sequence[Any] | None) -> tuple[EvalResult, list[Any] | None]:
        res = pool.rollout(SEGMENTS.index(segment), Z, starts=starts, capture_end=segment == "prefix")
        steps["row"] += int(res.steps.sum())
        steps["batch"] += int(res.sim_steps)
        return res.to_eval(), res.end_states

    try:
        search = StitchedSearch(spec.task.layout, prefix.layout, suffix.layout, pcols, scols, spec.ce, stitch)
        out = search.run(evaluate, on_iteration)
        out.row_steps, out.batch_steps = steps["row"], steps["batch"]
        return out, pool.setup_time_s
    finally:
        pool.close()


def validate_plan(spec: RunSpec, result: StitchedResult,
                  log_dir: Path | None = None) -> tuple[int, list[tuple[float, float]]]:
    """The confirmed feasible plans, cheapest first (``validation.candidates`` of them), each in
    the run's ``validation.replicas`` perturbed worlds (pruning off), and the one a run's
    validation would return: the cheapest whose 95 % Wilson lower bound reaches
    ``validation.min_success``, else the most robust (``realize.app.candidate_validation``).
    Returns (that plan's index in the list, [(confirmed cost, success share)] per plan)."""
    from realize.app.candidate_validation import wilson_interval
    from realize.app.validation import simulate_worlds, validation_worlds

    v = spec.validation
    if v is None or v.replicas < 1:
        raise ConfigError("validation is off: nothing to validate the stitched plans in")
    if result.candidates is None or not result.feasible:
        raise ValueError("the stitched search confirmed no feasible plan")
    done = result.confirmed
    picked = sorted((k for k in range(len(done)) if done[k][2]), key=lambda k: (done[k][1], done[k][0], k))
    picked = picked[:v.candidates]
    u = v.replicas + 1  # world 0 the unperturbed one, then the perturbed ones
    worlds = validation_worlds(spec.task.perturbation, spec.geometry.objects, v.replicas, spec.seed)
    Z = result.candidates[picked].to(torch.float64).repeat_interleave(u, dim=0)
    vspec = dataclasses.replace(spec, ce=dataclasses.replace(spec.ce, prune=False))  # every world to its end
    res, _ = simulate_worlds(vspec, Z, worlds.tile(len(picked) * u), log_dir)
    ok = res.feasible.reshape(len(picked), u)[:, 1:]
    table = [(done[k][1], float(ok[j].double().mean())) for j, k in enumerate(picked)]
    good = [j for j in range(len(picked)) if wilson_interval(int(ok[j].sum()), v.replicas)[0] >= v.min_success]
    best = good[0] if good else max(range(len(picked)), key=lambda j: (table[j][1], -table[j][0], -j))
    return best, table
