"""Re-sequencing in the blocks conventions: the symbolic state of stacked blocks read off an
observed scene, and the regions a new plan needs made like the task's own.

A domain of the blocks conventions (``configs/pddl/blocks_domain.pddl``: its ``:predicates``
name ``on``, ``ontable`` and ``clear``, and no ``item-at``) is read instead by
``blocks_facts``, over the problem's objects typed ``block`` (scene objects) and ``table``:
  * ``(on X S)`` for a block X resting on table S or on block S (its centre over S's top
    footprint, its bottom within ``STACK_SLACK_M`` of S's top, S itself not in the hand), with
    ``(ontable X)`` where S is a table;
  * ``(clear S)`` for every block with nothing resting on it (the held one too) and every table
    (the domain's tables are always clear);
  * ``(holding X)`` for the held block, else ``(hand-empty)``;
a block resting on nothing the domain can say (the floor, an object that is no block, tipped
over an edge) gets no ``on`` fact: no plan can grasp it, and the planner's "unsolvable" comes
with a line naming it. Where the planner finds no plan, it is asked again with a grasp region
for every block and a place region for every (block, support) pair the problem lacks
(``regions_resequence.pddl``). Where that one finds a plan, the regions it uses are made like
the task's own (hemispheres, added to the task's params as ``Re_grasp_X`` and ``Re_X_on_S``): a
grasp of X like a grasp region framed by its block, re-framed to X; X on block S like a place
region of the task framed by the block it places on, re-framed to S at the same height above the
two half heights; X on table S the same shape framed by S, centred over a free spot on S near
X (``_free_spot``: of the scene's own rest spots and points 10-18 cm around X, within the reach
of the scene's own spots from the base, the nearest to X with no other object within both radii
and ``SPOT_CLEARANCE_M``), e.g. a block stacked on a knocked-off one is set down beside it.
Where one cannot be made (the task has no region to make it like, every spot is taken), the
refusal names the regions the plan would need (one line).
What it doesn't: read the pick-place conventions or floor sites (``realize.repair.resequence``,
which calls ``resequence_blocks`` for a blocks domain), simulate, or search the plan's parameters.
"""

from __future__ import annotations

import logging
import math
import re
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from realize.repair.pddl_text import section, typed_objects
from realize.config import ConfigError
from realize.world.geometry import SceneGeometry
from realize.world.state import SceneState

__all__ = ["BLOCKS_PREDICATES", "is_blocks_domain", "blocks_facts", "resequence_blocks"]

log = logging.getLogger("realize")

BLOCKS_PREDICATES = ("on", "ontable", "clear", "holding", "hand-empty")  # the blocks domain's dynamic ones
STACK_SLACK_M = 0.015  # blocks: a bottom within this of a support's top rests on it (less than half a block)
SPOT_CLEARANCE_M = 0.04  # blocks: a spot to set a block down keeps this clear of every other object (the fingers)
SPOT_RINGS_M = (0.10, 0.14, 0.18)  # blocks: candidate spots at these distances around the block
SPOT_EDGE_M = 0.05  # blocks: candidate spots this far in from the table top's edges
SPOT_REACH_SLACK_M = 0.1  # blocks: candidate spots this much nearer or farther from the base than the scene's own


def is_blocks_domain(predicates: set[str]) -> bool:
    """Whether a domain with these predicates follows the blocks conventions (module docstring)."""
    return {"on", "ontable", "clear"} <= predicates and "item-at" not in predicates


def _rests_on(geometry: SceneGeometry, name: str, pose: Any, support: Any, support_pose: Any = None) -> bool:
    """Whether object ``name`` at ``pose`` rests on ``support``: a table (``Box``), or an object
    (``SceneObject``) at ``support_pose``: its centre over the support's top footprint, its
    bottom within ``STACK_SLACK_M`` of the support's top."""
    from dataclasses import replace

    from realize.world.objects import SceneObject

    x, y, z = pose.position
    bottom = z - geometry.object(name).half_height
    if isinstance(support, SceneObject):
        w, qx, qy, qz = support_pose.quaternion
        yaw = math.atan2(2 * (w * qz + qx * qy), 1 - 2 * (qy * qy + qz * qz))
        s = replace(support, position=tuple(support_pose.position), yaw=yaw)
        return s.contains_xy(x, y) and abs(bottom - s.top_z) <= STACK_SLACK_M
    return support.contains_xy(x, y) and abs(bottom - support.top_z) <= STACK_SLACK_M


def blocks_facts(state: SceneState, geometry: SceneGeometry, blocks: list[str], tables: list[str]
                 ) -> tuple[list[tuple[str, ...]], list[str]]:
    """The blocks domain's dynamic facts of ``state`` (module docstring) over the problem's
    ``blocks`` (scene objects) and ``tables``, and one note per block that rests on nothing the
    domain can say."""
    facts: list[tuple[str, ...]] = [("holding", state.held) if state.held else ("hand-empty",)]
    covered: set[str] = set()
    notes: list[str] = []
    for x in blocks:
        if x == state.held or x not in state.objects:
            continue
        pose = state.objects[x]
        on = next((s for s in blocks if s not in (x, state.held) and s in state.objects
                   and _rests_on(geometry, x, pose, geometry.object(s), state.objects[s])), None)
        if on is not None:
            facts.append(("on", x, on))
            covered.add(on)
            continue
        table = next((t for t in tables if _rests_on(geometry, x, pose, geometry.table(t))), None)
        if table is not None:
            facts += [("on", x, table), ("ontable", x)]
            continue
        px, py, pz = pose.position
        notes.append(f"{x} at ({px:.3f}, {py:.3f}, {pz:.3f}) rests on no table or block of the problem")
    facts += [("clear", s) for s in blocks if s not in covered] + [("clear", t) for t in tables]
    return facts, notes


@dataclass(frozen=True)
class _Needed:
    """A region the problem lacks: a grasp of ``block`` (``support`` None) or ``block`` placed on
    ``support``."""

    block: str
    support: str | None = None

    @property
    def name(self) -> str:
        return f"Re_grasp_{self.block}" if self.support is None else f"Re_{self.block}_on_{self.support}"

    def __str__(self) -> str:
        return f"a grasp of {self.block}" if self.support is None else f"{self.block} placed on {self.support}"


def _missing_regions(text: str, static: list[tuple[str, ...]], blocks: list[str], tables: list[str],
                     kinds: dict[str, str]) -> tuple[str, dict[str, _Needed]]:
    """``text`` (a blocks problem) with a grasp region per block that has none and a place region
    per (block, support) pair that has none, and those regions by name."""
    grasped = {f[2].casefold() for f in static if f[0].casefold() == "grasps" and len(f) == 3}
    placed = {(f[2].casefold(), f[3].casefold()) for f in static if f[0].casefold() == "place-on" and len(f) == 4}
    grasp_t = next((kinds[f[1].casefold()] for f in static if f[0].casefold() == "grasps"), "grasp_region")
    place_t = next((kinds[f[1].casefold()] for f in static if f[0].casefold() == "place-on"), "place_region")
    new: dict[str, _Needed] = {}
    decl, init = "", ""
    for x in blocks:
        if x.casefold() not in grasped:
            n = _Needed(x)
            new[n.name], decl, init = n, decl + f"\n    {n.name} - {grasp_t}", init + f"\n    (grasps {n.name} {x})"
        for s in blocks + tables:
            if s != x and (x.casefold(), s.casefold()) not in placed:
                n = _Needed(x, s)
                new[n.name], decl = n, decl + f"\n    {n.name} - {place_t}"
                init += f"\n    (place-on {n.name} {x} {s})"
    lo, hi = section(text, ":objects")
    text = text[:hi - 1] + decl + ")" + text[hi:]
    lo, hi = section(text, ":init")
    return text[:hi - 1] + init + ")" + text[hi:], new


def _free_spot(geometry: SceneGeometry, state: SceneState, block: str, table: str) -> tuple[float, float] | None:
    """Where on ``table`` to set ``block`` down: of the scene's own rest spots on it and the
    points ``SPOT_RINGS_M`` around where the block is now (16 directions), those on the top
    ``SPOT_EDGE_M`` in from its edges, as far from the robot's base as the scene's own spots on
    it (``SPOT_REACH_SLACK_M`` of slack either way) and free (no other observed object within
    both radii and ``SPOT_CLEARANCE_M``), the nearest to where the block is (a short carry: the
    monitor expects the block near where the plan began); None where none is free."""
    me, t = geometry.object(block), geometry.table(table)
    own = [o.position[:2] for o in geometry.objects if o.rests_on == table]
    bx, by = state.base[0], state.base[1]
    reach = [math.hypot(x - bx, y - by) for x, y in own]
    if not reach:
        return None
    lo, hi = min(reach) - SPOT_REACH_SLACK_M, max(reach) + SPOT_REACH_SLACK_M
    cx, cy = state.objects[block].position[:2] if block in state.objects else me.position[:2]
    ring = [(cx + r * math.cos(k * math.pi / 8), cy + r * math.sin(k * math.pi / 8)) for r in SPOT_RINGS_M
            for k in range(16)]
    others = [(p.position, geometry.object(o).radius) for o, p in state.objects.items() if o not in (block, state.held)]
    free = [(x, y) for x, y in [*own, *ring]
            if t.contains_xy(x, y, margin=-SPOT_EDGE_M) and lo <= math.hypot(x - bx, y - by) <= hi
            and all(math.hypot(p[0] - x, p[1] - y) >= me.radius + r + SPOT_CLEARANCE_M for p, r in others)]
    return min(free, key=lambda q: math.hypot(q[0] - cx, q[1] - cy)) if free else None


def _make_region(need: _Needed, params: Mapping[str, Any], static: list[tuple[str, ...]], blocks: list[str],
                 geometry: SceneGeometry, state: SceneState) -> dict[str, Any] | None:
    """The region ``need`` stands for, in the task's params format, made like the task's own
    (module docstring); None where the task has no region to make it like, or the table no
    free spot."""
    def framed(name: str, frame: str) -> dict[str, Any] | None:
        r = params.get(name)
        return dict(r) if isinstance(r, Mapping) and r.get("type") == "hemisphere" and \
            str(r.get("frame", "")).casefold() == frame.casefold() else None

    half = {b: geometry.object(b).half_height for b in blocks}
    lower = {b.casefold(): b for b in blocks}
    if need.support is None:
        like = next((framed(f[1], f[2]) for f in static if f[0].casefold() == "grasps" and len(f) == 3
                     and framed(f[1], f[2])), None)
        return None if like is None else dict(like, frame=need.block)
    # a place region of the task onto a block, framed by that block: its height above the two half heights
    like, over = None, 0.0
    for f in static:
        if f[0].casefold() == "place-on" and len(f) == 4 and f[3].casefold() in lower and framed(f[1], f[3]):
            like = framed(f[1], f[3])
            assert like is not None
            over = float(like["center"][2]) - half[lower[f[2].casefold()]] - half[lower[f[3].casefold()]]
            break
    if like is None:
        return None
    x = need.block
    if need.support in blocks:
        return dict(like, frame=need.support, center=[0.0, 0.0, half[x] + half[need.support] + over])
    spot = _free_spot(geometry, state, x, need.support)
    if spot is None:
        return None
    t = geometry.table(need.support)  # a table's frame: the centre of its top face
    return dict(like, frame=need.support, center=[spot[0] - t.center[0], spot[1] - t.center[1], half[x] + over])


def resequence_blocks(text: str, init_facts: list[tuple[str, ...]], domain: Path, problem: Path,
                      task_cfg: Mapping[str, Any], geometry: SceneGeometry, state: SceneState, out: Path,
                      problem_file: str) -> tuple[list[str], dict[str, Any]]:
    """The blocks domain's new plan (action texts) from ``state`` and the task's params with the
    regions it made (module docstring)."""
    from realize.realization.actions import TEMPLATES
    from realize.tasks.pddl import PlanningError, plan_from_pddl

    kinds = typed_objects(text)
    scene = {n.casefold(): n for n in geometry.object_names}
    tables_of = {t.name.casefold(): t.name for t in geometry.tables}
    names = {n.casefold(): n for n in re.findall(r"[^\s()]+", text)}  # the problem's spelling
    blocks = [scene[n] for n, k in kinds.items() if k == "block" and n in scene]
    tables = [tables_of[n] for n, k in kinds.items() if k == "table" and n in tables_of]
    static = [f for f in init_facts if f and f[0].casefold() not in BLOCKS_PREDICATES]
    facts, notes = blocks_facts(state, geometry, blocks, tables)
    planner = task_cfg.get("planner") or {}
    params = dict(task_cfg.get("params") or {})  # the task's symbolic parameters (a run's task may have no plan)
    lo, hi = section(text, ":init")
    init = "(:init\n" + "".join(f"    ({' '.join(f)})\n" for f in static + facts) + "  )"
    path = out / problem_file
    written = text[:lo] + init + text[hi:]
    path.write_text(f"; {problem.name} with the initial state observed at the re-sequence\n" + written)
    timeout = float(planner.get("timeout_s", 30.0))
    said = "; ".join(notes)
    try:
        plans = plan_from_pddl(domain, path, list(TEMPLATES), list(params), objects=geometry.object_names,
                               top_k=1, timeout_s=timeout)
    except PlanningError as e:
        plans, said = [], "; ".join([" ".join(str(e).split())[:300], *notes])
    if plans:
        return [str(a) for a in plans[0]], params
    # no plan: is there one with a region for every grasp and place the problem lacks?
    wider, new = _missing_regions(written, static, blocks, tables, kinds)
    wpath = out / ("regions_" + problem_file)
    wpath.write_text(f"; {path.name} with a grasp and place region for every block and support\n" + wider)
    try:
        wplans = plan_from_pddl(domain, wpath, list(TEMPLATES), [*params, *new],
                                objects=geometry.object_names, top_k=1, timeout_s=timeout)
    except PlanningError as e:  # said too: the wider problem should not fail where the narrower one did not
        wplans, said = [], "; ".join([said or "unsolvable", "with every region: " + " ".join(str(e).split())[:200]])
    needs = list(dict.fromkeys(new[p] for a in (wplans[0] if wplans else []) for p in a.params if p in new))
    if needs:
        made = {n.name: _make_region(n, params, static, blocks, geometry, state) for n in needs}
        lacking = [str(n) for n in needs if made[n.name] is None]
        if not lacking:
            log.info("re-sequence: the plan needs regions the task lacks, made like the task's own: %s",
                     ", ".join(f"{k} ({n})" for k, n in zip(made, needs)))
            return [str(a) for a in wplans[0]], {**params, **made}
        raise ConfigError(f"re-sequence: no plan from the observed state ({path}) with the task's regions; one "
                          f"needs a region the task does not define and none could be made like its own: "
                          f"{', '.join(lacking)}" + (f" ({said})" if notes else ""))
    observed = " ".join(f"({' '.join(names.get(w.casefold(), w) for w in f)})" for f in facts)
    raise ConfigError(f"re-sequence: the PDDL planner found no plan from the observed state ({path}): "
                      f"{said or 'unsolvable'}; observed {observed}")
