"""A gripper's grasp geometry from its finger links' kinematics and collision shapes.

What it does
------------
``grip_geometry(spec)`` puts the gripper's joints (the driven one and its mimics, at one value)
at ``K`` values from the closed limit to the open target, places the two finger links' collision
surfaces (``realize.robot.link_geometry``) in the TCP frame by the URDF's kinematics, and
measures, on a tube around the closing axis through the TCP (the fingertips' working line):

* the **width** between the pads (m): the inner surface of the finger on the closing axis's
  + side minus that of the finger on its - side;
* the **pad centre** on the closing axis (m from the TCP): where an object of that width sits;
* the joint's **type and unit** (prismatic: m, revolute: rad), from the URDF;
* how far the fingers **reach** beyond the TCP along the approach (at any opening), and their
  half width across the closing axis there: ``gripper.fingertip_reach`` (the grasp's back-off
  from a table) may not fall short of that reach.

``GripGeometry.joint_for_width(w)`` inverts the table (batched, piecewise linear), so a grasp can
pre-shape the fingers to a gap for any gripper: two prismatic fingers (width ``n * v``) or one
revolute jaw (width a sine of the angle, one-sided: its pad centre moves with the width).

``check_gripper(spec)`` refuses, in one ``ConfigError`` line naming the key, a gripper the agent
cannot build or the geometry cannot serve: a gripper joint that is fixed or continuous, mimic
joints of another type than the driven one, an ``open`` target outside the joint's limits, finger
links the gripper joints do not move, fingers that do not open wider than they close, a TCP
outside the open pads, a ``fingertip_reach`` short of the fingers' measured reach. It reads the URDF and the finger meshes only (no simulator).

What it doesn't: simulate contacts (``envs.robot_agent`` builds the fingers' material) or decide
when a grasp holds (``realize.scene``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache

import numpy as np
import torch
from torch import Tensor

from realize.config import ConfigError
from realize.robot.link_geometry import joint_transform, link_geometry
from realize.robot.spec import RobotSpec
from realize.robot.urdf import JointSpec, parse_urdf_joints, source_urdf

__all__ = ["GripGeometry", "grip_geometry", "check_gripper", "UNITS"]

UNITS = {"prismatic": "m", "revolute": "rad"}
TUBE = 0.006  # m: half width of the tube around the closing axis on which the pads are measured
SAMPLES = 4000  # surface points per finger link
K = 41  # joint values in the table
REACH_TOL = 0.001  # m: gripper.fingertip_reach may fall this far short of the measured reach (sampling)


@dataclass(frozen=True)
class GripGeometry:
    """The gripper's measured geometry (module docstring); the table runs from the joint's closed
    limit (``values[0]``) to the open target (``values[-1]``)."""

    joint_type: str  # "prismatic" | "revolute"
    unit: str  # "m" | "rad": the unit of gripper.open / closed
    values: tuple[float, ...]  # joint values (unit), increasing
    widths: tuple[float, ...]  # m between the pads at each value
    centres: tuple[float, ...]  # m: the pads' midpoint on the closing axis, from the TCP
    n_joints: int
    reach: float = 0.0  # m the fingers' collision shapes reach beyond the TCP along the approach (any opening)
    tip_half_width: float = 0.0  # m: half their width across the closing axis within 1 cm of that reach

    @property
    def width_open(self) -> float:
        """m between the pads at the open target."""
        return self.widths[-1]

    @property
    def width_closed(self) -> float:
        """m between the pads at the closed limit (0 or a little more: the pads touch)."""
        return self.widths[0]

    @property
    def one_sided(self) -> bool:
        """One driven joint and no mimic: the pad centre moves with the width."""
        return self.n_joints == 1

    def joint_for_width(self, width: Tensor) -> Tensor:
        """(...,) joint targets that leave ``width`` (...,) m between the pads, clamped to the table
        (never past the open target). A prismatic parallel gripper's is exactly ``width / n``
        (each finger moves its share of the gap; the table matches that law within 1 mm, tested)."""
        if self.joint_type == "prismatic":
            return (width / self.n_joints).clamp(min=0.0, max=self.values[-1])
        return _interp(width, self.widths, self.values)

    def centre_for_width(self, width: Tensor) -> Tensor:
        """(...,) m from the TCP along the closing axis to the pads' midpoint when they are
        ``width`` (...,) apart: where an object of that width ends up held (a one-sided jaw's
        moves with the width; a parallel gripper's stays on the TCP)."""
        return _interp(width, self.widths, self.centres)


def _interp(x: Tensor, xs: tuple[float, ...], ys: tuple[float, ...]) -> Tensor:
    """Piecewise-linear ``ys(xs)`` at ``x`` (batched), clamped to the table's ends."""
    order = sorted(range(len(xs)), key=lambda i: xs[i])
    xt = torch.tensor([xs[i] for i in order], dtype=x.dtype, device=x.device)
    yt = torch.tensor([ys[i] for i in order], dtype=x.dtype, device=x.device)
    xc = x.clamp(min=float(xt[0]), max=float(xt[-1])).contiguous()
    i = torch.searchsorted(xt, xc, right=True).clamp(1, len(xt) - 1)
    t = (xc - xt[i - 1]) / (xt[i] - xt[i - 1]).clamp(min=1e-12)
    return yt[i - 1] + t * (yt[i] - yt[i - 1])


def _pose_in(joints: dict[str, JointSpec], link: str, frame: str, values: dict[str, float]) -> np.ndarray:
    """4x4 pose of ``link`` in ``frame``'s frame (every joint at ``values``, absent 0)."""
    def chain(l: str) -> list[JointSpec]:
        out = []
        while l in joints:
            out.append(joints[l])
            l = joints[l].parent
        return out[::-1]

    def pose(l: str) -> np.ndarray:
        t = np.eye(4)
        for j in chain(l):
            t = t @ joint_transform(j, values.get(j.name, 0.0))
        return t

    return np.linalg.inv(pose(frame)) @ pose(link)


def _moved_by(joints: dict[str, JointSpec], link: str, names: set[str]) -> bool:
    while link in joints:
        if joints[link].name in names:
            return True
        link = joints[link].parent
    return False


@lru_cache(maxsize=16)
def _measure(urdf: str, joint_names: tuple[str, ...], fingers: tuple[str, str], tcp_link: str,
             offset: tuple[float, ...], approach: tuple[float, ...], closing: tuple[float, ...],
             values: tuple[float, ...]) -> tuple[tuple[float, ...], tuple[float, ...], float, float]:
    path = str(source_urdf(urdf))
    by_child = {j.child: j for j in parse_urdf_joints(path).values()}
    a, c = np.asarray(approach), np.asarray(closing)
    b = np.cross(a, c)
    axes = np.stack([a, b, c])  # rows: TCP-frame coordinates (along approach, across, along closing)
    pts = {f: link_geometry(path, f).sample_surface(SAMPLES, seed=0) for f in fingers}
    widths, centres, tips = [], [], []
    for v in values:
        vals = {n: v for n in joint_names}
        tubes = []
        for f in fingers:
            t = _pose_in(by_child, f, tcp_link, vals)
            p = (pts[f] @ t[:3, :3].T + t[:3, 3] - np.asarray(offset)) @ axes.T  # (n, 3) in (a, b, c)
            tips.append(p)
            tube = p[(np.abs(p[:, 0]) <= TUBE) & (np.abs(p[:, 1]) <= TUBE)]
            if len(tube) == 0:  # the finger does not cross the closing line: its nearest points to it
                d = np.hypot(p[:, 0], p[:, 1])
                tube = p[d <= d.min() + TUBE]
            tubes.append(tube[:, 2])
        # the finger farther along the closing axis is the + side one
        hi, lo = (tubes[0], tubes[1]) if tubes[0].mean() > tubes[1].mean() else (tubes[1], tubes[0])
        inner_hi, inner_lo = float(hi.min()), float(lo.max())
        widths.append(inner_hi - inner_lo)
        centres.append(0.5 * (inner_hi + inner_lo))
    every = np.concatenate(tips)
    reach = float(every[:, 0].max())
    tip_half = float(np.abs(every[every[:, 0] >= reach - 0.01, 1]).max())
    return tuple(widths), tuple(centres), reach, tip_half


def grip_geometry(spec: RobotSpec, where: str = "robot") -> GripGeometry:
    """The gripper's geometry (module docstring); refuses what ``check_gripper`` refuses, naming
    ``<where>.gripper.<key>``."""
    g = spec.gripper
    urdf_name = source_urdf(spec.urdf).name
    joints = {j.name: j for j in parse_urdf_joints(source_urdf(spec.urdf)).values()}
    by_child = {j.child: j for j in joints.values()}
    top, where = where, f"{where}.gripper"
    for n in g.joints:
        if n not in joints:
            raise ConfigError(f"{where}.joints: {n!r} is not a joint of {urdf_name}")
    first = joints[g.joints[0]]
    for n in g.joints:
        j = joints[n]
        if j.type not in UNITS:
            raise ConfigError(f"{where}.joints: {n!r} is a {j.type} joint; a finger joint must be prismatic (m) "
                              "or revolute (rad)")
        if j.type != first.type:
            raise ConfigError(f"{where}.joints: {n!r} is {j.type} but {first.name!r}, which it mimics, is "
                              f"{first.type}; the mimicking joints must be of the driven joint's type")
    unit = UNITS[first.type]
    lo, hi = first.lower, first.upper
    tol = 1e-6
    if not (lo - tol <= g.open <= hi + tol):
        raise ConfigError(f"{where}.open = {g.open} {unit} is invalid: outside {first.name}'s range "
                          f"[{lo:g}, {hi:g}] {unit} (a {first.type} joint: open and closed are in {unit})")
    for f in g.finger_links:
        if f not in by_child and f != spec.tcp.link:
            raise ConfigError(f"{where}.finger_links: {f!r} is not a link of {urdf_name}")
    if not any(_moved_by(by_child, f, set(g.joints)) for f in g.finger_links):
        raise ConfigError(f"{where}.finger_links = {list(g.finger_links)}: neither is moved by {where}.joints "
                          f"{list(g.joints)}, so the gripper cannot open or close them")
    # the closed end of the table: the joint's limit toward `closed` (closed may lie past it: a squeeze)
    start = max(g.closed, lo) if math.isfinite(lo) else g.closed
    values = tuple(float(x) for x in np.linspace(start, g.open, K))
    try:
        widths, centres, reach, tip_half = _measure(spec.urdf, tuple(g.joints), tuple(g.finger_links), spec.tcp.link,
                                   tuple(spec.tcp.offset), tuple(spec.tcp.approach_axis),
                                   tuple(spec.tcp.closing_axis), values)
    except ValueError as e:  # a finger link without collision geometry, or a mesh not found or not readable
        raise ConfigError(f"{where}.finger_links = {list(g.finger_links)}: {e}") from None
    geo = GripGeometry(first.type, unit, values, widths, centres, len(g.joints), reach, tip_half)
    if g.fingertip_reach < reach - REACH_TOL:
        raise ConfigError(f"{where}.fingertip_reach = {g.fingertip_reach} m is invalid: the fingers' collision shapes "
                          f"reach {reach:.4f} m beyond the TCP along tcp.approach_axis (a grasp backed off by less "
                          "puts them into the table)")
    if geo.width_open <= geo.width_closed + 1e-3:
        raise ConfigError(f"{where}.open = {g.open} {unit} is invalid: the fingers are {geo.width_open * 1e3:.1f} mm "
                          f"apart there and {geo.width_closed * 1e3:.1f} mm at {start:g} {unit}: open must open them")
    if abs(geo.centres[-1]) > 0.5 * geo.width_open:
        raise ConfigError(f"{top}.tcp.offset = {list(spec.tcp.offset)}: the TCP is {abs(geo.centres[-1]) * 1e3:.1f} mm "
                          f"from the open pads' midpoint along the closing axis, outside the "
                          f"{geo.width_open * 1e3:.1f} mm between them")
    return geo


def check_gripper(spec: RobotSpec, where: str = "robot") -> None:
    """Refuse a gripper the agent cannot build or grasp with, in one line naming the key."""
    grip_geometry(spec, where)
