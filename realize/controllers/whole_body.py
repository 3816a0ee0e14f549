"""Whole-body optimization fabric of a mobile manipulator: base x, y, yaw + upper joints to a gripper pose.

What it does: wraps the generic fabric (``realize.controllers.fabrics``) for a robot's model
(``realize.robot.kinematics.RobotKinematics``, built from its ``RobotSpec``):
  * the forcing term attracts three points of the gripper, the tool centre point (TCP), a point
    ``axis_length`` behind it on the approach axis and one beside it on the closing axis, to the
    same points of the goal pose; together they pull position and orientation;
  * collision leaves keep the robot's spheres off the scene's static boxes (tables, wall, ramp,
    a container; not the push scene's stick, which the gripper must touch) and off the floor,
    with a box signed distance (``realize.controllers.obstacles``); the spheres the robot spec
    names in ``fabric_exclude`` (fingers, the front of the hand) are left out of the box leaves
    (they must reach a cube lying on a table);
  * with ``movable`` obstacles given to a step (``controller.avoid_movable``,
    ``realize.controllers.movable``) the collision leaves also keep the robot's spheres off the
    movable objects where they stand now, per row (save the ones the row leaves out), and add one
    sphere about the object the row carries, fixed to the hand where it is held now, with leaves
    to every box (tables, floor, movable objects) and the sphere's radius grown by the same
    ``collision_margin``; pairs with movable objects or the held sphere act only within
    ``controller.avoid_range`` and their leaf values are floored (``BoxDistance``'s ``soft`` pairs);
  * joint-limit leaves for the upper joints (lift or torso, arm);
  * the fabric integrates its own reference state (q_ref, qd_ref), the way a fabric planner
    commands a real robot; the reference is re-synchronised with the measured state when they
    drift apart (contacts). Outputs: base velocity (world frame), upper-joint position and
    velocity targets for the PD drives, at the control rate, and a per-plan ``valid`` flag.
  * with ``compiled`` (a speed lever, off by default) the step runs as native code built ahead
    of time (``realize.controllers.fabric_package``), on the CPU.
What it doesn't: decide goals or phases (the grasp/place action templates do), or touch the
simulator (the rollout writes the targets to ``realize.scene.BatchedScene``).
"""

from __future__ import annotations

from dataclasses import dataclass

import torch
from torch import Tensor

from realize.controllers.settings import WholeBodyConfig
from realize.robot.layout import BASE, BASE_XY, YAW
from realize.controllers.fabrics import fabric_acceleration
from realize.controllers.fabric_package import load_package
from realize.controllers.movable import MovableObstacles
from realize.controllers.obstacles import BoxDistance, boxes_tensor
from realize.world.geometry import SceneGeometry
from realize.robot.jacobians import point_jets, prefix_ends
from realize.robot.chain import matvec3
from realize.robot.kinematics import RobotKinematics
from realize.robot.spec import DEFAULT_ROBOT, RobotSpec, load_robot_spec

LIMIT_MARGIN = 0.005  # rad (m for a lift): the fabric's state stays this far inside the limits


class _PoseMap:
    """Fabric kinematics of a robot with a 9-D 'pose' end effector:
    [TCP, TCP - L * approach axis, TCP + L * closing axis]."""

    def __init__(self, kin: RobotKinematics, axis_length: float, radii: Tensor):
        self.kin = kin
        self.axis_length = axis_length
        self.body_radii = radii
        ee = kin.ee_link
        self._ee = ee
        L = axis_length
        self._offsets = torch.stack([
            kin.tcp_offset,
            kin.tcp_offset - L * kin.approach_local,  # behind the TCP on the approach axis
            kin.tcp_offset + L * kin.closing_local,  # beside it on the closing axis
        ])
        self._mask = torch.cat([kin._ee_dof_mask.unsqueeze(0).expand(3, -1), kin.sphere_dof_mask], dim=0)
        self._ends = prefix_ends(self._mask)
        # with a held object: one more point, fixed to the end-effector link
        self._mask_held = torch.cat([self._mask, kin._ee_dof_mask.unsqueeze(0)], dim=0)
        self._ends_held = prefix_ends(self._mask_held)
        # a fixed base: its columns of q place the robot and never move, so the fabric sees no
        # base in the Jacobians (it then solves for the upper joints alone)
        self._locked: Tensor | None = None
        if kin.spec.base.fixed:
            on = torch.ones(kin.n_dof, dtype=kin.dtype, device=kin.device)
            on[BASE] = 0.0
            self._locked = on

    def __call__(self, q: Tensor) -> tuple[Tensor, Tensor]:  # pragma: no cover - jets is used
        return self.jets(q, torch.zeros_like(q))[0][0], self.kin(q)[1]

    def jets(self, q: Tensor, qd: Tensor, held_local: Tensor | None = None):
        """Jets of the attracted points and the sphere centres; with ``held_local`` (N, 3), a
        point fixed in the end-effector link's frame, one more sphere centre last."""
        k = self.kin
        fk, z, o = k._chain_terms(q, k._fk_links, None)
        r, p = fk[k.ee_link]
        ee_pts = matvec3(r.unsqueeze(-3), self._offsets) + p.unsqueeze(-2)  # (N, 3, 3)
        pts = torch.cat([ee_pts, k._sphere_centres(fk)], dim=-2)
        mask, ends = self._mask, self._ends
        if held_local is not None:
            pts = torch.cat([pts, (matvec3(r, held_local) + p).unsqueeze(-2)], dim=-2)
            mask, ends = self._mask_held, self._ends_held
        jac, vel, acc = point_jets(z, o, pts, mask, ends, qd, k._rev_mask)
        if self._locked is not None:
            jac = jac * self._locked  # qd's base part is zero, so vel and acc hold no base terms
        n = q.shape[0]
        ee = (pts[:, :3].reshape(n, 9), jac[:, :3].reshape(n, 9, -1), vel[:, :3].reshape(n, 9), acc[:, :3].reshape(n, 9))
        sph = (pts[:, 3:], jac[:, 3:], vel[:, 3:], acc[:, 3:])
        return ee, sph


class _HeldMap:
    """``_PoseMap`` of one step with a held object: one more sphere, per row (``held_local`` (N, 3)
    in the end-effector link's frame, radii (N, K + 1))."""

    def __init__(self, base: _PoseMap, held_local: Tensor, radii: Tensor):
        self.base, self.held_local, self.body_radii = base, held_local, radii

    def jets(self, q: Tensor, qd: Tensor):
        return self.base.jets(q, qd, self.held_local)


@dataclass
class FabricState:
    """Reference state integrated by the fabric, per plan: (N, n_dof) each (``realize.robot.layout``)."""

    q: Tensor
    qd: Tensor


class WholeBodyFabric:
    """Batched whole-body fabric controller of one robot in one scene geometry.

    Args:
        geometry: the world (its boxes become obstacles).
        cfg: fabric settings.
        dt: control period (s).
        device, dtype: where the controller computes (float64 is the safe default on CPU).
        robot: the robot (None: the default robot, ``realize.robot.spec.DEFAULT_ROBOT``).
    """

    def __init__(self, geometry: SceneGeometry, cfg: WholeBodyConfig | None = None, dt: float = 0.05,
                 device: torch.device | str = "cpu", dtype: torch.dtype = torch.float64,
                 robot: RobotSpec | None = None):
        self.cfg = cfg or WholeBodyConfig()  # checked when it was built
        self.dt = dt
        self.device, self.dtype = torch.device(device), dtype
        self.robot = robot or load_robot_spec(DEFAULT_ROBOT)
        self.kin = RobotKinematics(self.robot, device=device, dtype=dtype)
        names = list(self.kin.sphere_names)
        exclude = self.robot.fabric_exclusions(self.cfg.collision_exclude, names)
        radii = self.kin.sphere_radii.to(device, dtype) + self.cfg.collision_margin
        box_ok = torch.tensor([s not in exclude for s in names], device=device)
        floor_ok = self.kin.sphere_floor_mask.to(device=device, dtype=torch.bool)
        if self.cfg.floor_exclude:
            floor_ok = floor_ok & box_ok
        self.distance = BoxDistance(box_ok, floor_ok)
        self.map = _PoseMap(self.kin, self.cfg.axis_length, radii)
        self.boxes = boxes_tensor(geometry, self.cfg.floor).to(device, dtype)
        # the joint-limit leaves are singular at the limit: the fabric's state is kept inside it
        lo, up = self.kin.lower.to(device, dtype), self.kin.upper.to(device, dtype)
        self.lower, self.upper = lo, up
        self._clamp_lo, self._clamp_hi = lo + LIMIT_MARGIN, up - LIMIT_MARGIN
        self.fabric_cfg = self.cfg.fabric()
        limit = torch.full((self.kin.n_dof,), self.cfg.max_joint_speed, dtype=dtype, device=device)
        limit[BASE_XY] = self.cfg.max_base_speed
        limit[YAW] = self.cfg.max_yaw_rate
        if self.robot.base.fixed:
            limit[BASE] = 0.0
        self.speed_limit = limit
        # the step built into native code (a speed lever); other devices, or no boxes, run eagerly
        self._package = None
        if self.cfg.compiled and self.device.type == "cpu" and self.boxes.shape[0] > 0:
            self._package = load_package(self)

    def goal_points(self, position: Tensor, approach: Tensor, closing: Tensor) -> Tensor:
        """(N, 9) attractor goal from a TCP goal position and unit approach / closing axes (N, 3)."""
        L = self.cfg.axis_length
        return torch.cat([position, position - L * approach, position + L * closing], dim=1)

    def pose_points(self, q: Tensor) -> Tensor:
        """(N, 9) the three attracted gripper points at q."""
        return self.map.jets(q, torch.zeros_like(q))[0][0]

    def start(self, q: Tensor, qd: Tensor) -> FabricState:
        return FabricState(q.to(self.device, self.dtype).clone(), qd.to(self.device, self.dtype).clone())

    def step(self, state: FabricState, q_meas: Tensor, goal: Tensor, weight: Tensor | None = None,
             movable: MovableObstacles | None = None) -> tuple[FabricState, Tensor]:
        """Advance the reference one control period towards ``goal`` (N, 9); returns (state, valid).

        Rows whose reference drifted more than ``resync_tolerance`` from the measured joints
        (``q_meas``, (N, n_dof)) restart from the measured configuration at rest. With
        ``cfg.compiled`` (on the CPU, without a per-plan ``weight`` or ``movable`` obstacles) the
        built package computes it. ``movable``: the movable objects to avoid as well, and the
        object each row carries (``realize.controllers.movable``; see the module docstring).
        """
        args = (state.q, state.qd, q_meas.to(self.device, self.dtype), goal.to(self.device, self.dtype))
        if self._package is not None and weight is None and movable is None:
            q_next, qd_next, valid = self._package(*(a.contiguous() for a in args), self.boxes)
        else:
            q_next, qd_next, valid = self.step_tensors(*args, self.boxes, weight, movable)
        return FabricState(q_next, qd_next), valid

    def _with_movable(self, q_meas: Tensor, movable: MovableObstacles) -> tuple[Tensor, _HeldMap, BoxDistance]:
        """The boxes (N, M_static + m, BOX_COLUMNS), the map with the held sphere and the leaf map
        with the per-row pairs of a step that avoids ``movable`` objects."""
        mv = movable.to(self.device, self.dtype)
        n, m = mv.boxes.shape[:2]
        n_static = self.boxes.shape[0]
        boxes = torch.cat([self.boxes.expand(n, -1, -1), mv.boxes], dim=1)
        # the held point in the end-effector link's frame, from where the hand and the object are now
        r, p = self.kin._fk(q_meas, [self.kin.ee_link], None)[self.kin.ee_link]
        held = mv.held_radius > 0
        local = (r.transpose(-1, -2) @ (mv.held_centre - p).unsqueeze(-1)).squeeze(-1)
        local = torch.where(held[:, None], local, self.kin.tcp_offset.expand(n, 3))
        radius = torch.where(held, mv.held_radius + self.cfg.collision_margin, torch.ones_like(mv.held_radius))
        radii = torch.cat([self.map.body_radii.expand(n, -1), radius[:, None]], dim=1)
        # pairs: the robot's spheres keep their static rule and meet every object the row does not
        # leave out; the held sphere meets every box (the floor too) while held, save those left out
        k = self.map.body_radii.shape[0]
        keep = ~mv.ignore  # (n, m)
        robot = torch.cat([torch.ones(n, k, n_static, dtype=torch.bool, device=self.device),
                           keep[:, None, :].expand(n, k, m)], dim=2)
        held_row = torch.cat([held[:, None].expand(n, n_static), keep & held[:, None]], dim=1)
        pair_ok = torch.cat([robot, held_row[:, None, :]], dim=1)  # (n, k + 1, M)
        static_ok = torch.cat([self.distance.box_ok, torch.ones(1, dtype=torch.bool, device=self.device)])
        floor_ok = torch.cat([self.distance.floor_ok, torch.ones(1, dtype=torch.bool, device=self.device)])
        soft = torch.zeros(n, k + 1, n_static + m, dtype=torch.bool, device=self.device)
        soft[:, :, n_static:] = True
        soft[:, k, :] = True
        dist = BoxDistance(static_ok, floor_ok, pair_ok, soft, mv.range)
        return boxes, _HeldMap(self.map, local, radii), dist

    def step_tensors(self, q_ref: Tensor, qd_ref: Tensor, q_meas: Tensor, goal: Tensor, boxes: Tensor,
                     weight: Tensor | None = None, movable: MovableObstacles | None = None
                     ) -> tuple[Tensor, Tensor, Tensor]:
        """The step on plain tensors, the scene's ``boxes`` (M, BOX_COLUMNS) an argument: ``(q, qd, valid)``
        (what ``realize.controllers.fabric_package`` builds)."""
        drift = (q_ref - q_meas).abs().max(dim=1).values > self.cfg.resync_tolerance
        q = torch.where(drift[:, None], q_meas, q_ref)
        q = torch.maximum(torch.minimum(q, self._clamp_hi), self._clamp_lo)
        qd = torch.where(drift[:, None], torch.zeros_like(qd_ref), qd_ref)
        n = q.shape[0]
        kin, dist, obstacles = self.map, self.distance, boxes.expand(n, -1, -1)
        if movable is not None:
            obstacles, kin, dist = self._with_movable(q_meas, movable)
        qdd, valid = fabric_acceleration(
            q, qd, goal, kin, self.fabric_cfg,
            obstacles=obstacles, lower=self.lower, upper=self.upper, weight=weight,
            obstacle_distance=dist,
        )
        qd_next = qd + self.dt * qdd
        qd_next = torch.maximum(torch.minimum(qd_next, self.speed_limit), -self.speed_limit)
        q_next = q + self.dt * qd_next
        q_next = torch.maximum(torch.minimum(q_next, self._clamp_hi), self._clamp_lo)
        q_next = torch.where(valid[:, None], q_next, q_meas)
        qd_next = torch.where(valid[:, None], qd_next, torch.zeros_like(qd_next))
        return q_next, qd_next, valid
