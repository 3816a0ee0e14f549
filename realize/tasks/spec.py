"""Task specs: symbolic parameters with regions, the plan (actions bound to parameters by name),
the goal predicate psi_g and the final cost, parsed and checked from a task config.

What it does: turns a mapping such as ``configs/task/pick_place.yaml`` into a ``TaskSpec`` and
checks every name against the scene and the action templates, with errors that name the file
and key (``realize.config.ConfigError``). A region may name the object it is written relative to
(``frame: cube``; ``realize.tasks.frames``): the layout holds it placed in the world frame, and
``TaskSpec.frames`` remembers the frame (a warm start carries distributions with it). A plan is written as strings ``"move_to(Table1)"`` or
as ``{move_to: [Table1]}``.
What it doesn't: simulate (``realize.realization``), or plan symbolically (``realize.tasks.pddl``; the
resulting actions enter here through ``plan_from_actions``).
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from typing import Any, Mapping, Sequence

from realize.config import ConfigError
from realize.tasks.frames import WORLD, object_frames, place_region
from realize.world.geometry import SceneGeometry
from realize.tasks.param_layout import ParamLayout, region_from_dict
from realize.tasks.regions import Box, Region


@dataclass(frozen=True)
class ActionSpec:
    """One symbolic action: a template bound to symbolic parameters by name."""

    template: str
    params: tuple[str, ...]

    def __str__(self) -> str:
        return f"{self.template}({', '.join(self.params)})"


@dataclass(frozen=True)
class GoalSpec:
    """psi_g: every given condition must hold at the end of the plan."""

    cube_on: str | None = None  # a table name of the scene
    base_in: str | None = None  # a parameter whose region is a 2-D box
    cube_in_box: str | None = None  # a named container of the scene (move-and-push)


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


def check_plan(plan: Sequence[ActionSpec], layout: ParamLayout, templates: Mapping[str, Any], where: str) -> None:
    """Every action names a known template with parameters of the right kind."""
    if not plan:
        raise ConfigError(f"{where}: the plan is empty")
    for i, a in enumerate(plan):
        key = f"{where}[{i}]"
        if a.template not in templates:
            raise ConfigError(f"{key}: unknown action template {a.template!r} in {a}; known: {sorted(templates)}")
        tpl = templates[a.template]
        if len(a.params) != tpl.n_params:
            raise ConfigError(f"{key}: {a.template} takes {tpl.n_params} parameter(s), got {len(a.params)} in {a}")
        for p in a.params:
            if p not in layout.names:
                raise ConfigError(f"{key}: {a} is bound to undefined parameter {p!r}; defined: {layout.names}")
            region = layout.regions[p]
            if not tpl.accepts(region):
                raise ConfigError(
                    f"{key}: parameter {p!r} ({type(region).__name__}, dim {region.dim}) does not fit "
                    f"{a.template}: {tpl.param_doc}")


def task_from_dict(d: Mapping[str, Any], scene: SceneGeometry, templates: Mapping[str, Any],
                   source: str = "task") -> TaskSpec:
    """Build and check a TaskSpec. ``source`` names the file for error messages."""
    if not isinstance(d, Mapping):
        raise ConfigError(f"{source}: a task config is a mapping, got {type(d).__name__}")
    allowed = {"name", "params", "plan", "goal", "final_cost", "planner"}
    unknown = set(d) - allowed
    if unknown:
        raise ConfigError(f"{source}: unknown keys {sorted(unknown)}; allowed: {sorted(allowed)}")
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
        regions[str(name)] = place_region(region, known_frames[frame], where)
        if frame != WORLD:
            frames[str(name)] = frame
    layout = ParamLayout(regions)
    planner = dict(d.get("planner") or {})
    plan_items = d.get("plan")
    if plan_items is None and not planner.get("enabled", False):
        raise ConfigError(f"{source}: missing key 'plan' (or enable planner: {{enabled: true, ...}})")
    plan = [parse_action(it, f"{source}:plan[{i}]") for i, it in enumerate(plan_items or [])]
    if plan:
        check_plan(plan, layout, templates, f"{source}:plan")
    goal_d = d["goal"]
    if not isinstance(goal_d, Mapping):
        raise ConfigError(f"{source}:goal must be a mapping")
    g_unknown = set(goal_d) - {"cube_on", "base_in", "cube_in_box"}
    if g_unknown:
        raise ConfigError(f"{source}:goal: unknown predicates {sorted(g_unknown)}; allowed: cube_on, base_in, cube_in_box")
    goal = GoalSpec(**{k: (str(v) if v is not None else None) for k, v in goal_d.items()})
    tables = [t.name for t in scene.tables]
    if goal.cube_on is not None and goal.cube_on not in tables:
        raise ConfigError(f"{source}:goal.cube_on names unknown object {goal.cube_on!r}; tables: {tables}")
    if goal.base_in is not None:
        if goal.base_in not in regions:
            raise ConfigError(f"{source}:goal.base_in names unknown parameter {goal.base_in!r}; defined: {list(regions)}")
        r = regions[goal.base_in]
        if not (isinstance(r, Box) and r.dim == 2):
            raise ConfigError(f"{source}:goal.base_in: {goal.base_in!r} must be a 2-D box region")
    if goal.cube_in_box is not None:
        containers = [b.name for b in getattr(scene, "containers", ())]
        if goal.cube_in_box not in containers:
            raise ConfigError(f"{source}:goal.cube_in_box names unknown object {goal.cube_in_box!r}; containers: {containers}")
    final_cost = float(d.get("final_cost", 0.0))
    return TaskSpec(str(d.get("name", "task")), layout, plan, goal, final_cost, source, planner, frames)


def plan_from_actions(actions: Sequence[Any], layout: ParamLayout, templates: Mapping[str, Any],
                      where: str) -> list[ActionSpec]:
    """Actions with ``.template`` and ``.params`` (e.g. from PDDL) -> checked ActionSpecs."""
    plan = [ActionSpec(a.template, tuple(a.params)) for a in actions]
    check_plan(plan, layout, templates, where)
    return plan


def task_for_plan(task: TaskSpec, plan: Sequence[ActionSpec]) -> TaskSpec:
    """``task`` restricted to one candidate plan: the same goal and final cost, and a layout of
    only the parameters the plan binds (plus the goal's ``base_in``, whose region the goal
    check reads), in the task's order. ``plan`` must already be checked (``plan_from_actions``)."""
    used = {p for a in plan for p in a.params}
    if task.goal.base_in is not None:
        used.add(task.goal.base_in)
    regions = {n: r for n, r in task.layout.regions.items() if n in used}
    return TaskSpec(task.name, ParamLayout(regions), list(plan), task.goal, task.final_cost, task.source,
                    dict(task.planner), {n: f for n, f in task.frames.items() if n in regions})
