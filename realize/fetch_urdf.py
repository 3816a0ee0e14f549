"""Reading Fetch's URDF: joint specs, and the small rotation helpers used to fold them.

What it does: :func:`fetch_urdf_path` finds ManiSkill's ``fetch.urdf``; :func:`parse_urdf_joints`
reads every joint of a URDF into a :class:`JointSpec` (origin, axis, limits), keyed by child
link; :func:`rpy_matrix`, :func:`skew` and :func:`axis_rotation` turn URDF origins and axes into
float64 rotation matrices. All of it runs once, when a kinematic model is built.

What it doesn't: build the kinematic tree or compute anything batched (``realize.kinematic_chain``
and ``realize.kinematics`` do), read links, meshes or inertials.
"""

from __future__ import annotations

import math
import os
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from typing import Sequence

import torch
from torch import Tensor

__all__ = ["JointSpec", "fetch_urdf_path", "parse_urdf_joints", "rpy_matrix", "skew", "axis_rotation"]


@dataclass(frozen=True)
class JointSpec:
    """One URDF joint, as read from the file."""

    name: str
    type: str  # "fixed" | "revolute" | "continuous" | "prismatic"
    parent: str
    child: str
    xyz: tuple[float, float, float]
    rpy: tuple[float, float, float]
    axis: tuple[float, float, float]
    lower: float
    upper: float
    velocity: float


def fetch_urdf_path() -> str:
    """Path of ManiSkill's Fetch URDF inside the installed ``mani_skill`` package."""
    import mani_skill  # local import: only needed to locate the asset

    return os.path.join(mani_skill.PACKAGE_ASSET_DIR, "robots", "fetch", "fetch.urdf")


def _floats(text: str | None, default: tuple[float, ...]) -> tuple[float, ...]:
    if text is None:
        return default
    return tuple(float(v) for v in text.split())


def parse_urdf_joints(path: str) -> dict[str, JointSpec]:
    """All joints of a URDF, keyed by the name of their child link."""
    root = ET.parse(path).getroot()
    joints: dict[str, JointSpec] = {}
    for j in root.findall("joint"):
        origin = j.find("origin")
        axis = j.find("axis")
        limit = j.find("limit")
        jtype = j.get("type", "fixed")
        lower, upper = -math.inf, math.inf
        velocity = math.inf
        if limit is not None:
            velocity = float(limit.get("velocity", "inf"))
            if jtype in ("revolute", "prismatic"):
                lower = float(limit.get("lower", "-inf"))
                upper = float(limit.get("upper", "inf"))
        spec = JointSpec(
            name=j.get("name", ""),
            type=jtype,
            parent=j.find("parent").get("link"),  # type: ignore[union-attr]
            child=j.find("child").get("link"),  # type: ignore[union-attr]
            xyz=_floats(origin.get("xyz") if origin is not None else None, (0.0, 0.0, 0.0)),  # type: ignore[arg-type]
            rpy=_floats(origin.get("rpy") if origin is not None else None, (0.0, 0.0, 0.0)),  # type: ignore[arg-type]
            axis=_floats(axis.get("xyz") if axis is not None else None, (1.0, 0.0, 0.0)),  # type: ignore[arg-type]
            lower=lower,
            upper=upper,
            velocity=velocity,
        )
        joints[spec.child] = spec
    return joints


def rpy_matrix(rpy: Sequence[float]) -> Tensor:
    """URDF fixed-axis roll-pitch-yaw: R = Rz(yaw) Ry(pitch) Rx(roll), float64."""
    r, p, y = (float(v) for v in rpy)
    cr, sr, cp, sp, cy, sy = math.cos(r), math.sin(r), math.cos(p), math.sin(p), math.cos(y), math.sin(y)
    return torch.tensor(
        [
            [cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
            [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
            [-sp, cp * sr, cp * cr],
        ],
        dtype=torch.float64,
    )


def skew(a: Tensor) -> Tensor:
    """The cross-product matrix ``[a]x`` of a 3-vector (``[a]x b = a x b``)."""
    z = torch.zeros((), dtype=a.dtype)
    return torch.stack(
        [torch.stack([z, -a[2], a[1]]), torch.stack([a[2], z, -a[0]]), torch.stack([-a[1], a[0], z])]
    )


def axis_rotation(axis: Tensor, angle: float) -> Tensor:
    """Rotation by ``angle`` about the unit ``axis`` (Rodrigues), float64."""
    k = skew(axis)
    return torch.eye(3, dtype=torch.float64) + math.sin(angle) * k + (1.0 - math.cos(angle)) * (k @ k)
