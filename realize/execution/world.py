"""The execution world: one copy of the task's world standing in for the real robot's, disturbed on cue.

What it does: ``ExecutionWorld(spec, seed)`` builds a one-copy ``BatchedScene`` of a run spec
(its geometry, physics and robot) and places that copy in ONE world drawn from the task's
perturbation model (``realize.tasks.worlds.draw_worlds`` on its own stream,
``EXECUTION_STREAM``, so it is neither a search nor a validation world of the same seed;
``perturb=False``: the nominal world). The executor drives ``world.scene`` with the robot's
own controllers. Disturbances (``realize.execution.disturbances``) are carried out by
``apply``: objects and the base teleported, a held object knocked onto the surface below it
(moved sideways first where the effect says: a table's top, or the top of another object under
its footprint there; upright, at rest; the gripper command opened), tables moved (their static
PhysX actors posed anew; what rests on them moves along), box obstacles put in place (slid on
along their line where the drawn place overlaps the robot or an object). Every box an ``add_box`` of the world's
disturbances needs is built in the PhysX scene when the world is built, parked out of the way
(below the floor, outside the map), and only moved into place when it fires. Moved tables and
placed boxes stay where they are through ``scene.reset(state=...)`` (a restore moves dynamic
bodies and the robot only); ``reset()`` puts the whole world back at its start.
``observe()`` returns an ``Observation``: the copy's ``SceneState``, every table's centre and
yaw by name, and the boxes that appeared (``realize.execution.layout_updates`` turns an
observation into changes of the planner's scene config).
What it doesn't: decide when a disturbance fires (``Schedule``), run controllers or judge the
plan (the executor, ``realize.execution.monitor``). The world's ``scene.geometry`` stays the
belief it was built from: controllers run on a world see what the planner believes, not the
moved tables (``realize.execution.layout_updates.geometry_now`` gives the world as it is).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
import torch

from realize.config import ConfigError
from realize.execution.disturbances import (BASE, AddBox, Effect, KnockOut, MoveObject, MoveTable, PushBase,
                                            Scheduled)
from realize.tasks.worlds import SEARCH_STREAM, VALIDATION_STREAM, Worlds, draw_worlds
from realize.world.geometry import Box, SceneGeometry
from realize.world.state import SceneState

if TYPE_CHECKING:
    from realize.scene import EnvOptions

RunSpec = Any  # a run's spec (realize.spec.run_spec.RunSpec; the run layer sits above this one)

__all__ = ["EXECUTION_STREAM", "TablePose", "BoxSeen", "Observation", "ExecutionWorld"]

EXECUTION_STREAM = 3  # draw_worlds stream of the executed worlds (search: 1, validation: 2)
assert EXECUTION_STREAM not in (SEARCH_STREAM, VALIDATION_STREAM)
PARK_DEPTH = 10.0  # m below the floor where boxes wait
PARK_OUTSIDE = 50.0  # m beyond the map's low corner, in x and y
BOX_COLOR = (0.8, 0.3, 0.2, 1.0)
BOX_CLEARANCE_M = 0.05  # m an appearing box keeps from the robot and the objects
BOX_SLIDE_M = 0.05  # m: the step it slides on by until it does
ON_SURFACE = 0.01  # m: an object whose bottom is at least this high above a table's top - it rests on it


@dataclass(frozen=True)
class TablePose:
    """A table's centre (x, y) in the copy's local frame (m) and its yaw (rad)."""

    x: float
    y: float
    yaw: float = 0.0


@dataclass(frozen=True)
class BoxSeen:
    """A box obstacle that appeared: name, centre (x, y) on the floor and size (sx, sy, sz) (m)."""

    name: str
    center: tuple[float, float]
    size: tuple[float, float, float]


@dataclass(frozen=True)
class Observation:
    """What the world shows at one control step: the copy's state, the tables, the new boxes, the hand."""

    step: int
    time_s: float
    state: SceneState
    tables: dict[str, TablePose]
    boxes: tuple[BoxSeen, ...] = ()
    hand: tuple[float, ...] | None = None  # the hand link's pose (x, y, z, qw, qx, qy, qz), as the arm's encoders give it

    @property
    def held(self) -> str | None:
        return self.state.held


def _yaw(q: Sequence[float]) -> float:
    """Yaw (rad about +z) of a wxyz quaternion."""
    w, x, y, z = q
    return math.atan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))


def _upright(yaw: float) -> tuple[float, float, float, float]:
    return (math.cos(yaw / 2), 0.0, 0.0, math.sin(yaw / 2))


def _footprints_overlap(c1: Sequence[float], h1: Sequence[float], yaw1: float, c2: Sequence[float],
                        h2: Sequence[float], yaw2: float) -> bool:
    """Whether two rectangles (centre, half sizes, yaw) overlap by more than a millimetre: no
    separating axis among their four edge normals."""
    axes = [(math.cos(a), math.sin(a)) for yaw in (yaw1, yaw2) for a in (yaw, yaw + math.pi / 2)]
    d = (c2[0] - c1[0], c2[1] - c1[1])

    def radius(h: Sequence[float], yaw: float, n: tuple[float, float]) -> float:
        u, v = (math.cos(yaw), math.sin(yaw)), (-math.sin(yaw), math.cos(yaw))
        return h[0] * abs(u[0] * n[0] + u[1] * n[1]) + h[1] * abs(v[0] * n[0] + v[1] * n[1])

    return all(abs(d[0] * n[0] + d[1] * n[1]) < radius(h1, yaw1, n) + radius(h2, yaw2, n) - 1e-3 for n in axes)


class ExecutionWorld:
    """One copy of the run's world, drawn with ``seed``, disturbed by ``apply`` (module docstring).

    Args:
        spec: the run's spec (``realize.validation.replay.build_replay_spec(saved_plan(run_dir))``).
        seed: which world of the task's perturbation model (``EXECUTION_STREAM``).
        perturb: False: the nominal world (the task's config, unperturbed).
        disturbances: the world's drawn disturbances (``realize.execution.disturbances.draw``):
            every ``add_box`` among them gets its parked box now.
        env: the scene's env options (a render camera for video; None: none).
    """

    def __init__(self, spec: RunSpec, seed: int, *, perturb: bool = True, disturbances: Sequence[Scheduled] = (),
                 env: EnvOptions | None = None):
        from realize.scene import BatchedScene

        if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
            raise ConfigError(f"seed = {seed!r} is invalid: must be an integer >= 0")
        self.spec, self.seed, self.perturb = spec, seed, perturb
        self.belief: SceneGeometry = spec.geometry
        self.worlds: Worlds = draw_worlds(spec.task.perturbation, spec.geometry.objects, 1, seed,
                                          stream=EXECUTION_STREAM, nominal_first=not perturb)
        boxes = [s.effect for s in disturbances if isinstance(s.effect, AddBox)]
        names = [b.name for b in boxes]
        if len(set(names)) != len(names):
            raise ConfigError(f"disturbances: add_box names {names} must be unique")
        self.scene: BatchedScene = BatchedScene.from_spec(spec, 1, env=env)
        try:
            u = self.scene.u
            self._offset = np.array([*np.asarray(u.offsets[0], dtype=np.float64), 0.0])
            statics = list(self.scene.geometry.static_obstacles)
            self._table_boxes: dict[str, Box] = {t.name: t for t in self.scene.geometry.tables}
            self._table_entities = {b.name: a._objs[0] for b, a in zip(statics, u.obstacles[0])
                                    if b.name in self._table_boxes}
            self._box_specs = {b.name: b for b in boxes}
            self._box_entities = {b.name: self._build_box(b) for b in boxes}
            self.scene.set_worlds(self.worlds)
            self._tables: dict[str, TablePose] = {}
            self._placed: dict[str, BoxSeen] = {}
            self.log: list[str] = []
            self.reset()
        except BaseException:
            self.scene.close()
            raise

    # ------------------------------------------------------------------ building, resets
    def _build_box(self, b: AddBox) -> Any:
        import sapien

        half = [s / 2 for s in b.size]
        builder = self.scene.u.scene.create_actor_builder()
        builder.add_box_collision(half_size=half)
        builder.add_box_visual(half_size=half, material=sapien.render.RenderMaterial(base_color=list(BOX_COLOR)))
        builder.initial_pose = sapien.Pose(self._parked(b.size))
        return builder.build_static(name=f"execution_{b.name}")._objs[0]

    def _parked(self, size: tuple[float, float, float]) -> list[float]:
        g = self.belief
        return [g.bounds_low[0] - PARK_OUTSIDE + self._offset[0], g.bounds_low[1] - PARK_OUTSIDE + self._offset[1],
                -PARK_DEPTH - size[2]]

    def _pose_static(self, entity: Any, xyz: Sequence[float], yaw: float = 0.0) -> None:
        import sapien

        entity.set_pose(sapien.Pose([float(v) for v in np.asarray(xyz) + self._offset], list(_upright(yaw))))

    def reset(self) -> None:
        """Back to the world's start: tables where the config has them, boxes parked, the copy
        reset into its drawn world (robot start, object poses, friction, mass); ``log`` cleared."""
        import sapien

        for name, box in self._table_boxes.items():
            self._pose_static(self._table_entities[name], box.center, box.yaw)
            self._tables[name] = TablePose(box.center[0], box.center[1], box.yaw)
        for name, entity in self._box_entities.items():
            entity.set_pose(sapien.Pose(self._parked(self._box_specs[name].size)))
        self._placed.clear()
        self.log = []
        self.scene.reset(seed=self.seed)

    def start_state(self) -> SceneState:
        """The state the world starts in (after ``reset``): what the robot sees first."""
        return self.scene.capture_state(0, source=f"execution world seed {self.seed}")

    # ------------------------------------------------------------------ objects, robot
    def _set_object(self, name: str, position: Sequence[float], quaternion: Sequence[float]) -> None:
        import sapien

        actor = self.scene.u.object_actors[name][0]
        p = np.asarray(position, dtype=np.float64) + self._offset
        actor._objs[0].set_pose(sapien.Pose([float(v) for v in p], [float(v) for v in quaternion]))
        body = actor._bodies[0]
        body.set_linear_velocity(np.zeros(3, dtype=np.float32))
        body.set_angular_velocity(np.zeros(3, dtype=np.float32))

    def _object(self, name: str) -> tuple[list[float], list[float]]:
        pose = self.scene.object_pose(name)[0].tolist()
        return pose[:3], pose[3:]

    def _table_footprint(self, name: str) -> Box:
        b, t = self._table_boxes[name], self._tables[name]
        return dataclasses.replace(b, center=(t.x, t.y, b.center[2]), yaw=t.yaw)

    def surface_below(self, x: float, y: float) -> tuple[str, float]:
        """The surface under floor point (x, y): the table whose top covers it (its current
        place) and its top's height, else ``("floor", 0.0)``. Ramps, walls and boxes are not
        surfaces here."""
        for name in self._table_boxes:
            box = self._table_footprint(name)
            if box.contains_xy(x, y):
                return name, box.top_z
        return "floor", 0.0

    def held(self) -> str | None:
        k = int(self.scene.held_object()[0])
        return self.scene.object_names[k] if k >= 0 else None

    # ------------------------------------------------------------------ disturbances
    def apply(self, d: Scheduled | Effect) -> str:
        """Carry out one concrete disturbance now; returns a one-line description (also in ``log``)."""
        e = d.effect if isinstance(d, Scheduled) else d
        scene = self.scene
        step = scene.step_count
        if isinstance(e, MoveObject):
            p, q = self._object(e.object)
            self._set_object(e.object, (p[0] + e.dx, p[1] + e.dy, p[2]), q)
            text = f"moved {e.object} by ({e.dx:+.3f}, {e.dy:+.3f}) m to ({p[0] + e.dx:.3f}, {p[1] + e.dy:.3f})"
        elif isinstance(e, KnockOut):
            was_held = bool(scene.holds(e.object)[0])
            p, q = self._object(e.object)
            x, y = p[0] + e.dx, p[1] + e.dy  # (dx, dy) = (0, 0): straight down, as it always was
            surface, top = self.surface_below(x, y)
            me = scene.geometry.object(e.object)
            half = me.half_size[2]
            for o in scene.geometry.objects:  # another object under its footprint there: it lands on that
                if o.name == e.object:
                    continue
                po, qo = self._object(o.name)
                top_o = po[2] + o.half_size[2]
                if top < top_o <= p[2] - half + ON_SURFACE and _footprints_overlap(
                        (x, y), me.half_size[:2], _yaw(q), po[:2], o.half_size[:2], _yaw(qo)):
                    surface, top = o.name, top_o
            self._set_object(e.object, (x, y, top + half), _upright(_yaw(q)))
            scene.set_gripper(torch.zeros(1, dtype=torch.bool))
            sideways = f"by ({e.dx:+.3f}, {e.dy:+.3f}) m " if (e.dx, e.dy) != (0.0, 0.0) else ""
            text = (f"knocked {e.object} {'out of the hand ' if was_held else '(not held) '}{sideways}onto "
                    f"{surface} at ({x:.3f}, {y:.3f}); gripper opened")
        elif isinstance(e, MoveTable):
            text = self._move_table(e)
        elif isinstance(e, AddBox):
            text = self._add_box(e)
        elif isinstance(e, PushBase):
            text = self._push_base(e)
        else:  # pragma: no cover - the reader makes only the kinds above
            raise ConfigError(f"disturbance {e!r} is of no known kind")
        scene.state_changed()
        line = f"step {step}: {text}"
        self.log.append(line)
        return line

    def _move_table(self, e: MoveTable) -> str:
        before = self._table_footprint(e.table)
        held = self.held()
        riders = []
        for o in self.scene.geometry.objects:
            if o.name == held:
                continue
            p, q = self._object(o.name)
            if before.contains_xy(p[0], p[1]) and p[2] - o.half_size[2] >= before.top_z - ON_SURFACE:
                riders.append(o.name)
                self._set_object(o.name, (p[0] + e.dx, p[1] + e.dy, p[2]), q)
        t = self._tables[e.table]
        self._tables[e.table] = TablePose(t.x + e.dx, t.y + e.dy, t.yaw)
        self._pose_static(self._table_entities[e.table], (t.x + e.dx, t.y + e.dy, before.center[2]), t.yaw)
        with_ = f" with {', '.join(riders)}" if riders else ""
        return f"moved {e.table} by ({e.dx:+.3f}, {e.dy:+.3f}) m to ({t.x + e.dx:.3f}, {t.y + e.dy:.3f}){with_}"

    def _point(self, p: Any) -> np.ndarray:
        if p == BASE:
            return self.scene.base_pose()[0, :2].double().numpy()
        if isinstance(p, str):
            t = self._tables[p]
            return np.array([t.x, t.y])
        return np.asarray(p, dtype=np.float64)

    def _add_box(self, e: AddBox) -> str:
        if e.name not in self._box_entities:
            raise ConfigError(f"add_box {e.name!r}: this world was built without it (give the world its "
                              f"disturbances: ExecutionWorld(..., disturbances=...))")
        if e.center is not None:
            c = np.asarray(e.center, dtype=np.float64)
        else:
            assert e.between is not None
            a, b = self._point(e.between[0]), self._point(e.between[1])
            c = a + e.at * (b - a)
        c, moved = self._clear_of_bodies(c, e.size, None if e.between is None else self._point(e.between[1]))
        self._pose_static(self._box_entities[e.name], (c[0], c[1], e.size[2] / 2))
        self._placed[e.name] = BoxSeen(e.name, (float(c[0]), float(c[1])), tuple(e.size))
        further = "" if moved == 0 else f" ({moved:.2f} m further on than drawn: clear of the robot and the objects)" \
            if moved > 0 else " (overlapping the robot or an object: no clear place on its way)"
        return (f"box {e.name} {e.size[0]:g} x {e.size[1]:g} x {e.size[2]:g} m appeared at ({c[0]:.3f}, "
                f"{c[1]:.3f}){further}")

    def _bodies_aabbs(self) -> np.ndarray:
        """World-frame AABBs ``(K, 2, 3)`` of the robot's links and the objects, as they are now."""
        links = self.scene.u.agents[0].robot._objs[0].get_links()
        bodies = [lk for lk in links if lk.get_collision_shapes()]
        bodies += [self.scene.u.object_actors[n][0]._bodies[0] for n in self.scene.object_names]
        boxes = np.array([np.asarray(b.compute_global_aabb_tight(), dtype=np.float64) for b in bodies])
        return boxes - self._offset

    def _clear_of_bodies(self, c: np.ndarray, size: Sequence[float], towards: np.ndarray | None
                         ) -> tuple[np.ndarray, float]:
        """Centre ``c`` of a box of ``size`` (upright, axis-aligned, on the floor), slid on towards
        ``towards`` in 5 cm steps until its footprint keeps ``BOX_CLEARANCE_M`` from every robot
        link and object below its top (a box does not appear inside the robot; PhysX would throw
        what overlaps it across the map). Where no place up to ``towards`` is clear (or the box
        has a fixed centre), ``c`` as drawn. Returns (centre, how far it slid: 0 where it was
        clear, -1 where it overlaps something)."""
        aabbs = self._bodies_aabbs()
        half = np.asarray(size[:2], dtype=np.float64) / 2 + BOX_CLEARANCE_M
        low = aabbs[:, 0, 2] < float(size[2])  # what reaches below the box's top

        def clear(p: np.ndarray) -> bool:
            sep = (aabbs[:, 0, :2] > p + half) | (aabbs[:, 1, :2] < p - half)
            return bool((sep.any(axis=1) | ~low).all())

        if clear(c):
            return c, 0.0
        if towards is None:
            return c, -1.0
        d = towards - c
        length = float(np.linalg.norm(d))
        for s in np.arange(BOX_SLIDE_M, length + 1e-9, BOX_SLIDE_M):
            p = c + d * (s / length)
            if clear(p):
                return p, float(s)
        return c, -1.0

    def _push_base(self, e: PushBase) -> str:
        scene = self.scene
        held = self.held()
        art = scene.u.agents[0].robot._objs[0]
        qpos = np.asarray(art.get_qpos(), dtype=np.float32).copy()
        qvel = np.asarray(art.get_qvel(), dtype=np.float32).copy()
        for name, dv in zip(scene.robot.base.joints[:2], (e.dx, e.dy)):
            i = scene.joint_names.index(name)
            qpos[i] += np.float32(dv)
            qvel[i] = 0.0
        art.set_qpos(qpos)
        art.set_qvel(qvel)
        if held is not None:  # what the hand holds goes along
            p, q = self._object(held)
            self._set_object(held, (p[0] + e.dx, p[1] + e.dy, p[2]), q)
        scene.state_changed()
        x, y = scene.base_pose()[0, :2].tolist()
        return f"base pushed by ({e.dx:+.3f}, {e.dy:+.3f}) m to ({x:.3f}, {y:.3f})" + (
            f" with {held} in hand" if held else "")

    # ------------------------------------------------------------------ reads
    def tables(self) -> dict[str, TablePose]:
        return dict(self._tables)

    def boxes(self) -> tuple[BoxSeen, ...]:
        return tuple(self._placed.values())

    def observe(self) -> Observation:
        """The copy's state now, every table's pose and the boxes that appeared."""
        step = self.scene.step_count
        state = self.scene.capture_state(0, source=f"execution world seed {self.seed}, step {step}")
        return Observation(step, step * self.scene.control_dt, state, self.tables(), self.boxes(),
                           tuple(float(v) for v in self.scene.ee_pose()[0].tolist()))

    def close(self) -> None:
        self.scene.close()

    def __enter__(self) -> ExecutionWorld:
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()
