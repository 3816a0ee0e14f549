"""Whole-body optimization fabric for Fetch: base x, y, yaw + torso + 7 arm joints to a gripper pose.

What it does: wraps the generic fabric (``realize.controllers.fabrics``) for the Fetch model of
``realize.kinematics``:
  * the forcing term attracts three points of the gripper, the tool centre point (TCP), a point
    ``axis_length`` behind it on the approach axis and one beside it on the closing axis, to the
    same points of the goal pose; together they pull position and orientation;
  * collision leaves keep the robot's spheres off the scene's static boxes (tables, wall, ramp,
    a container; not the push scene's stick, which the gripper must touch) and off
    the floor, with a box signed distance; the fingers and the front of the gripper are left out
    of the box leaves (they must reach a cube lying on a table);
  * joint-limit leaves for torso and arm;
  * the fabric integrates its own reference state (q_ref, qd_ref), the way a fabric planner
    commands a real robot; the reference is re-synchronised with the measured state when they
    drift apart (contacts). Outputs: base velocity (world frame), torso/arm position and
    velocity targets for the PD drives, at the control rate, and a per-plan ``valid`` flag.
What it doesn't: decide goals or phases (the grasp/place action templates do), or touch the
simulator (the rollout writes the targets to ``realize.scene.BatchedScene``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, fields
from typing import Any, Mapping, Sequence

import torch
from torch import Tensor

from realize.geometry import SceneGeometry
from realize.controllers.fabrics import FabricConfig, fabric_acceleration
from realize.kinematics import FetchKinematics

# spheres that may touch a table top while grasping or placing a cube lying on it
DEFAULT_EXCLUDE = ("finger_r", "finger_l", "gripper_front")
FLOOR_HALF = 50.0
LIMIT_MARGIN = 0.005  # rad (m for the torso): the fabric's state stays this far inside the limits


class ControllerConfigError(ValueError):
    """A controller setting is invalid; the message names the key."""


@dataclass
class WholeBodyConfig:
    """Whole-body fabric settings (Hydra ``controller.fabric``). Every field is a config key."""

    gamma: float = 3.0  # attractor weight
    beta_close: float = 6.5  # damping near the goal (reference default)
    beta_distant: float = 0.01  # damping far from the goal
    k_psi: float = 5.0  # attractor potential gain
    axis_length: float = 0.25  # m, orientation points behind / beside the TCP
    collision_lam: float = 0.5
    collision_margin: float = 0.02  # m added to every sphere radius
    collision_exclude: tuple[str, ...] = DEFAULT_EXCLUDE
    floor: bool = True
    max_base_speed: float = 0.6  # m/s
    max_yaw_rate: float = 1.0  # rad/s
    max_joint_speed: float = 1.2  # rad/s or m/s for the torso
    resync_tolerance: float = 0.08  # reference/measured drift that triggers a re-sync

    def validate(self, prefix: str = "controller.fabric") -> None:
        for name in ("gamma", "k_psi", "axis_length", "max_base_speed", "max_yaw_rate", "max_joint_speed",
                     "resync_tolerance"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                raise ControllerConfigError(f"{prefix}.{name} = {v!r} is invalid: must be a finite number > 0")
        for name in ("beta_close", "beta_distant", "collision_lam", "collision_margin"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v >= 0):
                raise ControllerConfigError(f"{prefix}.{name} = {v!r} is invalid: must be a finite number >= 0")

    @classmethod
    def from_dict(cls, d: Mapping[str, Any] | None, prefix: str = "controller.fabric") -> "WholeBodyConfig":
        d = dict(d or {})
        known = {f.name for f in fields(cls)}
        bad = set(d) - known
        if bad:
            raise ControllerConfigError(f"{prefix}: unknown keys {sorted(bad)}; allowed: {sorted(known)}")
        if "collision_exclude" in d:
            d["collision_exclude"] = tuple(d["collision_exclude"])
        cfg = cls(**d)
        cfg.validate(prefix)
        return cfg

    def fabric(self) -> FabricConfig:
        return FabricConfig(gamma=self.gamma, beta_close=self.beta_close, beta_distant=self.beta_distant,
                            k_psi=self.k_psi, collision_lam=self.collision_lam)


def boxes_tensor(geometry: SceneGeometry, floor: bool = True) -> Tensor:
    """(M, 9) obstacle boxes: centre xyz, half sizes xyz, yaw, pitch, is-floor flag."""
    rows = [list(b.center) + list(b.half_size) + [b.yaw, b.pitch, 0.0] for b in geometry.static_obstacles]
    if floor:
        rows.append([0.0, 0.0, -FLOOR_HALF, FLOOR_HALF, FLOOR_HALF, FLOOR_HALF, 0.0, 0.0, 1.0])
    return torch.tensor(rows, dtype=torch.float64)


class BoxDistance:
    """Leaf map of the collision terms: sphere-to-box gap in units of the sphere radius.

    ``__call__(points (N,K,3), radii (N,K), boxes (N,M,9)) -> (N,K,M)``. Pairs that must not
    interact (``box_ok[k]`` False for a box, ``floor_ok[k]`` False for the floor) get a constant
    far distance, hence no force.
    """

    FAR = 10.0

    def __init__(self, box_ok: Tensor, floor_ok: Tensor):
        self.box_ok, self.floor_ok = box_ok, floor_ok

    def _local(self, points: Tensor, boxes: Tensor):
        c, h, yaw, pitch = boxes[..., 0:3], boxes[..., 3:6], boxes[..., 6], boxes[..., 7]
        cy, sy = torch.cos(yaw), torch.sin(yaw)
        cp, sp = torch.cos(pitch), torch.sin(pitch)
        zero, one = torch.zeros_like(cy), torch.ones_like(cy)
        rz = torch.stack([torch.stack([cy, -sy, zero], -1), torch.stack([sy, cy, zero], -1),
                          torch.stack([zero, zero, one], -1)], -2)
        ry = torch.stack([torch.stack([cp, zero, sp], -1), torch.stack([zero, one, zero], -1),
                          torch.stack([-sp, zero, cp], -1)], -2)
        rot = rz @ ry  # (N, M, 3, 3): box frame -> world
        u = points[:, :, None, :] - c[:, None, :, :]  # (N,K,M,3)
        local = torch.einsum("nmji,nkmj->nkmi", rot, u)  # R^T u
        return rot, local, h[:, None, :, :]

    def _ok(self, boxes: Tensor) -> Tensor:
        floor = boxes[..., 8][:, None, :] > 0.5
        dev = boxes.device
        return torch.where(floor, self.floor_ok.to(dev)[None, :, None], self.box_ok.to(dev)[None, :, None])

    def __call__(self, points: Tensor, body_radii: Tensor, boxes: Tensor) -> Tensor:
        _, local, h = self._local(points, boxes)
        qv = local.abs() - h
        outside = torch.sqrt((torch.clamp(qv, min=0.0) ** 2).sum(-1) + 1e-12)
        inside = torch.clamp(qv.max(dim=-1).values, max=0.0)
        # dimensionless like the reference's sphere leaf (|p - c| / (r_o + r_b) - 1): the gap
        # in units of the body sphere's radius, which keeps the leaves well-conditioned at dt
        dist = (outside + inside) / body_radii[:, :, None] - 1.0
        return torch.where(self._ok(boxes), dist, torch.full_like(dist, self.FAR))

    def jets(self, p: Tensor, Jp: Tensor, pd: Tensor, ap: Tensor, radii: Tensor, boxes: Tensor):
        """Closed-form leaf jets (value, Jacobian, velocity, curvature), flattened (N, K*M, ...)."""
        rot, local, h = self._local(p, boxes)
        s = torch.where(local >= 0, torch.ones_like(local), -torch.ones_like(local))
        qv = local.abs() - h
        act = (qv > 0).to(p.dtype)
        w = act * qv
        wn = torch.sqrt((w * w).sum(-1) + 1e-12)
        is_out = (qv > 0).any(-1)
        k = qv.argmax(dim=-1, keepdim=True)
        e_k = torch.zeros_like(qv).scatter(-1, k, 1.0)
        g_local = torch.where(is_out[..., None], act * s * w / wn[..., None], e_k * s)
        r = radii[:, :, None]
        g = torch.einsum("nmij,nkmj->nkmi", rot, g_local) / r[..., None]  # d phi / d p (world)
        val = torch.where(is_out, wn, qv.max(-1).values) / r - 1.0
        J = torch.einsum("nkmd,nkdj->nkmj", g, Jp)
        pdl = torch.einsum("nmji,nkj->nkmi", rot, pd)  # local velocity
        v = act * s * pdl
        curv_out = ((v * v).sum(-1) - (w * v).sum(-1) ** 2 / wn ** 2) / wn
        a = (g * ap[:, :, None, :]).sum(-1) + torch.where(is_out, curv_out, torch.zeros_like(curv_out)) / r
        phid = (g * pd[:, :, None, :]).sum(-1)
        ok = self._ok(boxes).expand_as(val)
        val = torch.where(ok, val, torch.full_like(val, self.FAR))
        J = torch.where(ok[..., None], J, torch.zeros_like(J))
        phid = torch.where(ok, phid, torch.zeros_like(phid))
        a = torch.where(ok, a, torch.zeros_like(a))
        return val.flatten(1), J.flatten(1, 2), phid.flatten(1), a.flatten(1)


class _PoseMap:
    """Fabric kinematics of Fetch with a 9-D 'pose' end effector:
    [TCP, TCP - L * approach axis, TCP + L * closing axis]."""

    def __init__(self, kin: FetchKinematics, axis_length: float, radii: Tensor):
        self.kin = kin
        self.axis_length = axis_length
        self.body_radii = radii
        ee = kin.ee_link
        self._ee = ee
        L, dt = axis_length, kin.tcp_offset.dtype
        self._offsets = torch.stack([
            kin.tcp_offset,
            kin.tcp_offset - torch.tensor([L, 0.0, 0.0], dtype=dt),  # behind the TCP on the approach axis
            kin.tcp_offset + torch.tensor([0.0, L, 0.0], dtype=dt),  # beside it on the closing axis
        ])

    def __call__(self, q: Tensor) -> tuple[Tensor, Tensor]:  # pragma: no cover - jets is used
        return self.jets(q, torch.zeros_like(q))[0][0], self.kin(q)[1]

    def jets(self, q: Tensor, qd: Tensor):
        k = self.kin
        fk, z, o = k._chain_terms(q, [k.ee_link] + list(dict.fromkeys(k.sphere_links)), None)
        r, p = fk[k.ee_link]
        ee_pts = (r.unsqueeze(-3) @ self._offsets.to(q).unsqueeze(-1)).squeeze(-1) + p.unsqueeze(-2)  # (N,3,3)
        pts = torch.cat([ee_pts, k._sphere_centres(fk)], dim=-2)
        mask = torch.cat([k._ee_dof_mask.unsqueeze(0).expand(3, -1), k.sphere_dof_mask], dim=0)
        jac = k._point_jacobian(z, o, pts, mask)
        vel = (jac @ qd.unsqueeze(-2).unsqueeze(-1)).squeeze(-1)
        acc = k._jdot_qdot(z, o, pts, mask, qd)
        n = q.shape[0]
        ee = (pts[:, :3].reshape(n, 9), jac[:, :3].reshape(n, 9, -1), vel[:, :3].reshape(n, 9), acc[:, :3].reshape(n, 9))
        sph = (pts[:, 3:], jac[:, 3:], vel[:, 3:], acc[:, 3:])
        return ee, sph


@dataclass
class FabricState:
    """Reference state integrated by the fabric, per plan: (N, 11) each."""

    q: Tensor
    qd: Tensor


class WholeBodyFabric:
    """Batched whole-body fabric controller of Fetch in one scene geometry.

    Args:
        geometry: the world (its boxes become obstacles).
        cfg: fabric settings.
        dt: control period (s).
        device, dtype: where the controller computes (float64 is the safe default on CPU).
    """

    def __init__(self, geometry: SceneGeometry, cfg: WholeBodyConfig | None = None, dt: float = 0.05,
                 device: torch.device | str = "cpu", dtype: torch.dtype = torch.float64):
        self.cfg = cfg or WholeBodyConfig()
        self.cfg.validate()
        self.dt = dt
        self.device, self.dtype = torch.device(device), dtype
        self.kin = FetchKinematics(device=device, dtype=dtype)
        names = list(self.kin.sphere_names)
        unknown = [s for s in self.cfg.collision_exclude if s not in names]
        if unknown:
            raise ControllerConfigError(
                f"controller.fabric.collision_exclude: unknown spheres {unknown}; known: {names}")
        radii = self.kin.sphere_radii.to(device, dtype) + self.cfg.collision_margin
        box_ok = torch.tensor([s not in self.cfg.collision_exclude for s in names], device=device)
        floor_ok = self.kin.sphere_floor_mask.to(device=device, dtype=torch.bool)
        self.distance = BoxDistance(box_ok, floor_ok)
        self.map = _PoseMap(self.kin, self.cfg.axis_length, radii)
        self.boxes = boxes_tensor(geometry, self.cfg.floor).to(device, dtype)
        # the joint-limit leaves are singular at the limit: the fabric's state is kept inside it
        lo, up = self.kin.lower.to(device, dtype), self.kin.upper.to(device, dtype)
        self.lower, self.upper = lo, up
        self._clamp_lo, self._clamp_hi = lo + LIMIT_MARGIN, up - LIMIT_MARGIN
        self.fabric_cfg = self.cfg.fabric()
        self.speed_limit = torch.tensor(
            [self.cfg.max_base_speed] * 2 + [self.cfg.max_yaw_rate] + [self.cfg.max_joint_speed] * 8,
            dtype=dtype, device=device)

    def goal_points(self, position: Tensor, approach: Tensor, closing: Tensor) -> Tensor:
        """(N, 9) attractor goal from a TCP goal position and unit approach / closing axes (N, 3)."""
        L = self.cfg.axis_length
        return torch.cat([position, position - L * approach, position + L * closing], dim=1)

    def pose_points(self, q: Tensor) -> Tensor:
        """(N, 9) the three attracted gripper points at q."""
        return self.map.jets(q, torch.zeros_like(q))[0][0]

    def start(self, q: Tensor, qd: Tensor) -> FabricState:
        return FabricState(q.to(self.device, self.dtype).clone(), qd.to(self.device, self.dtype).clone())

    def step(self, state: FabricState, q_meas: Tensor, goal: Tensor, weight: Tensor | None = None
             ) -> tuple[FabricState, Tensor]:
        """Advance the reference one control period towards ``goal`` (N, 9); returns (state, valid).

        Rows whose reference drifted more than ``resync_tolerance`` from the measured joints
        (``q_meas``, (N, 11)) restart from the measured configuration at rest.
        """
        q_meas = q_meas.to(self.device, self.dtype)
        drift = (state.q - q_meas).abs().max(dim=1).values > self.cfg.resync_tolerance
        q = torch.where(drift[:, None], q_meas, state.q)
        q = torch.maximum(torch.minimum(q, self._clamp_hi), self._clamp_lo)
        qd = torch.where(drift[:, None], torch.zeros_like(state.qd), state.qd)
        n = q.shape[0]
        boxes = self.boxes.expand(n, -1, -1)
        qdd, valid = fabric_acceleration(
            q, qd, goal.to(self.device, self.dtype), self.map, self.fabric_cfg,
            obstacles=boxes, lower=self.lower, upper=self.upper, weight=weight,
            obstacle_distance=self.distance,
        )
        qd_next = qd + self.dt * qdd
        qd_next = torch.maximum(torch.minimum(qd_next, self.speed_limit), -self.speed_limit)
        q_next = q + self.dt * qd_next
        q_next = torch.maximum(torch.minimum(q_next, self._clamp_hi), self._clamp_lo)
        q_next = torch.where(valid[:, None], q_next, q_meas)
        qd_next = torch.where(valid[:, None], qd_next, torch.zeros_like(qd_next))
        return FabricState(q_next, qd_next), valid
