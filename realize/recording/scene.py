"""Drawing a CE run's top-down scene into a rerun recording: the static world and, per
iteration, the sampled parameters and the rollouts' trajectories.

What it does (the paper's Fig. 2, in rerun):
* :func:`log_static_scene`: obstacle footprints, padded obstacles (rounded rectangles, as the A*
  grid inflates them), the world bounds, the movable objects, the robot's start and the
  parameter regions projected on the floor (also under each parameter's distribution view), and
  the y-flip that makes rerun's 2-D views show +y upwards;
* :func:`log_world_samples`: every sample's parameters coloured by success, and the iteration's
  best plan's parameters;
* :func:`log_trajectories`: the base trajectories of all samples coloured by success (capped and
  decimated), the best plan's base path and its end-effector path (xy).
Entities that have nothing to show in an iteration are cleared for it. The shapes come from
``realize.tasks.topdown``, so the paper figures draw the same ones.

What it doesn't: log the sampling distributions, scalars or text (``realize.recording.log``), or own
the recording stream (the caller passes ``rec``).
"""

from __future__ import annotations

from collections.abc import Collection
from typing import TYPE_CHECKING

import numpy as np
import rerun as rr

from realize.world.geometry import SceneGeometry
from realize.tasks.param_layout import ParamLayout
from realize.recording.paths import ENTITY_DIST, ENTITY_WORLD, entity, param_path
from realize.tasks.topdown import (
    BEST_RGB,
    decimate_time,
    fill_nan_forward,
    obstacle_outline,
    padded_outline,
    param_xy,
    rectangle,
    region_outlines,
    success_colors,
    to_numpy,
)

if TYPE_CHECKING:  # avoid importing the simulator stack just for a type
    from realize.realization.result import RolloutResult

__all__ = ["log_static_scene", "log_world_samples", "log_trajectories"]

_GREY_REGION = (175, 175, 175, 255)
_BLACK = (20, 20, 20, 255)
_PAD = (110, 110, 110, 255)


def log_static_scene(
    rec: rr.RecordingStream,
    layout: ParamLayout,
    geometry: SceneGeometry,
    padding: float,
    dist_params: Collection[str],
    y_up: bool = True,
) -> None:
    """Log the static world; region outlines of ``dist_params`` also go under their distribution view."""
    g = geometry
    if y_up:
        flip = rr.Transform3D(scale=[1.0, -1.0, 1.0])
        rec.log(ENTITY_WORLD, flip, static=True)
        rec.log(ENTITY_DIST, flip, static=True)
    boxes = list(g.obstacles)
    if boxes:
        rec.log(
            entity(ENTITY_WORLD, "obstacles"),
            rr.LineStrips2D(
                [obstacle_outline(b) for b in boxes],
                colors=[_BLACK] * len(boxes),
                radii=0.02,
                labels=[b.name for b in boxes],
                draw_order=20.0,
            ),
            static=True,
        )
        if padding > 0:
            rec.log(
                entity(ENTITY_WORLD, "obstacles_padded"),
                rr.LineStrips2D(
                    [padded_outline(b, padding) for b in boxes],
                    colors=[_PAD] * len(boxes),
                    radii=0.008,
                    draw_order=19.0,
                ),
                static=True,
            )
    rec.log(
        entity(ENTITY_WORLD, "bounds"),
        rr.LineStrips2D(
            [rectangle(np.add(g.bounds_low, g.bounds_high) / 2, np.subtract(g.bounds_high, g.bounds_low) / 2)],
            colors=[(210, 210, 210, 255)],
            radii=0.01,
            draw_order=1.0,
        ),
        static=True,
    )
    rec.log(
        entity(ENTITY_WORLD, "objects"),
        rr.Points2D([o.position[:2] for o in g.objects], colors=[(230, 50, 200, 255)] * len(g.objects),
                    radii=[max(o.radius, 0.03) for o in g.objects], labels=list(g.object_names), draw_order=45.0),
        static=True,
    )
    sx, sy, syaw = g.robot_start
    rec.log(
        entity(ENTITY_WORLD, "robot_start"),
        rr.Arrows2D(origins=[[sx, sy]], vectors=[[0.4 * np.cos(syaw), 0.4 * np.sin(syaw)]],
                    colors=[(60, 60, 60, 255)], radii=0.02, labels=["start"], draw_order=45.0),
        static=True,
    )
    for name, region in layout.regions.items():
        outlines = region_outlines(region)
        if not outlines:
            continue
        arch = rr.LineStrips2D(outlines, colors=[_GREY_REGION] * len(outlines), radii=0.01,
                               labels=[name] + [""] * (len(outlines) - 1), draw_order=10.0)
        rec.log(param_path(f"{ENTITY_WORLD}/regions", name), arch, static=True)
        if name in dist_params:
            rec.log(param_path(ENTITY_DIST, name, "region"), arch, static=True)


def log_world_samples(rec: rr.RecordingStream, layout: ParamLayout, Z: np.ndarray | None, colors: np.ndarray,
                      best: int) -> None:
    """Each parameter's samples (``Z`` (N, D), or None to clear) and the best sample's parameters."""
    for name in layout.names:
        path = param_path(f"{ENTITY_WORLD}/samples", name)
        if Z is None:
            rec.log(path, rr.Clear(recursive=False))
        else:
            rec.log(path, rr.Points2D(param_xy(layout, name, Z), colors=colors, radii=0.015,
                                      draw_order=40.0))
    bp = entity(ENTITY_WORLD, "best", "params")
    if Z is None or best < 0:
        rec.log(bp, rr.Clear(recursive=False))
    else:
        pts = np.stack([param_xy(layout, n, Z[best : best + 1])[0] for n in layout.names])
        rec.log(bp, rr.Points2D(pts, colors=[BEST_RGB + (255,)] * len(pts), radii=0.035,
                                labels=layout.names, draw_order=52.0))


def log_trajectories(
    rec: rr.RecordingStream,
    rollout: RolloutResult | None,
    feasible: np.ndarray,
    best: int,
    cost: np.ndarray,
    max_traj_points: int,
    max_trajectories: int | None,
) -> None:
    """Base trajectories by success, the best plan's base and EE paths (cleared without trajectories)."""
    paths = {k: entity(ENTITY_WORLD, *k.split(".")) for k in
             ("trajectories.succeeded", "trajectories.failed", "best.base", "best.ee")}
    base = None if rollout is None else to_numpy(rollout.traj_base, np.float64)
    if base is None or base.ndim != 3 or base.shape[0] != feasible.shape[0]:
        for p in paths.values():
            rec.log(p, rr.Clear(recursive=False))
        return
    base = decimate_time(fill_nan_forward(base[..., :2]), max_traj_points)
    progress = to_numpy(rollout.progress, np.float64)
    n_actions = int(to_numpy(rollout.action_success).shape[1])
    colors = success_colors(feasible, progress, n_actions, alpha=150)
    keep = np.isfinite(base).all(axis=(1, 2))
    if max_trajectories is not None and keep.sum() > max_trajectories:
        # successes first (by cost), then failures by progress: a stable lexicographic sort
        key_cost = np.where(feasible, np.nan_to_num(cost, nan=np.inf), np.inf)
        order = np.lexsort((key_cost, -(progress if progress is not None else 0 * cost), ~feasible))
        order = order[keep[order]][: max_trajectories]
        keep = np.zeros_like(keep)
        keep[order] = True
    for name, mask, radius, order in (
        ("trajectories.succeeded", keep & feasible, 0.008, 36.0),
        ("trajectories.failed", keep & ~feasible, 0.005, 35.0),
    ):
        rec.log(paths[name], rr.LineStrips2D(base[mask], colors=colors[mask], radii=radius, draw_order=order))
    if best < 0:
        rec.log(paths["best.base"], rr.Clear(recursive=False))
        rec.log(paths["best.ee"], rr.Clear(recursive=False))
        return
    rec.log(paths["best.base"], rr.LineStrips2D([base[best]], colors=[BEST_RGB + (255,)], radii=0.025,
                                                labels=["best base"], draw_order=50.0))
    ee = to_numpy(rollout.traj_ee, np.float64)
    if ee is not None and ee.ndim == 3 and ee.shape[0] > best:
        ee_b = decimate_time(fill_nan_forward(ee[best : best + 1, :, :2]), max_traj_points)[0]
        # rerun has no dashed lines: the EE path is thinner and lighter than the base path
        rec.log(paths["best.ee"], rr.LineStrips2D([ee_b], colors=[(120, 235, 255, 255)], radii=0.012,
                                                  labels=["best EE"], draw_order=51.0))
    else:
        rec.log(paths["best.ee"], rr.Clear(recursive=False))
