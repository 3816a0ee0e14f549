"""What the executor checks while a plan runs: the observed world against what the plan expects.

What it does: pure functions over an ``Observation`` (``realize.execution.world``) and an
``Expectation`` (what the plan assumes at one point of its execution; ``expectation`` derives it
from the task's plan, the belief geometry and the action index), each returning a list of
``Deviation(kind, detail)``:
  * ``grasp_lost``: the plan has an object in hand now (grasped by an earlier action, or by
    this one at its end, and not yet placed) and the state's ``held`` (the fingers' contact
    forces: ``BatchedScene.holds``) says otherwise;
  * ``object_moved``: an object the remaining actions grasp or push lies more than
    ``tolerance.object_m`` (xy) from where the plan assumed it (the belief);
  * ``support_moved``: a block that a remaining ``place`` stacks on (its place region is framed
    by it) stands more than ``SUPPORT_DROP_M`` lower or higher than the plan assumed: knocked
    off the block below it, the plan's tower no longer stands (a re-sequence, not a new pose);
  * ``table_moved``: a table's centre is more than ``tolerance.table_m`` from the belief;
  * ``path_blocked``: a box appeared that the belief geometry does not have, and it lies (any
    part of its footprint) within the belief map's bounds. This is deliberately conservative:
    it does not test whether the box crosses the remaining move_to's route, so every new box
    in the map asks for a replan (A* then plans around it, or finds the old path still free);
  * ``base_off``: at a move_to's end (``Expectation.base_target`` set) the base is more than
    ``tolerance.base_m`` from its target.
The checks read objects and tables by the names the task's plan and the scene use (nothing here
knows a robot or a particular object). ``check`` runs them all.
What it doesn't: read a simulator, decide how to repair (re-parameterize or re-sequence: the
executor), or check the goal.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

from realize.execution.settings import Tolerance

if TYPE_CHECKING:
    from realize.execution.world import Observation
    from realize.tasks.spec import ActionSpec, TaskSpec
    from realize.world.geometry import SceneGeometry

__all__ = ["Deviation", "Expectation", "KINDS", "held_by_plan", "expectation", "check_grasp", "check_objects",
           "check_supports", "check_tables", "check_path", "check_base", "check"]

KINDS = ("grasp_lost", "object_moved", "support_moved", "table_moved", "path_blocked", "base_off")
SUPPORT_DROP_M = 0.02  # m: a block a remaining place stacks on, this much lower or higher, left its support
GRASPS = ("grasp",)  # templates whose object the hand holds after them
RELEASES = ("place",)  # templates that let their object go
ACTS_ON = ("grasp", "push")  # templates that need their object where the plan assumed it


@dataclass(frozen=True)
class Deviation:
    kind: str  # one of KINDS
    detail: str

    def __str__(self) -> str:
        return f"{self.kind}: {self.detail}"


@dataclass(frozen=True)
class Expectation:
    """What the plan assumes at one point: the object in hand (or None), where the objects the
    remaining actions act on lie (xy), where the tables stand (xy), the names of the static
    fixtures the belief has (tables, walls, ramps, container parts), the belief map's bounds,
    and at a move_to's end its base target (xy; None elsewhere)."""

    held: str | None
    objects: dict[str, tuple[float, float]]
    tables: dict[str, tuple[float, float]]
    known_fixtures: frozenset[str]
    bounds_low: tuple[float, float]
    bounds_high: tuple[float, float]
    base_target: tuple[float, float] | None = None
    # the blocks a remaining place stacks on: at the height the plan found them (``support_z``), or, where the
    # plan itself stacked one, on the block it stacked it on (``stacked``); ``halves``: every object's half height
    support_z: dict[str, float] = field(default_factory=dict)
    stacked: dict[str, str] = field(default_factory=dict)
    halves: dict[str, float] = field(default_factory=dict)

    @property
    def supports(self) -> frozenset[str]:
        return frozenset(self.support_z) | frozenset(self.stacked)


def held_by_plan(task: TaskSpec, action: int, done: bool = False, start_held: str | None = None) -> str | None:
    """The object the plan has in hand during action ``action`` (``done``: at its end), starting
    with ``start_held`` in hand. During a grasp nothing is held yet; during a place its object
    is let go of at some point, so none is expected."""
    held = start_held
    last = action + 1 if done else action
    for a in task.plan[:last]:
        if a.template in GRASPS:
            held = a.obj
        elif a.template in RELEASES and a.obj == held:
            held = None
    if not done and action < len(task.plan) and task.plan[action].template in RELEASES:
        return None
    return held


def expectation(task: TaskSpec, belief: SceneGeometry, action: int, *, done: bool = False,
                start_held: str | None = None, objects_at: Mapping[str, tuple[float, float]] | None = None,
                base_target: tuple[float, float] | None = None) -> Expectation:
    """The ``Expectation`` during action ``action`` of ``task``'s plan (``done``: at its end) in
    the belief geometry ``belief``: the objects that actions after it (and it, while running)
    grasp or push, at ``objects_at`` (where the plan last saw them, e.g. a replan's start state)
    or else their belief rest position; ``base_target`` for a move_to's end."""
    held = held_by_plan(task, action, done, start_held)
    first = action + 1 if done else action
    objects: dict[str, tuple[float, float]] = {}
    for a in task.plan[first:]:
        if a.template in ACTS_ON and a.obj is not None and a.obj != held and a.obj not in objects:
            if objects_at is not None and a.obj in objects_at:
                xy = objects_at[a.obj]
            else:
                xy = belief.object(a.obj).position[:2]
            objects[a.obj] = (float(xy[0]), float(xy[1]))
    support_z: dict[str, float] = {}
    stacked: dict[str, str] = {}
    movable, carried = set(belief.object_names), {held}

    def below_of(a: ActionSpec) -> str | None:  # the block a place stacks on: its region's frame
        return next((task.frame_of(p) for p in a.params if task.frame_of(p) in movable), None) \
            if a.template in RELEASES else None

    placed_on = {a.obj: below_of(a) for a in task.plan[:first] if a.template in RELEASES}  # by this plan, so far
    for k, a in enumerate(task.plan[action:], start=action):
        below = below_of(a)
        if below is not None and below not in carried and k >= first:
            if placed_on.get(below) is not None:  # the plan stacked it: it must still stand on that block
                stacked[below] = placed_on[below]  # type: ignore[assignment]
            elif below not in support_z:  # as the plan found it
                at = objects_at.get(below) if objects_at is not None else None
                support_z[below] = float((at if at is not None and len(at) > 2 else belief.object(below).position)[2])
        if a.template in GRASPS + RELEASES:  # the plan moves it itself: where it stands now is no promise
            carried.add(a.obj)
    halves = {o.name: o.half_height for o in belief.objects}
    names = {b.name for b in belief.static_obstacles} | {c.name for c in belief.containers}
    return Expectation(held, objects, {t.name: (t.center[0], t.center[1]) for t in belief.tables},
                       frozenset(names), tuple(belief.bounds_low), tuple(belief.bounds_high), base_target,
                       support_z, stacked, halves)


def check_grasp(obs: Observation, exp: Expectation) -> list[Deviation]:
    if exp.held is not None and obs.state.held != exp.held:
        return [Deviation("grasp_lost", f"the plan holds {exp.held}; the hand holds {obs.state.held or 'nothing'}")]
    return []


def check_objects(obs: Observation, exp: Expectation, tol: Tolerance) -> list[Deviation]:
    out = []
    for name, (x, y) in exp.objects.items():
        pose = obs.state.objects.get(name)
        if pose is None:
            continue
        d = math.hypot(pose.position[0] - x, pose.position[1] - y)
        if d > tol.object_m:
            out.append(Deviation("object_moved", f"{name} is {d:.3f} m from ({x:.3f}, {y:.3f}) (tolerance "
                                                 f"{tol.object_m:g} m)"))
    return out


def check_supports(obs: Observation, exp: Expectation) -> list[Deviation]:
    objects = obs.state.objects
    expected = dict(exp.support_z)  # on the block the plan put it on: its bottom on that block's top
    expected.update({n: objects[b].position[2] + exp.halves[b] + exp.halves[n]
                     for n, b in exp.stacked.items() if b in objects})
    out = []
    for name, z in expected.items():
        dz = objects[name].position[2] - z if name in objects else 0.0
        if abs(dz) > SUPPORT_DROP_M:
            out.append(Deviation("support_moved", f"{name}, which a remaining place stacks on, is {abs(dz):.3f} m "
                                                  f"{'lower' if dz < 0 else 'higher'} than the plan assumed "
                                                  f"(tolerance {SUPPORT_DROP_M:g} m)"))
    return out


def check_tables(obs: Observation, exp: Expectation, tol: Tolerance) -> list[Deviation]:
    out = []
    for name, (x, y) in exp.tables.items():
        t = obs.tables.get(name)
        if t is None:
            continue
        d = math.hypot(t.x - x, t.y - y)
        if d > tol.table_m:
            out.append(Deviation("table_moved", f"{name} stands at ({t.x:.3f}, {t.y:.3f}), {d:.3f} m from the belief "
                                                f"(tolerance {tol.table_m:g} m)"))
    return out


def check_path(obs: Observation, exp: Expectation) -> list[Deviation]:
    out = []
    (lx, ly), (hx, hy) = exp.bounds_low, exp.bounds_high
    for b in obs.boxes:
        if b.name in exp.known_fixtures:
            continue
        (cx, cy), (sx, sy, _) = b.center, b.size
        if cx + sx / 2 >= lx and cx - sx / 2 <= hx and cy + sy / 2 >= ly and cy - sy / 2 <= hy:
            out.append(Deviation("path_blocked", f"new box {b.name} ({sx:g} x {sy:g} m) at ({cx:.3f}, {cy:.3f}) "
                                                 f"inside the map"))
    return out


def check_base(obs: Observation, exp: Expectation, tol: Tolerance) -> list[Deviation]:
    if exp.base_target is None:
        return []
    x, y = obs.state.base[:2]
    tx, ty = exp.base_target
    d = math.hypot(x - tx, y - ty)
    if d > tol.base_m:
        return [Deviation("base_off", f"base at ({x:.3f}, {y:.3f}), {d:.3f} m from its target ({tx:.3f}, {ty:.3f}) "
                                      f"(tolerance {tol.base_m:g} m)")]
    return []


def check(obs: Observation, exp: Expectation, tol: Tolerance) -> list[Deviation]:
    """Every check, in ``KINDS`` order."""
    return (check_grasp(obs, exp) + check_objects(obs, exp, tol) + check_supports(obs, exp) + check_tables(obs, exp, tol)
            + check_path(obs, exp) + check_base(obs, exp, tol))
