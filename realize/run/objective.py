"""The one number a sweep minimizes for a run: what the run function returns to Hydra's sweeper.

What it does: ``run_objective(result, horizon_cost)`` is the cost of the plan the run returns:
the validated candidate's nominal cost where the run's validation named one (``result.json``'s
``validation.returned``), else its best cost; a run with no feasible plan scores twice the
horizon cost (every control step of ``controller.max_time_s`` plus ``task.final_cost``), worse
than any plan that reaches the goal, so Optuna (``hydra/sweeper=optuna``, ``experiment=tune_ce``)
learns from it instead of dropping the trial. ``realize.run.assembly`` writes it into
``result.json`` as ``objective``; the sweep's ``summary.csv`` has a column for it.
What it doesn't: weigh wall time or robustness beyond what validation's choice of plan already
does (a plan validated below ``validation.min_success`` is returned as the most robust, at its cost).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

from realize.run_dir.directory import RunDir

__all__ = ["run_objective", "record_objective", "INFEASIBLE_FACTOR"]

INFEASIBLE_FACTOR = 2.0  # an infeasible run's objective: this times the horizon cost


def run_objective(result: Mapping[str, Any], horizon_cost: float) -> float:
    """The objective of a run from its ``result.json`` object (module docstring)."""
    best = result.get("best_cost")
    if not result.get("feasible") or not isinstance(best, (int, float)) or not math.isfinite(best):
        return INFEASIBLE_FACTOR * float(horizon_cost)
    v = result.get("validation")
    if isinstance(v, Mapping):
        try:
            return float(v["candidates"][int(v["returned"])]["cost"])
        except (KeyError, IndexError, TypeError, ValueError):
            pass  # a malformed record: the search's best
    return float(best)


def record_objective(run_dir: RunDir, max_time_s: float, control_freq: float, final_cost: float) -> float:
    """The finished run's objective, written into its ``result.json`` (a run that has one, a
    resumed complete run, keeps it); the horizon is ``max_time_s`` at ``control_freq``."""
    d = run_dir.result_json() or {}
    if "objective" in d:
        return float(d["objective"])
    value = run_objective(d, round(max_time_s * control_freq) + float(final_cost))
    run_dir.add_to_result("objective", value)
    return value
