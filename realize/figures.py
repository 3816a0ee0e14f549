"""The paper's figures (Figs. 2, 3 and 4 of the seed paper) from run directories, as PNG + CSV.

What it does: reads the files a run of ``realize`` (``realize.app``) leaves in its run directory
and draws, with matplotlib (Agg backend, no display needed):

* ``fig2`` – sampled plans of chosen CE iterations projected on the ground plane: base
  trajectories (orange tones, darker for successful plans), the sampled parameters as crosses,
  the iteration's best plan (base path cyan solid, end-effector path cyan dashed), the regions in
  light grey, the tables in black with their padding outline;
* ``fig3`` – the evolution of each parameter's sampling distribution: 2-sigma axis-aligned
  ellipses per iteration (x, y of 3-D parameters), coloured by iteration;
* ``fig4`` – best sampled cost per iteration (left axis) and share of successful samples (right
  axis), mean over runs with a +-1 sigma band.

Each writes the PNG and a CSV with exactly the numbers plotted. ``scripts/fig2.py``,
``scripts/fig3.py`` and ``scripts/fig4.py`` are the command-line entry points.

What it doesn't: run simulations (``scripts/fig4.py`` launches runs of the app as subprocesses)
or make up data: every figure reads real run files.

Run-directory files read here
-----------------------------
``result.json`` (written by the app): ``success_per_iter`` (list, share in [0, 1]),
``best_cost_per_iter`` (list, best feasible cost so far, ``null`` before any success); its
``config`` (the resolved run config) is the fallback source of the scene (see ``scene.json``).

``history.npz`` (``realize.results.History``): ``column_names`` (D,), ``mean``/``std`` (I, D),
the distribution *after* each iteration's refit (NaN while still uniform), and per iteration
``i`` (3-digit zero padded) ``Z_{i:03d}`` (N_i, D), ``cost_{i:03d}``, ``feasible_{i:03d}``
(N_i,), ``elite_idx_{i:03d}`` (K,). The sampling distribution of iteration ``i`` is therefore
``mean[i-1]``/``std[i-1]``; iteration 0 (uniform) is shown with the moments of ``Z_000``.
For a mixture (``ce.n_modes > 1``) ``mean``/``std`` hold its heaviest mode, which is what
fig3 draws (the other modes are in ``mode_mean``/``mode_std``/``mode_weight``, unused here).

``scene.json`` (write it with ``save_scene``): ``{"layout": ParamLayout.to_dict(),
"geometry": dataclasses.asdict(SceneGeometry), "padding": float}``. Without it the scene is
rebuilt from ``result.json["config"]`` (``task.params``, ``scene``,
``controller.astar.padding``).

``trajectories_iter{k}.npz`` (write it with ``save_trajectories``; ``k`` is the iteration, not
zero padded): ``traj_base`` (N, T, 2) float32 base (x, y) per recorded step, ``traj_ee``
(N, T, 3) float32 end-effector position, ``feasible`` (N,) bool, ``best`` () int64 index of the
iteration's best sample (-1 if none), and optionally ``Z`` (N, D) float64 (else taken from
``history.npz``), ``cost`` (N,) float64, ``progress`` (N,) float64, ``traj_t`` (T,) float32
seconds. Non-finite trajectory samples are forward-filled when drawn.
"""

from __future__ import annotations

import csv
import dataclasses
import json
import math
import os
import subprocess
import sys
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
from matplotlib.colors import Normalize  # noqa: E402
from matplotlib.lines import Line2D  # noqa: E402
from matplotlib.patches import Ellipse, PathPatch, Polygon  # noqa: E402
from matplotlib.path import Path as MplPath  # noqa: E402
import numpy as np  # noqa: E402

from realize.geometry import Box as ObstacleBox  # noqa: E402
from realize.geometry import GeometryCfg, SceneGeometry, build_geometry  # noqa: E402
from realize.param_layout import ParamLayout  # noqa: E402
from realize.regions import Fixed  # noqa: E402
from realize.topdown import (  # noqa: E402
    decimate_time,
    ellipse_params,
    fill_nan_forward,
    obstacle_outline,
    padded_outline,
    param_xy,
    planar_params,
    region_outlines,
    to_numpy,
)

__all__ = [
    "RunData",
    "load_run",
    "save_scene",
    "save_trajectories",
    "load_trajectories",
    "trajectories_path",
    "geometry_from_dict",
    "fig2",
    "fig3",
    "fig4",
    "find_run_dirs",
    "run_command",
    "launch_runs",
    "SCENE_FILE",
    "TRAJ_PATTERN",
]

SCENE_FILE = "scene.json"
TRAJ_PATTERN = "trajectories_iter{k}.npz"
RESULT_FILE = "result.json"
HISTORY_FILE = "history.npz"

CYAN = "#00c8e6"
REGION_GREY = "#d9d9d9"
REGION_EDGE = "#b0b0b0"
DPI = 150


# --------------------------------------------------------------------------------------------
# writing (called by the app)
# --------------------------------------------------------------------------------------------


def save_scene(run_dir: str | Path, layout: ParamLayout, geometry: SceneGeometry, padding: float = 0.2) -> Path:
    """Write ``scene.json``: what the figures need to draw the world and the regions."""
    path = Path(run_dir) / SCENE_FILE
    path.parent.mkdir(parents=True, exist_ok=True)
    doc = {"layout": layout.to_dict(), "geometry": dataclasses.asdict(geometry), "padding": float(padding)}
    path.write_text(json.dumps(doc, indent=2) + "\n")
    return path


def trajectories_path(run_dir: str | Path, iteration: int) -> Path:
    return Path(run_dir) / TRAJ_PATTERN.format(k=int(iteration))


def save_trajectories(
    run_dir: str | Path,
    iteration: int,
    traj_base: Any,
    traj_ee: Any,
    feasible: Any,
    best: int,
    *,
    Z: Any = None,
    cost: Any = None,
    progress: Any = None,
    traj_t: Any = None,
) -> Path:
    """Write ``trajectories_iter{iteration}.npz`` (format in the module docstring).

    Accepts torch tensors or arrays; with a ``RolloutResult`` ``r`` and an ``IterationRecord``
    ``rec``: ``save_trajectories(d, rec.iteration, r.traj_base, r.traj_ee, r.feasible, best,
    Z=rec.Z, cost=r.cost, progress=r.progress, traj_t=r.traj_t)``.
    """
    base = to_numpy(traj_base, np.float32)
    ee = to_numpy(traj_ee, np.float32)
    feas = to_numpy(feasible, bool)
    if base is None or base.ndim != 3 or base.shape[2] < 2:
        raise ValueError(f"traj_base must be (N, T, 2), got {None if base is None else base.shape}")
    n, t = base.shape[:2]
    if ee is None or ee.shape[:2] != (n, t):
        raise ValueError(f"traj_ee must be (N, T, 3) with N={n}, T={t}, got {None if ee is None else ee.shape}")
    if feas is None or feas.shape != (n,):
        raise ValueError(f"feasible must be ({n},), got {None if feas is None else feas.shape}")
    arrays: dict[str, np.ndarray] = {
        "traj_base": base[..., :2],
        "traj_ee": ee,
        "feasible": feas,
        "best": np.asarray(int(best), dtype=np.int64),
    }
    for key, v, dt in (("Z", Z, np.float64), ("cost", cost, np.float64), ("progress", progress, np.float64),
                       ("traj_t", traj_t, np.float32)):
        a = to_numpy(v, dt)
        if a is not None:
            arrays[key] = a
    path = trajectories_path(run_dir, iteration)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + ".tmp.npz")
    np.savez_compressed(tmp, **arrays)
    tmp.replace(path)
    return path


def load_trajectories(run_dir: str | Path, iteration: int) -> dict[str, np.ndarray]:
    path = trajectories_path(run_dir, iteration)
    if not path.is_file():
        have = sorted(p.name for p in Path(run_dir).glob("trajectories_iter*.npz"))
        raise FileNotFoundError(f"{path} does not exist (have: {have or 'none'}); the app writes it when "
                                "trajectories are recorded (logging.record=true)")
    with np.load(path, allow_pickle=False) as z:
        return {k: z[k] for k in z.files}


# --------------------------------------------------------------------------------------------
# reading a run directory
# --------------------------------------------------------------------------------------------


def geometry_from_dict(d: Mapping[str, Any]) -> SceneGeometry:
    """Inverse of ``dataclasses.asdict(SceneGeometry)``."""

    def box(b: Mapping[str, Any]) -> ObstacleBox:
        kw = {k: (tuple(v) if isinstance(v, list) else v) for k, v in b.items()}
        return ObstacleBox(**kw)

    kw: dict[str, Any] = {}
    for f in dataclasses.fields(SceneGeometry):
        if f.name not in d and f.default is not dataclasses.MISSING:
            continue  # written before the field existed
        v = d[f.name]
        if f.name in ("tables", "extras", "containers"):
            v = tuple(box(b) for b in v)
        elif f.name == "stick":
            v = None if v is None else box(v)
        elif isinstance(v, list):
            v = tuple(v)
        kw[f.name] = v
    return SceneGeometry(**kw)


def _nan_float(v: Any) -> float:
    if v is None:
        return math.nan
    try:
        return float(v)
    except (TypeError, ValueError):
        return math.nan


@dataclass
class RunData:
    """What a run directory holds, loaded lazily by the figure functions."""

    run_dir: Path
    result: dict[str, Any] = field(default_factory=dict)
    history: dict[str, np.ndarray] = field(default_factory=dict)
    layout: ParamLayout | None = None
    geometry: SceneGeometry | None = None
    padding: float = 0.2

    @property
    def n_iterations(self) -> int:
        if "mean" in self.history:
            return int(self.history["mean"].shape[0])
        return len(self.success_per_iter())

    @property
    def column_names(self) -> list[str]:
        if "column_names" in self.history:
            return [str(s) for s in self.history["column_names"].tolist()]
        return self.layout.column_names if self.layout is not None else []

    def iter_array(self, key: str, i: int) -> np.ndarray | None:
        a = self.history.get(f"{key}_{i:03d}")
        return None if a is None else np.asarray(a)

    def success_per_iter(self) -> np.ndarray:
        if "success_per_iter" in self.result:
            return np.array([_nan_float(v) for v in self.result["success_per_iter"]], dtype=np.float64)
        if "success_share" in self.history:
            return np.asarray(self.history["success_share"], dtype=np.float64)
        return np.zeros(0)

    def best_cost_per_iter(self) -> np.ndarray:
        if "best_cost_per_iter" in self.result:
            c = np.array([_nan_float(v) for v in self.result["best_cost_per_iter"]], dtype=np.float64)
        elif "best_cost" in self.history:
            c = np.asarray(self.history["best_cost"], dtype=np.float64)
        else:
            return np.zeros(0)
        return np.where(np.isfinite(c), c, np.nan)

    def sampling_distributions(self) -> tuple[np.ndarray, np.ndarray, list[str]]:
        """Mean and std ``(I + 1, D)`` of the distribution each iteration sampled from, plus the
        final refit as row ``I``; rows are NaN where unknown. Also a label per row."""
        mean = np.asarray(self.history["mean"], dtype=np.float64)
        std = np.asarray(self.history["std"], dtype=np.float64)
        n_it, d = mean.shape
        m = np.full((n_it + 1, d), np.nan)
        s = np.full((n_it + 1, d), np.nan)
        m[1:], s[1:] = mean, std
        labels = []
        for i in range(n_it + 1):
            uniform = not np.isfinite(m[i]).all()
            if uniform and i < n_it:
                Z = self.iter_array("Z", i)
                if Z is not None and Z.ndim == 2 and Z.shape[0] > 0:
                    m[i], s[i] = Z.mean(axis=0), Z.std(axis=0)
            labels.append("final" if i == n_it else ("uniform" if uniform else "gaussian"))
        return m, s, labels


def _scene_from_config(cfg: Mapping[str, Any]) -> tuple[ParamLayout, SceneGeometry, float] | None:
    try:
        geometry = build_geometry(GeometryCfg.from_mapping(cfg["scene"]))
        params = cfg.get("task", {}).get("params")
        if cfg.get("task_file"):
            import yaml

            p = Path(str(cfg["task_file"]))
            if p.is_file():
                params = (yaml.safe_load(p.read_text()) or {}).get("params", params)
        layout = ParamLayout.from_dict(params)
        padding = float(cfg.get("controller", {}).get("astar", {}).get("padding", 0.2))
    except Exception:  # a partial or foreign config: the caller reports what is missing
        return None
    return layout, geometry, padding


def load_run(run_dir: str | Path) -> RunData:
    """Read ``result.json``, ``history.npz`` and the scene of a run directory (what exists)."""
    run_dir = Path(run_dir)
    if not run_dir.is_dir():
        raise FileNotFoundError(f"{run_dir} is not a directory")
    data = RunData(run_dir=run_dir)
    rp = run_dir / RESULT_FILE
    if rp.is_file():
        data.result = json.loads(rp.read_text())
    hp = run_dir / HISTORY_FILE
    if hp.is_file():
        with np.load(hp, allow_pickle=False) as z:
            data.history = {k: z[k] for k in z.files}
    sp = run_dir / SCENE_FILE
    if sp.is_file():
        doc = json.loads(sp.read_text())
        data.layout = ParamLayout.from_dict(doc["layout"])
        data.geometry = geometry_from_dict(doc["geometry"])
        data.padding = float(doc.get("padding", 0.2))
    else:
        cfg = data.result.get("config")
        if not isinstance(cfg, Mapping):
            ck = run_dir / "checkpoint.json"
            cfg = json.loads(ck.read_text()).get("config") if ck.is_file() else None
        scene = _scene_from_config(cfg) if isinstance(cfg, Mapping) else None
        if scene is not None:
            data.layout, data.geometry, data.padding = scene
    if not data.result and not data.history:
        raise FileNotFoundError(f"{run_dir} holds neither {RESULT_FILE} nor {HISTORY_FILE}: not a realize run directory")
    return data


def _require_scene(data: RunData, who: str) -> tuple[ParamLayout, SceneGeometry]:
    if data.layout is None or data.geometry is None:
        raise FileNotFoundError(f"{who}: {data.run_dir} has no {SCENE_FILE} and its result.json config does not "
                                "describe the scene (task.params, scene)")
    return data.layout, data.geometry


def _write_csv(path: Path, header: Sequence[str], rows: Sequence[Sequence[Any]]) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    with path.open("w", newline="") as f:
        w = csv.writer(f)
        w.writerow(header)
        w.writerows(rows)


def _fmt(v: Any) -> Any:
    if isinstance(v, (float, np.floating)):
        return "" if not np.isfinite(v) else float(f"{float(v):.6g}")
    if isinstance(v, np.integer):
        return int(v)
    if isinstance(v, np.bool_):
        return bool(v)
    return v


# --------------------------------------------------------------------------------------------
# drawing helpers
# --------------------------------------------------------------------------------------------


def _draw_world(ax: Any, layout: ParamLayout, geometry: SceneGeometry, padding: float) -> None:
    """Regions (light grey fill), tables/extras (black) with the padding outline, cube, start."""
    for name, region in layout.regions.items():
        outlines = region_outlines(region)
        if not outlines:
            continue
        if isinstance(region, Fixed):
            for o in outlines:
                ax.plot(o[:, 0], o[:, 1], color=REGION_EDGE, lw=1.0, zorder=1)
            continue
        # outer + inner outlines as one compound path
        # (inner outlines reversed, so that the non-zero fill rule leaves an annulus' hole empty)
        rings = [outlines[0]] + [o[::-1] for o in outlines[1:]]
        path = MplPath.make_compound_path(*[MplPath(o) for o in rings])
        ax.add_patch(PathPatch(path, facecolor=REGION_GREY, edgecolor=REGION_EDGE, lw=0.6, alpha=0.7, zorder=1))
    for b in geometry.obstacles:
        if padding > 0:
            p = padded_outline(b, padding)
            ax.plot(p[:, 0], p[:, 1], color="black", lw=0.8, zorder=3)
        ax.add_patch(Polygon(obstacle_outline(b)[:-1], closed=True, facecolor="black", edgecolor="black", zorder=3))
    ax.plot(*geometry.cube_pos[:2], marker="s", ms=4, color="#e032c8", zorder=9, ls="none")
    sx, sy, syaw = geometry.robot_start
    ax.annotate("", xy=(sx + 0.35 * math.cos(syaw), sy + 0.35 * math.sin(syaw)), xytext=(sx, sy),
                arrowprops=dict(arrowstyle="->", color="0.3", lw=1.2), zorder=9)
    ax.plot(sx, sy, marker="o", ms=4, color="0.3", zorder=9, ls="none")


def _set_world_limits(ax: Any, geometry: SceneGeometry) -> None:
    ax.set_xlim(geometry.bounds_low[0], geometry.bounds_high[0])
    ax.set_ylim(geometry.bounds_low[1], geometry.bounds_high[1])
    ax.set_aspect("equal", adjustable="box")
    ax.set_xlabel("x [m]")


# --------------------------------------------------------------------------------------------
# Fig. 2
# --------------------------------------------------------------------------------------------


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
    data = load_run(run_dir)
    layout, geometry = _require_scene(data, "fig2")
    run_dir = Path(run_dir)
    if iterations is None or len(iterations) == 0:
        have = sorted(int(p.stem.removeprefix("trajectories_iter")) for p in run_dir.glob("trajectories_iter*.npz")
                      if p.stem.removeprefix("trajectories_iter").isdigit())
        if not have:
            raise FileNotFoundError(f"fig2: {run_dir} has no trajectories_iter*.npz files")
        iterations = sorted({have[0], have[len(have) // 2], have[-1]})
    iterations = [int(i) for i in iterations]
    out_png = Path(out_png) if out_png else run_dir / "figures" / "fig2.png"
    out_csv = Path(out_csv) if out_csv else out_png.with_suffix(".csv")
    trajs = [load_trajectories(run_dir, k) for k in iterations]

    n = len(iterations)
    fig, axes = plt.subplots(1, n, figsize=(4.2 * n + 0.4, 4.6), sharey=True, squeeze=False, layout="constrained")
    cmap = plt.get_cmap("Oranges")
    rows: list[list[Any]] = []
    for ax, k, tr in zip(axes[0], iterations, trajs):
        _draw_world(ax, layout, geometry, data.padding)
        feas = np.asarray(tr["feasible"], dtype=bool)
        N = feas.shape[0]
        best = int(tr.get("best", np.asarray(-1)))
        Z = tr.get("Z")
        if Z is None:
            Z = data.iter_array("Z", k)
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
                rows += [[k, int(i), bool(feas[i]), bool(i == best), name, 0, _fmt(x), _fmt(y)]
                         for i, (x, y) in zip(sel, xy)]
        t_idx = np.arange(base.shape[1])
        for j, i in enumerate(sel):
            rows += [[k, int(i), bool(feas[i]), bool(i == best), "base", int(s), _fmt(x), _fmt(y)]
                     for s, (x, y) in zip(t_idx, base[j])]
        if best >= 0:
            jb = int(np.nonzero(sel == best)[0][0])
            ax.plot(base[jb, :, 0], base[jb, :, 1], color=CYAN, lw=2.2, zorder=8)
            ee = decimate_time(fill_nan_forward(tr["traj_ee"][best : best + 1, :, :2]), max_points)[0]
            ax.plot(ee[:, 0], ee[:, 1], color=CYAN, lw=1.6, ls="--", zorder=8)
            rows += [[k, best, bool(feas[best]), True, "ee", int(s), _fmt(x), _fmt(y)] for s, (x, y) in enumerate(ee)]
            if Z is not None:
                bxy = np.stack([param_xy(layout, nm, Z[best : best + 1])[0] for nm in layout.names])
                ax.scatter(bxy[:, 0], bxy[:, 1], marker="x", s=40, c=CYAN, linewidths=2.0, zorder=9)
        share = feas.mean() if N else math.nan
        ax.set_title(f"Iteration {k}: {100 * share:.0f} % of {N} plans successful", fontsize=10)
        _set_world_limits(ax, geometry)
    axes[0][0].set_ylabel("y [m]")
    handles = [
        Line2D([], [], color=cmap(0.8), lw=1.2, label="base (successful plan)"),
        Line2D([], [], color=cmap(0.4), lw=0.8, alpha=0.6, label="base (failed plan)"),
        Line2D([], [], color=cmap(0.7), marker="x", ls="none", label="sampled parameters"),
        Line2D([], [], color=CYAN, lw=2.2, label="best plan: base"),
        Line2D([], [], color=CYAN, lw=1.6, ls="--", label="best plan: end effector"),
        PathPatch(MplPath(np.zeros((1, 2))), facecolor=REGION_GREY, edgecolor=REGION_EDGE, label="parameter regions"),
        Line2D([], [], color="black", lw=4, label=f"tables (+{100 * data.padding:.0f} cm padding)"),
    ]
    fig.legend(handles=handles, loc="outside lower center", ncol=4, fontsize=8, frameon=False)
    out_png.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out_png, dpi=DPI)
    plt.close(fig)
    _write_csv(out_csv, ["iteration", "sample", "feasible", "best", "series", "step", "x", "y"], rows)
    return out_png, out_csv


# --------------------------------------------------------------------------------------------
# Fig. 3
# --------------------------------------------------------------------------------------------


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
    data = load_run(run_dir)
    if "mean" not in data.history:
        raise FileNotFoundError(f"fig3: {data.run_dir} has no {HISTORY_FILE} with per-iteration mean/std")
    layout = data.layout
    if layout is None:
        raise FileNotFoundError(f"fig3: {data.run_dir} has no {SCENE_FILE} (or config) describing the parameters")
    names = data.column_names
    if names and names != layout.column_names:
        raise ValueError(f"fig3: history columns {names} do not match the layout {layout.column_names}")
    run_dir = Path(run_dir)
    out_png = Path(out_png) if out_png else run_dir / "figures" / "fig3.png"
    out_csv = Path(out_csv) if out_csv else out_png.with_suffix(".csv")
    mean, std, kinds = data.sampling_distributions()
    n_rows = mean.shape[0] if show_final else mean.shape[0] - 1
    params = planar_params(layout)
    ncol = min(len(params), 3)
    nrow = int(math.ceil(len(params) / ncol))
    fig, axes = plt.subplots(nrow, ncol, figsize=(3.6 * ncol + 1.0, 3.4 * nrow + 0.4), squeeze=False,
                             layout="constrained")
    cmap = plt.get_cmap("viridis")
    norm = Normalize(vmin=0, vmax=max(n_rows - 1, 1))
    rows: list[list[Any]] = []
    for ax, p in zip(axes.flat, params):
        region = layout.regions[p]
        for o in region_outlines(region):
            ax.plot(o[:, 0], o[:, 1], color=REGION_EDGE, lw=1.0, zorder=1)
        los, his = [], []
        for i in range(n_rows):
            if not np.isfinite(mean[i]).all() or not np.isfinite(std[i]).all():
                continue
            c, h = ellipse_params(layout, p, mean[i], std[i], n_sigma)
            final = kinds[i] == "final"
            ax.add_patch(Ellipse(c, 2 * h[0], 2 * h[1], fill=False, lw=1.8 if final else 1.3,
                                 ls="--" if final else "-", edgecolor=cmap(norm(i)), zorder=2 + i))
            ax.plot(*c, marker=".", ms=3, color=cmap(norm(i)), zorder=2 + i)
            sx, sy = param_xy(layout, p, std[i][None])[0]
            rows.append([p, i, kinds[i], _fmt(c[0]), _fmt(c[1]), _fmt(sx), _fmt(sy), _fmt(h[0]), _fmt(h[1])])
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
    cb.set_label("CE iteration" + (" (last: final refit, dashed)" if show_final else ""))
    fig.suptitle(f"Sampling distribution per CE iteration ({n_sigma:g}-sigma ellipses)", fontsize=11)
    out_png.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out_png, dpi=DPI)
    plt.close(fig)
    _write_csv(out_csv, ["param", "iteration", "kind", "mean_x", "mean_y", "std_x", "std_y", "half_x", "half_y"],
               rows)
    return out_png, out_csv


# --------------------------------------------------------------------------------------------
# Fig. 4
# --------------------------------------------------------------------------------------------


def find_run_dirs(paths: Sequence[str | Path]) -> list[Path]:
    """Run directories among ``paths``: each path that holds a ``result.json``, else its
    sub-directories (one level, e.g. a Hydra multirun folder) that do, sorted."""
    out: list[Path] = []
    for p in map(Path, paths):
        if (p / RESULT_FILE).is_file():
            out.append(p)
        elif p.is_dir():
            out += sorted(q for q in p.iterdir() if (q / RESULT_FILE).is_file())
    return out


def fig4(
    run_dirs: Sequence[str | Path],
    out_png: str | Path,
    out_csv: str | Path | None = None,
) -> tuple[Path, Path]:
    """Best sampled cost per iteration (left axis) and share of successful samples (right axis,
    in %), mean over runs with a +-1 sigma band (the paper's Fig. 4). A run's cost before its
    first success is missing and left out of that iteration's mean (``n_cost`` in the CSV).
    CSV rows: iteration, cost_mean, cost_std, n_cost, share_mean, share_std, n_share, then
    ``cost_<run>`` and ``share_<run>`` per run."""
    runs = [load_run(d) for d in run_dirs]
    if not runs:
        raise ValueError("fig4: no run directories")
    n_it = max(max(len(r.best_cost_per_iter()), len(r.success_per_iter())) for r in runs)
    if n_it == 0:
        raise ValueError("fig4: the runs hold no per-iteration results (best_cost_per_iter / success_per_iter)")

    def padded(a: np.ndarray) -> np.ndarray:
        return np.concatenate([a, np.full(n_it - len(a), np.nan)])

    cost = np.stack([padded(r.best_cost_per_iter()) for r in runs])  # (R, I)
    share = 100.0 * np.stack([padded(r.success_per_iter()) for r in runs])

    def stats(a: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        n = np.isfinite(a).sum(axis=0)
        with np.errstate(invalid="ignore", divide="ignore"):
            s = np.where(n > 0, np.nansum(a, axis=0), np.nan) / np.where(n > 0, n, 1)
            dev = np.sqrt(np.where(n > 0, np.nansum((a - s) ** 2, axis=0), np.nan) / np.where(n > 0, n, 1))
        return s, dev, n

    c_mean, c_std, c_n = stats(cost)
    s_mean, s_std, s_n = stats(share)
    it = np.arange(n_it)
    out_png = Path(out_png)
    out_csv = Path(out_csv) if out_csv else out_png.with_suffix(".csv")

    fig, ax = plt.subplots(figsize=(6.0, 3.8))
    c_col, s_col = "#1f5fbf", "#e07b00"
    ax.plot(it, c_mean, color=c_col, lw=2, marker="o", ms=3.5, label="best sampled cost")
    ax.fill_between(it, c_mean - c_std, c_mean + c_std, color=c_col, alpha=0.2, lw=0)
    ax.set_xlabel("CE iteration")
    ax.set_ylabel("cost of the best sampled plan", color=c_col)
    ax.tick_params(axis="y", colors=c_col)
    ax.set_xticks(it)
    ax.grid(alpha=0.3)
    ax2 = ax.twinx()
    ax2.plot(it, s_mean, color=s_col, lw=2, marker="s", ms=3.5, label="successful samples")
    ax2.fill_between(it, np.clip(s_mean - s_std, 0, 100), np.clip(s_mean + s_std, 0, 100), color=s_col,
                     alpha=0.2, lw=0)
    ax2.set_ylabel("successful sampled plans [%]", color=s_col)
    ax2.tick_params(axis="y", colors=s_col)
    ax2.set_ylim(0, 100)
    lines = ax.get_lines()[:1] + ax2.get_lines()[:1]
    ax.legend(lines, [ln.get_label() for ln in lines], loc="center right", fontsize=8)
    ax.set_title(f"Mean over {len(runs)} runs, band = \u00b11 \u03c3", fontsize=10)
    fig.tight_layout()
    out_png.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out_png, dpi=DPI)
    plt.close(fig)

    names = [r.run_dir.name or str(r.run_dir) for r in runs]
    if len(set(names)) != len(names):
        names = [f"{j}" for j in range(len(runs))]
    header = ["iteration", "cost_mean", "cost_std", "n_cost", "share_mean", "share_std", "n_share"]
    header += [f"cost_{n}" for n in names] + [f"share_{n}" for n in names]
    rows = [
        [int(i), _fmt(c_mean[i]), _fmt(c_std[i]), int(c_n[i]), _fmt(s_mean[i]), _fmt(s_std[i]), int(s_n[i])]
        + [_fmt(v) for v in cost[:, i]]
        + [_fmt(v) for v in share[:, i]]
        for i in it
    ]
    _write_csv(out_csv, header, rows)
    return out_png, out_csv


# --------------------------------------------------------------------------------------------
# launching the runs behind Fig. 4
# --------------------------------------------------------------------------------------------


def _hydra_value(path: Path) -> str:
    """A path as a Hydra override value (quoted if it holds characters Hydra would parse)."""
    s = str(path)
    safe = all(ch.isalnum() or ch in "/._-~+:" for ch in s)
    return s if safe else "'" + s.replace("\\", "\\\\").replace("'", "\\'") + "'"


def run_status(run_dir: str | Path) -> str | None:
    """``status`` of a run directory's ``result.json`` (``done``, ``running``, ``interrupted``,
    ``failed``), ``"unknown"`` if it has none, ``None`` without a ``result.json``."""
    p = Path(run_dir) / RESULT_FILE
    if not p.is_file():
        return None
    try:
        return str(json.loads(p.read_text()).get("status", "unknown"))
    except (OSError, json.JSONDecodeError):
        return None


def run_command(
    seed: int,
    run_dir: str | Path,
    experiment: str = "seed_paper",
    overrides: Sequence[str] = (),
    module: str = "realize",
    python: str | None = None,
) -> list[str]:
    """The command line of one run: ``python -m realize experiment=E seed=S hydra.run.dir=D``;
    an interrupted run (its ``checkpoint.json`` exists, status not ``done``/``failed``) is
    continued with ``resume=D`` instead."""
    py = python or sys.executable
    run_dir = Path(run_dir)
    if run_status(run_dir) in ("running", "interrupted") and (run_dir / "checkpoint.json").is_file():
        return [py, "-m", module, f"resume={_hydra_value(run_dir)}", f"hydra.run.dir={_hydra_value(run_dir)}"]
    return [py, "-m", module, f"experiment={experiment}", f"seed={int(seed)}",
            f"hydra.run.dir={_hydra_value(run_dir)}", *overrides]


def launch_runs(
    seeds: Sequence[int],
    root: str | Path,
    experiment: str = "seed_paper",
    overrides: Sequence[str] = (),
    *,
    module: str = "realize",
    jobs: int = 1,
    force: bool = False,
    env: Mapping[str, str] | None = None,
    echo: Callable[[str], None] = print,
) -> tuple[list[Path], list[tuple[int, int]]]:
    """Run the app once per seed into ``<root>/seed<S>`` (subprocesses, ``jobs`` at a time; the
    output of each goes to ``<root>/seed<S>.log``). Runs whose ``result.json`` says ``done`` are
    kept unless ``force``; interrupted ones are resumed. Returns the run directories that
    finished (status ``done``) and ``(seed, exit code)`` of those that did not."""
    root = Path(root)
    root.mkdir(parents=True, exist_ok=True)
    run_env = dict(os.environ if env is None else env)

    def one(seed: int) -> tuple[int, Path, int]:
        d = root / f"seed{seed}"
        if not force and run_status(d) == "done":
            echo(f"seed {seed}: {d} already done, kept")
            return seed, d, 0
        cmd = run_command(seed, d, experiment, overrides, module=module)
        echo(f"seed {seed}: {' '.join(cmd[1:])}")
        with (root / f"seed{seed}.log").open("w") as logf:
            rc = subprocess.run(cmd, stdout=logf, stderr=subprocess.STDOUT, env=run_env, check=False).returncode
        echo(f"seed {seed}: exit code {rc}, status {run_status(d)}")
        return seed, d, rc

    with ThreadPoolExecutor(max_workers=max(1, int(jobs))) as ex:
        results = list(ex.map(one, [int(s) for s in seeds]))
    done = [d for _, d, _ in results if run_status(d) == "done"]
    failed = [(s, rc) for s, d, rc in results if run_status(d) != "done"]
    return done, failed
