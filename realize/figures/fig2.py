"""Fig. 2 of the seed paper: sampled plans of chosen CE iterations projected on the ground plane.

What it does: ``fig2(run_dir, iterations)`` draws, per iteration, every sampled plan's base
trajectory (orange tones, darker and opaque for successful plans), its parameters as crosses,
the iteration's best plan (base cyan solid, end effector cyan dashed), the regions and the
tables; it writes the PNG and a CSV of every plotted point. Reads ``trajectories_iter{k}.npz``,
``history.npz`` (the samples, where the trajectories file has none) and the scene.
What it doesn't: record trajectories (a run does, with ``logging.record=true``).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.lines import Line2D
from matplotlib.patches import Patch, PathPatch
from matplotlib.path import Path as MplPath

from realize.figures.common import (
    CYAN,
    DPI,
    REGION_EDGE,
    REGION_GREY,
    draw_world,
    fmt,
    plt,
    require_scene,
    set_world_limits,
    write_csv,
)
from realize.run_dir.directory import RunDir
from realize.tasks.topdown import decimate_time, fill_nan_forward, param_xy

__all__ = ["fig2"]


def fig2(
    run_dir: str | Path,
    iterations: Sequence[int] | None = None,
    out_png: str | Path | None = None,
    out_csv: str | Path | None = None,
    max_points: int = 150,
    max_plans: int | None = None,
) -> tuple[Path, Path]:
    """Sampled plans of ``iterations`` projected on the ground plane (the paper's Fig. 2).

    Defaults: the first, middle and last iteration that have a trajectories file; PNG/CSV in
    ``<run_dir>/figures/fig2.{png,csv}``. ``max_plans`` caps the plans drawn per panel (the
    best, then the others in file order). CSV rows: iteration, sample, feasible, best, series
    (``base``, ``ee`` (best plan only) or a parameter name), step, x, y.
    """
    rd = RunDir.existing(run_dir)
    scene = require_scene(rd, "fig2")
    layout, geometry = scene.layout, scene.geometry
    history = rd.history_arrays()
    run_dir = rd.path
    if iterations is None or len(iterations) == 0:
        have = rd.trajectory_iterations()
        if not have:
            raise FileNotFoundError(f"fig2: {run_dir} has no trajectories_iter*.npz files")
        iterations = sorted({have[0], have[len(have) // 2], have[-1]})
    iterations = [int(i) for i in iterations]
    out_png = Path(out_png) if out_png else run_dir / "figures" / "fig2.png"
    out_csv = Path(out_csv) if out_csv else out_png.with_suffix(".csv")
    trajs = [rd.trajectories(k) for k in iterations]

    n = len(iterations)
    fig, axes = plt.subplots(1, n, figsize=(4.2 * n + 0.4, 4.6), sharey=True, squeeze=False, layout="constrained")
    cmap = plt.get_cmap("Oranges")
    rows: list[list[Any]] = []
    for ax, k, tr in zip(axes[0], iterations, trajs):
        draw_world(ax, layout, geometry, scene.padding)
        feas = np.asarray(tr["feasible"], dtype=bool)
        N = feas.shape[0]
        best = int(tr.get("best", np.asarray(-1)))
        Z = tr.get("Z")
        if Z is None:
            Z = history.get(f"Z_{k:03d}")
        if Z is not None and Z.shape[0] != N:
            raise ValueError(f"fig2: iteration {k}: Z has {Z.shape[0]} rows but the trajectories {N}")
        sel = np.arange(N)
        if max_plans is not None and N > max_plans:
            rest = sel[sel != best][: max(max_plans - (best >= 0), 0)]
            sel = np.sort(np.concatenate([rest, [best] if best >= 0 else []]).astype(int))
        base = decimate_time(fill_nan_forward(tr["traj_base"][sel][..., :2]), max_points)
        # orange tones: a per-plan shade, darker and opaque for successful plans, pale for failures
        shade = np.linspace(0.35, 0.75, len(sel)) if len(sel) > 1 else np.array([0.55])
        rng = np.random.default_rng(k)
        shade = rng.permutation(shade)
        ok = feas[sel]
        colors = np.asarray(cmap(np.where(ok, shade + 0.2, shade - 0.1)))
        colors[:, 3] = np.where(ok, 0.85, 0.35)
        order = np.argsort(ok, kind="stable")  # failures first, successes drawn on top
        for j in order:
            if sel[j] == best:
                continue
            ax.plot(base[j, :, 0], base[j, :, 1], color=colors[j], lw=1.1 if ok[j] else 0.6, zorder=4 + ok[j])
        if Z is not None:
            for name in layout.names:
                xy = param_xy(layout, name, Z[sel])
                ax.scatter(xy[:, 0], xy[:, 1], marker="x", s=14, c=colors, linewidths=0.8, zorder=6)
                rows += [[k, int(i), bool(feas[i]), bool(i == best), name, 0, fmt(x), fmt(y)]
                         for i, (x, y) in zip(sel, xy)]
        t_idx = np.arange(base.shape[1])
        for j, i in enumerate(sel):
            rows += [[k, int(i), bool(feas[i]), bool(i == best), "base", int(s), fmt(x), fmt(y)]
                     for s, (x, y) in zip(t_idx, base[j])]
        if best >= 0:
            jb = int(np.nonzero(sel == best)[0][0])
            ax.plot(base[jb, :, 0], base[jb, :, 1], color=CYAN, lw=2.2, zorder=8)
            ee = decimate_time(fill_nan_forward(tr["traj_ee"][best : best + 1, :, :2]), max_points)[0]
            ax.plot(ee[:, 0], ee[:, 1], color=CYAN, lw=1.6, ls="--", zorder=8)
            rows += [[k, best, bool(feas[best]), True, "ee", int(s), fmt(x), fmt(y)] for s, (x, y) in enumerate(ee)]
            if Z is not None:
                bxy = np.stack([param_xy(layout, nm, Z[best : best + 1])[0] for nm in layout.names])
                ax.scatter(bxy[:, 0], bxy[:, 1], marker="x", s=40, c=CYAN, linewidths=2.0, zorder=9)
        share = feas.mean() if N else math.nan
        ax.set_title(f"Iteration {k}: {100 * share:.0f} % of {N} plans successful", fontsize=10)
        set_world_limits(ax, geometry)
    axes[0][0].set_ylabel("y [m]")
    handles = [
        Line2D([], [], color=cmap(0.8), lw=1.2, label="base (successful plan)"),
        Line2D([], [], color=cmap(0.4), lw=0.8, alpha=0.6, label="base (failed plan)"),
        Line2D([], [], color=cmap(0.7), marker="x", ls="none", label="sampled parameters"),
        Line2D([], [], color=CYAN, lw=2.2, label="best plan: base"),
        Line2D([], [], color=CYAN, lw=1.6, ls="--", label="best plan: end effector"),
        PathPatch(MplPath(np.zeros((1, 2))), facecolor=REGION_GREY, edgecolor=REGION_EDGE, label="parameter regions"),
        Patch(facecolor="black", edgecolor="black", label="tables and other obstacles"),
        Line2D([], [], color="#e032c8", marker="s", ms=4, ls="none", label="objects"),
        Line2D([], [], color="0.3", marker="o", ms=4, ls="none", label="robot start"),
    ]
    if scene.padding > 0:  # draw_world outlines each obstacle grown by the A* padding
        handles.append(Line2D([], [], color="black", lw=0.8, label=f"A* padding (+{100 * scene.padding:.0f} cm)"))
    fig.legend(handles=handles, loc="outside lower center", ncol=4, fontsize=8, frameon=False)
    out_png.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out_png, dpi=DPI)
    plt.close(fig)
    write_csv(out_csv, ["iteration", "sample", "feasible", "best", "series", "step", "x", "y"], rows)
    return out_png, out_csv
