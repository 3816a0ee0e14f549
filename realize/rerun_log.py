"""Log a cross-entropy run to a rerun ``.rrd`` file on a ``ce_iteration`` timeline.

What it does: ``RerunLogger`` writes a recording (no viewer needed) that shows, per CE iteration,

* each parameter's sampling distribution as an axis-aligned 2-sigma ellipse (2-D parameters, and
  the first two columns (x, y) of 3-D ones), the ellipses of all iterations so far coloured by
  iteration (the paper's Fig. 3), the mean and the samples coloured by success;
* scalars: best cost so far, best cost of the iteration, elite cost min/mean/max, share of
  successful samples, sample counts, evaluation time;
* a top-down scene (the paper's Fig. 2): obstacle footprints, padded obstacles (rounded
  rectangles, as the A* grid inflates them), the parameter regions projected on the floor, the
  exit box, the cube and the robot's start; per iteration the sampled parameters, the base
  trajectories of all samples coloured by success, and the iteration's best plan: its base path,
  its end-effector path (xy) and its parameters;
* a default blueprint: the top-down scene, cost and success-share plots, and a grid with one
  distribution view per parameter.

Entity paths (``ENTITY_*`` below): ``/world/...`` for the scene, ``/distributions/<param>/...``,
``/stats/...``, ``/log``. Logged coordinates are world (x, y) in metres; the roots ``/world`` and
``/distributions`` carry a y-flip transform so that rerun's 2-D views (which draw +y downwards)
show +y upwards like a map. Non-finite scalars (``inf`` best cost before any success, ``NaN``
elite stats) are not logged, so a plot has no point for that iteration.

``read_rrd_summary`` reads a finished file back with ``rerun.chunk.RrdReader`` (entity paths,
per-iteration scalars, ellipses and instance counts), for tests and quick checks.

What it doesn't: open a viewer, stream over the network, read simulator state, or decide what
the sampling distribution was: the caller passes it (see ``RerunLogger.log_iteration``).
"""

from __future__ import annotations

from collections import Counter
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import rerun as rr
import rerun.blueprint as rrb

from envs.geometry import SceneGeometry
from realize.regions import ParamLayout
from realize.topdown import (
    BEST_RGB,
    decimate_time,
    ellipse_params,
    fill_nan_forward,
    iteration_colors,
    obstacle_outline,
    padded_outline,
    param_xy,
    planar_params,
    rectangle,
    region_outlines,
    success_colors,
    to_numpy,
)

if TYPE_CHECKING:  # avoid importing the simulator stack just for a type
    from realize.cross_entropy import IterationRecord
    from realize.realization.result import RolloutResult

__all__ = ["RerunLogger", "read_rrd_summary", "TIMELINE", "SCALAR_PATHS"]

TIMELINE = "ce_iteration"

ENTITY_WORLD = "world"
ENTITY_DIST = "distributions"
ENTITY_STATS = "stats"
ENTITY_LOG = "log"

# scalar entity -> (IterationRecord attribute or special key, series name, colour)
SCALAR_PATHS: dict[str, tuple[str, str, tuple[int, int, int]]] = {
    "stats/cost/best": ("best_cost", "best cost (all iterations)", (20, 90, 200)),
    "stats/cost/iteration_best": ("iteration_best_cost", "best cost (this iteration)", (100, 160, 240)),
    "stats/cost/elite_min": ("elite_cost_min", "elite cost min", (120, 120, 120)),
    "stats/cost/elite_mean": ("elite_cost_mean", "elite cost mean", (60, 60, 60)),
    "stats/cost/elite_max": ("elite_cost_max", "elite cost max", (170, 170, 170)),
    "stats/success/share": ("success_share", "share of successful samples", (40, 170, 70)),
    "stats/samples/n_samples": ("n_samples", "samples", (90, 90, 90)),
    "stats/samples/n_feasible": ("n_feasible", "successful samples", (40, 170, 70)),
    "stats/time/eval_s": ("eval_time", "evaluation time [s]", (200, 120, 40)),
}

_GREY_REGION = (175, 175, 175, 255)
_BLACK = (20, 20, 20, 255)
_PAD = (110, 110, 110, 255)


def _entity(*parts: str) -> str:
    """Join entity-path parts with "/" (empty parts dropped)."""
    out = []
    for p in parts:
        for q in str(p).split("/"):
            if q:
                out.append(q)
    return "/".join(out)


def _param_path(root: str, name: str, *rest: str) -> str:
    # parameter names are identifiers in practice; escape anything rerun treats specially
    safe = "".join(ch if (ch.isalnum() or ch in "_-.") else "_" for ch in name)
    return _entity(root, safe, *rest)


class RerunLogger:
    """Write a CE run to ``path`` (a ``.rrd`` file) as it goes; ``close()`` finishes the file.

    ``layout`` gives the parameter names and regions; ``geometry`` the static world; ``padding``
    the obstacle inflation drawn around each box (the A* padding, 0.2 m in the paper).
    ``n_iterations`` (optional) sets the scale of the per-iteration colours (default: 10, or
    the largest iteration seen). ``max_traj_points`` caps the time samples per logged trajectory
    (evenly strided, the last kept); ``max_trajectories`` caps how many of an iteration's
    trajectories are logged (all successful ones first, then failures by rank; ``None``: all).
    Usable as a context manager.
    """

    def __init__(
        self,
        path: str | Path,
        layout: ParamLayout,
        geometry: SceneGeometry,
        padding: float = 0.2,
        application_id: str = "realize",
        *,
        recording_id: str | None = None,
        n_iterations: int | None = None,
        max_traj_points: int = 200,
        max_trajectories: int | None = None,
        y_up: bool = True,
        blueprint: bool = True,
    ) -> None:
        if padding < 0:
            raise ValueError(f"padding must be >= 0, got {padding}")
        if max_traj_points < 2:
            raise ValueError(f"max_traj_points must be >= 2, got {max_traj_points}")
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self.layout = layout
        self.geometry = geometry
        self.padding = float(padding)
        self.n_iterations = n_iterations
        self.max_traj_points = int(max_traj_points)
        self.max_trajectories = max_trajectories
        self.params = planar_params(layout)
        self._closed = False
        self._history: dict[str, list[tuple[int, np.ndarray, np.ndarray]]] = {p: [] for p in self.params}
        self.rec = rr.RecordingStream(application_id, recording_id=recording_id)
        self.rec.save(self.path, default_blueprint=self.blueprint() if blueprint else None)
        self._log_static(y_up)

    # ---- context manager -----------------------------------------------------------------

    def __enter__(self) -> RerunLogger:
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()

    @property
    def closed(self) -> bool:
        return self._closed

    # ---- blueprint -----------------------------------------------------------------------

    def blueprint(self) -> rrb.Blueprint:
        """Default layout: top-down scene | cost and success plots | one view per parameter."""
        dist_views = [
            rrb.Spatial2DView(
                name=f"{p} distribution",
                origin="/",
                contents=[f"+ /{_param_path(ENTITY_DIST, p)}/**", f"+ /{ENTITY_DIST}"],
            )
            for p in self.params
        ]
        plots = rrb.Vertical(
            rrb.TimeSeriesView(name="Cost", origin=f"/{ENTITY_STATS}/cost"),
            rrb.TimeSeriesView(
                name="Success share",
                origin=f"/{ENTITY_STATS}/success",
                axis_y=rrb.ScalarAxis(range=(0.0, 1.0)),
            ),
            rrb.TextLogView(name="Log", origin=f"/{ENTITY_LOG}"),
            row_shares=[2, 2, 1],
        )
        scene = rrb.Spatial2DView(name="Top-down scene", origin="/", contents=[f"+ /{ENTITY_WORLD}/**"])
        return rrb.Blueprint(
            rrb.Horizontal(
                scene,
                plots,
                rrb.Grid(*dist_views, name="Distributions") if dist_views else rrb.Vertical(),
                column_shares=[3, 2, 3],
            ),
            rrb.TimePanel(state="expanded"),
            collapse_panels=False,
        )

    # ---- static scene --------------------------------------------------------------------

    def _log_static(self, y_up: bool) -> None:
        rec, g = self.rec, self.geometry
        if y_up:
            flip = rr.Transform3D(scale=[1.0, -1.0, 1.0])
            rec.log(ENTITY_WORLD, flip, static=True)
            rec.log(ENTITY_DIST, flip, static=True)
        boxes = list(g.obstacles)
        if boxes:
            rec.log(
                _entity(ENTITY_WORLD, "obstacles"),
                rr.LineStrips2D(
                    [obstacle_outline(b) for b in boxes],
                    colors=[_BLACK] * len(boxes),
                    radii=0.02,
                    labels=[b.name for b in boxes],
                    draw_order=20.0,
                ),
                static=True,
            )
            if self.padding > 0:
                rec.log(
                    _entity(ENTITY_WORLD, "obstacles_padded"),
                    rr.LineStrips2D(
                        [padded_outline(b, self.padding) for b in boxes],
                        colors=[_PAD] * len(boxes),
                        radii=0.008,
                        draw_order=19.0,
                    ),
                    static=True,
                )
        rec.log(
            _entity(ENTITY_WORLD, "exit"),
            rr.LineStrips2D(
                [rectangle((np.add(g.exit_low, g.exit_high)) / 2, np.subtract(g.exit_high, g.exit_low) / 2)],
                colors=[(120, 120, 200, 255)],
                radii=0.01,
                labels=["exit"],
                draw_order=11.0,
            ),
            static=True,
        )
        rec.log(
            _entity(ENTITY_WORLD, "bounds"),
            rr.LineStrips2D(
                [rectangle(np.add(g.bounds_low, g.bounds_high) / 2, np.subtract(g.bounds_high, g.bounds_low) / 2)],
                colors=[(210, 210, 210, 255)],
                radii=0.01,
                draw_order=1.0,
            ),
            static=True,
        )
        rec.log(
            _entity(ENTITY_WORLD, "cube"),
            rr.Points2D([g.cube_pos[:2]], colors=[(230, 50, 200, 255)], radii=max(g.cube_half_size, 0.03),
                        labels=["cube"], draw_order=45.0),
            static=True,
        )
        sx, sy, syaw = g.robot_start
        rec.log(
            _entity(ENTITY_WORLD, "robot_start"),
            rr.Arrows2D(origins=[[sx, sy]], vectors=[[0.4 * np.cos(syaw), 0.4 * np.sin(syaw)]],
                        colors=[(60, 60, 60, 255)], radii=0.02, labels=["start"], draw_order=45.0),
            static=True,
        )
        for name, region in self.layout.regions.items():
            outlines = region_outlines(region)
            if not outlines:
                continue
            arch = rr.LineStrips2D(outlines, colors=[_GREY_REGION] * len(outlines), radii=0.01,
                                   labels=[name] + [""] * (len(outlines) - 1), draw_order=10.0)
            rec.log(_param_path(f"{ENTITY_WORLD}/regions", name), arch, static=True)
            if name in self._history:
                rec.log(_param_path(ENTITY_DIST, name, "region"), arch, static=True)
        for path, (_, series, rgb) in SCALAR_PATHS.items():
            rec.log(path, rr.SeriesLines(colors=[rgb], names=[series], widths=[2.0]), static=True)
            rec.log(path, rr.SeriesPoints(colors=[rgb], names=[series], marker_sizes=[3.0]), static=True)

    # ---- per iteration -------------------------------------------------------------------

    def log_iteration(
        self,
        record: IterationRecord,
        rollout: RolloutResult | None = None,
        mean: Any = None,
        std: Any = None,
        weights: Any = None,
    ) -> None:
        """Log one CE iteration at ``ce_iteration = record.iteration``.

        ``mean``/``std`` (D,) are the distribution this iteration's samples were drawn from
        (i.e. the previous record's ``mean``/``std``); a mixture passes (k, D) and its
        ``weights`` (k,), and every mode with a positive weight gets its own ellipse. ``None`` (the uniform iteration 0) logs
        the moments of the samples ``record.Z`` instead (what ``CEState.init_mean``/``init_std``
        hold). ``rollout`` (optional) adds the base trajectories, the best plan's paths and
        failure reasons; without trajectories those entities are cleared for this iteration.
        """
        if self._closed:
            raise RuntimeError("RerunLogger.log_iteration after close()")
        rec = self.rec
        it = int(record.iteration)
        rec.set_time(TIMELINE, sequence=it)

        Z = to_numpy(record.Z, np.float64)
        cost = to_numpy(record.cost, np.float64)
        feasible = to_numpy(record.feasible, bool)
        progress = to_numpy(record.progress, np.float64)
        n_actions = None
        if rollout is not None:
            n_actions = int(to_numpy(rollout.action_success).shape[1])
            if progress is None:
                progress = to_numpy(rollout.progress, np.float64)
        colors = success_colors(feasible, progress, n_actions)
        elite = to_numpy(record.elite_idx, np.int64).reshape(-1)
        best = self._best_index(elite, cost, feasible, int(getattr(record, "best_idx", -1)))

        mean_np = to_numpy(mean, np.float64)
        std_np = to_numpy(std, np.float64)
        weights_np = to_numpy(weights, np.float64)
        if (mean_np is None or std_np is None) and Z is not None:
            mean_np, std_np, weights_np = Z.mean(axis=0), Z.std(axis=0), None
        self._log_scalars(record, rollout)
        self._log_distributions(it, Z, colors, elite, mean_np, std_np, weights_np)
        self._log_samples(Z, colors, best)
        self._log_trajectories(rollout, feasible, best, cost)
        self._log_text(record, rollout)

    @staticmethod
    def _best_index(elite: np.ndarray, cost: np.ndarray, feasible: np.ndarray, best_idx: int = -1) -> int:
        """The iteration's best sample: with elites, the record's ``best_idx`` (the first elite
        unless robust kNN scoring reordered them), else the lowest-cost feasible sample, else -1."""
        if elite.size:
            return best_idx if best_idx >= 0 else int(elite[0])
        if feasible.any():
            return int(np.where(feasible, np.nan_to_num(cost, nan=np.inf), np.inf).argmin())
        return -1

    def _log_scalars(self, record: IterationRecord, rollout: RolloutResult | None) -> None:
        for path, (attr, _, _) in SCALAR_PATHS.items():
            v = getattr(record, attr, None)
            if v is None:
                continue
            v = float(v)
            if np.isfinite(v):
                self.rec.log(path, rr.Scalars(v))
        if rollout is not None and np.isfinite(rollout.wall_time_s):
            self.rec.log(_entity(ENTITY_STATS, "time", "rollout_s"), rr.Scalars(float(rollout.wall_time_s)))

    def _log_distributions(
        self,
        it: int,
        Z: np.ndarray | None,
        colors: np.ndarray,
        elite: np.ndarray,
        mean: np.ndarray | None,
        std: np.ndarray | None,
        weights: np.ndarray | None = None,
    ) -> None:
        rec = self.rec
        modes: list[tuple[np.ndarray, np.ndarray]] = []
        labels = [f"it {it}"]
        if mean is not None and std is not None and mean.ndim == 2:
            w = np.ones(mean.shape[0]) if weights is None else weights
            live = [j for j in range(mean.shape[0]) if w[j] > 0]
            modes = [(mean[j], std[j]) for j in live]
            labels = [f"it {it} mode {j} ({w[j]:.0%})" for j in live]
        elif mean is not None and std is not None:
            modes = [(mean, std)]
        n_it = self.n_iterations or max(10, it + 1)
        radii = None
        if Z is not None:
            radii = np.full(Z.shape[0], 0.012, dtype=np.float32)
            radii[elite[elite < Z.shape[0]]] = 0.03
        for p in self.params:
            if modes:
                cs, hs = [], []
                for m_, s_ in modes:
                    c, h = ellipse_params(self.layout, p, m_, s_)
                    cs.append(c)
                    hs.append(h)
                hist = self._history[p]
                hist.extend((it, c, h) for c, h in zip(cs, hs))
                its = np.array([k for k, _, _ in hist])
                cols = iteration_colors(its, n_it)
                col = tuple(cols[-1]) + (255,)
                rec.log(
                    _param_path(ENTITY_DIST, p, "sigma2"),
                    rr.Ellipses2D(centers=cs, half_sizes=hs, colors=[col] * len(cs),
                                  line_radii=0.012, labels=labels, draw_order=30.0),
                )
                rec.log(
                    _param_path(ENTITY_DIST, p, "history"),
                    rr.Ellipses2D(centers=np.stack([c_ for _, c_, _ in hist]),
                                  half_sizes=np.stack([h_ for _, _, h_ in hist]),
                                  colors=cols, line_radii=0.006, draw_order=29.0),
                )
                rec.log(_param_path(ENTITY_DIST, p, "mean"),
                        rr.Points2D(cs, colors=[col] * len(cs), radii=0.025, draw_order=31.0))
            else:
                for leaf in ("sigma2", "mean"):
                    rec.log(_param_path(ENTITY_DIST, p, leaf), rr.Clear(recursive=False))
            if Z is not None:
                rec.log(_param_path(ENTITY_DIST, p, "samples"),
                        rr.Points2D(param_xy(self.layout, p, Z), colors=colors, radii=radii, draw_order=25.0))
            else:
                rec.log(_param_path(ENTITY_DIST, p, "samples"), rr.Clear(recursive=False))

    def _log_samples(self, Z: np.ndarray | None, colors: np.ndarray, best: int) -> None:
        rec = self.rec
        for name in self.layout.names:
            path = _param_path(f"{ENTITY_WORLD}/samples", name)
            if Z is None:
                rec.log(path, rr.Clear(recursive=False))
            else:
                rec.log(path, rr.Points2D(param_xy(self.layout, name, Z), colors=colors, radii=0.015,
                                          draw_order=40.0))
        bp = _entity(ENTITY_WORLD, "best", "params")
        if Z is None or best < 0:
            rec.log(bp, rr.Clear(recursive=False))
        else:
            pts = np.stack([param_xy(self.layout, n, Z[best : best + 1])[0] for n in self.layout.names])
            rec.log(bp, rr.Points2D(pts, colors=[BEST_RGB + (255,)] * len(pts), radii=0.035,
                                    labels=self.layout.names, draw_order=52.0))

    def _log_trajectories(
        self, rollout: RolloutResult | None, feasible: np.ndarray, best: int, cost: np.ndarray
    ) -> None:
        rec = self.rec
        paths = {k: _entity(ENTITY_WORLD, *k.split(".")) for k in
                 ("trajectories.succeeded", "trajectories.failed", "best.base", "best.ee")}
        base = None if rollout is None else to_numpy(rollout.traj_base, np.float64)
        if base is None or base.ndim != 3 or base.shape[0] != feasible.shape[0]:
            for p in paths.values():
                rec.log(p, rr.Clear(recursive=False))
            return
        base = decimate_time(fill_nan_forward(base[..., :2]), self.max_traj_points)
        progress = to_numpy(rollout.progress, np.float64)
        n_actions = int(to_numpy(rollout.action_success).shape[1])
        colors = success_colors(feasible, progress, n_actions, alpha=150)
        keep = np.isfinite(base).all(axis=(1, 2))
        if self.max_trajectories is not None and keep.sum() > self.max_trajectories:
            # successes first (by cost), then failures by progress: a stable lexicographic sort
            key_cost = np.where(feasible, np.nan_to_num(cost, nan=np.inf), np.inf)
            order = np.lexsort((key_cost, -(progress if progress is not None else 0 * cost), ~feasible))
            order = order[keep[order]][: self.max_trajectories]
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
            ee_b = decimate_time(fill_nan_forward(ee[best : best + 1, :, :2]), self.max_traj_points)[0]
            # rerun has no dashed lines: the EE path is thinner and lighter than the base path
            rec.log(paths["best.ee"], rr.LineStrips2D([ee_b], colors=[(120, 235, 255, 255)], radii=0.012,
                                                      labels=["best EE"], draw_order=51.0))
        else:
            rec.log(paths["best.ee"], rr.Clear(recursive=False))

    def _log_text(self, record: IterationRecord, rollout: RolloutResult | None) -> None:
        msg = (
            f"iteration {record.iteration}: {record.n_feasible}/{record.n_samples} successful "
            f"({100 * record.success_share:.1f} %), best cost {record.best_cost:.1f}, "
            f"sampled {record.sampled_from}, refit {record.refit}"
        )
        if rollout is not None and rollout.failure:
            reasons = Counter(f.split(":", 1)[1] if ":" in f else f for f in rollout.failure if f)
            if reasons:
                msg += "; failures: " + ", ".join(f"{k} x{v}" for k, v in reasons.most_common(5))
        self.rec.log(ENTITY_LOG, rr.TextLog(msg, level=rr.TextLogLevel.INFO))

    # ---- finish --------------------------------------------------------------------------

    def close(self) -> None:
        """Flush and disconnect, so the file gets its footer. Idempotent."""
        if self._closed:
            return
        self._closed = True
        self.rec.flush()
        self.rec.disconnect()


# --------------------------------------------------------------------------------------------
# reading back
# --------------------------------------------------------------------------------------------

_PRIMARY = (
    "Scalars:scalars",
    "Ellipses2D:half_sizes",
    "Points2D:positions",
    "LineStrips2D:strips",
    "Arrows2D:vectors",
    "TextLog:text",
)


def read_rrd_summary(path: str | Path) -> dict[str, Any]:
    """Read a ``.rrd`` written by ``RerunLogger`` (or any recording on ``ce_iteration``).

    Returns a dict with
    ``entity_paths`` (sorted, with leading ``/``), ``static_paths``, ``iterations`` (sorted
    ``ce_iteration`` values), ``scalars`` ``{path: {iteration: value}}``, ``per_iteration``
    ``{iteration: {path: value}}`` (the same scalars by iteration), ``ellipses``
    ``{path: {iteration: {"centers": [[x, y], ...], "half_sizes": [[hx, hy], ...]}}}``,
    ``counts`` ``{path: {iteration: number of instances}}`` for points/strips/ellipses/arrows/
    text (0 for a clear), ``application_id``, ``recording_id`` and ``n_blueprints``.
    """
    import rerun.chunk as rc

    reader = rc.RrdReader(str(path))
    recs = reader.recordings()
    if not recs:
        raise ValueError(f"{path}: no recording store in the file")
    store = reader.stream(store=recs[0]).collect()
    entity_paths: set[str] = set()
    static_paths: set[str] = set()
    iterations: set[int] = set()
    scalars: dict[str, dict[int, float]] = {}
    ellipses: dict[str, dict[int, dict[str, list]]] = {}
    counts: dict[str, dict[int, int]] = {}
    for ch in store.stream().to_chunks():
        ep = ch.entity_path
        if ep.startswith("/__"):
            continue
        entity_paths.add(ep)
        rb = ch.to_record_batch()
        names = rb.schema.names
        if ch.is_static or TIMELINE not in names:
            static_paths.add(ep)
            continue
        its = [int(v) for v in rb.column(TIMELINE).to_pylist()]
        iterations.update(its)
        cleared = rb.column("Clear:is_recursive").to_pylist() if "Clear:is_recursive" in names else [None] * len(its)
        for comp in _PRIMARY:
            if comp not in names:
                continue
            vals = rb.column(comp).to_pylist()
            for i, v in zip(its, vals):
                if v is None:
                    continue
                counts.setdefault(ep, {})[i] = len(v)
                if comp == "Scalars:scalars" and len(v):
                    scalars.setdefault(ep, {})[i] = float(v[0])
            if comp == "Ellipses2D:half_sizes":
                cents = rb.column("Ellipses2D:centers").to_pylist() if "Ellipses2D:centers" in names else [None] * len(its)
                for i, h, c in zip(its, vals, cents):
                    if h is not None:
                        ellipses.setdefault(ep, {})[i] = {"centers": c or [], "half_sizes": h}
        for i, clr in zip(its, cleared):
            if clr is not None:
                counts.setdefault(ep, {}).setdefault(i, 0)
    per_iteration: dict[int, dict[str, float]] = {}
    for ep, d in scalars.items():
        for i, v in d.items():
            per_iteration.setdefault(i, {})[ep] = v
    return {
        "application_id": recs[0].application_id,
        "recording_id": recs[0].recording_id,
        "n_blueprints": len(reader.blueprints()),
        "entity_paths": sorted(entity_paths),
        "static_paths": sorted(static_paths),
        "iterations": sorted(iterations),
        "scalars": {k: dict(sorted(v.items())) for k, v in sorted(scalars.items())},
        "per_iteration": dict(sorted(per_iteration.items())),
        "ellipses": ellipses,
        "counts": counts,
    }
