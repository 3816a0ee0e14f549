"""World geometry of the realize scenes: the config (``GeometryCfg``) and the boxes it makes.

What it does: describes the world (tables, an optional wall or ramp, the exit area, the movable
objects by name (``objects``, ``realize.world.objects``) and the robot's start pose) in one copy's local frame, checks it (``GeometryCfg`` is a
``realize.config.Settings``: bad values raise ``ConfigError`` naming the key), and offers the
obstacle boxes that the controllers (A* occupancy grid, fabric collision terms), the figures and
the ManiSkill tasks need (``build_geometry`` -> ``SceneGeometry``). The ``push`` variant
(move-and-push) adds an open box (a static container: floor and four low walls) on the floor;
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

__all__ = ["VARIANTS", "Box", "SceneGeometry", "TableCfg", "GeometryCfg", "build_geometry"]

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
    extras: tuple[Box, ...]  # wall / ramp / the container's floor and walls
    objects: tuple[SceneObject, ...]  # movable, by name, in config order
    robot_start: tuple[float, float, float]  # x, y, yaw
    robot_radius: float
    exit_low: tuple[float, float]
    exit_high: tuple[float, float]
    bounds_low: tuple[float, float]
    bounds_high: tuple[float, float]
    containers: tuple[Box, ...] = ()  # push variant: open boxes, outer bounds (walls in extras)
    container_wall: float = 0.0  # wall thickness of the containers (m)

    @property
    def object_names(self) -> tuple[str, ...]:
        return tuple(o.name for o in self.objects)

    def object(self, name: str) -> SceneObject:
        for o in self.objects:
            if o.name == name:
                return o
        raise KeyError(f"scene has no object named {name!r}; objects: {list(self.object_names)}")

    def object_index(self, name: str) -> int:
        """Position of object ``name`` in ``objects`` (the m axis of the scene's (N, m, ...) reads)."""
        return self.object_names.index(self.object(name).name)

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

    def container(self, name: str) -> Box:
        for c in self.containers:
            if c.name == name:
                return c
        raise KeyError(f"scene has no container named {name!r}; containers: {[c.name for c in self.containers]}")

    def table(self, name: str) -> Box:
        for t in self.tables:
            if t.name == name:
                return t
        raise KeyError(f"scene has no table named {name!r}; tables: {[t.name for t in self.tables]}")

    @property
    def extent(self) -> tuple[float, float]:
        """Size (x, y) of the world rectangle; used to tile copies without overlap."""
        return (self.bounds_high[0] - self.bounds_low[0], self.bounds_high[1] - self.bounds_low[1])


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
class GeometryCfg(Settings):
    """Config of the world (the Hydra ``scene`` group maps onto this one to one).

    Single-value bounds are field metadata; how the parts fit together (the cube on its table or
    stick, nothing under the robot's start, bounds and exit non-empty) is ``check``, which builds
    the boxes once to see."""

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
    robot_start: tuple[float, float, float] = setting((-2.0, 0.0, 0.0))
    robot_radius: float = setting(0.32, gt=0)
    exit_low: tuple[float, float] = setting((1.8, -0.4))
    exit_high: tuple[float, float] = setting((2.6, 0.4))
    bounds_low: tuple[float, float] = setting((-3.0, -3.0))
    bounds_high: tuple[float, float] = setting((3.2, 3.0))
    # wall variant: a thin wall across the direct route between the tables
    wall_center: tuple[float, float] = setting((0.0, 0.0))
    wall_size: tuple[float, float, float] = setting((1.6, 0.1, 1.0), check=_all_positive)
    # ramp variant: a slippery tilted plank between the tables whose low end rests on table2's
    # near edge, so a cube released above it slides onto table2 (30 deg; PhysX averages the two
    # frictions: (cube 1.0 + ramp 0.0) / 2 = 0.5 < tan 30 deg = 0.58)
    ramp_center: tuple[float, float] = setting((0.0, -0.63))  # low end 3 cm over table 2's near edge
    ramp_length: float = setting(0.7, gt=0)
    ramp_width: float = setting(0.4, gt=0)
    ramp_drop: float = setting(0.35, gt=0)  # and < ramp_length (check)
    ramp_friction: float = setting(0.0, ge=0)
    # push variant: an open box on the floor (inner footprint, wall height); its stick and the
    # cube on the stick's top are objects (objects.stick rests on the floor, objects.cube on the stick)
    box_center: tuple[float, float] = setting((0.8, 0.0))
    box_inner: tuple[float, float] = setting((0.4, 0.4))  # and larger than the cube (check)
    box_wall_height: float = setting(0.12, gt=0, le=0.5)
    box_wall_thickness: float = setting(0.02, gt=0, le=0.1)

    def check(self, where: str) -> None:
        _assemble(self, where)


def _err(where: str, key: str, value: Any, allowed: str) -> ConfigError:
    return ConfigError(f"{where}.{key} = {value!r} is invalid: {allowed}")


def build_geometry(cfg: GeometryCfg) -> SceneGeometry:
    """The boxes of a (checked) ``GeometryCfg``: the world of one copy in its local frame."""
    return _assemble(cfg, cfg.config_key)


def _assemble(cfg: GeometryCfg, where: str) -> SceneGeometry:
    """Turn ``cfg`` into boxes and placed objects; raises ``ConfigError`` naming ``<where>.<key>``
    where the parts do not fit together (single values are already checked by the fields)."""
    push = cfg.variant == "push"
    names = [t.name for t in cfg.tables]
    if len(cfg.tables) < 2 and not push:
        raise _err(where, "tables", names, "need at least two tables (pick and place)")
    if len(set(names)) != len(names):
        raise _err(where, "tables", names, "table names must be unique")
    tables = [Box(t.name, (t.center[0], t.center[1], t.height / 2), (t.size[0] / 2, t.size[1] / 2, t.height / 2))
              for t in cfg.tables]
    objects = place_objects(cfg.objects, {t.name: t for t in tables}, f"{where}.objects")
    extras: list[Box] = []
    containers: tuple[Box, ...] = ()
    if push:
        box_parts, container = _container_parts(cfg, objects, where)
        extras.extend(box_parts)
        containers = (container,)
    for o in objects:
        if o.rests_on != FLOOR:
            continue
        for b in tables:
            if b.contains_xy(*o.position[:2], margin=o.half_size[0] + o.half_size[1]):
                raise _err(where, f"objects.{o.name}.offset", list(cfg.objects[o.name].offset),
                           f"{o.name} stands on the floor inside {b.name}'s footprint")

    if cfg.variant == "wall":
        wx, wy, wz = cfg.wall_size
        extras.append(
            Box("wall", (cfg.wall_center[0], cfg.wall_center[1], wz / 2), (wx / 2, wy / 2, wz / 2),
                color=(0.6, 0.6, 0.65, 1.0))
        )
    elif cfg.variant == "ramp":
        if not cfg.ramp_drop < cfg.ramp_length:
            raise _err(where, "ramp_drop", cfg.ramp_drop, f"must be > 0 and < ramp_length ({cfg.ramp_length})")
        # The ramp runs along y from table1's side (high end) to table2's side (low end).
        t1, t2 = tables[0], tables[1]
        low_z = 2 * t2.half_size[2] + 0.01
        high_z = low_z + cfg.ramp_drop
        pitch = math.asin(min(1.0, cfg.ramp_drop / cfg.ramp_length))
        thick = 0.02
        # yaw = -pi/2 makes the box's local +x point towards -y (from table1 to table2)
        extras.append(
            Box("ramp", (cfg.ramp_center[0], cfg.ramp_center[1], (low_z + high_z) / 2),
                (cfg.ramp_length / 2, cfg.ramp_width / 2, thick / 2),
                yaw=-math.pi / 2 * (1 if t1.center[1] > t2.center[1] else -1), pitch=pitch,
                color=(0.55, 0.55, 0.6, 1.0), friction=cfg.ramp_friction)
        )
    sx, sy, syaw = cfg.robot_start
    floor_boxes = [Box(o.name, o.position, o.half_size, yaw=o.yaw) for o in objects if o.rests_on == FLOOR]
    for b in tables + extras + floor_boxes:
        if b.contains_xy(sx, sy, margin=cfg.robot_radius):
            raise _err(where, "robot_start", cfg.robot_start, f"the robot's footprint overlaps {b.name}")
    bl, bh = cfg.bounds_low, cfg.bounds_high
    if not (bl[0] < bh[0] and bl[1] < bh[1]):
        raise _err(where, "bounds_low", (bl, bh), "bounds_low must be < bounds_high in x and y")
    if not (bl[0] + cfg.robot_radius <= sx <= bh[0] - cfg.robot_radius and bl[1] + cfg.robot_radius <= sy <= bh[1] - cfg.robot_radius):
        raise _err(where, "robot_start", cfg.robot_start, f"must lie inside the bounds {bl}..{bh}")
    el, eh = cfg.exit_low, cfg.exit_high
    if not (el[0] < eh[0] and el[1] < eh[1]):
        raise _err(where, "exit_low", (el, eh), "the exit rectangle is empty (exit_low must be < exit_high)")
    return SceneGeometry(
        variant=cfg.variant,
        tables=tuple(tables),
        extras=tuple(extras),
        objects=objects,
        robot_start=(sx, sy, syaw),
        robot_radius=cfg.robot_radius,
        exit_low=tuple(el),
        exit_high=tuple(eh),
        bounds_low=tuple(bl),
        bounds_high=tuple(bh),
        containers=containers,
        container_wall=cfg.box_wall_thickness if push else 0.0,
    )


def _container_parts(cfg: GeometryCfg, objects: tuple[SceneObject, ...], where: str) -> tuple[list[Box], Box]:
    """The push variant's open box: its five static boxes (floor, walls) and its outer bounds
    (named ``box``, for the goal predicate)."""
    ix, iy = cfg.box_inner
    h, w = cfg.box_wall_height, cfg.box_wall_thickness
    smallest = min((2 * min(o.half_size[0], o.half_size[1]) for o in objects if o.rests_on != FLOOR), default=0.0)
    if min(ix, iy) <= smallest:
        raise _err(where, "box_inner", cfg.box_inner, f"both sides must be larger than the objects ({smallest} m)")
    bx, by = cfg.box_center
    ox, oy = ix / 2 + w, iy / 2 + w  # outer half sizes
    colour = (0.3, 0.45, 0.7, 1.0)
    floor = w / 2
    parts = [
        Box("box_floor", (bx, by, floor / 2), (ox, oy, floor / 2), color=colour),
        Box("box_wall_xn", (bx - ix / 2 - w / 2, by, h / 2), (w / 2, oy, h / 2), color=colour),
        Box("box_wall_xp", (bx + ix / 2 + w / 2, by, h / 2), (w / 2, oy, h / 2), color=colour),
        Box("box_wall_yn", (bx, by - iy / 2 - w / 2, h / 2), (ix / 2, w / 2, h / 2), color=colour),
        Box("box_wall_yp", (bx, by + iy / 2 + w / 2, h / 2), (ix / 2, w / 2, h / 2), color=colour),
    ]
    outer = Box("box", (bx, by, h / 2), (ox, oy, h / 2), color=colour)
    for o in objects:
        if o.rests_on == FLOOR and outer.contains_xy(o.position[0], o.position[1], margin=max(o.half_size[:2])):
            raise _err(where, "box_center", cfg.box_center, f"the box overlaps {o.name}")
    return parts, outer
