"""A CE run in 3-D in its rerun recording, beside the 2-D views: the world, the robot along each
iteration's best plan, the samples and why they failed.

What it does: ``Scene3D`` logs under ``/world3d`` (z up, metres, the copy's world frame)

* once: every static box of the world (tables, wall, ramp, container walls; ``Boxes3D`` with
  their yaw and pitch), every 2-D box parameter region as a floor patch (the exit), every movable object where it starts and the robot's link meshes
  (``realize.recording.robot``);
* per CE iteration ``k``, when the rollout recorded trajectories: the best plan's robot (every
  link's pose from the recorded whole-body joints, ``RobotKinematics.link_poses``), its objects and
  its TCP, and the action it is executing as a label at the TCP, each recorded sample on the
  ``control_step`` timeline at ``k * STEP_STRIDE + step`` (iteration 3's step 412 is 300412:
  scrubbing it plays the best plans one after another) and at ``ce_iteration = k`` (the end of
  that plan); the TCP path as a line;
* per iteration: every sample's parameters in 3-D (``/world3d/samples/<param>``: grasp and
  place points at their height, base positions on the floor), coloured by success, labelled
  with its failure reason on the parameter of the action that failed.
What it doesn't: draw the top-down views, distributions or plots (``realize.recording.log``,
``realize.recording.scene``), or read a simulator.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np
import rerun as rr

from realize.tasks.frames import position_columns
from realize.world.geometry import Box, SceneGeometry
from realize.tasks.param_layout import ParamLayout
from realize.tasks.regions import Box as RegionBox
from realize.recording.paths import ENTITY_WORLD_3D, TIMELINE, param_path
from realize.recording.robot import RobotLogger, robot_model
from realize.tasks.topdown import BEST_RGB, to_numpy

if TYPE_CHECKING:
    from realize.realization.result import RolloutResult
    from realize.robot.spec import RobotSpec

__all__ = ["Scene3D", "ENTITY_3D", "STEP_TIMELINE", "STEP_STRIDE"]

ENTITY_3D = ENTITY_WORLD_3D
STEP_TIMELINE = "control_step"
STEP_STRIDE = 100_000  # control_step = iteration * STEP_STRIDE + the step within the best plan
_AREA_RGB = (90, 170, 90, 120)
_SETTLE_S = 2.0  # s of a plan's frames shown after its counted steps (an object goal settles 1.5 s)


def _box_quat_xyzw(b: Box) -> list[float]:
    """The box's rotation Rz(yaw) Ry(pitch) as an xyzw quaternion."""
    cy, sy = math.cos(b.yaw / 2), math.sin(b.yaw / 2)
    cp, sp = math.cos(b.pitch / 2), math.sin(b.pitch / 2)
    return [-sy * sp, cy * sp, sy * cp, cy * cp]


def _rgba(c: tuple[float, ...]) -> tuple[int, int, int, int]:
    return tuple(int(round(255 * min(max(v, 0.0), 1.0))) for v in (tuple(c) + (1.0,))[:4])  # type: ignore[return-value]


def _reason(failure: str) -> tuple[int, str]:
    """``"2:place:timeout"`` -> ``(2, "place: timeout")``; ``""`` -> ``(-1, "")``."""
    parts = failure.split(":", 2)
    if len(parts) < 3 or not parts[0].strip().lstrip("-").isdigit():
        return -1, failure
    return int(parts[0]), f"{parts[1]}: {parts[2]}"


class Scene3D:
    """The 3-D part of a CE run's recording (module docstring).

    ``plan`` names the plan's actions in order (``"grasp(Cube_g)"``), ``control_freq`` converts
    recorded seconds into control steps, ``robot`` is the run's ``RobotSpec`` (None: no robot)."""

    def __init__(self, rec: rr.RecordingStream, layout: ParamLayout, geometry: SceneGeometry,
                 plan: list[str], control_freq: float, robot: RobotSpec | None = None) -> None:
        self.rec, self.layout, self.geometry = rec, layout, geometry
        self.plan, self.control_freq = list(plan), float(control_freq)
        self.robot = None if robot is None else RobotLogger(rec, robot_model(robot), f"{ENTITY_3D}/best/robot")
        # which parameter each action binds (its failure is labelled there): the last argument
        # (an object the action handles comes first: grasp(cube, Cube_g))
        self.action_param = [a.split("(", 1)[1].split(",")[-1].strip(" )") if "(" in a else "" for a in self.plan]

    def log_static(self) -> None:
        rec, g = self.rec, self.geometry
        boxes = list(g.static_obstacles)
        rec.log(f"{ENTITY_3D}/obstacles", rr.Boxes3D(
            centers=[b.center for b in boxes], half_sizes=[b.half_size for b in boxes],
            quaternions=[_box_quat_xyzw(b) for b in boxes], colors=[_rgba(b.color) for b in boxes],
            labels=[b.name for b in boxes], fill_mode=rr.components.FillMode.Solid), static=True)
        for name, region in self.layout.regions.items():  # a base's target area (the exit): a floor patch
            if isinstance(region, RegionBox) and region.dim == 2:
                (x0, y0), (x1, y1) = region.low, region.high
                rec.log(param_path(f"{ENTITY_3D}/areas", name), rr.Boxes3D(
                    centers=[[(x0 + x1) / 2, (y0 + y1) / 2, 0.005]], half_sizes=[[(x1 - x0) / 2, (y1 - y0) / 2, 0.005]],
                    colors=[_AREA_RGB], labels=[name]), static=True)
        for o in g.objects:  # where each object starts (faint), and the best plan's object (solid)
            rgb = [int(round(255 * c)) for c in o.color[:3]]
            rec.log(f"{ENTITY_3D}/objects_start/{o.name}", rr.Boxes3D(
                centers=[o.position], half_sizes=[o.half_size], colors=[(*rgb, 90)], labels=[o.name]), static=True)
            rec.log(f"{ENTITY_3D}/best/objects/{o.name}", rr.Boxes3D(half_sizes=[o.half_size], colors=[(*rgb, 255)],
                                                                     fill_mode=rr.components.FillMode.Solid), static=True)
        if self.robot is not None:
            self.robot.log_static()

    # ---- per iteration -------------------------------------------------------------------

    def log_samples(self, it: int, Z: np.ndarray | None, colors: np.ndarray, failure: list[str] | None) -> None:
        """Every sample's parameters in 3-D, failure reasons on the failing action's parameter."""
        if Z is None:
            return
        self.set_iteration(it)
        reasons = [_reason(f) for f in (failure or [""] * Z.shape[0])]
        for name in self.layout.names:
            region, sl = self.layout.regions[name], self.layout.slices[name]
            k = position_columns(region)
            if k < 2:
                continue
            xyz = np.zeros((Z.shape[0], 3))
            xyz[:, :k] = Z[:, sl][:, :k]
            labels = [r if a >= 0 and a < len(self.action_param) and self.action_param[a] == name else ""
                      for a, r in reasons]
            self.rec.log(param_path(f"{ENTITY_3D}/samples", name),
                         rr.Points3D(xyz, colors=colors, radii=0.012, labels=labels, show_labels=False))

    def log_best_plan(self, it: int, rollout: RolloutResult | None, best: int) -> None:
        """The best plan's robot, objects, TCP and current action on ``control_step``."""
        if rollout is None or best < 0 or rollout.traj_t is None or best >= rollout.traj_ee.shape[0]:
            return
        t = to_numpy(rollout.traj_t, np.float64)
        end = float(to_numpy(rollout.steps, np.float64)[best]) / self.control_freq + _SETTLE_S
        T = max(1, int(np.searchsorted(t, end, side="right")))  # its frames until it stopped (and settled)
        steps = it * STEP_STRIDE + np.round(t[:T] * self.control_freq).astype(np.int64)
        idx = [rr.TimeColumn(STEP_TIMELINE, sequence=steps), rr.TimeColumn(TIMELINE, sequence=np.full(T, it))]
        ee = to_numpy(rollout.traj_ee, np.float64)[best, :T]
        objs = to_numpy(rollout.traj_objects, np.float64)[best, :T] if rollout.traj_objects is not None else None
        rec = self.rec
        if objs is not None:
            for k, o in enumerate(self.geometry.objects[:objs.shape[1]]):
                rec.send_columns(f"{ENTITY_3D}/best/objects/{o.name}", indexes=idx,
                                 columns=rr.Boxes3D.columns(centers=objs[:, k]))
        acts = getattr(rollout, "traj_action", None)
        if acts is not None:
            a = np.clip(to_numpy(acts, np.int64)[best, :T], 0, len(self.plan) - 1)
            labels = [f"{i + 1}/{len(self.plan)} {self.plan[i]}" for i in a]
            rec.send_columns(f"{ENTITY_3D}/best/action", indexes=idx,
                             columns=rr.Points3D.columns(positions=ee, labels=labels))
        if self.robot is not None and getattr(rollout, "traj_q", None) is not None:
            self.robot.log_trajectory(to_numpy(rollout.traj_q, np.float64)[best, :T], idx)
        self.set_iteration(it)
        rec.log(f"{ENTITY_3D}/best/tcp_path", rr.LineStrips3D([ee], colors=[BEST_RGB + (255,)], radii=0.006))

    def set_iteration(self, it: int) -> None:
        """Log what follows at ``ce_iteration = it`` and ``control_step = it * STEP_STRIDE``."""
        self.rec.set_time(TIMELINE, sequence=it)
        self.rec.set_time(STEP_TIMELINE, sequence=it * STEP_STRIDE)
