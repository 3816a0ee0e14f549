"""Stitched segments on a run's workers: the plan cut in two, realized side by side, confirmed whole.

What it does (the cut itself is ``realize.tasks.split``'s ``split_task`` and ``default_split``,
importable from here too):
  * ``run_segments(spec)`` and ``stitched_doc``: a run with ``stitch.enabled``: its three tasks,
    history keys and ``StitchedSearch`` (``realize.app.assembly`` runs it in the search loop:
    ``history.npz`` holds the confirmation, ``history_c1.npz`` the prefix's rounds,
    ``history_c2.npz`` the suffix's), and what its ``result.json`` says of the segments;
  * ``stitched_search(spec, stitch)``: opens the run's workers with the three tasks (whole plan,
    prefix, suffix), runs ``realize.search.stitched.StitchedSearch`` on them (the prefix's rows
    capture their end states, ``PlanRealizer.rollout(capture_end=True)``; the suffix's rows each
    start from one, ``starts``; the confirmation realizes whole plans) and returns its result;
  * ``validate_plan(spec, result)``: the cheapest confirmed plans in the validation's perturbed
    worlds, and the one a run's validation would return (``realize.app.candidate_validation``).
On a CPU host the two segments run as two calls on the same workers, one after the other: each
worker realizes its shards one after another anyway, so a batch holding both segments would cost
the same.
What it doesn't: write a run directory or a checkpoint (``scripts/bench_stitch.py`` measures the
search this way; a run with ``stitch.enabled`` goes through ``realize.app.assembly`` and the
search loop like any run), or run a robust, kNN-ranked, top-k, replan or warm-started search
(refused).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import torch
from torch import Tensor

from realize.app.run_config import RunSpec, stitch_refusal
from realize.config import ConfigError
from realize.search.protocol import EvalResult
from realize.run_dir.names import HISTORY_FILE, candidate_file
from realize.run_dir.summaries import IterationSummary
from realize.search.stitched import (PREFIX, SEGMENT_NAMES, SUFFIX, StitchConfig, StitchedIteration, StitchedResult,
                                     StitchedSearch)
from realize.tasks.spec import TaskSpec
from realize.tasks.split import default_split, split_task

__all__ = ["split_task", "default_split", "run_segments", "stitched_doc", "stitched_search", "validate_plan",
           "SEGMENTS"]

SEGMENTS = tuple(SEGMENT_NAMES[k] for k in (None, PREFIX, SUFFIX))  # the workers' task index of each segment


def run_segments(spec: RunSpec) -> tuple[list[TaskSpec], list[int | None], StitchedSearch]:
    """A run with ``stitch.enabled``: its tasks (the whole plan, the prefix, the suffix: the
    workers' tasks 0, 1, 2), the history keys of their batches (None, PREFIX, SUFFIX) and the
    searcher (its pool's states read back from a checkpoint as ``SceneState``)."""
    from realize.world.state import SceneState

    st = spec.stitch
    assert st is not None and st.split is not None  # (resolved by build_run_spec)
    prefix, suffix, pcols, scols = split_task(spec.task, st.split)
    search = StitchedSearch(spec.task.layout, prefix.layout, suffix.layout, pcols, scols, spec.ce, st,
                            device=spec.placement.device, read_state=SceneState.from_json)
    return [spec.task, prefix, suffix], [None, PREFIX, SUFFIX], search


def stitched_doc(st: StitchConfig, tasks: Sequence[TaskSpec], records: Sequence[IterationSummary]) -> dict[str, Any]:
    """``result.json["stitched"]``: the cut, the budget, each batch's segment (the top level's
    per-iteration series hold every batch, in order) and each segment's history file."""
    return {"split": st.split, "prefix": tasks[1].describe(), "suffix": tasks[2].describe(),
            "n_prefix": st.n_prefix, "n_suffix": st.n_suffix, "rounds": st.iterations, "pool": st.pool,
            "confirm": st.confirm, "segment_per_iter": [SEGMENT_NAMES[r.candidate] for r in records],
            "history": {name: HISTORY_FILE if k is None else candidate_file(HISTORY_FILE, k)
                        for k, name in SEGMENT_NAMES.items()}}


def _check(spec: RunSpec) -> None:
    refusal = stitch_refusal(spec.ce, spec.planner.top_k, spec.replan is not None, spec.warm_start is not None)
    if refusal is not None:
        raise ConfigError(f"stitched segments cannot run {refusal}")


def stitched_search(spec: RunSpec, stitch: StitchConfig, split: int | None = None, *, log_dir: Path | None = None,
                    on_iteration: Callable[[StitchedIteration], None] | None = None) -> tuple[StitchedResult, float]:
    """The stitched search of ``spec``'s task on its workers: (result, the workers' setup seconds)."""
    from realize.app.workers.pool import open_pool

    _check(spec)
    k = split if split is not None else stitch.split if stitch.split is not None else default_split(spec.task)
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
