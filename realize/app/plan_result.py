"""What the planner's calls take and return: the replan budget, the timings and the result.

What it does: ``ReplanBudget`` (the small search of one replan, as run-config overrides),
``PlanTimings`` (where a call's time went) and ``PlanResult`` (the typed result of
``realize.app.planner.Planner.plan`` / ``replan`` / ``resequence``).
What it doesn't: run anything (``realize.app.planner``).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from realize.app.assembly import RunOutcome
from realize.config import ConfigError

__all__ = ["ReplanBudget", "PlanTimings", "PlanResult"]


@dataclass(frozen=True)
class ReplanBudget:
    """The search of one replan: ``n_envs`` copies (and samples) per iteration, ``n_elite``
    elites, at most ``iterations``; with ``stop_when_feasible`` it ends after the first
    iteration (from ``min_iterations`` on) whose best plan reaches the goal. ``validation``
    replicas of the task's perturbations after it (0: none; a replan starts from an observed
    state, so what is left uncertain is small). ``workers``: rollout workers (None: as the run);
    ``shard_rows``: copies per PhysX scene (None: as the run).
    ``progress``/``rerun``: the progress bar and the rerun recording of each replan."""

    n_envs: int = 32
    n_elite: int = 4
    iterations: int = 3
    stop_when_feasible: bool = True
    min_iterations: int = 1
    validation: int = 0
    workers: int | None = None
    shard_rows: int | None = 16  # copies per PhysX scene: 32 copies in 2 scenes keep both cores of a laptop busy
    progress: bool = False
    rerun: bool = False

    def __post_init__(self) -> None:
        for name in ("n_envs", "n_elite", "iterations", "min_iterations"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int) or v < 1:
                raise ConfigError(f"replan budget: {name} = {v!r} is invalid: must be an integer >= 1")
        if self.n_elite > self.n_envs:
            raise ConfigError(f"replan budget: n_elite = {self.n_elite} is more than n_envs = {self.n_envs}")
        if isinstance(self.validation, bool) or not isinstance(self.validation, int) or self.validation < 0:
            raise ConfigError(f"replan budget: validation = {self.validation!r} is invalid: an integer >= 0")

    @staticmethod
    def elites_for(n_envs: int) -> int:
        """The elites of a budget given only its copies: an eighth from 32 copies on (the
        default's 4 of 32), a quarter below, at least one."""
        return max(1, n_envs // 8 if n_envs >= 32 else n_envs // 4)

    @classmethod
    def from_mapping(cls, d: Mapping[str, Any] | None, where: str = "replan budget") -> ReplanBudget:
        d = dict(d or {})
        known = set(cls.__dataclass_fields__)
        unknown = sorted(set(d) - known)
        if unknown:
            raise ConfigError(f"{where}: unknown key(s) {unknown}; known: {sorted(known)}")
        return cls(**d)

    def overrides(self) -> dict[str, Any]:
        """The run-config keys this budget sets (dotted key -> value)."""
        out: dict[str, Any] = {"ce.n_envs": self.n_envs, "ce.n_elite": self.n_elite, "ce.iterations": self.iterations,
                               "ce.schedule": "constant", "ce.n_envs_end": None, "ce.replicas": 1,
                               "validation.replicas": self.validation, "logging.progress": self.progress,
                               "logging.rerun": self.rerun, "logging.record": self.rerun}
        if self.workers is not None:
            out["workers.n"] = self.workers
        if self.shard_rows is not None:
            out["sim.shard_rows"] = self.shard_rows
        return out


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
