"""The figures' inputs as a sink: ``scene.json`` once, ``trajectories_iter{k}.npz`` per iteration.

What it does: ``TrajectorySink`` writes the scene (layout, geometry, A* padding) when opened and,
for every iteration whose rollout recorded trajectories (``logging.record``), the sampled base
and end-effector paths with the iteration's best feasible sample marked (the record's
``best_idx``: the first elite unless kNN-robust ranking reordered them). Only for single-plan
runs (the figure readers assume one parameter layout); a stitched run's are its whole-plan
batches (``whole_plans_only``: the confirmation), its segments' layouts being the plan's parts. Not critical.
What it doesn't: draw (``realize.figures``) or define the file format (``realize.run_dir.scene_files``).
"""

from __future__ import annotations

from typing import Any

from realize.tasks.param_layout import ParamLayout
from realize.run_dir.directory import RunDir
from realize.sinks.base import Iteration

__all__ = ["TrajectorySink"]


class TrajectorySink:
    """``scene.json`` and ``trajectories_iter{k}.npz`` (see the module docstring)."""

    name = "figure trajectory files"
    critical = False

    def __init__(self, run_dir: RunDir, layout: ParamLayout, geometry: Any, padding: float,
                 record: bool = True, whole_plans_only: bool = False) -> None:
        self.rd, self.layout, self.geometry, self.padding = run_dir, layout, geometry, padding
        self.wants_trajectories = record  # logging.record: without it only scene.json is written
        self.whole_plans_only = whole_plans_only  # a stitched run: only batches of the whole plan (candidate None)

    def open(self) -> None:
        self.rd.write_scene(self.layout, self.geometry, padding=self.padding)

    def on_iteration(self, it: Iteration) -> None:
        rec, res = it.record, it.rollout
        if res.traj_base is None or (self.whole_plans_only and it.batch.candidate is not None):
            return
        top = int(rec.best_idx) if rec.elite_idx.numel() or rec.n_remembered else -1  # (ce.keep_elites: maybe none)
        best = top if top >= 0 and bool(rec.feasible[top]) else -1
        self.rd.write_trajectories(rec.iteration, res.traj_base, res.traj_ee, res.feasible, best,
                                   Z=rec.Z, cost=res.cost, progress=res.progress, traj_t=res.traj_t)

    def close(self, status: str | None, error: str | None) -> None:
        pass
