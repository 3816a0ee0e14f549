"""Symbolic plans from PDDL: parse a domain/problem pair, solve it, map it onto templates.

The paper (Sec. IV) gets its candidate symbolic plan from an off-the-shelf PDDL planner run on
the action templates extended with preconditions and effects. This module is that bridge:

* it parses the pair with unified-planning's ``PDDLReader``;
* it solves it with the real Fast Downward optimal planner (``fast-downward-opt``, from the
  ``up-fast-downward`` package) when one plan is asked for, or with SymK's top-k search
  (``symk``, from ``up-symk``) for the ``top_k`` cheapest plans, which come back cheapest first
  (action costs if the domain declares them, else plan length, as the planner orders them);
  SymK's repeated final report is dropped, and PDDL plans that differ only in bookkeeping
  arguments collapse into one skeleton, so fewer than ``top_k`` plans may come back;
* with unit action costs, plans of equal length are put in a fixed order (then by their text),
  as SymK's own order of ties can vary between calls;
* it maps each plan onto realize's vocabulary as :class:`PlannedAction` values.

Mapping rule
------------
* A PDDL action maps to the action template with the same name, compared case-insensitively
  (PDDL lowercases every name). Every action of the domain must name a template; this is
  checked before solving, so a domain cannot yield a plan that cannot be realized.
* If the domain declares a type named ``region``, an action argument is a template parameter
  exactly when its object is of type ``region`` or one of its subtypes. Of the other arguments,
  the first whose object is named like a movable object of the scene (``scene.objects``,
  compared case-insensitively) is the object the action handles (``grasp(cube, Cube_g)``); the
  rest (where the robot is parked, spots, ...) are symbolic bookkeeping and are dropped.
  Without a ``region`` type every argument that names no scene object is a template parameter.
* Template parameters keep their PDDL order and are mapped back, case-insensitively, to the
  spelling of the task's symbolic parameter names (``cube_g`` -> ``Cube_g``). An argument that
  names no parameter is an error.

Example: ``move_to(table1, loc_start, loc_table1)`` with ``table1`` of type ``base_region``
becomes ``PlannedAction("move_to", ("Table1",))``; ``grasp(cube_g, cube_a, loc_table1)`` in a
scene with an object ``cube_a`` becomes ``PlannedAction("grasp", ("Cube_g",), "cube_a")``.

Not done here: template arities and parameter/region compatibility are checked by the caller
that owns the templates; temporal, numeric and non-deterministic planning are out of scope;
the symbolic plan cost is not returned (the planner orders plans by it).
Every failure raises :class:`PlanningError`, whose message names the file and the item.
"""

from __future__ import annotations

import contextlib
import re
import tempfile
from collections.abc import Collection, Iterable
from dataclasses import dataclass
from pathlib import Path

import unified_planning.shortcuts as ups
from unified_planning.engines import PlanGenerationResultStatus as Status
from unified_planning.io import PDDLReader
from unified_planning.model import Problem
from unified_planning.plans import ActionInstance, SequentialPlan

__all__ = ["PlannedAction", "PlanningError", "plan_from_pddl"]

OPTIMAL_ENGINE = "fast-downward-opt"
TOP_K_ENGINE = "symk"
_ENGINE_PACKAGE = {OPTIMAL_ENGINE: "up-fast-downward", TOP_K_ENGINE: "up-symk"}
REGION_TYPE = "region"

_VERDICT = re.compile(r"unsolvable|without finding|exit code|error\b", re.IGNORECASE)
_SOLVED = (Status.SOLVED_SATISFICING, Status.SOLVED_OPTIMALLY, Status.INTERMEDIATE)


class PlanningError(ValueError):
    """A PDDL domain/problem could not be read, solved, or mapped onto the task."""


@dataclass(frozen=True)
class PlannedAction:
    """One symbolic action: a template name bound to symbolic parameter names, and the scene
    object it handles (None: none named)."""

    template: str
    params: tuple[str, ...]
    obj: str | None = None

    def __str__(self) -> str:
        return f"{self.template}({', '.join(((self.obj,) if self.obj else ()) + self.params)})"


MAX_TIE_PLANS = 64  # at most this many plans are asked for to complete the k-th length class


def plan_from_pddl(
    domain: Path,
    problem: Path,
    templates: Collection[str],
    params: Collection[str],
    *,
    objects: Collection[str] = (),
    top_k: int = 1,
    timeout_s: float = 30,
) -> list[list[PlannedAction]]:
    """Plan with PDDL and return up to ``top_k`` symbolic plans, cheapest first.

    ``templates`` are the action template names the code can execute and ``params`` the task's
    symbolic parameter names, ``objects`` the scene's movable objects; all are matched
    case-insensitively and returned in the task's spelling. With ``top_k == 1`` the single plan is optimal (Fast Downward); with more, SymK's
    top-k search returns the k best distinct plans (fewer if fewer exist).
    """
    domain, problem = Path(domain), Path(problem)
    if top_k < 1:
        raise PlanningError(f"top_k must be >= 1, got {top_k}")
    for kind, path in (("domain", domain), ("problem", problem)):
        if not path.is_file():
            raise PlanningError(f"PDDL {kind} file not found: {path}")
    template_of = _casefold_index(templates, "template")
    param_of = _casefold_index(params, "symbolic parameter")
    object_of = _casefold_index(objects, "scene object")

    task = _parse(domain, problem)
    for action in task.actions:
        if action.name.casefold() not in template_of:
            raise PlanningError(
                f"{domain}: PDDL action {action.name!r} matches no action template; "
                f"known templates: {sorted(templates)}"
            )

    engine = OPTIMAL_ENGINE if top_k == 1 else TOP_K_ENGINE
    if top_k > 1 and _unit_costs(task):
        raw_plans = _solve_ties_complete(task, engine, top_k, timeout_s, domain, problem)
        # SymK reports equally long plans in an order that can vary between calls, and which of
        # them make the k best varies too: with every plan as long as the k-th one at hand,
        # sort (length, then text) so the candidate list, and a top-k run, is reproducible
        raw_plans = sorted(raw_plans, key=lambda p: (len(p.actions), [str(a) for a in p.actions]))
    else:
        raw_plans = _solve(task, engine, top_k, timeout_s, domain, problem)
    region = _region_type(task)
    plans: list[list[PlannedAction]] = []
    for raw in raw_plans:
        plan = [
            _map_action(ai, template_of, param_of, object_of, region, problem) for ai in raw.actions
        ]
        if plan not in plans:  # distinct PDDL plans can share a skeleton
            plans.append(plan)
    return plans[:top_k]


def _casefold_index(names: Iterable[str], what: str) -> dict[str, str]:
    """Map casefolded names to their original spelling, refusing case-only clashes."""
    index: dict[str, str] = {}
    for name in names:
        key = name.casefold()
        if key in index and index[key] != name:
            raise PlanningError(
                f"{what} names {index[key]!r} and {name!r} differ only in case; "
                "PDDL cannot tell them apart"
            )
        index[key] = name
    return index


def _parse(domain: Path, problem: Path) -> Problem:
    """Parse the domain alone first, so that an error names the file it comes from."""
    reader = PDDLReader()
    try:
        reader.parse_problem(str(domain))
    except Exception as err:  # the reader raises parser, UP and plain Python errors alike
        raise PlanningError(f"cannot parse PDDL domain {domain}: {err}") from err
    try:
        return reader.parse_problem(str(domain), str(problem))
    except Exception as err:
        raise PlanningError(
            f"cannot parse PDDL problem {problem} (domain {domain}): {err}"
        ) from err


def _solve(
    task: Problem, engine: str, top_k: int, timeout_s: float, domain: Path, problem: Path
) -> list[SequentialPlan]:
    env = task.environment
    env.credits_stream = None  # unified-planning prints engine credits to stdout otherwise
    if engine not in env.factory.engines:
        raise PlanningError(
            f"PDDL planner engine {engine!r} is not installed: "
            f"pip install {_ENGINE_PACKAGE[engine]}"
        )
    where = f"domain {domain}, problem {problem}"
    with tempfile.TemporaryDirectory(prefix="realize-pddl-") as private, contextlib.chdir(private):
        # Fast Downward's driver writes output.sas into the working directory: planners run at
        # once from one directory (a sweep's jobs, a study beside another) read each other's
        return _solve_here(task, engine, top_k, timeout_s, where)


def _solve_here(task: Problem, engine: str, top_k: int, timeout_s: float, where: str) -> list[SequentialPlan]:
    if top_k == 1:
        with ups.OneshotPlanner(name=engine) as planner:
            result = planner.solve(task, timeout=timeout_s)
        if result.status not in _SOLVED or result.plan is None:
            raise PlanningError(
                f"{engine} found no plan ({where}): status {result.status.name}"
                f"{_timeout_hint(result.status, timeout_s)}{_log_tail(result.log_messages)}"
            )
        return [result.plan]

    plans: list[SequentialPlan] = []
    last = None
    with ups.AnytimePlanner(
        name=engine, params={"number_of_plans": top_k, "loopless": True}
    ) as planner:
        for result in planner.get_solutions(task, timeout=timeout_s):
            last = result
            # the final result repeats the last intermediate plan: keep plans by identity
            if result.plan is not None and result.status in _SOLVED:
                if not any(_same_plan(result.plan, p) for p in plans):
                    plans.append(result.plan)
    if not plans:
        status = last.status.name if last is not None else "no result"
        logs = _log_tail(last.log_messages) if last is not None else ""
        hint = _timeout_hint(last.status, timeout_s) if last is not None else ""
        raise PlanningError(f"{engine} found no plan ({where}): status {status}{hint}{logs}")
    return plans


def _solve_ties_complete(
    task: Problem, engine: str, top_k: int, timeout_s: float, domain: Path, problem: Path
) -> list[SequentialPlan]:
    """The k best plans plus every other plan as long as the k-th (asking for twice as many
    until a longer plan shows up, the planner runs out, or ``MAX_TIE_PLANS`` is reached)."""
    n = top_k
    while True:
        plans = _solve(task, engine, n, timeout_s, domain, problem)
        lengths = sorted(len(p.actions) for p in plans)
        if len(plans) < n or lengths[-1] > lengths[min(top_k, len(lengths)) - 1] or n >= MAX_TIE_PLANS:
            return plans
        n = min(2 * n, MAX_TIE_PLANS)


def _unit_costs(task: Problem) -> bool:
    """Whether a plan's cost is its length (no action costs or other metric declared)."""
    from unified_planning.model.metrics import MinimizeSequentialPlanLength

    return all(isinstance(m, MinimizeSequentialPlanLength) for m in task.quality_metrics)


def _same_plan(a: SequentialPlan, b: SequentialPlan) -> bool:
    return [str(x) for x in a.actions] == [str(x) for x in b.actions]


def _timeout_hint(status: Status, timeout_s: float) -> str:
    if status == Status.TIMEOUT:
        return f" (timed out after timeout_s={timeout_s:g})"
    if status in (Status.UNSOLVABLE_PROVEN, Status.UNSOLVABLE_INCOMPLETELY):
        return " (the problem is unsolvable: no action sequence reaches the goal)"
    return ""


def _log_tail(messages) -> str:
    """The planner's verdict lines (unsolvable, stopped, exit code), not its whole log."""
    lines = [
        line.strip()
        for m in messages or ()
        for line in m.message.splitlines()
        if _VERDICT.search(line) and not line.rstrip().endswith("exit code: 0")
    ]
    return f"; planner says: {' / '.join(lines[-3:])}" if lines else ""


def _region_type(task: Problem):
    for t in task.user_types:
        if t.name.casefold() == REGION_TYPE:
            return t
    return None


def _is_region(obj_type, region) -> bool:
    if region is None:
        return True
    t = obj_type
    while t is not None:
        if t == region:
            return True
        t = t.father
    return False


def _map_action(
    ai: ActionInstance, template_of: dict[str, str], param_of: dict[str, str], object_of: dict[str, str],
    region, problem: Path
) -> PlannedAction:
    name = ai.action.name
    bound: list[str] = []
    handled: str | None = None
    for arg in ai.actual_parameters:
        obj = arg.object()
        scene_object = object_of.get(obj.name.casefold())
        if scene_object is not None and (region is None or not _is_region(obj.type, region)):
            handled = handled or scene_object
            continue
        if not _is_region(obj.type, region):
            continue
        try:
            bound.append(param_of[obj.name.casefold()])
        except KeyError:
            raise PlanningError(
                f"{problem}: argument {obj.name!r} of planned action "
                f"{name}({', '.join(str(a) for a in ai.actual_parameters)}) names no "
                f"symbolic parameter/region; known params: {sorted(param_of.values())}"
            ) from None
    return PlannedAction(template_of[name.casefold()], tuple(bound), handled)
