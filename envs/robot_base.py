"""Where each copy's robot base stands: placed at an episode's start, read back as (x, y, yaw).

What it does: two kinds of base (``realize.robot.spec.BaseSpec``):
  * a mobile base: the articulation's root sits at the task's ``robot_start`` (plus the tile's
    offset) with zero yaw, and the planar x, y, yaw joints hold the base pose relative to it, so
    joint velocities are world-frame velocities;
  * a fixed base: the root is the base itself, at the copy's start, ``base.height`` above the
    floor, turned by the start's yaw; it has no joints.
``load_poses`` gives the roots' poses at build time, ``place`` puts one tile's copies at their
starts at an episode's reset, ``base_poses`` reads every copy's base pose in its local frame.
What it doesn't: draw the start (the task's reset noise and explicit offsets do) or drive the base.
"""

from __future__ import annotations

import math
from typing import Sequence

import sapien
import torch
from mani_skill.utils.structs.pose import Pose

from realize.robot.spec import RobotSpec

__all__ = ["load_poses", "place", "base_poses"]


def _yaw_quat(yaw: float) -> list[float]:
    """wxyz quaternion of a turn by ``yaw`` about z."""
    return [math.cos(yaw / 2), 0.0, 0.0, math.sin(yaw / 2)]


def load_poses(spec: RobotSpec, start: Sequence[float], offsets: Sequence[Sequence[float]]) -> list[sapien.Pose]:
    """The root pose of each tile's robot at build time (``start``: the task's x, y, yaw)."""
    sx, sy, syaw = start
    z, q = (spec.base.height, _yaw_quat(syaw)) if spec.base.fixed else (0.0, [1.0, 0.0, 0.0, 0.0])
    return [sapien.Pose(p=[sx + ox, sy + oy, z], q=q) for ox, oy in offsets]


def place(agent, spec: RobotSpec, qpos: torch.Tensor, names: list[str], start_xy: torch.Tensor,
          robot_start: Sequence[float], off: torch.Tensor, turn: torch.Tensor | None = None) -> None:
    """Put ``agent``'s copies (one tile, ``b`` rows) at their starts ``start_xy`` (b, 2): a fixed
    base's root there, turned by the start's yaw plus ``turn`` (b,) rad where given, or a mobile
    base's planar joints in ``qpos`` (b, J; written in place) with the root at the task's start.
    ``off``: the tile's offset (2,)."""
    b = start_xy.shape[0]
    if spec.base.fixed:
        root = torch.cat([start_xy + off, torch.full((b, 1), spec.base.height)], dim=1)
        quat = torch.tensor([_yaw_quat(robot_start[2])]).repeat(b, 1) if turn is None else \
            torch.tensor([_yaw_quat(robot_start[2] + float(t)) for t in turn])
    else:
        ix, iy, iyaw = (names.index(j) for j in spec.base.joints)
        rel = start_xy - torch.tensor(robot_start[:2])
        qpos[:, ix], qpos[:, iy] = rel[:, 0], rel[:, 1]
        qpos[:, iyaw] = robot_start[2]
        root = torch.cat([torch.tensor(robot_start[:2]) + off, torch.zeros(1)]).repeat(b, 1)
        quat = torch.tensor([[1.0, 0, 0, 0]]).repeat(b, 1)
    agent.robot.set_pose(Pose.create_from_pq(root, quat))


def base_poses(agents: Sequence, spec: RobotSpec, offsets: torch.Tensor, robot_start: Sequence[float]) -> torch.Tensor:
    """(N, 3) every copy's base x, y (its local frame) and yaw, in copy order (the agents' rows
    one after the other); ``offsets`` (tiles, 2) on the agents' device."""
    if spec.base.fixed:
        rows = []
        for c, a in enumerate(agents):
            pose = a.robot.pose
            w, z = pose.q[:, 0], pose.q[:, 3]  # a root turned about z only
            rows.append(torch.cat([pose.p[:, :2] - offsets[c], (2 * torch.atan2(z, w))[:, None]], dim=1))
        return torch.cat(rows)
    start = torch.tensor(robot_start[:2], dtype=torch.float32, device=offsets.device)
    names = list(agents[0].robot.active_joints_map.keys())
    idx = [names.index(j) for j in spec.base.joints]
    q = torch.cat([a.robot.get_qpos()[:, idx] for a in agents])
    return torch.cat([q[:, :2] + start, q[:, 2:]], dim=1)
