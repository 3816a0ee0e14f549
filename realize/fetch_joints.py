"""Fetch's whole-body joint layout: joint names, their order, and qpos conversions.

What it does
------------
* :data:`WHOLE_BODY_JOINT_NAMES`: the 11 degrees of freedom of ``q`` =
  ``[x, y, yaw, torso, shoulder_pan, shoulder_lift, upperarm_roll, elbow_flex, forearm_roll,
  wrist_flex, wrist_roll]``, in that order (index ``i`` of ``q`` is joint ``i`` here).
* :data:`FULL_JOINT_NAMES`: ManiSkill's 15 active joints of Fetch, in the simulator's order;
  :data:`HELD_JOINT_NAMES`: the four of them (head, fingers) that are not in ``q``.
* The maps between a ``(..., 15)`` simulator qpos and a ``(..., 11)`` whole-body ``q``
  (:func:`whole_body_qpos_from_full`, :func:`full_qpos_from_whole_body`), out-of-place and
  differentiable, on any device.

What it doesn't: read the URDF, compute kinematics (``realize.kinematics``), or name slices of
the state for controllers.
"""

from __future__ import annotations

from typing import Sequence

import torch
from torch import Tensor

__all__ = [
    "WHOLE_BODY_JOINT_NAMES",
    "FULL_JOINT_NAMES",
    "HELD_JOINT_NAMES",
    "whole_body_indices",
    "whole_body_qpos_from_full",
    "full_qpos_from_whole_body",
]

WHOLE_BODY_JOINT_NAMES: tuple[str, ...] = (
    "root_x_axis_joint",
    "root_y_axis_joint",
    "root_z_rotation_joint",
    "torso_lift_joint",
    "shoulder_pan_joint",
    "shoulder_lift_joint",
    "upperarm_roll_joint",
    "elbow_flex_joint",
    "forearm_roll_joint",
    "wrist_flex_joint",
    "wrist_roll_joint",
)
"""The 11 degrees of freedom, in the order of ``q``."""

FULL_JOINT_NAMES: tuple[str, ...] = (
    "root_x_axis_joint",
    "root_y_axis_joint",
    "root_z_rotation_joint",
    "torso_lift_joint",
    "head_pan_joint",
    "shoulder_pan_joint",
    "head_tilt_joint",
    "shoulder_lift_joint",
    "upperarm_roll_joint",
    "elbow_flex_joint",
    "forearm_roll_joint",
    "wrist_flex_joint",
    "wrist_roll_joint",
    "r_gripper_finger_joint",
    "l_gripper_finger_joint",
)
"""ManiSkill 3.0.1's ``robot.get_active_joints()`` order for Fetch (breadth-first over the
URDF tree; checked against a live env in ``tests/test_kinematics.py``)."""

HELD_JOINT_NAMES: tuple[str, ...] = (
    "head_pan_joint",
    "head_tilt_joint",
    "r_gripper_finger_joint",
    "l_gripper_finger_joint",
)
"""The active joints that are not degrees of freedom of ``q``: held at fixed values."""


def whole_body_indices(full_joint_names: Sequence[str] = FULL_JOINT_NAMES) -> list[int]:
    """Positions of the 11 whole-body joints inside a full active-joint vector."""
    names = list(full_joint_names)
    return [names.index(n) for n in WHOLE_BODY_JOINT_NAMES]


def whole_body_qpos_from_full(qpos_full: Tensor, full_joint_names: Sequence[str] = FULL_JOINT_NAMES) -> Tensor:
    """``(..., 15)`` ManiSkill qpos -> ``(..., 11)`` whole-body q (a differentiable gather)."""
    idx = torch.tensor(whole_body_indices(full_joint_names), device=qpos_full.device)
    return torch.index_select(qpos_full, -1, idx)


def full_qpos_from_whole_body(
    q: Tensor,
    rest: Tensor | None = None,
    full_joint_names: Sequence[str] = FULL_JOINT_NAMES,
    head_pan: float = 0.0,
    head_tilt: float = 0.0,
    finger: float = 0.05,
) -> Tensor:
    """``(..., 11)`` whole-body q -> ``(..., 15)`` full qpos in ``full_joint_names`` order.

    The joints that are not in ``q`` (head, fingers) are taken from ``rest`` (a full qpos
    broadcastable to ``(..., 15)``, e.g. the current simulator state) when given, else from
    ``head_pan``, ``head_tilt`` and ``finger``. Out-of-place: differentiable w.r.t. ``q``.
    """
    names = list(full_joint_names)
    wb = whole_body_indices(names)
    others = [i for i in range(len(names)) if i not in wb]
    if rest is None:
        defaults = {"head_pan_joint": head_pan, "head_tilt_joint": head_tilt}
        vals = torch.tensor([defaults.get(names[i], finger) for i in others], dtype=q.dtype, device=q.device)
        extra = vals.expand(*q.shape[:-1], len(others))
    else:
        extra = torch.index_select(rest.to(q.dtype), -1, torch.tensor(others, device=q.device))
        extra = extra.expand(*q.shape[:-1], len(others))
    stacked = torch.cat([q, extra], dim=-1)  # [wb joints..., other joints...]
    order = wb + others  # full index of each stacked column
    perm = torch.tensor([order.index(i) for i in range(len(names))], device=q.device)
    return torch.index_select(stacked, -1, perm)
