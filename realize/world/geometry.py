"""World geometry of the realize scenes: the config (``GeometryCfg``) and the boxes it makes.

What it does: describes the world (tables, walls, ramps and open boxes by name, the world bounds,
the movable objects by name (``objects``, ``realize.world.objects``) and the robot's start pose) in one copy's local frame, checks it (``GeometryCfg`` is a
``realize.config.Settings``: bad values raise ``ConfigError`` naming the key), and offers the
obstacle boxes that the controllers (A* occupancy grid, fabric collision terms), the figures and
the ManiSkill tasks need (``build_geometry`` -> ``SceneGeometry``). The ``push`` variant
(move-and-push) has an open box (a static container: floor and four low walls) on the floor;
its scene config stands an object (the stick) on the floor with the cube on its top; tables are
optional there and serve as plain obstacles.
What it doesn't: build anything in a simulator (the tasks in ``envs/`` do), nor hold the
symbolic parameter regions of a plan (those live in the task config, see ``realize/tasks/regions.py``).
Pure data: no torch, no simulator imports.

Frames: z up, floor at z = 0, metres, yaw in radians about +z. Boxes are given by their centre
and half extents; a box may be tilted about its local y axis (`pitch`) to make a ramp.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, ClassVar

from realize.config import ConfigError, Settings, setting
from realize.world.objects import FLOOR, ObjectCfg, SceneObject, place_objects

__all__ = ["VARIANTS", "Box", "SceneGeometry", "TableCfg", "WallCfg", "RampCfg", "ContainerCfg", "GeometryCfg",
           "build_geometry", "check_robot_start", "with_fixed_base_start"]

VARIANTS = ("plain", "wall", "ramp", "push")


@dataclass(frozen=True)
class Box:
    """A static box obstacle: centre (x, y, z), half sizes (hx, hy, hz), yaw and pitch (rad)."""

    name: str
    center: tuple[float, float, float]
    half_size: tuple[float, float, float]
    yaw: float = 0.0
    pitch: float = 0.0
    color: tuple[float, float, float, float] = (0.45, 0.32, 0.22, 1.0)
    friction: float | None = None  # surface friction (static = dynamic); None: the simulator default

    @property
    def top_z(self) -> float:
        """Height of the highest point of the box (exact for un-pitched boxes)."""
        hx, _, hz = self.half_size
        return self.center[2] + abs(math.sin(self.pitch)) * hx + math.cos(self.pitch) * hz

    def footprint_half_size(self) -> tuple[float, float]:
        """Half extents of the box projected on the floor (in its own yawed frame)."""
        hx, hy, hz = self.half_size
        return (abs(math.cos(self.pitch)) * hx + abs(math.sin(self.pitch)) * hz, hy)

    def contains_xy(self, x: float, y: float, margin: float = 0.0) -> bool:
        """Whether floor point (x, y) lies inside the padded footprint."""
        dx, dy = x - self.center[0], y - self.center[1]
        c, s = math.cos(self.yaw), math.sin(self.yaw)
        lx, ly = c * dx + s * dy, -s * dx + c * dy
        fx, fy = self.footprint_half_size()
        return abs(lx) <= fx + margin and abs(ly) <= fy + margin


@dataclass(frozen=True)
class SceneGeometry:
    """The whole world of one copy (local frame): static boxes and the movable objects at rest."""

    variant: str
    tables: tuple[Box, ...]
    extras: tuple[Box, ...]  # the containers' floors and walls, then walls, then ramps
    objects: tuple[SceneObject, ...]  # movable, by name, in config order
    robot_start: tuple[float, float, float]  # x, y, yaw
    bounds_low: tuple[float, float]
    bounds_high: tuple[float, float]
    containers: tuple[Box, ...] = ()  # open boxes, outer bounds (their floor and walls are in extras)
    container_walls: tuple[float, ...] = ()  # wall thickness of each container (m)

    @property
    def object_names(self) -> tuple[str, ...]:
        return tuple(o.name for o in self.objects)

    def object(self, name: str) -> SceneObject:
        return _named(self.objects, name, "object")

    def object_index(self, name: str) -> int:
        """Position of object ``name`` in ``objects`` (the m axis of the scene's (N, m, ...) reads)."""
        names = self.object_names
        if name not in names:
            raise KeyError(f"scene has no object named {name!r}; objects: {list(names)}")
        return names.index(name)

    @property
    def floor_objects(self) -> tuple[Box, ...]:
        """Footprint boxes of the objects standing on the floor at rest (a stick): obstacles for
        the base planner, but not for the fabric (they are pushed)."""
        return tuple(Box(o.name, o.position, o.half_size, yaw=o.yaw, color=o.color)
                     for o in self.objects if o.rests_on == FLOOR)

    @property
    def static_obstacles(self) -> tuple[Box, ...]:
        """Every static box (the fabric's collision boxes; the stick is not one: it is pushed)."""
        return self.tables + self.extras

    @property
    def obstacles(self) -> tuple[Box, ...]:
        """Every box the robot base must avoid (A* occupancy): the static boxes and the footprints
        of the objects standing on the floor (``floor_objects``) at rest."""
        return self.static_obstacles + self.floor_objects

    def container_wall(self, name: str) -> float:
        """Wall thickness (m) of container ``name``."""
        return self.container_walls[self.containers.index(self.container(name))]

    def container(self, name: str) -> Box:
        return _named(self.containers, name, "container")

    def table(self, name: str) -> Box:
        return _named(self.tables, name, "table")

    @property
    def extent(self) -> tuple[float, float]:
        """Size (x, y) of the world rectangle; used to tile copies without overlap."""
        return (self.bounds_high[0] - self.bounds_low[0], self.bounds_high[1] - self.bounds_low[1])


def _named(items: tuple[Any, ...], name: str, what: str) -> Any:
    """The item of ``items`` called ``name`` (``KeyError`` naming the ones there are)."""
    for it in items:
        if it.name == name:
            return it
    raise KeyError(f"scene has no {what} named {name!r}; {what}s: {[it.name for it in items]}")


def _in(lo: float, hi: float, why: str = "") -> Callable[[float], str | None]:
    return lambda v: None if lo <= v <= hi else f"must be in [{lo}, {hi}] m{why}"


def _all_positive(v: tuple[float, ...]) -> str | None:
    return None if min(v) > 0 else "all sides must be > 0"


@dataclass
class TableCfg(Settings):
    """One table: centre (x, y), top size (x, y) and height (m)."""

    config_key: ClassVar[str] = "scene.tables"

    name: str = setting("table1")
    center: tuple[float, float] = setting((0.0, 1.2))
    size: tuple[float, float] = setting((0.6, 0.6), check=lambda v: None if min(v) > 0 else "both sides must be > 0")
    height: float = setting(0.72, check=_in(0.3, 1.1, " for Fetch to work at it"))


@dataclass
class WallCfg(Settings):
    """A thin static wall standing on the floor: centre (x, y) and size (x, y, height)."""

    config_key: ClassVar[str] = "scene.walls"

    name: str = "wall"
    center: tuple[float, float] = (0.0, 0.0)
    size: tuple[float, float, float] = setting((1.6, 0.1, 1.0), check=_all_positive)


@dataclass
class RampCfg(Settings):
    """A static plank tilted from ``high_table``'s side down onto ``low_table``'s near edge (along
    y, between the two tables): its low end 1 cm over the low table's top, ``drop`` m lower than
    its high end. Slippery by default: a cube released above it slides onto the low table
    (30 deg; PhysX averages the two frictions: (cube 1.0 + ramp 0.0) / 2 = 0.5 < tan 30 deg)."""

    config_key: ClassVar[str] = "scene.ramps"

    name: str = "ramp"
    center: tuple[float, float] = (0.0, -0.63)  # the default tables: low end 3 cm over table 2's near edge
    length: float = setting(0.7, gt=0)
    width: float = setting(0.4, gt=0)
    drop: float = setting(0.35, gt=0)  # and < length (check)
    friction: float = setting(0.0, ge=0)
    high_table: str = "table1"
    low_table: str = "table2"

    def check(self, where: str) -> None:
        if not self.drop < self.length:
            raise ConfigError(f"{where}.drop = {self.drop!r} is invalid: must be > 0 and < length ({self.length})")


@dataclass
class ContainerCfg(Settings):
    """An open box on the floor (floor plate and four walls, open top): centre (x, y), inner
    footprint (x, y), wall height and thickness (m)."""

    config_key: ClassVar[str] = "scene.containers"

    name: str = "box"
    center: tuple[float, float] = (0.8, 0.0)
    inner: tuple[float, float] = (0.4, 0.4)  # and larger than the objects (check)
    wall_height: float = setting(0.12, gt=0, le=0.5)
    wall_thickness: float = setting(0.02, gt=0, le=0.1)


@dataclass
class GeometryCfg(Settings):
    """Config of the world (the Hydra ``scene`` group maps onto this one to one).

    Named entries: ``tables``, movable ``objects`` (``realize.world.objects``), and the static
    fixtures ``walls``, ``ramps`` and ``containers`` (open boxes). ``variant`` names the
    ManiSkill task that builds the world (``push``: ``RealizeMoveAndPush-v1``; the others
    ``RealizePickPlace-v1``) and labels results; every fixture listed is built whatever it says.
    Single-value bounds are field metadata; how the parts fit together (objects on their
    supports, nothing under the robot's start, bounds non-empty, unique names) is
    ``check``, which builds the boxes once to see. Where the robot must end (the exit) is not
    the world's: it is the task's goal region (``goal.base_in``, e.g. ``task.params.Exit``)."""

    config_key: ClassVar[str] = "scene"

    variant: str = setting("plain", choices=VARIANTS)
    tables: list[TableCfg] = setting(
        default_factory=lambda: [
            TableCfg("table1", (0.0, 1.2), (0.6, 0.6), 0.72),
            TableCfg("table2", (0.0, -1.2), (0.6, 0.6), 0.72),
        ]
    )
    # movable objects by name (realize.world.objects): where each rests, its shape, mass, friction
    objects: dict[str, ObjectCfg] = setting(default_factory=lambda: {"cube": ObjectCfg()})
    walls: list[WallCfg] = setting(default_factory=list)
    ramps: list[RampCfg] = setting(default_factory=list)
    containers: list[ContainerCfg] = setting(default_factory=list)
    robot_start: tuple[float, float, float] = setting((-2.0, 0.0, 0.0))
    # where a fixed-base robot (robot.base.joints = []) is bolted (x, y, yaw) in a scene whose
    # robot_start parks a mobile robot out of an arm's reach; null: robot_start for every robot
    # (``with_fixed_base_start``)
    fixed_base_start: tuple[float, float, float] | None = setting(None)
    bounds_low: tuple[float, float] = setting((-3.0, -2.5))
    bounds_high: tuple[float, float] = setting((3.0, 2.5))

    def check(self, where: str) -> None:
        _assemble(self, where)


def _err(where: str, key: str, value: Any, allowed: str) -> ConfigError:
    return ConfigError(f"{where}.{key} = {value!r} is invalid: {allowed}")


def check_robot_start(g: SceneGeometry, footprint_radius: float, where: str = "scene",
                      key: str = "robot_start") -> None:
    """The robot's start keeps its footprint (the robot spec's ``base.footprint_radius``) off
    every obstacle the base avoids and inside the world's bounds (``ConfigError`` naming
    ``scene.<key>``: the key the start came from). The world alone cannot say: the footprint is
    the robot's."""
    sx, sy, _ = g.robot_start
    r = float(footprint_radius)
    for b in g.obstacles:
        if b.contains_xy(sx, sy, margin=r):
            raise _err(where, key, g.robot_start,
                       f"the robot's footprint (robot.base.footprint_radius = {r}) overlaps {b.name}")
    (x0, y0), (x1, y1) = g.bounds_low, g.bounds_high
    if not (x0 + r <= sx <= x1 - r and y0 + r <= sy <= y1 - r):
        raise _err(where, key, g.robot_start, f"must keep the robot's footprint (robot.base.footprint_radius "
                   f"= {r}) inside the bounds {g.bounds_low}..{g.bounds_high}")


def with_fixed_base_start(scene: dict[str, Any], fixed_base: bool) -> tuple[dict[str, Any], str]:
    """The scene config (plain data) a robot meets, and the key its start came from: for a
    fixed-base robot, ``robot_start`` replaced by the scene's ``fixed_base_start`` where it has
    one (the arm's stand at the table edge, where a mobile robot would park farther back);
    otherwise unchanged. Idempotent, so a saved run's config (already replaced) reads the same
    again."""
    mount = scene.get("fixed_base_start")
    if not fixed_base or mount is None:
        return scene, "robot_start"
    return {**scene, "robot_start": list(mount)}, "fixed_base_start"


def build_geometry(cfg: GeometryCfg) -> SceneGeometry:
    """The boxes of a (checked) ``GeometryCfg``: the world of one copy in its local frame."""
    return _assemble(cfg, cfg.config_key)


def _assemble(cfg: GeometryCfg, where: str) -> SceneGeometry:
    """Turn ``cfg`` into boxes and placed objects; raises ``ConfigError`` naming ``<where>.<key>``
    where the parts do not fit together (single values are already checked by the fields)."""
    push = cfg.variant == "push"
    names = [t.name for t in cfg.tables]
    if not cfg.tables and not push:
        raise _err(where, "tables", names, "need at least one table (objects rest on tables)")
    if len(set(names)) != len(names):
        raise _err(where, "tables", names, "table names must be unique")
    if push and not cfg.containers:
        raise _err(where, "containers", [], "the push variant needs an open box (its goal: an object in it)")
    fixtures = names + [f.name for f in (*cfg.walls, *cfg.ramps, *cfg.containers)] + list(cfg.objects)
    for name in fixtures:
        if fixtures.count(name) > 1:
            raise _err(where, "tables", name, "every table, wall, ramp, container and object needs its own name")
    tables = [Box(t.name, (t.center[0], t.center[1], t.height / 2), (t.size[0] / 2, t.size[1] / 2, t.height / 2))
              for t in cfg.tables]
    objects = place_objects(cfg.objects, {t.name: t for t in tables}, f"{where}.objects")
    extras: list[Box] = []
    containers: list[Box] = []
    for i, c in enumerate(cfg.containers):
        box_parts, container = _container_parts(c, objects, f"{where}.containers[{i}]")
        extras.extend(box_parts)
        containers.append(container)
    for o in objects:
        if o.rests_on != FLOOR:
            continue
        for b in tables:
            if b.contains_xy(*o.position[:2], margin=o.half_size[0] + o.half_size[1]):
                raise _err(where, f"objects.{o.name}.offset", list(cfg.objects[o.name].offset),
                           f"{o.name} stands on the floor inside {b.name}'s footprint")

    for w in cfg.walls:
        wx, wy, wz = w.size
        extras.append(Box(w.name, (w.center[0], w.center[1], wz / 2), (wx / 2, wy / 2, wz / 2),
                          color=(0.6, 0.6, 0.65, 1.0)))
    by_name = {t.name: t for t in tables}
    for i, r in enumerate(cfg.ramps):
        for key in ("high_table", "low_table"):
            if getattr(r, key) not in by_name:
                raise _err(where, f"ramps[{i}].{key}", getattr(r, key), f"no table of that name; tables: {names}")
        # the ramp runs along y from the high table's side to the low table's side
        t_high, t_low = by_name[r.high_table], by_name[r.low_table]
        low_z = 2 * t_low.half_size[2] + 0.01
        high_z = low_z + r.drop
        pitch = math.asin(min(1.0, r.drop / r.length))
        thick = 0.02
        # yaw = -pi/2 makes the box's local +x point towards -y (from the high table to the low one)
        extras.append(
            Box(r.name, (r.center[0], r.center[1], (low_z + high_z) / 2), (r.length / 2, r.width / 2, thick / 2),
                yaw=-math.pi / 2 * (1 if t_high.center[1] > t_low.center[1] else -1), pitch=pitch,
                color=(0.55, 0.55, 0.6, 1.0), friction=r.friction)
        )
    bl, bh = cfg.bounds_low, cfg.bounds_high
    if not (bl[0] < bh[0] and bl[1] < bh[1]):
        raise _err(where, "bounds_low", (bl, bh), "bounds_low must be < bounds_high in x and y")
    for key in ("robot_start", "fixed_base_start"):
        start = getattr(cfg, key)
        if start is None:
            continue
        for b in tables + extras:
            if b.contains_xy(start[0], start[1]):
                raise _err(where, key, start, f"the robot's base stands inside {b.name}")
        if not (bl[0] <= start[0] <= bh[0] and bl[1] <= start[1] <= bh[1]):
            raise _err(where, key, start, f"must lie inside the bounds {bl}..{bh}")
    sx, sy, syaw = cfg.robot_start
    return SceneGeometry(
        variant=cfg.variant,
        tables=tuple(tables),
        extras=tuple(extras),
        objects=objects,
        robot_start=(sx, sy, syaw),
        bounds_low=tuple(bl),
        bounds_high=tuple(bh),
        containers=tuple(containers),
        container_walls=tuple(c.wall_thickness for c in cfg.containers),
    )


def _container_parts(c: ContainerCfg, objects: tuple[SceneObject, ...], where: str) -> tuple[list[Box], Box]:
    """An open box: its five static boxes (``<name>_floor``, ``<name>_wall_xn`` ...) and its
    outer bounds (named as the container, for the goal predicate and its frame)."""
    ix, iy = c.inner
    h, w = c.wall_height, c.wall_thickness
    smallest = min((2 * min(o.half_size[0], o.half_size[1]) for o in objects if o.rests_on != FLOOR), default=0.0)
    if min(ix, iy) <= smallest:
        raise _err(where, "inner", c.inner, f"both sides must be larger than the objects ({smallest} m)")
    bx, by = c.center
    ox, oy = ix / 2 + w, iy / 2 + w  # outer half sizes
    colour = (0.3, 0.45, 0.7, 1.0)
    floor = w / 2
    parts = [
        Box(f"{c.name}_floor", (bx, by, floor / 2), (ox, oy, floor / 2), color=colour),
        Box(f"{c.name}_wall_xn", (bx - ix / 2 - w / 2, by, h / 2), (w / 2, oy, h / 2), color=colour),
        Box(f"{c.name}_wall_xp", (bx + ix / 2 + w / 2, by, h / 2), (w / 2, oy, h / 2), color=colour),
        Box(f"{c.name}_wall_yn", (bx, by - iy / 2 - w / 2, h / 2), (ix / 2, w / 2, h / 2), color=colour),
        Box(f"{c.name}_wall_yp", (bx, by + iy / 2 + w / 2, h / 2), (ix / 2, w / 2, h / 2), color=colour),
    ]
    outer = Box(c.name, (bx, by, h / 2), (ox, oy, h / 2), color=colour)
    for o in objects:
        if o.rests_on == FLOOR and outer.contains_xy(o.position[0], o.position[1], margin=max(o.half_size[:2])):
            raise _err(where, "center", c.center, f"the box overlaps {o.name}")
    return parts, outer
