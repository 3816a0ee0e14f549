"""What the planner's calls take and return: the replan budget, the timings and the result.

What it does: ``ReplanBudget`` (the small search of one replan, as run-config overrides; a
settings group of its own, ``realize.execution.replan_budget``, here for the planner's callers),
``PlanTimings`` (where a call's time went) and ``PlanResult`` (the typed result of
``realize.run.planner.Planner.plan`` / ``replan`` / ``resequence``).
What it doesn't: run anything (``realize.run.planner``).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

from realize.run.assembly import RunOutcome
from realize.execution.replan_budget import ReplanBudget

__all__ = ["ReplanBudget", "PlanTimings", "PlanResult"]


@dataclass(frozen=True)
class PlanTimings:
    """Where a call's wall time went (s): workers and scenes (built or taken over), the search,
    the validation after it, and everything (config, files) in ``total_s``."""

    setup_s: float
    search_s: float
    validation_s: float
    total_s: float

    def to_dict(self) -> dict[str, float]:
        return {"setup_s": self.setup_s, "search_s": self.search_s, "validation_s": self.validation_s,
                "total_s": self.total_s}


@dataclass(frozen=True)
class PlanResult:
    """What ``plan``/``replan`` return. ``plan`` is the realized plan's text (a replan's: the
    remaining actions), ``actions`` its actions, ``params`` the returned plan's parameters by
    name (``z`` over ``columns``, the validation's returned candidate where there is one; with
    no feasible plan the search's best-ranked sample), ``cost`` its cost (inf if infeasible), ``validation`` the result.json block (None: none),
    ``run_dir`` where everything is. ``from_action``: the first action of the whole plan it
    realizes (0 for ``plan``); ``scene``: ``"built"`` (new workers), ``"rebuilt"`` (new scenes
    in the running workers: the world's layout changed) or ``"kept"`` (an earlier call's). ``outcome``: the run's ``RunOutcome`` (status, exit code)."""

    plan: str
    actions: tuple[str, ...]
    params: dict[str, list[float]]
    z: tuple[float, ...]
    columns: tuple[str, ...]
    cost: float
    feasible: bool
    status: str
    iterations_done: int
    validation: dict[str, Any] | None
    run_dir: Path
    timings: PlanTimings
    outcome: RunOutcome
    from_action: int = 0
    scene: str = "built"
    stopped_early: bool = False
    whole_plan: str = ""

    def to_dict(self) -> dict[str, Any]:
        return {"plan": self.plan, "actions": list(self.actions), "params": self.params, "z": list(self.z),
                "columns": list(self.columns), "cost": self.cost, "feasible": self.feasible, "status": self.status,
                "iterations_done": self.iterations_done, "run_dir": str(self.run_dir),
                "timings": self.timings.to_dict(), "from_action": self.from_action, "scene": self.scene,
                "stopped_early": self.stopped_early, "whole_plan": self.whole_plan}
