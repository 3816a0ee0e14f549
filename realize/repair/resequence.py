"""A new action sequence from where the world stands: the symbolic state read off an observed
scene, and the PDDL planner run from it.

What it does: where the remaining plan can no longer reach the goal (the object fell out of the
hand, so ``place`` has nothing to place), ``resequence_task(task_cfg, geometry, state, out_dir)``
derives the symbolic state of the observed world, writes the task's PDDL problem with that
initial state (``resequence.pddl`` in ``out_dir``), solves it with the task's domain (Fast
Downward, ``realize.tasks.pddl``) and returns the task mapping with the new plan (the same
params, goal and final cost; a blocks plan's params with the regions it needed made, below, and
its ``planner.enabled`` off, so that the run takes that plan rather than plan the task's own
problem again), ready for ``realize.run.planner.Planner.resequence``.

The symbolic state (``symbolic_facts``), by the conventions of ``configs/pddl/`` (its domains
name these predicates; a domain without them cannot be re-planned from a state, which is said
in one line):
  * ``(robot-at S)``: S of a ``(base-near R S)`` fact whose base region R (the task's param)
    contains the base, with ``BASE_SLACK_M`` of slack; else the problem's own start site;
  * ``(holding O)`` for the held object, else ``(hand-empty)``;
  * ``(item-at O loc_T)`` for an object that rests on table T (its centre above T's top
    footprint, within ``REST_SLACK_M`` of the top): the site is ``loc_<table name>``;
  * ``(item-at O loc_lying_O)`` for an object anywhere else (on the floor, tipped against a
    table's edge, on another object): the problem gets that site, where the object lies, a base
    region ``Near_O`` (an annulus framed by O, radii ``pickup``, default ``execute.pickup_m``; the
    task gets it as a parameter) and ``(base-near Near_O loc_lying_O)``, so any domain whose grasp
    takes an item from the site it is at picks it up from there (its grasp region is framed by
    the object already);
every other fact of the problem's ``:init`` (the static ones) is kept as written.

A domain of the blocks conventions (``on``, ``ontable``, ``clear``; no ``item-at``) is read by
``realize.repair.resequence_blocks`` instead.
What it doesn't: simulate, or search the new plan's parameters (the planner does).
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

import torch

from realize.repair.pddl_text import domain_predicates, section, strip_comments
from realize.repair.pddl_text import facts as pddl_facts
from realize.repair.resequence_blocks import is_blocks_domain, resequence_blocks
from realize.config import ConfigError
from realize.world.geometry import SceneGeometry
from realize.world.state import SceneState

__all__ = ["symbolic_facts", "resequence_task", "lying_site", "pickup_region", "on_floor", "DYNAMIC_PREDICATES", "RESEQUENCE_PROBLEM"]

DYNAMIC_PREDICATES = ("robot-at", "hand-empty", "holding", "item-at")
RESEQUENCE_PROBLEM = "resequence.pddl"
BASE_SLACK_M = 0.25  # a base this far outside a base region still counts as parked there
REST_SLACK_M = 0.05  # an object's bottom within this of a table's top rests on it


def symbolic_facts(state: SceneState, geometry: SceneGeometry, task: Any, static: list[tuple[str, ...]],
                   start_site: str) -> list[tuple[str, ...]]:
    """The dynamic facts of ``state`` (module docstring) given the problem's ``static`` facts."""
    facts: list[tuple[str, ...]] = []
    base = torch.tensor([state.base[0], state.base[1]], dtype=torch.float64)
    at = None
    names = {n.casefold(): n for n in task.layout.names}
    for f in static:
        if f[0].casefold() != "base-near" or len(f) != 3 or f[1].casefold() not in names:
            continue
        region = task.layout.regions[names[f[1].casefold()]]
        z = torch.zeros(1, region.dim, dtype=torch.float64)
        z[0, :2] = base  # a task's regions are in the world frame (their frames resolved when it was built)
        if bool(region.contains(z, tol=BASE_SLACK_M)[0]):
            at = f[2]
            break
    facts.append(("robot-at", at or start_site))
    facts.append(("holding", state.held) if state.held else ("hand-empty",))
    for name, pose in state.objects.items():
        if name == state.held:
            continue
        o = geometry.object(name)
        x, y, z = pose.position
        for t in geometry.tables:
            if t.contains_xy(x, y) and abs((z - o.half_height) - t.top_z) <= REST_SLACK_M:
                facts.append(("item-at", name, f"loc_{t.name}"))
                break
        else:  # not on a table's top: a site of its own, where it lies
            facts.append(("item-at", name, lying_site(name)))
    return facts


def on_floor(state: SceneState, geometry: SceneGeometry, obj: str) -> bool:
    """Object ``obj`` of ``state`` lies on the floor (its bottom within ``REST_SLACK_M`` of it)."""
    return abs(state.objects[obj].position[2] - geometry.object(obj).half_height) <= REST_SLACK_M


def lying_site(obj: str) -> str:
    """The PDDL site of object ``obj`` lying off every table's top (the floor, a table's edge)."""
    return f"loc_lying_{obj}"


def pickup_region(obj: str) -> str:
    """The base region (a task parameter) from which the robot picks ``obj`` up where it lies."""
    return f"Near_{obj}"


def _add_lying_sites(text: str, task_cfg: dict[str, Any], objects: list[str], pickup: Mapping[str, float]) -> str:
    """``text`` (the problem) with a site and a base region per object off the tables, and their
    ``base-near`` facts; ``task_cfg['params']`` with each region: an annulus framed by the object
    (so it follows where the object lies, ``controller.track_objects``) of radii ``pickup``."""
    if not objects:
        return text
    lo, hi = section(text, ":objects")
    decl = "".join(f"\n    {pickup_region(o)} - base_region\n    {lying_site(o)} - site" for o in objects)
    text = text[:hi - 1] + decl + ")" + text[hi:]
    params = dict(task_cfg.get("params") or {})
    for o in objects:
        params[pickup_region(o)] = {"type": "annulus", "frame": o, "center": [0.0, 0.0],
                                   "r_min": float(pickup["r_min"]), "r_max": float(pickup["r_max"])}
    task_cfg["params"] = params
    return text


def resequence_task(task_cfg: Mapping[str, Any], geometry: SceneGeometry, state: SceneState,
                    out_dir: str | Path, pickup: Mapping[str, float] | None = None) -> dict[str, Any]:
    """The task mapping ``task_cfg`` with the plan the PDDL planner finds from ``state``
    (module docstring). ``ConfigError`` (one line) where the task has no PDDL files, the domain
    lacks the predicates, or no plan reaches the goal from there."""
    from realize.spec.task_plans import _resolve_path, build_task
    from realize.realization.actions import TEMPLATES
    from realize.tasks.pddl import PlanningError, plan_from_pddl

    planner = task_cfg.get("planner") or {}
    if not planner.get("domain") or not planner.get("problem"):
        raise ConfigError("re-sequence: the task names no PDDL domain and problem (task.planner.domain/problem), "
                          "so no new action sequence can be planned")
    domain = _resolve_path(planner["domain"], "task.planner.domain")
    problem = _resolve_path(planner["problem"], "task.planner.problem")
    text = strip_comments(problem.read_text())
    lo, hi = section(text, ":init")
    if is_blocks_domain(domain_predicates(domain)):
        out = Path(out_dir)
        out.mkdir(parents=True, exist_ok=True)
        new = dict(task_cfg)
        new["plan"], new["params"] = resequence_blocks(text, pddl_facts(text[lo:hi]), domain, problem, task_cfg,
                                                       geometry, state, out, RESEQUENCE_PROBLEM)
        new["planner"] = dict(planner, enabled=False)  # the plan is the one above: not the problem's again
        return new
    static = [f for f in pddl_facts(text[lo:hi]) if f and f[0].casefold() not in DYNAMIC_PREDICATES]
    start = next((f[1] for f in pddl_facts(text[lo:hi]) if f and f[0].casefold() == "robot-at" and len(f) == 2), None)
    if start is None:
        raise ConfigError(f"re-sequence: {problem} has no (robot-at SITE) fact; its domain does not follow the "
                          f"conventions {DYNAMIC_PREDICATES} of realize/repair/resequence.py")
    plain = dict(task_cfg)
    plain["planner"] = dict(planner, enabled=False, top_k=1)
    task = build_task(plain, geometry, "re-sequence")
    facts = symbolic_facts(state, geometry, task, static, start)
    lying = [f[1] for f in facts if f[0] == "item-at" and f[2] == lying_site(f[1])]
    if lying:
        plain = dict(plain)
        if pickup is None:  # execute.pickup_m's default
            from realize.execution.settings import ExecuteSettings

            pickup = dict(zip(("r_min", "r_max"), ExecuteSettings().pickup_m))
        text = _add_lying_sites(text, plain, lying, pickup)
        lo, hi = section(text, ":init")
        static += [("base-near", pickup_region(o), lying_site(o)) for o in lying]
        task = build_task(plain, geometry, "re-sequence")
        facts = symbolic_facts(state, geometry, task, static, start)
    init = "(:init\n" + "".join(f"    ({' '.join(f)})\n" for f in static + facts) + "  )"
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    path = out / RESEQUENCE_PROBLEM
    path.write_text(f"; {problem.name} with the initial state observed at the re-sequence\n"
                    + text[:lo] + init + text[hi:])
    try:
        plans = plan_from_pddl(domain, path, list(TEMPLATES), task.layout.names, objects=geometry.object_names,
                               top_k=1, timeout_s=float(planner.get("timeout_s", 30.0)))
    except PlanningError as e:
        raise ConfigError(f"re-sequence: {' '.join(str(e).split())[:400]}") from None
    if not plans:
        raise ConfigError(f"re-sequence: the PDDL planner found no plan from the observed state ({path})")
    new = dict(task_cfg)
    new["params"] = plain.get("params", task_cfg.get("params"))
    new["plan"] = [str(a) for a in plans[0]]
    new["planner"] = dict(planner, enabled=False)  # the plan is the one above: not the problem's again
    return new
