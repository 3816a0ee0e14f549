"""A whole robot's collision spheres fitted from its URDF, and the sphere file they go into.

What it does: :func:`fit_robot_spheres` fits every link with collision geometry (or the links
given) by ``realize.robot.sphere_fit.fit_spheres``: ``counts[link]`` spheres, or else the fewest
(up to ``max_spheres``) whose radii are at most ``max_radius`` (default per link: half the middle
edge of its bounding box, :func:`link_radius_bound`), and sets each sphere's ``check_floor`` by
:func:`floor_checks` (false where the link, or the sphere, reaches the floor at every
configuration of the short prismatic joints' limits, all else at 0). :func:`write_fitted_spheres`
writes them with the header that marks a file as fitted (``FITTED_MARK``). ``scripts/fit_spheres.py``
and ``realize.robot.onboard`` are its two callers.

What it doesn't: report coverage (the script prints that), compare files, or fit self-collision
models; it reads collision meshes only (``realize.robot.link_geometry``).
"""

from __future__ import annotations

import datetime as _dt
import itertools
from dataclasses import dataclass
from pathlib import Path
from typing import Mapping, Sequence

import numpy as np

from realize.robot.link_geometry import joint_transform
from realize.robot.sphere_file import SphereSpec, write_spheres
from realize.robot.sphere_fit import LinkGeometry, Sphere, collision_links, fit_spheres, link_geometry
from realize.robot.urdf import JointSpec, parse_urdf_joints

__all__ = ["FITTED_MARK", "FitSettings", "link_poses", "floor_checks", "link_radius_bound", "fit_robot_spheres",
           "write_fitted_spheres", "corner_configs"]

FITTED_MARK = "fitted by scripts/fit_spheres.py"
PRISMATIC_RANGE = 2.0  # m: prismatic joints of at most this range are a lift, torso or finger; wider ones a planar base


@dataclass(frozen=True)
class FitSettings:
    """How hard to fit: ``samples`` surface samples per link, ``max_spheres`` per link without a
    count, one radius bound for all (``max_radius``; None: each link's own), the seed, and how far
    above the floor counts as touching it (``floor_tol``, m)."""

    samples: int = 3000
    max_spheres: int = 4
    max_radius: float | None = None
    seed: int = 0
    floor_tol: float = 0.01


def link_poses(joints: dict[str, JointSpec], values: dict[str, float], links: list[str]) -> dict[str, np.ndarray]:
    """4x4 pose of each link in the URDF root frame, joints at ``values`` (absent: 0)."""
    out: dict[str, np.ndarray] = {}

    def pose(link: str) -> np.ndarray:
        if link not in out:
            j = joints.get(link)
            out[link] = np.eye(4) if j is None else pose(j.parent) @ joint_transform(j, values.get(j.name, 0.0))
        return out[link]

    return {l: pose(l) for l in links}


def _chain(joints: dict[str, JointSpec], link: str) -> list[JointSpec]:
    chain = []
    while link in joints:
        chain.append(joints[link])
        link = joints[link].parent
    return chain


def _short_prismatic(j: JointSpec) -> bool:
    finite = np.isfinite(j.lower) and np.isfinite(j.upper)
    return j.type == "prismatic" and finite and j.upper - j.lower <= PRISMATIC_RANGE


def corner_configs(joints: list[JointSpec]) -> list[dict[str, float]]:
    """Every combination of the short-range prismatic joints at their limits; all else at 0."""
    lifts = [j for j in joints if _short_prismatic(j)]
    combos = itertools.product(*[(j.lower, j.upper) for j in lifts])
    return [{j.name: v for j, v in zip(lifts, combo)} for combo in combos]


def _lowest(joints: dict[str, JointSpec], link: str, local: np.ndarray, radius: float = 0.0) -> list[float]:
    """Lowest root-frame z of ``local`` points of ``link`` (minus ``radius``), at each corner configuration."""
    out = []
    for cfg in corner_configs(_chain(joints, link)):
        t = link_poses(joints, cfg, [link])[link]
        out.append(float((local @ t[:3, :3].T + t[:3, 3])[:, 2].min()) - radius)
    return out


def floor_checks(joints: dict[str, JointSpec], geom: LinkGeometry, spheres: list[Sphere], tol: float) -> list[bool]:
    """``check_floor`` of each sphere of ``geom``'s link (rule in the module docstring)."""
    if max(_lowest(joints, geom.link, geom.vertices)) <= tol:
        return [False] * len(spheres)
    return [max(_lowest(joints, geom.link, np.asarray([s.centre]), s.radius)) > tol for s in spheres]


def link_radius_bound(geometry: LinkGeometry) -> float:
    """The default sphere radius bound of a link (m): half the middle edge of its collision
    geometry's axis-aligned bounding box (in its own frame)."""
    edges = sorted(float(e) for e in geometry.bounds[1] - geometry.bounds[0])
    return 0.5 * edges[1]


def fit_robot_spheres(urdf: Path, settings: FitSettings = FitSettings(), links: Sequence[str] | None = None,
                      counts: Mapping[str, int] | None = None,
                      geoms: Mapping[str, LinkGeometry] | None = None) -> list[SphereSpec]:
    """Spheres named ``<link>_<i>`` for ``links`` (default: every link with collision geometry)
    of the URDF file ``urdf`` (module docstring). A mesh it cannot read is a one-line ``ConfigError``."""
    links = list(links) if links is not None else collision_links(urdf)
    counts = counts or {}
    joints = parse_urdf_joints(str(urdf))
    geoms = geoms or {l: link_geometry(urdf, l) for l in links}
    fitted: list[SphereSpec] = []
    for link in links:
        g = geoms[link]
        if link in counts:
            spheres = fit_spheres(g, n_spheres=counts[link], n_samples=settings.samples, seed=settings.seed)
        else:
            bound = link_radius_bound(g) if settings.max_radius is None else settings.max_radius
            spheres = fit_spheres(g, max_radius=bound, max_spheres=settings.max_spheres,
                                  n_samples=settings.samples, seed=settings.seed)
        checks = floor_checks(joints, g, spheres, settings.floor_tol)
        fitted += [SphereSpec(f"{link}_{i}", link, s.centre, s.radius, c)
                   for i, (s, c) in enumerate(zip(spheres, checks))]
    return fitted


def write_fitted_spheres(out: Path, robot: str, urdf: Path, fitted: Sequence[SphereSpec], samples: int,
                         command: str, without_spheres: Sequence[str] = ()) -> None:
    """Write ``fitted`` to ``out`` with the header of a fitted file (``FITTED_MARK``, the method,
    and ``command``, the command line that made it)."""
    header = [
        f"Collision spheres of {robot}, {FITTED_MARK} (realize.robot.sphere_fit)",
        f"on {_dt.datetime.now(_dt.timezone.utc):%Y-%m-%d} to the collision geometry of {urdf.name}. Per link: vertices,",
        f"sharp-edge points and {samples} surface samples split among the link's spheres (principal-axis",
        "and k-means++ starts, Lloyd rounds; each sphere then shrunk to the minimal enclosing ball of what",
        "only it covers, then grown to cover fresh samples); centres rounded to 1 mm, radii rounded up.",
        "check_floor: false for spheres that cannot leave the floor (their link reaches the floor at every",
        "lift height, or they do). Offsets in the link frame (m), radii (m). Made with (sphere counts:",
        "--count, else those of the file it replaced):",
        f"  .venv/bin/python {command}",
    ]
    write_spheres(out, robot, fitted, header, without_spheres=without_spheres)
