"""Task specs: symbolic parameters with regions, the plan (actions bound to parameters by name),
the goal predicate psi_g and the final cost, parsed and checked from a task config.

What it does: turns a mapping such as ``configs/task/pick_place.yaml`` (params, plan, goal,
final cost, planner, and the ``perturbation`` model of ``realize.tasks.perturbation``) into a ``TaskSpec`` and
checks every name against the scene and the action templates, with errors that name the file
and key (``realize.config.ConfigError``). A region may name the object it is written relative to
(``frame: cube``; ``realize.tasks.frames``): the layout holds it placed in the world frame, and
``TaskSpec.frames`` remembers the frame (a warm start carries distributions with it). A plan is written as strings ``"move_to(Table1)"`` or
as ``{move_to: [Table1]}``; an action that handles an object names it first, by its scene name:
``"grasp(cube, Cube_g)"``, ``"place(cube, Cube_p)"``, ``"push(stick, Stick_p)"``. The plan is
checked symbolically before anything runs: the hand holds at most one object (``grasp`` needs an
empty hand, ``place`` the object it names in hand, ``push`` an empty hand).
What it doesn't: simulate (``realize.realization``), or plan symbolically (``realize.tasks.pddl``; the
resulting actions enter here through ``plan_from_actions``).
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from typing import Any, Mapping, Sequence

from realize.config import ConfigError, check_unknown, did_you_mean
from realize.tasks.frames import WORLD, object_frames, place_region
from realize.tasks.hemisphere import Hemisphere
from realize.world.geometry import SceneGeometry
from realize.tasks.goal_spec import GoalSpec, goal_from_dict
from realize.tasks.param_layout import ParamLayout, region_from_dict
from realize.tasks.perturbation import Perturbation
from realize.tasks.regions import Region

__all__ = ["ActionSpec", "GoalSpec", "TaskSpec", "parse_action", "bind_objects", "check_plan", "check_hand",
           "task_from_dict", "plan_from_actions", "task_for_plan"]


@dataclass(frozen=True)
class ActionSpec:
    """One symbolic action: a template bound to symbolic parameters by name, and for templates
    that handle an object (``Template.takes_object``) the scene object it handles."""

    template: str
    params: tuple[str, ...]
    obj: str | None = None

    def __str__(self) -> str:
        args = ((self.obj,) if self.obj is not None else ()) + self.params
        return f"{self.template}({', '.join(args)})"


@dataclass
class TaskSpec:
    name: str
    layout: ParamLayout
    plan: list[ActionSpec]
    goal: GoalSpec
    final_cost: float = 0.0
    source: str = "task"
    planner: dict[str, Any] = field(default_factory=dict)
    # the frame each parameter's region was written in (``realize.tasks.frames``); the layout holds
    # the regions placed in the world frame
    frames: dict[str, str] = field(default_factory=dict)
    # how the world a plan meets may differ (``realize.tasks.perturbation``): validation's replicas
    perturbation: Perturbation = field(default_factory=Perturbation)

    def frame_of(self, param: str) -> str:
        return self.frames.get(param, WORLD)

    @property
    def n_actions(self) -> int:
        return len(self.plan)

    def describe(self) -> str:
        return ", ".join(str(a) for a in self.plan)


_CALL = re.compile(r"^\s*([A-Za-z_][A-Za-z0-9_]*)\s*\(\s*([^()]*)\)\s*$")


def parse_action(item: Any, where: str) -> ActionSpec:
    """``"grasp(Cube_g)"`` or ``{grasp: [Cube_g]}`` -> ActionSpec."""
    if isinstance(item, str):
        m = _CALL.match(item)
        if not m:
            raise ConfigError(f"{where}: cannot parse action {item!r}; write it as name(Param, ...)")
        args = tuple(a.strip() for a in m.group(2).split(",") if a.strip())
        return ActionSpec(m.group(1), args)
    if isinstance(item, Mapping) and len(item) == 1:
        (name, args), = item.items()
        if isinstance(args, str):
            args = [args]
        return ActionSpec(str(name), tuple(str(a) for a in args))
    raise ConfigError(f"{where}: an action is a string 'name(Param)' or a one-key mapping, got {item!r}")


def bind_objects(plan: Sequence[ActionSpec], templates: Mapping[str, Any], objects: Sequence[str],
                 where: str) -> list[ActionSpec]:
    """Split off the object argument (the first) of every action whose template handles an
    object: ``grasp(cube, Cube_g)`` -> ``ActionSpec("grasp", ("Cube_g",), obj="cube")``."""
    out = []
    for i, a in enumerate(plan):
        tpl = templates.get(a.template)
        if tpl is None or not getattr(tpl, "takes_object", False) or a.obj is not None:
            out.append(a)
            continue
        if len(a.params) != tpl.n_params + 1:
            raise ConfigError(f"{where}[{i}]: {a.template} takes an object and {tpl.n_params} parameter(s), got "
                              f"{a}; write {a.template}(<object>, <Param>) with an object of {list(objects)}")
        out.append(ActionSpec(a.template, a.params[1:], a.params[0]))
    return out


def check_hand(plan: Sequence[ActionSpec], where: str, held: str | None = None) -> None:
    """The hand holds at most one object: ``grasp`` needs it empty, ``place`` the object it names
    in hand, ``push`` it empty (``held``: what it holds when the plan starts)."""
    hand = held
    for i, a in enumerate(plan):
        key = f"{where}[{i}]"
        if a.template == "grasp":
            if hand is not None:
                raise ConfigError(f"{key}: {a} needs an empty hand, but {hand} is held there")
            hand = a.obj
        elif a.template == "place":
            if hand != a.obj:
                now = f"{hand} is in hand" if hand is not None else "the hand is empty"
                raise ConfigError(f"{key}: {a} places {a.obj}, but {now} there")
            hand = None
        elif a.template == "push" and hand is not None:
            raise ConfigError(f"{key}: {a} pushes with the closed gripper, but {hand} is held there")


def check_plan(plan: Sequence[ActionSpec], layout: ParamLayout, templates: Mapping[str, Any], where: str,
               objects: Sequence[str] | None = None, held: str | None = None) -> None:
    """Every action names a known template with parameters of the right kind and, where it
    handles one, an object of the scene (``objects``; None: not checked); then the hand's
    contents through the plan (``check_hand``)."""
    if not plan:
        raise ConfigError(f"{where}: the plan is empty")
    for i, a in enumerate(plan):
        key = f"{where}[{i}]"
        if a.template not in templates:
            raise ConfigError(f"{key}: unknown action template {a.template!r} in {a}; known: {sorted(templates)}"
                              f"{did_you_mean(a.template, sorted(templates))}")
        tpl = templates[a.template]
        if len(a.params) != tpl.n_params:
            raise ConfigError(f"{key}: {a.template} takes {tpl.n_params} parameter(s), got {len(a.params)} in {a}")
        if getattr(tpl, "takes_object", False):
            if a.obj is None:
                raise ConfigError(f"{key}: {a} names no object; write {a.template}(<object>, <Param>)")
            if objects is not None and a.obj not in objects:
                raise ConfigError(f"{key}: {a} names unknown object {a.obj!r}; the scene's objects: {list(objects)}"
                                  f"{did_you_mean(a.obj, list(objects))}")
        elif a.obj is not None:
            raise ConfigError(f"{key}: {a.template} handles no object, got {a}")
        for p in a.params:
            if p not in layout.names:
                raise ConfigError(f"{key}: {a} is bound to undefined parameter {p!r}; defined: {layout.names}"
                                  f"{did_you_mean(p, layout.names)}")
            region = layout.regions[p]
            if not tpl.accepts(region):
                raise ConfigError(
                    f"{key}: parameter {p!r} ({type(region).__name__}, dim {region.dim}) does not fit "
                    f"{a.template}: {tpl.param_doc}")
    check_hand(plan, where, held)


def check_fixed_base(plan: Sequence[ActionSpec], templates: Mapping[str, Any], robot_name: str, where: str) -> None:
    """A fixed-base robot's plan drives no base: its first ``move_to`` (any template that
    ``moves_base``) is one ``ConfigError`` naming the action."""
    for i, a in enumerate(plan):
        if getattr(templates.get(a.template), "moves_base", False):
            raise ConfigError(f"{where}[{i}]: {a} drives the base, but robot {robot_name!r} has a fixed base "
                              "(robot.base.joints = []): its plans have no move_to")


# the Hydra defaults list a task of configs/task/ may have (read as a task file it changes
# nothing): the perturbation model's defaults, which the task's perturbation keys change
TASK_DEFAULTS = ({"perturbation": "default"}, "_self_")


def task_from_dict(d: Mapping[str, Any], scene: SceneGeometry, templates: Mapping[str, Any],
                   source: str = "task", held: str | None = None) -> TaskSpec:
    """Build and check a TaskSpec. ``source`` names the file for error messages; ``held``: what
    the hand holds where the plan starts (a replan of a whole new plan from an observed state)."""
    if not isinstance(d, Mapping):
        raise ConfigError(f"{source}: a task config is a mapping, got {type(d).__name__}")
    allowed = {"name", "params", "plan", "goal", "final_cost", "planner", "perturbation", "defaults"}
    check_unknown(d, sorted(allowed), source)
    if "defaults" in d and (not isinstance(d["defaults"], list) or any(e not in TASK_DEFAULTS for e in d["defaults"])):
        raise ConfigError(f"{source}:defaults = {d['defaults']!r} is invalid: a task's defaults list names only "
                          f"{list(TASK_DEFAULTS)}")
    for key in ("params", "goal"):
        if key not in d:
            raise ConfigError(f"{source}: missing key {key!r}")
    params = d["params"]
    if not isinstance(params, Mapping) or not params:
        raise ConfigError(f"{source}:params must be a non-empty mapping of name -> region")
    regions: dict[str, Region] = {}
    frames: dict[str, str] = {}
    known_frames = object_frames(scene)
    for name, rd in params.items():
        where = f"{source}:params.{name}"
        rd = dict(rd) if isinstance(rd, Mapping) else rd
        frame = str(rd.pop("frame", WORLD)) if isinstance(rd, dict) else WORLD
        if frame not in known_frames:
            raise ConfigError(f"{where}.frame = {frame!r} is invalid: this scene's frames are {sorted(known_frames)}")
        try:
            region = region_from_dict(rd, where=where)
        except ConfigError:
            raise
        except (ValueError, TypeError, KeyError) as e:
            raise ConfigError(str(e)) from None
        region = place_region(region, known_frames[frame], where)
        if isinstance(region, Hemisphere) and region.facing == "robot":  # the band toward the robot's start
            region = region.facing_from(*scene.robot_start[:2])
        regions[str(name)] = region
        if frame != WORLD:
            frames[str(name)] = frame
    layout = ParamLayout(regions)
    planner = dict(d.get("planner") or {})
    plan_items = d.get("plan")
    if plan_items is None and not planner.get("enabled", False):
        raise ConfigError(f"{source}: missing key 'plan' (or enable planner: {{enabled: true, ...}})")
    objects = scene.object_names
    plan = [parse_action(it, f"{source}:plan[{i}]") for i, it in enumerate(plan_items or [])]
    plan = bind_objects(plan, templates, objects, f"{source}:plan")
    if plan:
        check_plan(plan, layout, templates, f"{source}:plan", objects, held=held)
    goal = goal_from_dict(d["goal"], scene, regions, source)
    final_cost = float(d.get("final_cost", 0.0))
    perturbation = Perturbation.from_mapping(d.get("perturbation"), f"{source}:perturbation")
    return TaskSpec(str(d.get("name", "task")), layout, plan, goal, final_cost, source, planner, frames, perturbation)


def plan_from_actions(actions: Sequence[Any], layout: ParamLayout, templates: Mapping[str, Any],
                      where: str, objects: Sequence[str] | None = None) -> list[ActionSpec]:
    """Actions with ``.template``, ``.params`` and ``.obj`` (e.g. from PDDL) -> checked ActionSpecs."""
    plan = [ActionSpec(a.template, tuple(a.params), getattr(a, "obj", None)) for a in actions]
    check_plan(plan, layout, templates, where, objects)
    return plan


def task_for_plan(task: TaskSpec, plan: Sequence[ActionSpec]) -> TaskSpec:
    """``task`` restricted to one candidate plan: the same goal and final cost, and a layout of
    only the parameters the plan binds (plus the goal's ``base_in`` and ``at`` regions, which
    the goal check reads), in the task's order. ``plan`` must already be checked (``plan_from_actions``)."""
    used = {p for a in plan for p in a.params} | set(task.goal.params())
    regions = {n: r for n, r in task.layout.regions.items() if n in used}
    return TaskSpec(task.name, ParamLayout(regions), list(plan), task.goal, task.final_cost, task.source,
                    dict(task.planner), {n: f for n, f in task.frames.items() if n in regions}, task.perturbation)
