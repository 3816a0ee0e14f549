"""Log a cross-entropy run to a rerun ``.rrd`` file on a ``ce_iteration`` timeline.

What it does: ``RerunLogger`` writes a recording (no viewer needed) and, per CE iteration, logs

* each parameter's sampling distribution as an axis-aligned 2-sigma ellipse (2-D parameters, and
  the first two columns (x, y) of 3-D ones), the ellipses of all iterations so far coloured by
  iteration (the paper's Fig. 3), the mean and the samples coloured by success;
* scalars: best cost so far, best cost of the iteration, elite cost min/mean/max, share of
  successful samples, sample counts, evaluation time; and a text line with failure reasons;
* through ``realize.recording.scene``, the top-down scene (the paper's Fig. 2: obstacles, regions,
  objects, start) once, and per iteration the sampled parameters, the base trajectories of all
  samples coloured by success and the iteration's best plan;
* through ``realize.recording.world3d`` (given the plan), the world in 3-D under ``/world3d``: its boxes,
  the robot's links, objects and current action along each iteration's best plan on the
  ``control_step`` timeline, every sample's parameters in 3-D with its failure reason.
The recording gets the default blueprint of ``realize.recording.paths`` (where the entity paths and
the scalar series are defined). Logged coordinates are world (x, y) in metres; the roots
``/world`` and ``/distributions`` carry a y-flip transform so that rerun's 2-D views (which draw
+y downwards) show +y upwards like a map. Non-finite scalars (``inf`` best cost before any
success, ``NaN`` elite stats) are not logged, so a plot has no point for that iteration.
``realize.recording.read.read_rrd_summary`` reads a finished file back.

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

from realize.world.geometry import SceneGeometry
from realize.tasks.param_layout import ParamLayout
from realize.recording.paths import (
    ENTITY_DIST,
    ENTITY_LOG,
    ENTITY_STATS,
    SCALAR_PATHS,
    TIMELINE,
    blueprint,
    entity,
    param_path,
)
from realize.recording.world3d import Scene3D
from realize.recording.scene import log_static_scene, log_trajectories, log_world_samples
from realize.tasks.topdown import ellipse_params, iteration_colors, param_xy, planar_params, success_colors, to_numpy

if TYPE_CHECKING:  # avoid importing the simulator stack just for a type
    from realize.search.ce.state import IterationRecord
    from realize.realization.result import RolloutResult
    from realize.robot.spec import RobotSpec

__all__ = ["RerunLogger"]


class RerunLogger:
    """Write a CE run to ``path`` (a ``.rrd`` file) as it goes; ``close()`` finishes the file.

    ``layout`` gives the parameter names and regions; ``geometry`` the static world; ``padding``
    the obstacle inflation drawn around each box (the A* padding, 0.2 m in the paper).
    ``n_iterations`` (optional) sets the scale of the per-iteration colours (default: 10, or
    the largest iteration seen). ``max_traj_points`` caps the time samples per logged trajectory
    (evenly strided, the last kept); ``max_trajectories`` caps how many of an iteration's
    trajectories are logged (all successful ones first, then failures by rank; ``None``: all).
    ``plan`` (the action names, in order) turns on the 3-D view (``realize.recording.world3d``) with
    ``control_freq`` (Hz) and the ``robot`` to draw. Usable as a context manager.
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
        plan: list[str] | None = None,
        control_freq: float = 20.0,
        robot: RobotSpec | None = None,
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
        self.scene3d = None if plan is None else Scene3D(self.rec, layout, geometry, plan, control_freq, robot)
        self._log_static(y_up)
        if self.scene3d is not None:
            self.scene3d.log_static()

    # ---- context manager -----------------------------------------------------------------

    def __enter__(self) -> RerunLogger:
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()

    @property
    def closed(self) -> bool:
        return self._closed

    # ---- blueprint and static scene ----------------------------------------------------

    def blueprint(self) -> rrb.Blueprint:
        """Default layout: top-down scene | cost and success plots | one view per parameter."""
        return blueprint(self.params)

    def _log_static(self, y_up: bool) -> None:
        log_static_scene(self.rec, self.layout, self.geometry, self.padding, self._history, y_up)
        for path, (_, series, rgb) in SCALAR_PATHS.items():
            self.rec.log(path, rr.SeriesLines(colors=[rgb], names=[series], widths=[2.0]), static=True)
            self.rec.log(path, rr.SeriesPoints(colors=[rgb], names=[series], marker_sizes=[3.0]), static=True)

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
        if self.scene3d is not None:  # everything of iteration k also sits at control_step k * STEP_STRIDE
            self.scene3d.set_iteration(it)

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
        log_world_samples(rec, self.layout, Z, colors, best)
        log_trajectories(rec, rollout, feasible, best, cost, self.max_traj_points, self.max_trajectories)
        self._log_text(record, rollout)
        if self.scene3d is not None:
            self.scene3d.log_samples(it, Z, colors, None if rollout is None else rollout.failure)
            self.scene3d.log_best_plan(it, rollout, best)

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
            self.rec.log(entity(ENTITY_STATS, "time", "rollout_s"), rr.Scalars(float(rollout.wall_time_s)))

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
                    param_path(ENTITY_DIST, p, "sigma2"),
                    rr.Ellipses2D(centers=cs, half_sizes=hs, colors=[col] * len(cs),
                                  line_radii=0.012, labels=labels, draw_order=30.0),
                )
                rec.log(
                    param_path(ENTITY_DIST, p, "history"),
                    rr.Ellipses2D(centers=np.stack([c_ for _, c_, _ in hist]),
                                  half_sizes=np.stack([h_ for _, _, h_ in hist]),
                                  colors=cols, line_radii=0.006, draw_order=29.0),
                )
                rec.log(param_path(ENTITY_DIST, p, "mean"),
                        rr.Points2D(cs, colors=[col] * len(cs), radii=0.025, draw_order=31.0))
            else:
                for leaf in ("sigma2", "mean"):
                    rec.log(param_path(ENTITY_DIST, p, leaf), rr.Clear(recursive=False))
            if Z is not None:
                rec.log(param_path(ENTITY_DIST, p, "samples"),
                        rr.Points2D(param_xy(self.layout, p, Z), colors=colors, radii=radii, draw_order=25.0))
            else:
                rec.log(param_path(ENTITY_DIST, p, "samples"), rr.Clear(recursive=False))

    def _log_text(self, record: IterationRecord, rollout: RolloutResult | None) -> None:
        msg = (
            f"iteration {record.iteration}: {record.n_feasible}/{record.n_envs} successful "
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
