"""The robot in a rerun recording: its link meshes once, its link poses along a joint trajectory.

What it does:
  * ``robot_model(spec)``: the kinematics model of a ``realize.robot.spec.RobotSpec`` (the one
    place the recording builds it);
  * ``link_meshes(urdf)``: per URDF link, a mesh rerun can show (``Asset3D``: STL, OBJ, glTF/GLB)
    with its origin and scale: the smallest of its visual and collision meshes in such a format
    (Fetch's visuals are COLLADA ``.dae``, its collision meshes STL), up to ``MAX_MESH_BYTES``;
    files found as SAPIEN finds them (``realize.robot.urdf.mesh_file``), a mesh found nowhere
    left out (the robot is shown without it);
  * ``RobotLogger``: logs the meshes statically under ``<root>/<link>/mesh`` and, for a
    whole-body trajectory ``q (T, n_dof)``, the pose of every link with a mesh (``Transform3D``:
    translation and quaternion) as columns on the given time columns (``rr.send_columns``: one
    chunk per link, however long the trajectory). Links without a mesh (frames such as the
    cameras') are not logged.
What it doesn't: choose what trajectory to show or the timelines (``realize.recording.world3d``), or
record joints (``realize.realization.result.TrajectoryRecorder`` does).
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import rerun as rr

from realize.config import ConfigError
from realize.robot.urdf import element_origin, mesh_file, read_urdf, rpy_matrix, urdf_floats

if TYPE_CHECKING:
    from realize.robot.kinematics import RobotKinematics
    from realize.robot.spec import RobotSpec

__all__ = ["LinkMesh", "robot_model", "link_meshes", "matrix_to_quat_xyzw", "RobotLogger"]

_MEDIA = {".stl": rr.MediaType.STL, ".obj": rr.MediaType.OBJ, ".glb": rr.MediaType.GLB, ".gltf": rr.MediaType.GLTF}
_GREY = (200, 200, 205, 255)
MAX_MESH_BYTES = 300_000  # a larger mesh file is left out of the recording (it is logged once, but it is bytes)


def robot_model(spec: RobotSpec) -> RobotKinematics:
    """The robot's kinematics model (float32, CPU): the only place this module builds one."""
    from realize.robot.kinematics import RobotKinematics

    return RobotKinematics(spec)


@dataclass(frozen=True)
class LinkMesh:
    """A link's mesh file, its origin in the link frame (xyz, rpy) and scale."""

    link: str
    path: Path
    xyz: tuple[float, float, float]
    rpy: tuple[float, float, float]
    scale: tuple[float, float, float]


def _meshes_of(link: ET.Element, urdf: Path) -> list[LinkMesh]:
    """The link's visual and collision meshes in a format rerun reads (those found)."""
    out = []
    for el in link.findall("visual") + link.findall("collision"):
        mesh = el.find("geometry/mesh")
        if mesh is None or Path(mesh.get("filename", "")).suffix.lower() not in _MEDIA:
            continue
        try:
            path = mesh_file(mesh.get("filename", ""), urdf).resolve()
        except ConfigError:  # a mesh found nowhere: the recording shows the robot without it
            continue
        xyz, rpy = element_origin(el)
        out.append(LinkMesh(link.get("name", ""), path, xyz, rpy, urdf_floats(mesh.get("scale"), (1.0, 1.0, 1.0))))
    return out


def link_meshes(urdf: str | Path, max_bytes: int = MAX_MESH_BYTES) -> dict[str, LinkMesh]:
    """Link name -> the mesh rerun shows for it: the smallest of its visual and collision meshes
    in a format rerun reads, if at most ``max_bytes`` (Fetch's 0.4 MB e-stop and laser meshes
    are left out); links without one are absent."""
    path = Path(urdf)
    root = read_urdf(path)
    out = {}
    for link in root.findall("link"):
        found = sorted(_meshes_of(link, path), key=lambda m: m.path.stat().st_size)
        if found and found[0].path.stat().st_size <= max_bytes:
            out[found[0].link] = found[0]
    return out


def matrix_to_quat_xyzw(r: np.ndarray) -> np.ndarray:
    """Rotation matrices ``(..., 3, 3)`` -> unit quaternions ``(..., 4)`` (x, y, z, w), w >= 0."""
    r = np.asarray(r, dtype=np.float64)
    m00, m11, m22 = r[..., 0, 0], r[..., 1, 1], r[..., 2, 2]
    q = np.stack([
        np.sqrt(np.maximum(0.0, 1.0 + m00 - m11 - m22)) / 2,
        np.sqrt(np.maximum(0.0, 1.0 - m00 + m11 - m22)) / 2,
        np.sqrt(np.maximum(0.0, 1.0 - m00 - m11 + m22)) / 2,
        np.sqrt(np.maximum(0.0, 1.0 + m00 + m11 + m22)) / 2,
    ], axis=-1)
    q[..., 0] = np.copysign(q[..., 0], r[..., 2, 1] - r[..., 1, 2])
    q[..., 1] = np.copysign(q[..., 1], r[..., 0, 2] - r[..., 2, 0])
    q[..., 2] = np.copysign(q[..., 2], r[..., 1, 0] - r[..., 0, 1])
    return q / np.linalg.norm(q, axis=-1, keepdims=True)


class RobotLogger:
    """The robot of ``kin`` under entity ``root`` of ``rec`` (module docstring)."""

    def __init__(self, rec: rr.RecordingStream, kin: RobotKinematics, root: str) -> None:
        self.rec, self.kin, self.root = rec, kin, root.strip("/")
        self.meshes = {k: v for k, v in link_meshes(kin.urdf_path).items() if k in kin.link_names}
        self.links = [k for k in kin.link_names if k in self.meshes]

    def path(self, link: str) -> str:
        return f"{self.root}/{link}"

    def log_static(self) -> None:
        """Each link's mesh, once."""
        for link in self.links:
            m = self.meshes[link]
            self.rec.log(f"{self.path(link)}/mesh",
                         rr.Transform3D(translation=m.xyz, quaternion=matrix_to_quat_xyzw(rpy_matrix(m.rpy).numpy()).tolist(), scale=m.scale),
                         static=True)
            self.rec.log(f"{self.path(link)}/mesh",
                         rr.Asset3D(contents=m.path.read_bytes(), media_type=_MEDIA[m.path.suffix.lower()],
                                    albedo_factor=_GREY), static=True)

    def poses(self, q: np.ndarray) -> np.ndarray:
        """``(T, L, 4, 4)`` world poses of every link along ``q (T, n_dof)`` (the whole-body
        joints, base x, y, yaw in the copy's world frame)."""
        import torch

        with torch.no_grad():
            t = self.kin.link_poses(torch.as_tensor(np.asarray(q), dtype=self.kin.dtype), self.links)
        return t.cpu().numpy().astype(np.float64)

    def log_trajectory(self, q: np.ndarray, indexes: list[Any]) -> None:
        """Every link's pose along ``q (T, n_dof)`` at the rows of the time columns ``indexes``."""
        poses = self.poses(q)
        quats = matrix_to_quat_xyzw(poses[..., :3, :3]).astype(np.float32)
        trans = poses[..., :3, 3].astype(np.float32)
        for j, link in enumerate(self.links):
            self.rec.send_columns(self.path(link), indexes=indexes,
                                  columns=rr.Transform3D.columns(translation=trans[:, j], quaternion=quats[:, j]))
