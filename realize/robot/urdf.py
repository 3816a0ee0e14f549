"""A robot's URDF: where it is, a derived copy where meshes must be swapped, its joints.

What it does: :func:`resolve_urdf` turns a spec's ``urdf`` (``mani_skill:<path>`` inside ManiSkill's
bundled assets, or a path relative to the repository) into a file to load; where the spec maps
visual-mesh extensions (``visual_mesh_ext``, e.g. ``.dae`` -> ``.glb`` for a URDF that names files
ManiSkill does not ship), it writes a derived URDF into a cache folder, every mesh path made
absolute (pointing at the bundled files) and the visual ones swapped; nothing is copied into
the repository. :func:`read_urdf` parses a URDF file; :func:`parse_urdf_joints` reads every
joint into a :class:`JointSpec` (origin, axis, limits), keyed by child link; :func:`rpy_matrix`,
:func:`skew` and :func:`axis_rotation` turn URDF origins and axes into float64 rotation
matrices. All of it runs once, when a model is built.

Mesh files: :func:`mesh_file` is the one place a ``<mesh filename>`` becomes a file, for every
reader (grasp geometry, sphere fitting, the recording, the derived URDF), found where SAPIEN's
URDF loader (which ManiSkill uses) finds it: a ``package://`` name with the prefix dropped, in
the URDF's folder or else in the nearest folder above it that has it (SAPIEN's ``package_dir``
argument is never passed here); any other name relative to the URDF's folder, or absolute.
:func:`urdf_for_pytorch_kinematics` gives a URDF's text as pytorch_kinematics' parser takes it.

Errors: a URDF that is not readable XML, a joint without its parent or child link, and a mesh
found nowhere are each one ``realize.config.ConfigError`` line naming the URDF file and what is
missing (for a mesh: the filename as written and the places tried).

What it doesn't: build the kinematic tree or compute anything batched (``realize.robot.chain``
and ``realize.robot.kinematics`` do), read inertials, read the meshes themselves
(``realize.robot.link_geometry`` does), or load anything into the simulator.
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

__all__ = ["fixed_base_joints", "JointSpec", "resolve_urdf", "source_urdf", "read_urdf", "parse_urdf_joints",
           "urdf_floats", "element_origin", "mesh_candidates", "mesh_file", "urdf_for_pytorch_kinematics",
           "rpy_matrix", "skew", "axis_rotation"]

MANI_SKILL_PREFIX = "mani_skill:"
PACKAGE_PREFIX = "package://"


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
    root = read_urdf(src)
    for kind in ("visual", "collision"):
        for el in root.iter(kind):
            for m in el.iter("mesh"):
                name = m.get("filename", "")
                suffix = Path(name).suffix
                if kind == "visual" and suffix in visual_mesh_ext:
                    name = name[:-len(suffix)] + visual_mesh_ext[suffix]
                try:
                    m.set("filename", str(mesh_file(name, src)))
                except ConfigError as e:
                    raise ConfigError(f"robot.urdf = {urdf!r} with visual_mesh_ext = {visual_mesh_ext}: {e}") from None
    text = ET.tostring(root, encoding="unicode")
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


def read_urdf(path: str | os.PathLike[str]) -> ET.Element:
    """The root ``<robot>`` element of a URDF file; a file that cannot be read, is not XML or is
    not a URDF is one ``ConfigError`` line naming it."""
    try:
        root = ET.parse(path).getroot()
    except ET.ParseError as e:
        raise ConfigError(f"URDF {os.fspath(path)}: not readable XML ({e})") from None
    except OSError as e:
        raise ConfigError(f"URDF {os.fspath(path)}: cannot be read ({e.strerror or e})") from None
    if root.tag != "robot":
        raise ConfigError(f"URDF {os.fspath(path)}: its root element is <{root.tag}>, not <robot>")
    return root


def mesh_candidates(filename: str, urdf: str | os.PathLike[str]) -> list[Path]:
    """Where a ``<mesh filename>`` of the URDF file ``urdf`` may be, in the order SAPIEN's URDF
    loader looks (module docstring): for ``package://<name>``, ``<name>`` in the URDF's folder,
    then in each folder above it up to the file system's root; for any other name, that name in
    the URDF's folder (an absolute name: itself)."""
    folder = Path(os.fspath(urdf)).parent.absolute()
    if not filename.startswith(PACKAGE_PREFIX):
        return [folder / filename]
    name = filename[len(PACKAGE_PREFIX):]
    return list(dict.fromkeys(d / name for d in (folder, *folder.parents)))


def mesh_file(filename: str, urdf: str | os.PathLike[str]) -> Path:
    """The file a ``<mesh filename>`` of the URDF file ``urdf`` names: the first of
    :func:`mesh_candidates` that exists. None existing is one ``ConfigError`` line naming the
    URDF, the filename as written and the places tried."""
    where = f"URDF {os.fspath(urdf)}"
    if not filename.strip():
        raise ConfigError(f"{where}: a <mesh> without a filename")
    tried = mesh_candidates(filename, urdf)
    for path in tried:
        if path.is_file():
            return path
    if len(tried) > 1:
        folder = Path(os.fspath(urdf)).parent.absolute()
        places = f"{filename[len(PACKAGE_PREFIX):]} in {folder} and in each of the {len(tried) - 1} folders above it"
    else:
        places = str(tried[0])
    raise ConfigError(f"{where}: mesh file {filename!r} not found (tried {places})")


def urdf_for_pytorch_kinematics(path: str | os.PathLike[str]) -> bytes:
    """The URDF file's XML as pytorch_kinematics' parser takes it: it requires ``effort`` and
    ``velocity`` on every joint's ``<limit>`` (ManiSkill's Koch arm gives neither, the mobile
    Panda's base no effort); where absent they are set to 0. Neither plays any part in
    kinematics; everything else is as in the file."""
    root = read_urdf(path)
    for joint in root.findall("joint"):
        limit = joint.find("limit")
        if limit is not None:
            limit.attrib.setdefault("effort", "0")
            limit.attrib.setdefault("velocity", "0")
    return ET.tostring(root)


def parse_urdf_joints(path: str | os.PathLike[str]) -> dict[str, JointSpec]:
    """All joints of a URDF, keyed by the name of their child link; a joint without its parent
    or child link, or with a number that is not one, is one ``ConfigError`` line."""
    joints: dict[str, JointSpec] = {}
    for j in read_urdf(path).findall("joint"):
        name = j.get("name", "")
        try:
            spec = _joint_spec(j, name)
        except ValueError as e:
            raise ConfigError(f"URDF {os.fspath(path)}: joint {name!r}: {e}") from None
        joints[spec.child] = spec
    return joints


def _joint_spec(j: ET.Element, name: str) -> JointSpec:
    links = {}
    for end in ("parent", "child"):
        el = j.find(end)
        link = el.get("link") if el is not None else None
        if not link:
            raise ValueError(f"no <{end} link=...>")
        links[end] = link
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
    return JointSpec(
        name=name,
        type=jtype,
        parent=links["parent"],
        child=links["child"],
        xyz=xyz,  # type: ignore[arg-type]
        rpy=rpy,  # type: ignore[arg-type]
        axis=urdf_floats(axis.get("xyz") if axis is not None else None, (1.0, 0.0, 0.0)),  # type: ignore[arg-type]
        lower=lower,
        upper=upper,
        velocity=velocity,
    )


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
