"""Top-down (ground-plane) geometry shared by the rerun logger and the paper figures.

What it does: turns the static world (``realize.world.geometry.SceneGeometry``) and the parameter regions
(``realize.tasks.regions``) into plain numpy polylines in the floor plane (x, y), so that the rerun
recording (``realize.recording.log``) and the matplotlib figures (``realize.figures``) draw exactly
the same shapes:

* obstacle footprints (yawed, pitched boxes projected on the floor) as closed rectangles;
* padded obstacles as rounded rectangles: the Minkowski sum of the footprint with a disc of
  radius ``padding``, the same inflation the A* occupancy grid uses
  (``realize.controllers.occupancy``);
* regions projected on the floor: an annulus as its two circles, a hemisphere cap as the circles
  bounding its xy footprint, a box as its (x, y) rectangle, a fixed point as a small cross;
* 2-sigma ellipse parameters of a per-column Gaussian (first two columns of a parameter);
* small array helpers: conversion of tensors to numpy, NaN-safe trajectory decimation, colours.

What it doesn't: import a plotting or logging backend, or know about simulation.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from realize.world.geometry import Box as ObstacleBox
from realize.tasks.hemisphere import Hemisphere
from realize.tasks.param_layout import ParamLayout
from realize.tasks.regions import Annulus, Fixed, Region
from realize.tasks.regions import Box as BoxRegion

__all__ = [
    "to_numpy",
    "rectangle",
    "rounded_rectangle",
    "circle",
    "obstacle_outline",
    "padded_outline",
    "region_outlines",
    "region_xy_radii",
    "param_xy",
    "planar_params",
    "ellipse_params",
    "decimate_time",
    "fill_nan_forward",
    "lerp_colors",
    "success_colors",
    "iteration_colors",
    "VIRIDIS",
    "SUCCESS_RGB",
    "FAIL_RGB",
    "FAIL_NEAR_RGB",
    "BEST_RGB",
]

# colours (RGB, 0..255)
SUCCESS_RGB = (40, 170, 70)
FAIL_RGB = (200, 40, 30)  # failed in the first action
FAIL_NEAR_RGB = (245, 160, 40)  # failed in the last action
BEST_RGB = (0, 200, 230)  # cyan, as the paper's Fig. 2
# a few anchors of matplotlib's viridis (0, 0.25, 0.5, 0.75, 1), interpolated linearly
VIRIDIS = np.array(
    [[68, 1, 84], [59, 82, 139], [33, 145, 140], [94, 201, 98], [253, 231, 37]], dtype=np.float64
)


def to_numpy(x: Any, dtype: Any = None) -> np.ndarray | None:
    """A numpy copy of a torch tensor (any device), array or sequence; ``None`` stays ``None``."""
    if x is None:
        return None
    if hasattr(x, "detach"):
        x = x.detach().cpu().numpy()
    return np.asarray(x, dtype=dtype)


# --------------------------------------------------------------------------------------------
# shapes
# --------------------------------------------------------------------------------------------


def _rot(yaw: float) -> np.ndarray:
    c, s = math.cos(yaw), math.sin(yaw)
    return np.array([[c, -s], [s, c]])


def rectangle(center: Sequence[float], half: Sequence[float], yaw: float = 0.0) -> np.ndarray:
    """Closed outline ``(5, 2)`` of a rectangle with half extents ``half`` turned by ``yaw``."""
    hx, hy = float(half[0]), float(half[1])
    local = np.array([[-hx, -hy], [hx, -hy], [hx, hy], [-hx, hy], [-hx, -hy]])
    if yaw != 0.0:
        local = local @ _rot(yaw).T
    return local + np.asarray(center[:2], dtype=np.float64)


def rounded_rectangle(
    center: Sequence[float], half: Sequence[float], yaw: float, radius: float, n_arc: int = 8
) -> np.ndarray:
    """Closed outline of ``rectangle(center, half, yaw)`` inflated by a disc of ``radius``
    (its Minkowski sum with the disc: straight sides, quarter-circle corners)."""
    if radius <= 0:
        return rectangle(center, half, yaw)
    hx, hy = float(half[0]), float(half[1])
    corners = np.array([[hx, -hy], [hx, hy], [-hx, hy], [-hx, -hy]])
    start = np.array([-0.5, 0.0, 0.5, 1.0]) * math.pi  # arc around each corner, counter-clockwise
    t = start[:, None] + np.linspace(0.0, 0.5 * math.pi, n_arc + 1)[None, :]  # (4, n_arc+1)
    pts = corners[:, None, :] + radius * np.stack([np.cos(t), np.sin(t)], axis=-1)
    pts = pts.reshape(-1, 2)
    pts = np.concatenate([pts, pts[:1]], axis=0)
    return pts @ _rot(yaw).T + np.asarray(center[:2], dtype=np.float64)


def circle(center: Sequence[float], radius: float, n: int = 64) -> np.ndarray:
    """Closed outline ``(n + 1, 2)`` of a circle."""
    t = np.linspace(0.0, 2.0 * math.pi, n + 1)
    return np.asarray(center[:2], dtype=np.float64) + radius * np.stack([np.cos(t), np.sin(t)], axis=-1)


def obstacle_outline(box: ObstacleBox) -> np.ndarray:
    """Floor footprint of a (possibly pitched) obstacle box."""
    return rectangle(box.center, box.footprint_half_size(), box.yaw)


def padded_outline(box: ObstacleBox, padding: float) -> np.ndarray:
    """Footprint inflated by ``padding`` (rounded corners, as the A* occupancy grid)."""
    return rounded_rectangle(box.center, box.footprint_half_size(), box.yaw, padding)


def region_xy_radii(region: Hemisphere) -> tuple[float, float]:
    """Smallest and largest distance from the centre's vertical axis over the cap, i.e. the
    inner and outer radius of the cap's floor footprint (an annulus, or a disc if inner is 0)."""
    a, b = region.polar_min, region.polar_max
    s_a, s_b = math.sin(a), math.sin(b)
    outer = 1.0 if a <= math.pi / 2 <= b else max(s_a, s_b)
    inner = min(s_a, s_b)
    return region.radius * inner, region.radius * outer


def region_outlines(region: Region, n: int = 96) -> list[np.ndarray]:
    """Floor-plane polylines that outline ``region`` (see the module docstring)."""
    if isinstance(region, Annulus):
        out = [circle(region.center, region.r_max, n)]
        if region.r_min > 0:
            out.append(circle(region.center, region.r_min, n))
        return out
    if isinstance(region, Hemisphere):
        r_in, r_out = region_xy_radii(region)
        out = [circle(region.center, r_out, n)]
        if r_in > 1e-9:
            out.append(circle(region.center, r_in, n))
        return out
    if isinstance(region, BoxRegion):
        if region.dim < 2:
            return []
        lo, hi = np.array(region.low[:2]), np.array(region.high[:2])
        return [rectangle((lo + hi) / 2, (hi - lo) / 2)]
    if isinstance(region, Fixed):
        v = np.array(list(region.value[:2]) + [0.0] * max(0, 2 - region.dim))
        d = 0.04
        return [v + np.array([[-d, -d], [d, d]]), v + np.array([[-d, d], [d, -d]])]
    return []


# --------------------------------------------------------------------------------------------
# parameters and distributions
# --------------------------------------------------------------------------------------------


def param_xy(layout: ParamLayout, name: str, Z: np.ndarray) -> np.ndarray:
    """``(N, 2)`` floor-plane coordinates of parameter ``name`` in rows of ``Z (N, D)``: its first
    two columns (x, y); a 1-D parameter gets y = 0."""
    cols = Z[:, layout.slices[name]]
    if cols.shape[1] >= 2:
        return cols[:, :2]
    return np.concatenate([cols, np.zeros_like(cols)], axis=1)


def ellipse_params(
    layout: ParamLayout, name: str, mean: np.ndarray, std: np.ndarray, n_sigma: float = 2.0
) -> tuple[np.ndarray, np.ndarray]:
    """Centre ``(2,)`` and half axes ``(2,)`` (``n_sigma`` * std) of the axis-aligned ellipse of
    parameter ``name`` (first two columns; a 1-D parameter gets a flat ellipse at y = 0)."""
    c = param_xy(layout, name, np.asarray(mean, dtype=np.float64)[None])[0]
    h = n_sigma * param_xy(layout, name, np.asarray(std, dtype=np.float64)[None])[0]
    return c, h


def planar_params(layout: ParamLayout) -> list[str]:
    """Parameters worth a distribution plot: every one that is not ``Fixed``."""
    return [n for n, r in layout.regions.items() if not isinstance(r, Fixed)]


# --------------------------------------------------------------------------------------------
# trajectories and colours
# --------------------------------------------------------------------------------------------


def fill_nan_forward(traj: np.ndarray) -> np.ndarray:
    """Replace non-finite samples of ``traj (N, T, k)`` by the last finite one before them
    (and leading ones by the first finite one); rows without any finite sample stay NaN."""
    traj = np.asarray(traj, dtype=np.float64)
    ok = np.isfinite(traj).all(axis=-1)  # (N, T)
    if ok.all():
        return traj
    T = traj.shape[1]
    idx = np.where(ok, np.arange(T)[None, :], -1)
    idx = np.maximum.accumulate(idx, axis=1)
    first = np.where(ok.any(axis=1), ok.argmax(axis=1), 0)
    idx = np.where(idx < 0, first[:, None], idx)
    return np.take_along_axis(traj, idx[..., None], axis=1)


def decimate_time(traj: np.ndarray, max_points: int) -> np.ndarray:
    """Keep at most ``max_points`` evenly strided time samples of ``(N, T, k)``, always the last."""
    T = traj.shape[1]
    if max_points <= 1 or T <= max_points:
        return traj
    step = int(math.ceil((T - 1) / (max_points - 1)))
    idx = np.arange(0, T, step)
    if idx[-1] != T - 1:
        idx = np.append(idx, T - 1)
    return traj[:, idx]


def lerp_colors(anchors: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Piecewise-linear colour map: ``t`` in [0, 1] (any shape) -> ``(..., 3)`` uint8."""
    anchors = np.asarray(anchors, dtype=np.float64)
    t = np.clip(np.asarray(t, dtype=np.float64), 0.0, 1.0)
    x = t * (len(anchors) - 1)
    i = np.minimum(np.floor(x).astype(int), len(anchors) - 2)
    f = (x - i)[..., None]
    return np.round(anchors[i] * (1 - f) + anchors[i + 1] * f).astype(np.uint8)


def success_colors(feasible: np.ndarray, progress: np.ndarray | None = None, n_actions: int | None = None,
                   alpha: int = 255) -> np.ndarray:
    """``(N, 4)`` uint8 RGBA: green for successful samples; failures from red (failed in the
    first action) to orange (failed in the last) when ``progress`` (actions completed) and
    ``n_actions`` are known, else red."""
    feasible = np.asarray(feasible, dtype=bool)
    n = feasible.shape[0]
    if progress is not None and n_actions and n_actions > 1:
        t = np.asarray(progress, dtype=np.float64) / (n_actions - 1)
    else:
        t = np.zeros(n)
    fail = lerp_colors(np.array([FAIL_RGB, FAIL_NEAR_RGB]), t)
    rgb = np.where(feasible[:, None], np.array(SUCCESS_RGB, dtype=np.uint8)[None], fail)
    a = np.full((n, 1), alpha, dtype=np.uint8)
    return np.concatenate([rgb.astype(np.uint8), a], axis=1)


def iteration_colors(iterations: np.ndarray, n_iterations: int) -> np.ndarray:
    """``(k, 3)`` uint8 viridis colours of iteration indices on a scale of ``n_iterations``."""
    denom = max(n_iterations - 1, 1)
    return lerp_colors(VIRIDIS, np.asarray(iterations, dtype=np.float64) / denom)
