"""A link's collision geometry as the URDF gives it: triangle meshes in the link frame.

What it does: :func:`link_geometry` reads one link's ``<collision>`` elements (mesh files with their
``scale``; ``box``, ``cylinder`` and ``sphere`` primitives; each with its ``<origin>`` xyz/rpy; any
number of elements) into a :class:`LinkGeometry`, which samples its surface, finds points along
its sharp edges, tells inside from outside (generalized winding number, robust to meshes that are
not closed) and measures exact point-to-solid distances. :func:`collision_links` lists the links
with any collision geometry. Mesh files are found as SAPIEN finds them
(``realize.robot.urdf.mesh_file``: ``package://`` names searched up the URDF's folders); a mesh
found nowhere, or a file that is not a mesh with triangles, is one ``ConfigError`` line naming
the URDF and the file.
What it doesn't: fit or judge spheres (``realize.robot.sphere_fit``), or know any robot.
"""

from __future__ import annotations

import math
import os
import xml.etree.ElementTree as ET
from typing import Sequence

import numpy as np
import trimesh

import torch

from realize.config import ConfigError
from realize.robot.urdf import JointSpec, axis_rotation, element_origin, mesh_file, read_urdf, rpy_matrix, urdf_floats

__all__ = ["LinkGeometry", "collision_links", "link_geometry", "origin_matrix", "joint_transform"]


class LinkGeometry:
    """A link's collision geometry: triangle meshes in the link frame."""

    def __init__(self, link: str, meshes: Sequence[trimesh.Trimesh]) -> None:
        if not meshes:
            raise ValueError(f"link {link!r} has no collision geometry")
        self.link = link
        self.meshes: tuple[trimesh.Trimesh, ...] = tuple(meshes)
        self._joined = trimesh.util.concatenate(list(self.meshes)) if len(self.meshes) > 1 else self.meshes[0]

    @property
    def vertices(self) -> np.ndarray:
        """All mesh vertices, ``(n, 3)``."""
        return np.asarray(self._joined.vertices, dtype=np.float64)

    @property
    def area(self) -> float:
        """Total surface area (m^2)."""
        return float(self._joined.area)

    def transformed(self, transform: np.ndarray) -> "LinkGeometry":
        """The same geometry moved by a 4x4 ``transform`` (e.g. into another frame)."""
        return LinkGeometry(self.link, [m.copy().apply_transform(transform) for m in self.meshes])

    @property
    def bounds(self) -> np.ndarray:
        """Axis-aligned bounds ``[[min x, y, z], [max x, y, z]]``."""
        return np.asarray(self._joined.bounds, dtype=np.float64)

    def sample_surface(self, n: int, seed: int) -> np.ndarray:
        """``n`` surface points, uniform by area over all meshes, ``(n, 3)``."""
        pts, _ = trimesh.sample.sample_surface(self._joined, n, seed=seed)
        return np.asarray(pts, dtype=np.float64)

    def feature_points(self, spacing: float) -> np.ndarray:
        """Points every ``spacing`` along the meshes' sharp edges (dihedral angle over 20 degrees),
        where the surface's points farthest from a sphere's centre tend to lie, ``(n, 3)``."""
        out = [np.zeros((0, 3))]
        for mesh in self.meshes:
            sharp = np.asarray(mesh.face_adjacency_angles) > math.radians(20.0)
            ends = np.asarray(mesh.vertices)[np.asarray(mesh.face_adjacency_edges)[sharp]]  # (e, 2, 3)
            for a, b in ends:
                n = int(math.ceil(np.linalg.norm(b - a) / spacing))
                if n > 1:
                    t = (np.arange(1, n) / n)[:, None]
                    out.append(a + t * (b - a))
        return np.concatenate(out)

    def contains(self, points: np.ndarray) -> np.ndarray:
        """Whether each point is inside any of the meshes (winding number > 1/2), ``(n,)`` bool."""
        inside = np.zeros(len(points), dtype=bool)
        for mesh in self.meshes:
            inside |= np.abs(_winding_numbers(np.asarray(mesh.triangles, dtype=np.float64), points)) > 0.5
        return inside

    def distance(self, points: np.ndarray) -> np.ndarray:
        """Distance of each point to the geometry taken as a solid (0 inside), ``(n,)``."""
        tri = np.asarray(self._joined.triangles, dtype=np.float64)
        d = _surface_distance(tri, points)
        d[self.contains(points)] = 0.0
        return d


# ----------------------------------------------------------------------------- reading the URDF


def origin_matrix(xyz: Sequence[float], rpy: Sequence[float]) -> np.ndarray:
    """The 4x4 transform of a URDF ``<origin>`` (rotation :func:`realize.robot.urdf.rpy_matrix`)."""
    t = np.eye(4)
    t[:3, :3] = rpy_matrix(rpy).numpy()
    t[:3, 3] = [float(v) for v in xyz]
    return t


def joint_transform(j: JointSpec, value: float) -> np.ndarray:
    """The 4x4 transform from a URDF joint's parent link to its child at joint value ``value``
    (m for a prismatic joint, rad for a revolute one; a fixed joint's origin alone)."""
    t = origin_matrix(j.xyz, j.rpy)
    if j.type not in ("prismatic", "revolute", "continuous"):
        return t
    axis = np.asarray(j.axis, dtype=np.float64)
    axis = axis / np.linalg.norm(axis)
    m = np.eye(4)
    if j.type == "prismatic":
        m[:3, 3] = axis * value
    else:
        m[:3, :3] = axis_rotation(torch.as_tensor(axis), value).numpy()
    return t @ m


_CYLINDER_SECTIONS = 64


def _primitive_mesh(geom: ET.Element) -> trimesh.Trimesh:
    """A box, cylinder (axis z) or sphere as a mesh that contains the exact primitive."""
    if geom.tag == "box":
        return trimesh.creation.box(extents=urdf_floats(geom.get("size"), (0.0, 0.0, 0.0)))
    if geom.tag == "cylinder":
        # circumscribed polygon: its faces touch the true cylinder, its corners lie outside it
        radius = float(geom.get("radius", "0")) / math.cos(math.pi / _CYLINDER_SECTIONS)
        return trimesh.creation.cylinder(radius=radius, height=float(geom.get("length", "0")),
                                         sections=_CYLINDER_SECTIONS)
    if geom.tag == "sphere":
        radius = float(geom.get("radius", "0"))
        mesh = trimesh.creation.icosphere(subdivisions=3, radius=radius)
        # scale so that the nearest face plane is at the true radius (the mesh then contains it)
        normals = np.asarray(mesh.face_normals)
        nearest = np.abs(np.einsum("ij,ij->i", normals, np.asarray(mesh.triangles)[:, 0])).min()
        mesh.apply_scale(radius / nearest)
        return mesh
    raise ValueError(f"unsupported collision geometry <{geom.tag}>")


def _load_mesh(filename: str, urdf: str | os.PathLike[str]) -> trimesh.Trimesh:
    """The triangle mesh a ``<mesh filename>`` of ``urdf`` names; a file trimesh cannot read, or
    one without triangles, is one ``ConfigError`` line naming both files."""
    path = mesh_file(filename, urdf)
    where = f"URDF {os.fspath(urdf)}: mesh file {filename!r} ({path})"
    try:
        mesh = trimesh.load(path, force="mesh")
    except Exception as e:  # trimesh's loaders raise anything from ValueError to ImportError
        raise ConfigError(f"{where} is not a readable mesh ({type(e).__name__}: {' '.join(str(e).split())})") from None
    if not isinstance(mesh, trimesh.Trimesh) or len(mesh.faces) == 0:
        raise ConfigError(f"{where} is not a readable mesh (no triangles in it)")
    return mesh


def _collision_meshes(link: ET.Element, urdf: str | os.PathLike[str]) -> list[trimesh.Trimesh]:
    meshes = []
    for col in link.findall("collision"):
        geom_el = col.find("geometry")
        if geom_el is None or len(geom_el) == 0:
            continue
        geom = geom_el[0]
        if geom.tag == "mesh":
            mesh = _load_mesh(geom.get("filename", ""), urdf)
            scale = urdf_floats(geom.get("scale"), (1.0, 1.0, 1.0))
            mesh.apply_transform(np.diag([*scale, 1.0]))
        else:
            mesh = _primitive_mesh(geom)
        mesh.apply_transform(origin_matrix(*element_origin(col)))
        meshes.append(mesh)
    return meshes


def collision_links(urdf_path: str | os.PathLike[str]) -> list[str]:
    """Names of the URDF's links that have at least one ``<collision>`` geometry, in file order."""
    root = read_urdf(urdf_path)
    return [l.get("name", "") for l in root.findall("link") if l.find("collision/geometry") is not None]


def link_geometry(urdf_path: str | os.PathLike[str], link: str) -> LinkGeometry:
    """One link's collision geometry, in the link frame (mesh files: ``realize.robot.urdf.mesh_file``);
    a link the URDF lacks is one ``ConfigError`` line."""
    root = read_urdf(urdf_path)
    for el in root.findall("link"):
        if el.get("name") == link:
            return LinkGeometry(link, _collision_meshes(el, urdf_path))
    raise ConfigError(f"URDF {os.fspath(urdf_path)}: no link {link!r}")


# ----------------------------------------------------------------------------- geometry kernels

_CHUNK = 2_000_000  # points x triangles per vectorized block


def _winding_numbers(tri: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Generalized winding number of a triangle soup ``(f, 3, 3)`` at ``points`` ``(n, 3)``
    (solid angle of each triangle by the Van Oosterom-Strackee formula, summed, over 4 pi)."""
    out = np.empty(len(points))
    step = max(1, _CHUNK // max(1, len(tri)))
    for s in range(0, len(points), step):
        p = points[s:s + step, None, None, :]
        v = tri[None] - p  # (m, f, 3, 3)
        a, b, c = v[:, :, 0], v[:, :, 1], v[:, :, 2]
        la, lb, lc = (np.linalg.norm(x, axis=-1) for x in (a, b, c))
        num = np.einsum("mfi,mfi->mf", a, np.cross(b, c))
        den = (la * lb * lc + np.einsum("mfi,mfi->mf", a, b) * lc + np.einsum("mfi,mfi->mf", b, c) * la
               + np.einsum("mfi,mfi->mf", c, a) * lb)
        out[s:s + step] = 2.0 * np.arctan2(num, den).sum(axis=1) / (4.0 * math.pi)
    return out


def _segment_distance(p: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    ab = b - a
    t = np.clip(np.einsum("mfi,fi->mf", p - a, ab) / np.maximum(np.einsum("fi,fi->f", ab, ab), 1e-30), 0.0, 1.0)
    return np.linalg.norm(p - (a + t[..., None] * ab), axis=-1)


def _surface_distance(tri: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Exact distance of each point to a triangle soup: to the plane where the projection falls
    inside the triangle, else to the nearest edge."""
    out = np.empty(len(points))
    a, b, c = tri[:, 0], tri[:, 1], tri[:, 2]
    n = np.cross(b - a, c - a)
    n_len = np.linalg.norm(n, axis=-1)
    good = n_len > 1e-18
    n_unit = np.where(good[:, None], n / np.maximum(n_len, 1e-30)[:, None], 0.0)
    step = max(1, _CHUNK // max(1, len(tri)))
    for s in range(0, len(points), step):
        p = points[s:s + step, None, :]  # (m, 1, 3)
        h = np.einsum("mfi,fi->mf", p - a, n_unit)
        q = p - h[..., None] * n_unit  # projection on the plane
        inside = good.copy()[None]
        for u, v in ((a, b), (b, c), (c, a)):
            inside = inside & (np.einsum("mfi,fi->mf", np.cross(v - u, q - u), n_unit) >= 0.0)
        edge = np.minimum(np.minimum(_segment_distance(p, a, b), _segment_distance(p, b, c)),
                          _segment_distance(p, c, a))
        out[s:s + step] = np.where(inside, np.abs(h), edge).min(axis=1)
    return out
