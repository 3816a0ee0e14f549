"""The sample budget of a top-k run: how successive halving shares CE iterations among candidates.

Budget rule
-----------
Let ``N = ce.n_envs`` (samples per CE iteration), ``T = ce.iterations`` and ``K`` the number of
distinct candidates the planner returned (``1 <= K <= k``; fewer than k is normal).

* The whole run simulates at most ``T x N`` samples, exactly the budget of a single-plan run
  with the same ``ce`` settings (less only if a candidate's search converges early,
  ``ce.converge_std``).
* Halving rounds ``r = 0, 1, ...`` run while more than one candidate survives, with
  ``S_0 = K`` and ``S_{r+1} = ceil(S_r / 2)`` survivors. In round ``r`` every survivor runs
  ``m`` CE iterations of ``N`` samples, each continuing its own search where it stopped; then the
  survivors are ranked and the ``floor(S_r / 2)`` worst are dropped (``dropped_round = r``).
* The last survivor, the winner, runs the remaining ``T - m * sum_r S_r`` iterations (plus any
  iterations that converged candidates left unspent).
* ``m = task.planner.round_iterations``; ``null`` (default) picks the largest ``m`` that leaves
  the winner at least ``m`` final iterations, ``m = max(1, floor(T / (sum_r S_r + 1)))``.
  The rounds must fit: ``m * sum_r S_r <= T``, else a ``ConfigError`` (before any simulation).

Example: ``T = 10``, ``K = 3``: survivors 3 then 2 (sum 5), ``m = floor(10 / 6) = 1``; round 0
costs 3 iterations, round 1 costs 2, the winner then runs 5 more (7 of the 10 in all).

What it doesn't: run the rounds or rank candidates (``realize.search.candidates``).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from realize.config import ConfigError

__all__ = ["HalvingBudget", "plan_budget"]


def _survivors(k: int) -> tuple[int, ...]:
    """Survivors per halving round for ``k`` candidates: k, ceil(k/2), ... down to 2 (none for 1)."""
    out = []
    while k > 1:
        out.append(k)
        k = (k + 1) // 2
    return tuple(out)


@dataclass(frozen=True)
class HalvingBudget:
    """The schedule of one halving run (see the module docstring for the rule).

    ``survivors[r]`` candidates run ``round_iterations`` CE iterations each in round ``r``;
    the winner then runs ``final_iterations``. ``n_envs`` samples per iteration."""

    n_candidates: int
    total_iterations: int
    n_envs: int
    round_iterations: int
    survivors: tuple[int, ...]

    @property
    def n_rounds(self) -> int:
        return len(self.survivors)

    @property
    def round_total(self) -> int:
        """CE iterations the halving rounds take together (all candidates)."""
        return self.round_iterations * sum(self.survivors)

    @property
    def final_iterations(self) -> int:
        """CE iterations left to the winner after the rounds (nominal: no early convergence)."""
        return self.total_iterations - self.round_total

    @property
    def total_samples(self) -> int:
        """The run's sample budget: ``total_iterations x n_envs``, as a single-plan run."""
        return self.total_iterations * self.n_envs

    def to_dict(self) -> dict[str, Any]:
        return {
            "n_candidates": self.n_candidates,
            "total_iterations": self.total_iterations,
            "n_envs_per_iteration": self.n_envs,
            "total_samples": self.total_samples,
            "round_iterations": self.round_iterations,
            "survivors_per_round": list(self.survivors),
            "final_iterations": self.final_iterations,
        }


def plan_budget(
    n_candidates: int,
    total_iterations: int,
    n_envs: int,
    round_iterations: int | None = None,
    *,
    keys: tuple[str, str, str] = ("task.planner.top_k", "ce.iterations", "task.planner.round_iterations"),
) -> HalvingBudget:
    """The halving schedule for ``n_candidates``; ``ConfigError`` naming ``keys`` (candidates,
    iterations, round iterations) if the rounds do not fit into ``total_iterations``."""
    k_key, t_key, m_key = keys
    if n_candidates < 1:
        raise ConfigError(f"{k_key} = {n_candidates} is invalid: must be >= 1")
    if total_iterations < 1 or n_envs < 1:
        raise ConfigError(f"{t_key} = {total_iterations} / n_envs = {n_envs}: both must be >= 1")
    surv = _survivors(n_candidates)
    s = sum(surv)
    if round_iterations is None:
        m = max(1, total_iterations // (s + 1))
    else:
        if round_iterations < 1:
            raise ConfigError(f"{m_key} = {round_iterations} is invalid: must be >= 1 (or null: automatic)")
        m = round_iterations
    if m * s > total_iterations:
        rounds = " + ".join(str(x) for x in surv)
        raise ConfigError(
            f"{t_key} = {total_iterations} is too small for {k_key} = {n_candidates}: the halving rounds "
            f"need {m} x ({rounds}) = {m * s} CE iterations ({m_key} = {m} per survivor and round); "
            f"raise {t_key} to >= {m * s} or lower {k_key}"
            + ("" if round_iterations is None else f" or {m_key}")
        )
    return HalvingBudget(n_candidates, total_iterations, n_envs, m, surv)
