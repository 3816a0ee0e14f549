"""Collision spheres fitted to a link's collision geometry, and how well spheres cover it.

What it does
------------
* :func:`link_geometry` / :func:`collision_links` (from ``realize.robot.link_geometry``, offered
  here too) read a link's ``<collision>`` elements from a URDF into a :class:`LinkGeometry`:
  triangle meshes in the link frame.
* :func:`fit_spheres` covers a :class:`LinkGeometry` with spheres (link frame), deterministically
  for a given ``seed``, either with a given number of spheres or with as few as keep every radius
  under ``max_radius``.
* :func:`coverage` measures a set of spheres against the geometry: the share of surface samples
  inside the union of the spheres, and the largest overshoot (defined below).

Method of :func:`fit_spheres`
-----------------------------
The points to cover are the mesh vertices, points along the sharp edges (every 1/200 of the
link's bounding-box diagonal) and area-uniform surface samples (seeded). For ``k``
spheres, several starts are tried (``k`` equal slices along the points' principal axis, and
seeded k-means++ picks); each start runs a few Lloyd rounds (assign every point to its nearest
centre, move the centre to the middle of its cluster's bounding box; radius = the largest
distance in the cluster). Then a tightening pass: each sphere in turn is re-centred and
shrunk to the minimal enclosing ball of the points that no other sphere covers (so every point
stays covered). The start with the least total ``sum(radius**3)`` (a proxy of the volume the
spheres add) wins. Last, three fresh sets of surface samples (other seeds) are checked and, for
each sample left outside, the sphere nearest to reaching it grows just enough to. Centres are
rounded to ``round_to`` and radii rounded *up* after adding the rounding shift of the centre, so
every fitted point is still covered after rounding. Every
fitting point is inside the spheres by construction; surface coverage of other samples is close
to 100 % (check it with :func:`coverage` and a seed of its own).

Overshoot
---------
The overshoot of a set of spheres is the largest distance from a point of any sphere's surface to
the link's collision geometry taken as a solid (0 for surface points inside the geometry): how
far beyond the real geometry the spheres make the link reach. It is evaluated on ``n_dirs``
Fibonacci directions per sphere; inside/outside uses the generalized winding number of each
mesh (robust to meshes that are not closed), distance is exact point-to-triangle distance.

What it doesn't: model self-collision, decide which spheres check the floor, know any robot or
write sphere files (``scripts/fit_spheres.py`` does), or follow joints: every link is fitted on
its own, in its own frame.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Sequence

import numpy as np
from scipy.spatial import ConvexHull, QhullError

from realize.robot.link_geometry import LinkGeometry, collision_links, link_geometry, origin_matrix

__all__ = [
    "Sphere",
    "LinkGeometry",
    "Coverage",
    "collision_links",
    "link_geometry",
    "fit_spheres",
    "coverage",
    "origin_matrix",
]


@dataclass(frozen=True)
class Sphere:
    """A sphere in a link's frame (metres)."""

    centre: tuple[float, float, float]
    radius: float


@dataclass(frozen=True)
class Coverage:
    """How well spheres cover a link: see :func:`coverage`."""

    share_inside: float  # share of surface samples inside the union of the spheres
    worst_outside: float  # largest distance of a sample outside every sphere (m, 0 if none)
    overshoot: float  # largest distance of a sphere-surface point from the geometry (m)
    n_spheres: int


def _fibonacci_directions(n: int) -> np.ndarray:
    i = np.arange(n) + 0.5
    z = 1.0 - 2.0 * i / n
    phi = math.pi * (3.0 - math.sqrt(5.0)) * i
    r = np.sqrt(1.0 - z * z)
    return np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=1)


# ----------------------------------------------------------------------------- fitting


def _hull_points(pts: np.ndarray) -> np.ndarray:
    """The points' convex-hull vertices (all points where the hull is degenerate)."""
    if len(pts) < 5:
        return pts
    try:
        return pts[ConvexHull(pts).vertices]
    except QhullError:  # flat or collinear
        return pts


def _enclosing_ball(pts: np.ndarray, iterations: int = 400) -> tuple[np.ndarray, float]:
    """Approximate minimal enclosing ball (Badoiu-Clarkson steps from the bounding-box centre, on
    the convex-hull vertices); the radius is exact for the returned centre."""
    hull = _hull_points(pts)
    c = 0.5 * (hull.min(axis=0) + hull.max(axis=0))
    for i in range(iterations):
        far = hull[np.argmax(((hull - c) ** 2).sum(axis=1))]
        c = c + (far - c) / (i + 2.0)
    return c, float(np.sqrt(((pts - c) ** 2).sum(axis=1)).max())


def _principal_slices(pts: np.ndarray, k: int) -> np.ndarray:
    mean = pts.mean(axis=0)
    _, _, vt = np.linalg.svd(pts - mean, full_matrices=False)
    t = (pts - mean) @ vt[0]
    edges = np.linspace(t.min(), t.max(), k + 1)
    label = np.clip(np.searchsorted(edges, t, side="right") - 1, 0, k - 1)
    mids = 0.5 * (edges[:-1] + edges[1:])
    return np.stack([pts[label == j].mean(axis=0) if np.any(label == j) else mean + vt[0] * mids[j] for j in range(k)])


def _kmeanspp(pts: np.ndarray, k: int, rng: np.random.Generator) -> np.ndarray:
    centres = [pts[rng.integers(len(pts))]]
    for _ in range(1, k):
        d2 = ((pts[:, None, :] - np.asarray(centres)[None]) ** 2).sum(axis=-1).min(axis=1)
        centres.append(pts[rng.choice(len(pts), p=d2 / d2.sum())] if d2.sum() > 0 else pts[rng.integers(len(pts))])
    return np.asarray(centres)


def _lloyd(pts: np.ndarray, centres: np.ndarray, rounds: int) -> tuple[np.ndarray, np.ndarray]:
    k = len(centres)
    radii = np.zeros(k)
    for _ in range(rounds):
        label = ((pts[:, None, :] - centres[None]) ** 2).sum(axis=-1).argmin(axis=1)
        new = centres.copy()
        for j in range(k):
            if np.any(label == j):
                cluster = pts[label == j]
                new[j] = 0.5 * (cluster.min(axis=0) + cluster.max(axis=0))
        if np.allclose(new, centres, atol=1e-7):
            centres = new
            break
        centres = new
    label = ((pts[:, None, :] - centres[None]) ** 2).sum(axis=-1).argmin(axis=1)
    for j in range(k):
        mine = pts[label == j]
        radii[j] = float(np.sqrt(((mine - centres[j]) ** 2).sum(axis=1)).max()) if len(mine) else 0.0
    return centres, radii


def _tighten(pts: np.ndarray, centres: np.ndarray, radii: np.ndarray, passes: int = 2) -> tuple[np.ndarray, np.ndarray]:
    """Re-centre and shrink each sphere to the points no other sphere covers (coverage is kept)."""
    centres, radii = centres.copy(), radii.copy()
    k = len(centres)
    for _ in range(passes):
        for j in range(k):
            dist = np.sqrt(((pts[:, None, :] - centres[None]) ** 2).sum(axis=-1))
            others = np.delete(dist - radii[None], j, axis=1)
            alone = others.min(axis=1) > 0.0 if k > 1 else np.ones(len(pts), dtype=bool)
            if np.any(alone):
                centres[j], radii[j] = _enclosing_ball(pts[alone])
            else:
                radii[j] = 0.0
    return centres, radii


def _round(centres: np.ndarray, radii: np.ndarray, round_to: float) -> list[Sphere]:
    spheres = []
    for c, r in zip(centres, radii):
        if r <= 0.0:
            continue  # a sphere left with nothing to cover
        cr = np.round(c / round_to) * round_to
        rr = math.ceil((r + float(np.linalg.norm(cr - c))) / round_to - 1e-9) * round_to
        centre = tuple(round(float(v), 6) + 0.0 for v in cr)  # + 0.0: no -0.0 in files
        spheres.append(Sphere(centre, round(rr, 6)))  # type: ignore[arg-type]
    return sorted(spheres, key=lambda s: (sum(v * v for v in s.centre), s.centre))  # nearest the link origin first


def _fit_k(pts: np.ndarray, k: int, seed: int, restarts: int) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    starts = [_principal_slices(pts, k)] + [_kmeanspp(pts, k, rng) for _ in range(restarts if k > 1 else 0)]
    best: tuple[float, np.ndarray, np.ndarray] | None = None
    for start in starts:
        c, r = _tighten(pts, *_lloyd(pts, start, rounds=15))
        score = float((r ** 3).sum())
        if best is None or score < best[0] - 1e-15:
            best = (score, c, r)
    assert best is not None
    return best[1], best[2]


def _grow(pts: np.ndarray, centres: np.ndarray, radii: np.ndarray) -> np.ndarray:
    """Grow, for each point outside every sphere, the sphere it is nearest to leaving, to reach it."""
    radii = radii.copy()
    dist = np.sqrt(((pts[:, None, :] - centres[None]) ** 2).sum(axis=-1))
    gap = dist - radii[None]
    out = np.flatnonzero(gap.min(axis=1) > 0.0)
    for i in out[np.argsort(gap[out].min(axis=1))]:
        j = int(np.argmin(dist[i] - radii))
        radii[j] = max(radii[j], float(dist[i, j]))
    return radii


def _fit_covering(geometry: LinkGeometry, pts: np.ndarray, k: int, n_samples: int, seed: int,
                  restarts: int, round_to: float) -> list[Sphere]:
    centres, radii = _fit_k(pts, k, seed, restarts)
    for extra in range(1, _GROW_ROUNDS + 1):  # fresh samples: cover what falls between the fitted ones
        radii = _grow(geometry.sample_surface(2 * n_samples, seed + 7919 * extra), centres, radii)
    return _round(centres, radii, round_to)


_GROW_ROUNDS = 3
_EDGE_POINTS = 200  # points along a sharp edge as long as the link's bounding-box diagonal


def fit_spheres(
    geometry: LinkGeometry,
    n_spheres: int | None = None,
    max_radius: float | None = None,
    max_spheres: int = 8,
    n_samples: int = 3000,
    seed: int = 0,
    restarts: int = 8,
    round_to: float = 0.001,
) -> list[Sphere]:
    """Spheres (link frame) covering ``geometry``; see the module docstring for the method.

    Args:
        geometry: the link's collision geometry (:func:`link_geometry`).
        n_spheres: how many spheres; if None, the fewest (1..``max_spheres``) whose largest radius
            is at most ``max_radius`` (``max_spheres`` if none is).
        max_radius: radius bound used when ``n_spheres`` is None (required then).
        n_samples: surface samples to cover, besides the mesh vertices.
        seed: seeds the surface samples and the k-means++ starts; same inputs give the same spheres.
        restarts: k-means++ starts tried besides the principal-axis start.
        round_to: centres are rounded to this, radii rounded up (keeping coverage).
    """
    if n_spheres is None and max_radius is None:
        raise ValueError("give n_spheres or max_radius")
    if n_spheres is not None and n_spheres < 1:
        raise ValueError("n_spheres must be >= 1")
    spacing = float(np.linalg.norm(geometry.bounds[1] - geometry.bounds[0])) / _EDGE_POINTS
    pts = np.unique(np.concatenate([geometry.vertices, geometry.feature_points(spacing),
                                    geometry.sample_surface(n_samples, seed)]), axis=0)
    if n_spheres is not None:
        return _fit_covering(geometry, pts, n_spheres, n_samples, seed, restarts, round_to)
    assert max_radius is not None
    spheres: list[Sphere] = []
    for k in range(1, max_spheres + 1):
        spheres = _fit_covering(geometry, pts, k, n_samples, seed, restarts, round_to)
        if max(s.radius for s in spheres) <= max_radius + 1e-12:
            break
    return spheres


# ----------------------------------------------------------------------------- coverage


def coverage(
    geometry: LinkGeometry,
    spheres: Sequence[Sphere],
    n_samples: int = 5000,
    seed: int = 12345,
    n_dirs: int = 256,
    tolerance: float = 0.0,
) -> Coverage:
    """How well ``spheres`` (link frame) cover ``geometry``.

    ``share_inside``: the share of ``n_samples`` area-uniform surface samples (seeded by ``seed``;
    pick a seed other than the fit's to test on fresh points) that lie inside the union of the
    spheres, a sample counting as inside within ``tolerance`` metres of a sphere.
    ``worst_outside``: the largest distance from a sample to the union (0 if all are inside).
    ``overshoot``: the largest distance from a point of a sphere's surface to the geometry as a
    solid (0 inside it), over ``n_dirs`` directions per sphere: how far the spheres reach beyond the
    link. With no spheres: share 0 and overshoot 0.
    """
    samples = geometry.sample_surface(n_samples, seed)
    if not spheres:
        return Coverage(0.0, float("inf"), 0.0, 0)
    c = np.asarray([s.centre for s in spheres], dtype=np.float64)
    r = np.asarray([s.radius for s in spheres], dtype=np.float64)
    gap = (np.sqrt(((samples[:, None, :] - c[None]) ** 2).sum(axis=-1)) - r[None]).min(axis=1)
    surface = (c[:, None, :] + r[:, None, None] * _fibonacci_directions(n_dirs)[None]).reshape(-1, 3)
    return Coverage(
        share_inside=float((gap <= tolerance).mean()),
        worst_outside=float(max(0.0, gap.max())),
        overshoot=float(geometry.distance(surface).max()),
        n_spheres=len(spheres),
    )
