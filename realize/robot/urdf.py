"""A robot's URDF: where it is, a derived copy where meshes must be swapped, its joints.

What it does: :func:`resolve_urdf` turns a spec's ``urdf`` (``mani_skill:<path>`` inside ManiSkill's
bundled assets, or a path relative to the repository) into a file to load; where the spec maps
visual-mesh extensions (``visual_mesh_ext``, e.g. ``.dae`` -> ``.glb`` for a URDF that names files
ManiSkill does not ship), it writes a derived URDF into a cache folder, every mesh path made
absolute (pointing at the bundled files) and the visual ones swapped; nothing is copied into
the repository. :func:`parse_urdf_joints` reads every joint into a :class:`JointSpec` (origin,
axis, limits), keyed by child link; :func:`rpy_matrix`, :func:`skew` and :func:`axis_rotation`
turn URDF origins and axes into float64 rotation matrices. All of it runs once, when a model
is built.

What it doesn't: build the kinematic tree or compute anything batched (``realize.robot.chain``
and ``realize.robot.kinematics`` do), read inertials, or load anything into the simulator.
"""

from __future__ import annotations

import hashlib
import math
import os
import xml.etree.ElementTree as ET
from pathlib import Path
from dataclasses import dataclass
from typing import Sequence

import torch
from torch import Tensor

from realize.config import ConfigError
from realize.paths import REPO_ROOT, cache_dir

__all__ = ["fixed_base_joints", "JointSpec", "resolve_urdf", "source_urdf", "parse_urdf_joints", "urdf_floats", "element_origin", "mesh_path",
           "rpy_matrix", "skew", "axis_rotation"]

MANI_SKILL_PREFIX = "mani_skill:"


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


def source_urdf(urdf: str) -> Path:
    """The file a spec's ``urdf`` names: ``mani_skill:<path>`` inside ManiSkill's assets, else a
    path (relative: to the repository). A missing file is a one-line ``ConfigError``."""
    if urdf.startswith(MANI_SKILL_PREFIX):
        import mani_skill  # local import: only needed to locate the asset

        path = Path(mani_skill.PACKAGE_ASSET_DIR) / urdf[len(MANI_SKILL_PREFIX):]
    else:
        path = Path(urdf) if Path(urdf).is_absolute() else REPO_ROOT / urdf
    if not path.is_file():
        raise ConfigError(f"robot.urdf = {urdf!r}: no such file ({path})")
    return path


def resolve_urdf(urdf: str, visual_mesh_ext: dict[str, str] | None = None) -> str:
    """The URDF file to load for a spec's ``urdf`` and ``visual_mesh_ext`` (see the module
    docstring): the source file itself, or a derived copy in the cache folder."""
    src = source_urdf(urdf)
    if not visual_mesh_ext:
        return str(src)
    tree = ET.parse(src)
    missing: list[str] = []
    for kind in ("visual", "collision"):
        for mesh in tree.getroot().iter():
            if mesh.tag != kind:
                continue
            for m in mesh.iter("mesh"):
                path = mesh_path(m.get("filename", ""), src.parent)
                if kind == "visual" and path.suffix in visual_mesh_ext:
                    path = path.with_suffix(visual_mesh_ext[path.suffix])
                if not path.is_file():
                    missing.append(str(path))
                m.set("filename", str(path))
    if missing:
        raise ConfigError(f"robot.urdf = {urdf!r}: mesh files missing after visual_mesh_ext = "
                          f"{visual_mesh_ext}: {missing[:3]}{' ...' if len(missing) > 3 else ''}")
    text = ET.tostring(tree.getroot(), encoding="unicode")
    key = hashlib.sha256((str(src) + text).encode()).hexdigest()[:12]
    out = cache_dir("urdf") / f"{src.stem}-{key}.urdf"
    if not out.is_file() or out.read_text() != text:
        tmp = out.with_suffix(f".tmp{os.getpid()}")
        tmp.write_text(text)
        os.replace(tmp, out)  # atomic: a concurrent worker never reads half a file
    return str(out)


def urdf_floats(text: str | None, default: tuple[float, ...]) -> tuple[float, ...]:
    """The numbers of a URDF attribute (``xyz``, ``rpy``, ``size``, ``scale``): ``default`` where it is
    absent or empty; one number where three are expected stands for all three (a uniform scale)."""
    if not text or not text.strip():
        return default
    v = tuple(float(x) for x in text.split())
    return v * 3 if len(v) == 1 and len(default) == 3 else v


def element_origin(el: ET.Element) -> tuple[tuple[float, ...], tuple[float, ...]]:
    """``(xyz, rpy)`` of an element's ``<origin>`` child (zeros where it has none)."""
    origin = el.find("origin")
    get = (lambda k: None) if origin is None else origin.get
    return urdf_floats(get("xyz"), (0.0, 0.0, 0.0)), urdf_floats(get("rpy"), (0.0, 0.0, 0.0))


def mesh_path(filename: str, urdf_dir: str | os.PathLike[str]) -> Path:
    """The file a URDF ``<mesh filename>`` names (``package://`` dropped; relative to the URDF's folder)."""
    name = filename[len("package://"):] if filename.startswith("package://") else filename
    return Path(name) if Path(name).is_absolute() else Path(urdf_dir) / name


def parse_urdf_joints(path: str) -> dict[str, JointSpec]:
    """All joints of a URDF, keyed by the name of their child link."""
    root = ET.parse(path).getroot()
    joints: dict[str, JointSpec] = {}
    for j in root.findall("joint"):
        xyz, rpy = element_origin(j)
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
            xyz=xyz,  # type: ignore[arg-type]
            rpy=rpy,  # type: ignore[arg-type]
            axis=urdf_floats(axis.get("xyz") if axis is not None else None, (1.0, 0.0, 0.0)),  # type: ignore[arg-type]
            lower=lower,
            upper=upper,
            velocity=velocity,
        )
        joints[spec.child] = spec
    return joints


def fixed_base_joints(joints: dict[str, JointSpec], names: Sequence[str], height: float) -> dict[str, JointSpec]:
    """A fixed-base robot's kinematic model: ``joints`` (a URDF's, keyed by child link) with a
    planar base ahead of its root link: ``names`` (x and y prismatic, yaw continuous; no limits)
    from a ``world`` frame, the root ``height`` above it. These joints place the robot where the
    scene bolted it; they are the base columns of ``q`` and are not in the simulated robot."""
    children = {j.child for j in joints.values()}
    roots = sorted({j.parent for j in joints.values()} - children)
    if len(roots) != 1:
        raise ValueError(f"a URDF with one root link is needed for a fixed base, found roots {roots}")
    x, y, yaw = names
    links = (f"{x}_link", f"{y}_link", roots[0])
    inf = math.inf
    virtual = [
        JointSpec(x, "prismatic", "world", links[0], (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), (1.0, 0.0, 0.0), -inf, inf, inf),
        JointSpec(y, "prismatic", links[0], links[1], (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), (0.0, 1.0, 0.0), -inf, inf, inf),
        JointSpec(yaw, "continuous", links[1], links[2], (0.0, 0.0, float(height)), (0.0, 0.0, 0.0), (0.0, 0.0, 1.0),
                  -inf, inf, inf),
    ]
    return {**{j.child: j for j in virtual}, **joints}


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
