"""Disturbances of an executed plan, as data: when each fires, what it does, and when it is due.

What it does:
  * ``read_disturbances(entries, geometry, plan_actions)`` reads a list of mappings (an
    ``execute`` preset's ``disturbances``) into ``Disturbance`` values and checks every entry
    before anything is simulated: one ``ConfigError`` line per problem (an unknown effect or key,
    an object or table the scene does not have (the known ones listed), an action index outside
    the plan (its length said), a negative distance or size, an empty range). Entry format::

        - trigger: {action: 2, delay_s: 1.5}          # t s of control time after action K (0-based,
                                                       # of the ORIGINAL plan) begins
          move_table: {table: table2, distance: [0.2, 0.4], direction_deg: [0, 360]}
        - trigger: {when: held, object: cube, delay_s: 0.5}   # t s after the object is first held
          knock_out: {object: cube}

    Effects (one key per entry): ``move_object {object, dx, dy}`` (teleported by dx, dy, same z,
    at rest), ``knock_out {object[, dx, dy]}`` (out of the hand onto the surface below it, a
    table's top or another object's, upright and at rest; with a displacement, moved sideways by
    it first: a block knocked off a tower lands beside it; without one, nothing is drawn for it),
    ``move_table {table, dx, dy}`` (a static table moved, what rests on it with it),
    ``add_box {name, center: [x, y], size: [sx, sy, sz]}`` (a new box obstacle on the floor),
    ``push_base {dx, dy}`` (the robot's base displaced). Any ``dx, dy`` may instead be drawn per
    world: ``distance: [lo, hi]`` (m) and ``direction_deg: [lo, hi]`` (default [0, 360]); a box's
    ``center`` may instead be ``between: [A, B]`` with ``at: [lo, hi]`` (the fraction along the
    segment A -> B, drawn per world), A and B each a table name (its centre), ``base`` (where the
    robot's base stands when the box appears) or an [x, y] point.
  * ``draw(disturbances, rng)`` draws every range once, in list order, from a numpy Generator
    (a fixed entry draws nothing): the concrete ``Scheduled`` list of one world.
  * ``realize.execution.schedule.Schedule`` says which are due at a control step.
What it doesn't: touch a simulator (``realize.execution.world.ExecutionWorld.apply`` carries an
effect out), or decide how to react (``realize.execution.monitor``, the executor).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any, ClassVar, Union

import numpy as np

from realize.config import ConfigError, as_mapping, check_unknown
from realize.world.geometry import SceneGeometry

__all__ = ["Trigger", "Displacement", "BoxCenter", "Disturbance", "MoveObject", "KnockOut", "MoveTable", "AddBox",
           "PushBase", "Effect", "Scheduled", "EFFECTS", "BASE", "read_disturbances", "draw"]

HELD = "held"  # the one condition a trigger may wait for
BASE = "base"  # a ``between`` end point: the robot's base when the box appears

Point = Union[str, tuple[float, float]]  # a table name, BASE, or (x, y)


# ------------------------------------------------------------------------------ data
@dataclass(frozen=True)
class Trigger:
    """When a disturbance fires: ``delay_s`` of control time after action ``action`` of the
    original plan begins, or (``when == "held"``) after ``object`` is first held."""

    delay_s: float = 0.0
    action: int | None = None
    when: str | None = None
    object: str | None = None

    def describe(self) -> str:
        if self.action is not None:
            return f"{self.delay_s:g} s after action {self.action} begins"
        return f"{self.delay_s:g} s after {self.object} is first held"


@dataclass(frozen=True)
class Displacement:
    """A planar move: fixed ``(dx, dy)``, or ``distance`` in [lo, hi] m along a direction in
    ``direction_deg`` [lo, hi] (degrees from +x), drawn per world."""

    dx: float = 0.0
    dy: float = 0.0
    distance: tuple[float, float] | None = None
    direction_deg: tuple[float, float] = (0.0, 360.0)

    def draw(self, rng: np.random.Generator) -> tuple[float, float]:
        if self.distance is None:
            return (self.dx, self.dy)
        r = float(rng.uniform(*self.distance))
        a = math.radians(float(rng.uniform(*self.direction_deg)))
        return (r * math.cos(a), r * math.sin(a))


@dataclass(frozen=True)
class BoxCenter:
    """Where a new box stands: a fixed ``center``, or a fraction in ``at`` along ``between``."""

    center: tuple[float, float] | None = None
    between: tuple[Point, Point] | None = None
    at: tuple[float, float] = (0.5, 0.5)

    def draw(self, rng: np.random.Generator) -> BoxCenter:
        if self.between is None:
            return self
        f = float(rng.uniform(*self.at))
        return BoxCenter(between=self.between, at=(f, f))


# concrete effects: what one world's disturbance does
@dataclass(frozen=True)
class MoveObject:
    kind: ClassVar[str] = "move_object"
    object: str
    dx: float
    dy: float


@dataclass(frozen=True)
class KnockOut:
    """An object knocked onto the surface below it; ``dx, dy`` (m): moved sideways first (0, 0:
    straight down, the effect without a displacement)."""

    kind: ClassVar[str] = "knock_out"
    object: str
    dx: float = 0.0
    dy: float = 0.0


@dataclass(frozen=True)
class MoveTable:
    kind: ClassVar[str] = "move_table"
    table: str
    dx: float
    dy: float


@dataclass(frozen=True)
class AddBox:
    """A box standing on the floor; ``center`` fixed, or ``between`` end points and the drawn
    fraction ``at`` (resolved where the box appears: ``BASE`` is the base's xy then)."""

    kind: ClassVar[str] = "add_box"
    name: str
    size: tuple[float, float, float]
    center: tuple[float, float] | None = None
    between: tuple[Point, Point] | None = None
    at: float = 0.5


@dataclass(frozen=True)
class PushBase:
    kind: ClassVar[str] = "push_base"
    dx: float
    dy: float


Effect = Union[MoveObject, KnockOut, MoveTable, AddBox, PushBase]
EFFECTS = ("move_object", "knock_out", "move_table", "add_box", "push_base")


@dataclass(frozen=True)
class Disturbance:
    """One checked entry, ranges not yet drawn: ``kind`` (one of ``EFFECTS``), ``target`` (the
    object, table or new box's name; None for ``push_base``), ``move`` (move_object,
    move_table, push_base; knock_out where it gives a displacement, else None), ``box`` and
    ``size`` (add_box)."""

    index: int
    trigger: Trigger
    kind: str
    target: str | None = None
    move: Displacement | None = None
    box: BoxCenter | None = None
    size: tuple[float, float, float] | None = None


@dataclass(frozen=True)
class Scheduled:
    """A drawn disturbance of one world: its entry index, trigger and concrete effect."""

    index: int
    trigger: Trigger
    effect: Effect


# ------------------------------------------------------------------------------ reading
_MOVE_KEYS = ("dx", "dy", "distance", "direction_deg")
_KEYS = {
    "move_object": ("object",) + _MOVE_KEYS,
    "knock_out": ("object",) + _MOVE_KEYS,  # the displacement optional
    "move_table": ("table",) + _MOVE_KEYS,
    "add_box": ("name", "center", "between", "at", "size"),
    "push_base": _MOVE_KEYS,
}


def _number(v: Any, where: str, *, ge: float | None = None) -> float:
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(float(v)):
        raise ConfigError(f"{where} = {v!r} is invalid: must be a finite number")
    if ge is not None and float(v) < ge:
        raise ConfigError(f"{where} = {v!r} is invalid: must be >= {ge:g}")
    return float(v)


def _numbers(v: Any, n: int, where: str, *, ge: float | None = None, gt: float | None = None) -> tuple[float, ...]:
    if isinstance(v, (str, bytes)) or not isinstance(v, Sequence) or len(v) != n:
        raise ConfigError(f"{where} = {v!r} is invalid: must be a list of {n} numbers")
    out = tuple(_number(x, f"{where}[{i}]", ge=ge) for i, x in enumerate(v))
    if gt is not None and min(out) <= gt:
        raise ConfigError(f"{where} = {list(v)!r} is invalid: every value must be > {gt:g}")
    return out


def _range(v: Any, where: str, *, ge: float | None = None) -> tuple[float, float]:
    lo, hi = _numbers(v, 2, where, ge=ge)
    if lo > hi:
        raise ConfigError(f"{where} = {list(v)!r} is invalid: an empty range (low > high)")
    return (lo, hi)


def _name(v: Any, known: Sequence[str], what: str, where: str) -> str:
    if not isinstance(v, str) or v not in known:
        raise ConfigError(f"{where} = {v!r} is invalid: the scene has no {what} of that name; {what}s: {list(known)}")
    return v


def _trigger(v: Any, objects: Sequence[str], n_actions: int, plan: str, where: str) -> Trigger:
    d = as_mapping(v, where)
    check_unknown(d, ("action", "when", "object", "delay_s"), where)
    delay = _number(d.get("delay_s", 0.0), f"{where}.delay_s", ge=0.0)
    if ("action" in d) == ("when" in d):
        raise ConfigError(f"{where} = {d!r} is invalid: give either action (an index of the plan) or when: {HELD}")
    if "action" in d:
        k = d["action"]
        if "object" in d:
            raise ConfigError(f"{where}.object = {d['object']!r} is invalid: an action trigger names no object")
        if isinstance(k, bool) or not isinstance(k, int) or not 0 <= k < n_actions:
            raise ConfigError(f"{where}.action = {k!r} is invalid: the plan has {n_actions} actions, numbered "
                              f"from 0 ({plan})")
        return Trigger(delay_s=delay, action=k)
    if d["when"] != HELD:
        raise ConfigError(f"{where}.when = {d['when']!r} is invalid: allowed ['{HELD}']")
    return Trigger(delay_s=delay, when=HELD, object=_name(d.get("object"), objects, "object", f"{where}.object"))


def _displacement(d: Mapping[str, Any], where: str) -> Displacement:
    fixed = [k for k in ("dx", "dy") if k in d]
    if "distance" in d:
        if fixed:
            raise ConfigError(f"{where}.{fixed[0]} = {d[fixed[0]]!r} is invalid: give dx, dy or distance, not both")
        direction = _range(d.get("direction_deg", (0.0, 360.0)), f"{where}.direction_deg")
        return Displacement(distance=_range(d["distance"], f"{where}.distance", ge=0.0), direction_deg=direction)
    if "direction_deg" in d:
        raise ConfigError(f"{where}.direction_deg = {d['direction_deg']!r} is invalid: it goes with distance")
    if not fixed:
        raise ConfigError(f"{where} = {dict(d)!r} is invalid: give dx and dy, or distance: [lo, hi]")
    return Displacement(dx=_number(d.get("dx", 0.0), f"{where}.dx"), dy=_number(d.get("dy", 0.0), f"{where}.dy"))


def _point(v: Any, tables: Sequence[str], where: str) -> Point:
    if isinstance(v, str):
        if v == BASE:
            return BASE
        return _name(v, tables, "table", where)
    return _numbers(v, 2, where)  # type: ignore[return-value]


def _box(d: Mapping[str, Any], geometry: SceneGeometry, where: str) -> tuple[BoxCenter, tuple[float, float, float]]:
    size = _numbers(d.get("size"), 3, f"{where}.size", ge=0.0, gt=0.0)
    tables = [t.name for t in geometry.tables]
    if ("center" in d) == ("between" in d):
        raise ConfigError(f"{where} = {dict(d)!r} is invalid: give center: [x, y] or between: [A, B] (tables, "
                          f"'{BASE}' or [x, y])")
    if "center" in d:
        if "at" in d:
            raise ConfigError(f"{where}.at = {d['at']!r} is invalid: it goes with between")
        return BoxCenter(center=_numbers(d["center"], 2, f"{where}.center")), size  # type: ignore[arg-type]
    b = d["between"]
    if isinstance(b, (str, bytes)) or not isinstance(b, Sequence) or len(b) != 2:
        raise ConfigError(f"{where}.between = {b!r} is invalid: must be a list of two points")
    ends = (_point(b[0], tables, f"{where}.between[0]"), _point(b[1], tables, f"{where}.between[1]"))
    at = _range(d.get("at", (0.5, 0.5)), f"{where}.at", ge=0.0)
    if at[1] > 1.0:
        raise ConfigError(f"{where}.at = {list(d['at'])!r} is invalid: fractions must be in [0, 1]")
    return BoxCenter(between=ends, at=at), size  # type: ignore[return-value]


def read_disturbances(entries: Sequence[Any] | None, geometry: SceneGeometry, plan_actions: Sequence[str],
                      where: str = "disturbances") -> list[Disturbance]:
    """Check and read ``entries`` (module docstring) against the scene's objects and tables and
    the plan's actions (their texts, ``str(ActionSpec)``). Raises a one-line ``ConfigError``."""
    if entries is None:
        return []
    if isinstance(entries, (str, bytes, Mapping)) or not isinstance(entries, Sequence):
        raise ConfigError(f"{where} = {entries!r} is invalid: must be a list of entries")
    objects = list(geometry.object_names)
    tables = [t.name for t in geometry.tables]
    plan = "; ".join(f"{i}: {a}" for i, a in enumerate(plan_actions))
    out: list[Disturbance] = []
    boxes: list[str] = []
    fixtures = set(tables) | {b.name for b in geometry.extras} | {c.name for c in geometry.containers} | set(objects)
    for i, e in enumerate(entries):
        w = f"{where}[{i}]"
        d = as_mapping(e, w)
        kinds = [k for k in d if k != "trigger"]
        unknown = [k for k in kinds if k not in EFFECTS]
        if unknown:
            raise ConfigError(f"{w}: unknown effect {unknown[0]!r}; effects: {list(EFFECTS)}")
        if len(kinds) != 1:
            raise ConfigError(f"{w} = {d!r} is invalid: give a trigger and exactly one effect of {list(EFFECTS)}")
        if "trigger" not in d:
            raise ConfigError(f"{w}: no trigger (trigger: {{action: K, delay_s: t}} or {{when: held, object: NAME, "
                              f"delay_s: t}})")
        trigger = _trigger(d["trigger"], objects, len(plan_actions), plan, f"{w}.trigger")
        kind = kinds[0]
        ew = f"{w}.{kind}"
        p = as_mapping(d[kind] if d[kind] is not None else {}, ew)
        check_unknown(p, _KEYS[kind], ew)
        if kind in ("move_object", "knock_out"):
            sideways = kind == "move_object" or any(k in p for k in _MOVE_KEYS)
            out.append(Disturbance(i, trigger, kind, _name(p.get("object"), objects, "object", f"{ew}.object"),
                                   move=_displacement(p, ew) if sideways else None))
        elif kind == "move_table":
            out.append(Disturbance(i, trigger, kind, _name(p.get("table"), tables, "table", f"{ew}.table"),
                                   move=_displacement(p, ew)))
        elif kind == "push_base":
            out.append(Disturbance(i, trigger, kind, None, move=_displacement(p, ew)))
        else:
            name = p.get("name", f"box{len(boxes)}")
            if not isinstance(name, str) or not name:
                raise ConfigError(f"{ew}.name = {name!r} is invalid: must be a non-empty string")
            if name in fixtures or name in boxes:
                raise ConfigError(f"{ew}.name = {name!r} is invalid: the scene or another box already has that "
                                  f"name")
            boxes.append(name)
            center, size = _box(p, geometry, ew)
            out.append(Disturbance(i, trigger, kind, name, box=center, size=size))
    return out


# ------------------------------------------------------------------------------ drawing
def draw(disturbances: Sequence[Disturbance], rng: np.random.Generator) -> list[Scheduled]:
    """One world's concrete disturbances: every range drawn once, in list order."""
    out: list[Scheduled] = []
    for d in disturbances:
        effect: Effect
        if d.kind == "add_box":
            assert d.box is not None and d.size is not None and d.target is not None
            c = d.box.draw(rng)
            effect = AddBox(d.target, d.size, center=c.center, between=c.between, at=c.at[0])
        elif d.kind == "knock_out":
            assert d.target is not None
            effect = KnockOut(d.target) if d.move is None else KnockOut(d.target, *d.move.draw(rng))
        else:
            assert d.move is not None
            dx, dy = d.move.draw(rng)
            if d.kind == "move_object":
                effect = MoveObject(str(d.target), dx, dy)
            elif d.kind == "move_table":
                effect = MoveTable(str(d.target), dx, dy)
            else:
                effect = PushBase(dx, dy)
        out.append(Scheduled(d.index, d.trigger, effect))
    return out
