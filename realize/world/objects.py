"""Movable objects of a scene, by name: their config entries and the solids they become.

What it does: ``ObjectCfg`` is one entry of the ``scene.objects`` mapping (name -> entry): a
shape (``box`` with edge lengths ``size``, or an upright ``cylinder`` with ``radius`` and
``height``), mass, friction, colour, and where it rests: ``rests_on`` a table of the scene, the
``floor``, or on the top face of another object (the move-and-push cube on its stick), at
``offset`` (x, y) from that support's centre, turned by ``yaw``. ``place_objects`` turns the
entries into ``SceneObject`` values (position of the centre at rest, half extents) in the order
given, refusing (one ``ConfigError`` naming the key) a support that does not exist, an object
whose centre is not above its support's top, two objects that overlap, and cycles of supports.
What it doesn't: build anything in a simulator (``envs/``), or know which object a plan moves
(the task's actions name it, ``realize.tasks.spec``).
Pure data: no torch, no simulator imports.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import ClassVar

from realize.config import ConfigError, Settings, setting

__all__ = ["FLOOR", "SHAPES", "ObjectCfg", "SceneObject", "place_objects"]

FLOOR = "floor"
SHAPES = ("box", "cylinder")
DEFAULT_BOX = (0.045, 0.045, 0.045)  # a box without a size: the seed paper's 4.5 cm cube


def _positive_sides(v: tuple[float, float, float] | None) -> str | None:
    if v is None:
        return None
    return None if min(v) > 0 and max(v) <= 1.5 else "every side must be > 0 and <= 1.5 m"


@dataclass
class ObjectCfg(Settings):
    """One movable object (module docstring). A box has ``size`` (default ``DEFAULT_BOX``); a
    cylinder ``radius`` and ``height`` (its axis is vertical at rest)."""

    config_key: ClassVar[str] = "scene.objects"

    shape: str = setting("box", choices=SHAPES)
    size: tuple[float, float, float] | None = setting(None, check=_positive_sides)  # box; None: DEFAULT_BOX
    radius: float | None = setting(None, gt=0, le=0.5)
    height: float | None = setting(None, gt=0, le=1.5)
    rests_on: str = "table1"  # a table, "floor", or another object (not "on": YAML reads that as true)
    offset: tuple[float, float] = (0.0, 0.0)  # from the support's centre (m)
    yaw: float = setting(0.0, ge=-math.pi, le=math.pi)
    mass: float = setting(0.05, gt=0)  # kg
    friction: float = setting(1.0, ge=0)  # static = dynamic
    color: tuple[float, float, float, float] = (0.85, 0.1, 0.1, 1.0)

    def check(self, where: str) -> None:
        if self.shape == "box":
            if self.size is None:
                self.size = DEFAULT_BOX
            if self.radius is not None or self.height is not None:
                raise ConfigError(f"{where}: a box has a size, not a radius or height (set shape: cylinder)")
        else:
            if self.size is not None:
                raise ConfigError(f"{where}.size = {list(self.size)!r} is invalid: a cylinder has radius and height, "
                                  "not a size")
            if self.radius is None or self.height is None:
                raise ConfigError(f"{where}: a cylinder needs radius and height (m), got radius = {self.radius!r}, "
                                  f"height = {self.height!r}")


@dataclass(frozen=True)
class SceneObject:
    """A movable solid at its rest pose in one copy's local frame: centre ``position``, half
    extents ``half_size`` along its own axes (a cylinder: radius, radius, half height)."""

    name: str
    shape: str
    half_size: tuple[float, float, float]
    position: tuple[float, float, float]
    yaw: float
    mass: float
    friction: float
    color: tuple[float, float, float, float]
    rests_on: str

    @property
    def half_height(self) -> float:
        return self.half_size[2]

    @property
    def top_z(self) -> float:
        return self.position[2] + self.half_size[2]

    @property
    def radius(self) -> float:
        """Horizontal half extent that bounds the object in every direction (m)."""
        hx, hy, _ = self.half_size
        return hx if self.shape == "cylinder" else math.hypot(hx, hy)

    def volume(self) -> float:
        hx, hy, hz = self.half_size
        if self.shape == "cylinder":
            return math.pi * hx * hx * (2 * hz)
        return (2 * hx) * (2 * hy) * (2 * hz)

    def contains_xy(self, x: float, y: float, margin: float = 0.0) -> bool:
        """Whether floor point (x, y) lies inside the padded footprint."""
        dx, dy = x - self.position[0], y - self.position[1]
        if self.shape == "cylinder":
            return math.hypot(dx, dy) <= self.half_size[0] + margin
        c, s = math.cos(self.yaw), math.sin(self.yaw)
        lx, ly = c * dx + s * dy, -s * dx + c * dy
        return abs(lx) <= self.half_size[0] + margin and abs(ly) <= self.half_size[1] + margin


class _Support:
    """What an object can rest on: a centre (x, y), a top height and a footprint test."""

    def __init__(self, name: str, center: tuple[float, float], top: float, contains, whole: bool) -> None:
        self.name, self.center, self.top, self.contains = name, center, top, contains
        self.whole = whole  # a table: the object's whole footprint must lie on it


def place_objects(objects: Mapping[str, ObjectCfg], tables: Mapping[str, object], where: str) -> tuple[SceneObject, ...]:
    """The ``SceneObject`` of every entry, in the order given (``tables``: name -> ``Box`` of the
    scene's tables; ``where``: the config key of the mapping, for errors)."""
    supports: dict[str, _Support] = {FLOOR: _Support(FLOOR, (0.0, 0.0), 0.0, lambda x, y, m: True, False)}
    for name, t in tables.items():
        supports[name] = _Support(name, (t.center[0], t.center[1]), 2 * t.half_size[2], t.contains_xy, True)
    placed: dict[str, SceneObject] = {}
    pending = dict(objects)
    for name in objects:
        if name in supports:
            raise ConfigError(f"{where}.{name}: the name is taken by a table or the floor; name objects apart")
    while pending:
        ready = [n for n, o in pending.items() if o.rests_on in supports]
        if not ready:
            n, o = next(iter(pending.items()))
            if o.rests_on in pending:
                raise ConfigError(f"{where}.{n}.rests_on = {o.rests_on!r} is invalid: the objects {sorted(pending)} rest on each "
                                  "other in a cycle")
            known = sorted(set(supports) | set(objects))
            raise ConfigError(f"{where}.{n}.rests_on = {o.rests_on!r} is invalid: no table or object of that name; known: {known}")
        for n in ready:
            o = pending.pop(n)
            sup = supports[o.rests_on]
            if o.shape == "box":
                half = (o.size[0] / 2, o.size[1] / 2, o.size[2] / 2)
            else:
                half = (o.radius, o.radius, o.height / 2)
            x, y = sup.center[0] + o.offset[0], sup.center[1] + o.offset[1]
            if not sup.contains(x, y, -min(half[0], half[1]) if sup.whole else 0.0):
                what = "the object must rest on" if sup.whole else "the centre must lie above"
                raise ConfigError(f"{where}.{n}.offset = {list(o.offset)!r} is invalid: {what} {o.rests_on}'s top")
            obj = SceneObject(n, o.shape, half, (x, y, sup.top + half[2]), o.yaw, o.mass, o.friction,
                              tuple(o.color), o.rests_on)
            placed[n] = obj
            supports[n] = _Support(n, (x, y), obj.top_z, obj.contains_xy, False)
    out = tuple(placed[n] for n in objects)
    for i, a in enumerate(out):
        for b in out[i + 1:]:
            if b.rests_on == a.name or a.rests_on == b.name:
                continue
            overlap_z = abs(a.position[2] - b.position[2]) < a.half_height + b.half_height
            if overlap_z and math.hypot(a.position[0] - b.position[0], a.position[1] - b.position[1]) < (
                    _inner(a) + _inner(b)):
                raise ConfigError(f"{where}.{b.name}: it overlaps {a.name} (centres "
                                  f"{math.dist(a.position[:2], b.position[:2]):.3f} m apart): put objects apart")
    return out


def _inner(o: SceneObject) -> float:
    """Half the smaller horizontal extent: two objects closer than the sum of these overlap."""
    return min(o.half_size[0], o.half_size[1])
