"""Rerun recordings as a sink: one ``.rrd`` per plan searched, written as the run goes.

What it does: ``RerunSink`` opens a ``realize.recording.log.RerunLogger`` for a plan when its first
iteration arrives (``logging.rrd``, ``<stem>_c{i}.rrd`` per candidate of a top-k run; a resumed
run's plan that already has iterations gets ``<name>.from-it{k}.rrd``) and logs every
iteration with the distribution its batch was drawn from (mixture weights included), and the
run in 3-D when given the plans' actions (``realize.recording.world3d``: the robot along each iteration's
best plan on the ``control_step`` timeline). Not
critical: if it fails, the run goes on without recordings (``realize.sinks.base.SinkSet``).
What it doesn't: define what is drawn (``realize.recording.log``).
"""

from __future__ import annotations

import logging
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from realize.tasks.param_layout import ParamLayout
from realize.sinks.base import Iteration

__all__ = ["RerunSink", "recording_name"]

log = logging.getLogger("realize")


def recording_name(rrd: str, candidate: int | None, start_iteration: int) -> str:
    """``realize.rrd`` -> ``realize_c1.rrd`` (candidate 1) -> ``realize_c1.from-it3.rrd`` (a
    segment that starts after 3 iterations of that plan)."""
    p = Path(rrd)
    stem = p.stem if candidate is None else f"{p.stem}_c{candidate}"
    if start_iteration > 0:
        stem = f"{stem}.from-it{start_iteration}"
    return str(p.with_name(stem + p.suffix))


class RerunSink:
    """One recording per plan (see the module docstring). ``plans`` maps a batch's candidate
    (``None`` for a single plan) to ``(file path, layout)``; ``record``: ask the rollout for trajectories (``logging.record``)."""

    name = "rerun recording"
    critical = False

    def __init__(self, plans: Mapping[int | None, tuple[Path, ParamLayout]], geometry: Any, padding: float,
                 n_iterations: int, record: bool = True, *, actions: Mapping[int | None, list[str]] | None = None,
                 control_freq: float = 20.0, robot: Any = None) -> None:
        self.plans = dict(plans)
        # the 3-D view (realize.recording.world3d): each plan's action names, the control rate, the robot
        self.actions = dict(actions or {})
        self.control_freq, self.robot = control_freq, robot
        self.wants_trajectories = record  # the scene view shows sample trajectories when recorded
        self.geometry, self.padding, self.n_iterations = geometry, padding, n_iterations
        self.loggers: dict[int | None, Any] = {}
        self._logger_cls: Any = None

    def open(self) -> None:
        from realize.recording.log import RerunLogger

        self._logger_cls = RerunLogger

    def on_iteration(self, it: Iteration) -> None:
        key = it.batch.candidate
        lg = self.loggers.get(key)
        if lg is None:
            path, layout = self.plans[key]
            lg = self.loggers[key] = self._logger_cls(path, layout, self.geometry, padding=self.padding,
                                                      n_iterations=self.n_iterations, plan=self.actions.get(key),
                                                      control_freq=self.control_freq, robot=self.robot)
        lg.log_iteration(it.record, it.rollout, it.batch.mean, it.batch.std, it.batch.weights)

    def close(self, status: str | None, error: str | None) -> None:
        for lg in self.loggers.values():
            try:
                lg.close()
            except Exception as e:  # pragma: no cover
                log.warning("closing the rerun recording %s failed: %s", getattr(lg, "path", ""), e)
        self.loggers.clear()
