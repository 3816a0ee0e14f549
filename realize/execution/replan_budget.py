"""The search of one replan: ``ReplanBudget``, a settings group of an execution (``execute.budget``).

What it does: ``ReplanBudget`` holds ``n_envs`` copies (and samples) per iteration, ``n_elite``
elites, at most ``iterations``; with ``stop_when_feasible`` the search ends after the first
iteration (from ``min_iterations`` on) whose best plan reaches the goal. ``validation``
replicas of the task's perturbations after it (0: none; a replan starts from an observed
state, so what is left uncertain is small). ``workers``: rollout workers (None: as the run);
``shard_rows``: copies per PhysX scene (None: as the run). ``progress``/``rerun``: the progress
bar and the rerun recording of each replan. Its defaults are written here only: an execute
preset (``configs/execute/``) sets ``budget:`` keys where it differs, ``scripts/execute.py``'s
``--n-envs``, ``--iterations`` and ``--validation`` override them, and ``realize.Planner``'s
``replan``/``resequence`` take one (default: this class's). ``overrides()`` says it as
run-config keys. ``elites_for(n)`` is the elites of a budget given only its copies.
What it doesn't: search (``realize.run.planner.Planner`` runs the replan on these keys).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, ClassVar

from realize.config import ConfigError, Settings, setting

__all__ = ["ReplanBudget"]


@dataclass
class ReplanBudget(Settings):
    """The search of one replan (module docstring)."""

    config_key: ClassVar[str] = "execute.budget"

    n_envs: int = setting(32, ge=1)
    n_elite: int = setting(4, ge=1)
    iterations: int = setting(3, ge=1)
    stop_when_feasible: bool = True
    min_iterations: int = setting(1, ge=1)
    validation: int = setting(0, ge=0)
    workers: int | None = setting(None, ge=1)
    shard_rows: int | None = setting(16, ge=1)  # copies per PhysX scene: 32 copies in 2 scenes keep both cores busy
    progress: bool = False
    rerun: bool = False

    def check(self, where: str) -> None:
        if self.n_elite > self.n_envs:
            raise ConfigError(f"{where}.n_elite = {self.n_elite} is invalid: must be <= {where}.n_envs = {self.n_envs}")

    @staticmethod
    def elites_for(n_envs: int) -> int:
        """The elites of a budget given only its copies: an eighth from 32 copies on, a quarter
        below, at least one."""
        return max(1, n_envs // 8 if n_envs >= 32 else n_envs // 4)

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
