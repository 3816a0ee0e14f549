"""Fig. 3 of the seed paper: each parameter's sampling distribution per CE iteration.

What it does: ``fig3(run_dir)`` draws, per parameter (not ``Fixed``), the 2-sigma axis-aligned
ellipse (x, y of 3-D parameters) of the distribution each iteration sampled from, coloured by
iteration, and the final refit (dashed); it writes the PNG and a CSV of the ellipses.
``sampling_distributions(history)`` is that sequence of distributions from ``history.npz``'s
arrays: iteration ``i`` sampled from the refit of iteration ``i - 1``; iteration 0 (uniform)
is shown with the moments of its samples; a mixture's heaviest mode. A stitched run
(``levers=stitched``) draws each parameter from its segment's history (``history_c1.npz``, the
prefix; ``history_c2.npz``, the suffix, which starts in round 1), one colour per round
(``stitched_distributions``).
What it doesn't: draw the other modes of a mixture (they are in ``mode_mean``/``mode_std``).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.colors import Normalize
from matplotlib.lines import Line2D
from matplotlib.patches import Ellipse

from realize.figures.common import DPI, REGION_EDGE, fmt, plt, write_csv
from realize.run_dir.directory import RunDir
from realize.run_dir.names import HISTORY_FILE, SCENE_FILE
from realize.tasks.topdown import ellipse_params, param_xy, planar_params, region_outlines

__all__ = ["fig3", "sampling_distributions", "stitched_distributions"]


def sampling_distributions(history: Mapping[str, np.ndarray]) -> tuple[np.ndarray, np.ndarray, list[str]]:
    """Mean and std ``(I + 1, D)`` of the distribution each iteration sampled from, plus the
    final refit as row ``I``; rows are NaN where unknown. Also a label per row (``uniform``,
    ``gaussian``, ``final``)."""
    mean = np.asarray(history["mean"], dtype=np.float64)
    std = np.asarray(history["std"], dtype=np.float64)
    n_it, d = mean.shape
    m = np.full((n_it + 1, d), np.nan)
    s = np.full((n_it + 1, d), np.nan)
    m[1:], s[1:] = mean, std
    labels = []
    for i in range(n_it + 1):
        uniform = not np.isfinite(m[i]).all()
        if uniform and i < n_it:
            Z = history.get(f"Z_{i:03d}")
            if Z is not None and Z.ndim == 2 and Z.shape[0] > 0:
                m[i], s[i] = Z.mean(axis=0), Z.std(axis=0)
        labels.append("final" if i == n_it else ("uniform" if uniform else "gaussian"))
    return m, s, labels


def stitched_distributions(rd: RunDir, columns: list[str], segments: int = 2) -> tuple[np.ndarray, np.ndarray, list[str]]:
    """``sampling_distributions`` of a stitched run over the whole plan's ``columns``: row ``r``
    holds round ``r``'s prefix distribution and the suffix's of the same round (the suffix's
    iteration ``r - 1``; none in round 0), the last row both final refits. A chain of
    ``segments``: segment j's distributions from round j on (histories 1 .. segments)."""
    hists = [rd.history_arrays(k) for k in range(1, segments + 1)]
    if any("mean" not in h for h in hists):
        raise FileNotFoundError(f"fig3: {rd.path} is a stitched run without every segment's history")
    dists = [sampling_distributions(h) for h in hists]
    mp, labels = dists[0][0], dists[0][2]
    mean, std = np.full((mp.shape[0], len(columns)), np.nan), np.full((mp.shape[0], len(columns)), np.nan)
    for h, (m, sd, _) in zip(hists, dists):
        cols = [columns.index(str(c)) for c in h["column_names"].tolist()]
        first = mp.shape[0] - m.shape[0]
        mean[first:, cols], std[first:, cols] = m, sd
    return mean, std, labels


def fig3(
    run_dir: str | Path,
    out_png: str | Path | None = None,
    out_csv: str | Path | None = None,
    n_sigma: float = 2.0,
    show_final: bool = True,
) -> tuple[Path, Path]:
    """Evolution of each parameter's normal distribution (the paper's Fig. 3): per parameter
    (not ``Fixed``), the ``n_sigma`` ellipse of the distribution each iteration sampled from
    (iteration 0: the uniform samples' moments), coloured by iteration, and the final refit.
    CSV rows: param, iteration, kind (uniform | gaussian | final), mean_x, mean_y, std_x, std_y,
    half_x, half_y."""
    rd = RunDir.existing(run_dir)
    history = rd.history_arrays()
    if "mean" not in history:
        raise FileNotFoundError(f"fig3: {rd.path} has no {HISTORY_FILE} with per-iteration mean/std")
    scene = rd.scene()
    if scene is None:
        raise FileNotFoundError(f"fig3: {rd.path} has no {SCENE_FILE} (or config) describing the parameters")
    layout = scene.layout
    names = [str(s) for s in history["column_names"].tolist()] if "column_names" in history else []
    if names and names != layout.column_names:
        raise ValueError(f"fig3: history columns {names} do not match the layout {layout.column_names}")
    run_dir = Path(run_dir)
    out_png = Path(out_png) if out_png else run_dir / "figures" / "fig3.png"
    out_csv = Path(out_csv) if out_csv else out_png.with_suffix(".csv")
    stitched = (rd.result_json() or {}).get("stitched")
    segments = len(stitched.get("splits") or [0]) + 1 if isinstance(stitched, dict) else 2
    mean, std, kinds = (stitched_distributions(rd, layout.column_names, segments) if stitched
                        else sampling_distributions(history))
    n_rows = mean.shape[0] if show_final else mean.shape[0] - 1
    params = planar_params(layout)
    ncol = min(len(params), 3)
    nrow = int(math.ceil(len(params) / ncol))
    fig, axes = plt.subplots(nrow, ncol, figsize=(3.6 * ncol + 1.0, 3.4 * nrow + 0.4), squeeze=False,
                             layout="constrained")
    # one colour per row, centred on integer ticks: the colour bar shows whole iterations only
    cmap = plt.get_cmap("viridis", max(n_rows, 1))
    norm = Normalize(vmin=-0.5, vmax=max(n_rows, 1) - 0.5)
    rows: list[list[Any]] = []
    for ax, p in zip(axes.flat, params):
        region = layout.regions[p]
        for o in region_outlines(region):
            ax.plot(o[:, 0], o[:, 1], color=REGION_EDGE, lw=1.0, zorder=1)
        los, his = [], []
        for i in range(n_rows):
            c, h = ellipse_params(layout, p, mean[i], std[i], n_sigma)
            if not np.isfinite(c).all() or not np.isfinite(h).all():  # (a stitched run's suffix in round 0)
                continue
            final = kinds[i] == "final"
            ax.add_patch(Ellipse(c, 2 * h[0], 2 * h[1], fill=False, lw=1.8 if final else 1.3,
                                 ls="--" if final else "-", edgecolor=cmap(norm(i)), zorder=2 + i))
            ax.plot(*c, marker=".", ms=3, color=cmap(norm(i)), zorder=2 + i)
            sx, sy = param_xy(layout, p, std[i][None])[0]
            rows.append([p, i, kinds[i], fmt(c[0]), fmt(c[1]), fmt(sx), fmt(sy), fmt(h[0]), fmt(h[1])])
            los.append(c - h)
            his.append(c + h)
        lo_b, hi_b = region.bounds()
        lo = np.minimum(np.min(los, axis=0) if los else np.inf, lo_b.numpy()[:2])
        hi = np.maximum(np.max(his, axis=0) if his else -np.inf, hi_b.numpy()[:2])
        pad = 0.08 * float(np.max(hi - lo)) + 1e-3
        ax.set_xlim(lo[0] - pad, hi[0] + pad)
        ax.set_ylim(lo[1] - pad, hi[1] + pad)
        ax.set_aspect("equal")
        dims = region.coord_names
        ax.set_title(f"{p} ({'x, y of ' + ', '.join(dims) if len(dims) > 2 else ', '.join(dims)})", fontsize=10)
        ax.set_xlabel("x [m]")
        ax.set_ylabel("y [m]")
        ax.tick_params(labelsize=8)
    for ax in list(axes.flat)[len(params):]:
        ax.set_visible(False)
    sm = plt.cm.ScalarMappable(norm=norm, cmap=cmap)
    cb = fig.colorbar(sm, ax=axes.ravel().tolist(), shrink=0.8, pad=0.02)
    step = max(1, int(math.ceil(n_rows / 12)))  # at most ~12 labels
    ticks = sorted(set(range(0, n_rows, step)) | ({n_rows - 1} if n_rows else set()))
    cb.set_ticks(ticks, labels=["final" if show_final and t == n_rows - 1 else str(t) for t in ticks])
    cb.minorticks_off()
    final = " (final: the last refit, dashed)" if show_final else ""
    cb.set_label(("round" if stitched else "CE iteration") + final)
    handles = [Line2D([], [], color=REGION_EDGE, lw=1.0, label="parameter region"),
               Line2D([], [], color=cmap(norm(0)), lw=1.3, label=f"sampling distribution ({n_sigma:g} sigma)")]
    if show_final:
        handles.append(Line2D([], [], color=cmap(norm(n_rows - 1)), lw=1.8, ls="--", label="final refit"))
    fig.legend(handles=handles, loc="outside lower center", ncol=len(handles), fontsize=8, frameon=False)
    per = "round of the stitched search" if stitched else "CE iteration"
    fig.suptitle(f"Sampling distribution per {per} ({n_sigma:g}-sigma ellipses)", fontsize=11)
    out_png.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out_png, dpi=DPI)
    plt.close(fig)
    write_csv(out_csv, ["param", "iteration", "kind", "mean_x", "mean_y", "std_x", "std_y", "half_x", "half_y"],
               rows)
    return out_png, out_csv
