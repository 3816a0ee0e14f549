"""What the executor does on a deviation: check before repairing, re-parameterize, re-sequence.

What it does: ``Segment`` is one stretch of execution (a plan, its parameters, the state it
assumed at its start, the map it plans in). ``go_on(ex, ...)`` checks the remaining plan from
the believed state (``realize.execution.precheck``) and, where it still reaches the goal often
enough, returns the same plan's remaining actions as the next segment (the map as believed now);
``repair(ex, ...)`` re-parameterizes (``Planner.replan``: the remaining actions from the state)
where the remaining plan can start from the state, else re-sequences (a new PDDL plan from the
symbolic state read off the world, ``realize.repair.resequence``), and returns the replan's record
and the next segment. ``ex`` is the ``realize.repair.executor.Executor`` of the world.
What it doesn't: run the world, hold the robot while it thinks, or judge replans after the
fact (``realize.repair.study.judge_replans``).
"""

from __future__ import annotations

import logging
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from realize.repair.records import ReplanRecord
from realize.config import ConfigError
from realize.execution.layout_updates import geometry_changes
from realize.execution.world import Observation

__all__ = ["Segment", "go_on", "repair", "why_no_plan", "stack_changes", "EXECUTION_BACKEND"]

# an executed world is one copy restored and disturbed through the CPU backend's setters (the GPU
# backend's restore has never run), whatever backend the run searched on
EXECUTION_BACKEND = "cpu"

log = logging.getLogger("realize")


class Segment:
    """One stretch of execution: a plan (``task``, ``z``) run in the world, with the disturbances
    due and (closed loop) the monitor; ``start``: the state the plan assumed at its start (the
    belief; None: the world's start); ``belief``: the map its controllers plan in; ``offset``: the
    original plan's index of the task's action 0 (None: a re-sequenced plan, whose actions the
    triggers do not name); ``rollout``: the controller settings it was searched with (a replan's
    own, e.g. a floor pick's; None: the run's)."""

    def __init__(self, task: Any, z: Sequence[float], start: Any, belief: Any, offset: int | None,
                 rollout: Any = None) -> None:
        self.task, self.z, self.start, self.belief, self.offset = task, list(z), start, belief, offset
        self.rollout = rollout  # the controllers' settings the plan was searched with (None: the run's)
        self.action = 0


def go_on(ex: Any, seg: Segment, obs: Observation, a: int, reasons: list[str]) -> tuple[Segment | None, float]:
    """Check before you repair (``settings.precheck``): simulate the rest of the plan from
    the believed state; where it succeeds often enough, the same plan goes on (with the
    world as believed now). Returns (that segment or None, the check's wall time)."""
    from realize.tasks.suffix import check_suffix_start, suffix_columns, task_suffix
    from realize.world.geometry import build_geometry

    if ex.precheck is None or not ex.precheck.settings.copies or a >= seg.task.n_actions \
            or reasons[0].startswith("action_failed") or _restack(reasons):
        return None, 0.0
    try:
        suffix = task_suffix(seg.task, a)
        check_suffix_start(suffix, obs.state)
        now_cfg = ex.layout(obs)
    except ConfigError:
        return None, 0.0
    chk = ex.precheck(seg.task, seg.z, a, obs.state, now_cfg)
    ex.log.checks.append({"step": ex.now(), "action": a, "reason": reasons, **chk.to_dict()})
    log.info("world %d: check from action %d: %d/%d reach the goal: %s", ex.k, a, chk.successes, chk.copies,
             "go on" if chk.go_on else "repair")
    if ex.recorder is not None:
        ex.recorder.event(ex.now(), f"check from action {a}: {chk.successes}/{chk.copies}, "
                                          f"{'go on' if chk.go_on else 'repair'}")
    if not chk.go_on:
        return None, chk.wall_s
    z = [seg.z[c] for c in suffix_columns(seg.task, a)]
    offset = None if seg.offset is None else seg.offset + a
    return Segment(suffix, z, obs.state, build_geometry(now_cfg), offset, seg.rollout), chk.wall_s


def repair(ex: Any, seg: Segment, source: Any, obs: Observation, a: int, reasons: list[str]
           ) -> tuple[ReplanRecord, Segment | None]:
    """Re-parameterize (the remaining actions from the state) or re-sequence (a new plan)."""
    from realize.validation.replay import build_replay_spec, saved_plan
    from realize.repair.resequence import on_floor, pickup_region, resequence_task
    from realize.tasks.suffix import check_suffix_start, task_suffix

    t0 = time.perf_counter()
    state = obs.state
    changes = geometry_changes(obs, ex.spec.geometry_cfg, ex.moved_m())
    changes = [*changes, *stack_changes(ex.spec, ex.settings.stack_level_rad, ex.settings.stack_avoid_movable)]
    kind = "re-parameterize"
    if a >= seg.task.n_actions or _restack(reasons):  # all done but no goal, or the tower it builds on fell
        kind = "re-sequence"
    else:
        try:
            check_suffix_start(task_suffix(seg.task, a), state)
        except ConfigError:
            kind = "re-sequence"
    rdir = ex.out / "replans" / f"world-{ex.k}-replan-{len(ex.log.replans)}"
    try:
        task_cfg = None
        if kind == "re-sequence":
            from realize.world.geometry import build_geometry

            now_geo = build_geometry(ex.layout(obs))
            task_cfg = resequence_task(saved_plan(source).config["task"], now_geo, state, rdir,
                                       pickup=dict(zip(("r_min", "r_max"), ex.settings.pickup_m)))
            if any(pickup_region(o) in (task_cfg.get("params") or {}) and on_floor(state, now_geo, o)
                   for o in state.objects):
                changes = [*changes, "controller.fabric.floor_exclude=true"]  # the fingers reach the floor
            if not task_cfg["plan"] and a >= seg.task.n_actions:
                # symbolically done, geometrically not (the base just outside the exit): the last action again
                kind, a, task_cfg = "re-parameterize", seg.task.n_actions - 1, None
        if task_cfg is None:
            src_cfg = saved_plan(source).config
            base_k = 0 if src_cfg.get("replan") is None or src_cfg.get("replan_from") is None else \
                int(src_cfg["replan"]["action"] or 0)
            res = ex.planner.replan(state, base_k + a, changes, source=source, run_dir=rdir,
                                      budget=ex.replan_budget(), seed=ex.spec.seed)
        else:
            res = ex.planner.resequence(task_cfg, state, changes, source=source, run_dir=rdir,
                                          budget=ex.replan_budget(), seed=ex.spec.seed)
    except ConfigError as e:
        wall = time.perf_counter() - t0
        return ReplanRecord(kind, ex.now(), a, reasons + [f"refused: {e}"], wall, False, None, "", str(rdir),
                            "", changes), None
    wall = time.perf_counter() - t0
    rec = ReplanRecord(kind, ex.now(), res.from_action, reasons, wall, res.feasible,
                       res.cost if res.feasible else None, res.plan, str(res.run_dir), res.scene, changes,
                       res.timings.to_dict())
    log.info("world %d: %s from action %d in %.1f s: %s (cost %s)", ex.k, kind, res.from_action, wall, res.plan,
             f"{res.cost:.0f}" if res.feasible else "none")
    if not res.feasible:
        return rec, None
    rspec = build_replay_spec(saved_plan(res.run_dir), EXECUTION_BACKEND, judged=True)
    whole = ex.spec.task.describe()
    offset = res.from_action if rspec.config.get("task", {}).get("plan") == ex.run.config["task"].get("plan") \
        and whole.endswith(rspec.task.describe()) else None
    return rec, Segment(rspec.task, res.z, rspec.start, rspec.geometry, offset, rspec.rollout)


def stacks_blocks(spec: Any) -> bool:
    """Whether the spec's plan places an object on a region framed by another movable object."""
    task, names = spec.task, set(spec.geometry.object_names)
    return any(a.template == "place" and any(task.frame_of(p) in names for p in a.params) for a in task.plan)


def stack_changes(spec: Any, max_turn: float | None, avoid_movable: bool) -> list[str]:
    """The controller changes a repair of a plan that stacks searches and executes with (none for
    a plan that does not stack, nor for one its run's own controllers already set):

    * a held box set down level (``controller.place_level`` = ``max_turn``, rad;
      ``execute.stack_level_rad``, None: no change). Released as held, a box grasped 20-30 degrees
      off its axis and placed down a tilted approach meets the block below on one edge and tips it
      or itself off (``tests/test_level_place.py``).
    * the fabric kept off the movable objects where they stand (``controller.avoid_movable``;
      ``execute.stack_avoid_movable``). Without it a rebuild's carry can sweep the block it just
      set back on the tower off again, and the world uses its replans on the same deviation.
    """
    if not stacks_blocks(spec):
        return []
    out = [f"++controller.place_level={max_turn}"] if max_turn is not None and spec.rollout.place_level is None else []
    if avoid_movable and not spec.rollout.avoid_movable:
        out.append("++controller.avoid_movable=true")
    return out


def why_no_plan(rec: ReplanRecord, state: Any) -> str:
    """One line on why a repair found no plan: the planner's refusal, or the plan it tried and
    found no realization of; objects lying on the floor are named with where they lie."""
    refused = [r[len("refused: "):] for r in rec.reason if r.startswith("refused: ")]
    text = refused[0][:300] if refused else f"no realization of {rec.plan or 'the plan'} reached the goal"
    from realize.repair.resequence import pickup_region

    floor = [f"{o} lies at ({p.position[0]:.2f}, {p.position[1]:.2f}, {p.position[2]:.3f})"
             for o, p in state.objects.items() if pickup_region(o) in rec.plan]
    if refused and "unsolvable" in text.casefold():  # where the objects lie that no fact placed
        floor += [f"{o} at ({p.position[0]:.2f}, {p.position[1]:.2f}, {p.position[2]:.3f})"
                  for o, p in state.objects.items() if o != state.held]
    return "; ".join([text, *floor])


def _restack(reasons: list[str]) -> bool:
    """A block the remaining plan stacks on left its place (``support_moved``): the plan's
    symbolic state no longer holds, so no new pose can repair it."""
    return any("support_moved" in r for r in reasons)
