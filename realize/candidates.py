"""Cross-entropy over the k best symbolic plans with one shared sample budget (successive halving).

The PDDL planner ranks plans by symbolic cost, but the cheapest symbolic plan need not be the
cheapest to realize. With ``task.planner.top_k = k > 1`` the run realizes up to k candidate
plans and spends one sample budget on them by successive halving (Karnin et al., 2013).

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
  The rounds must fit: ``m * sum_r S_r <= T``, else ``BudgetError`` (before any simulation).

Example: ``T = 10``, ``K = 3``: survivors 3 then 2 (sum 5), ``m = floor(10 / 6) = 1``; round 0
costs 3 iterations, round 1 costs 2, the winner then runs 5 more (7 of the 10 in all).

Ranking (after each round; ties keep the planner's order): candidates with a feasible sample
come first, by their best feasible cost; the others follow, ranked as the CE fallback ranks
infeasible samples (``realize.cross_entropy.rank_samples``), by their best sample's progress,
here as a share of the plan's actions (plans differ in length), descending, then its distance
to success ascending.

Each candidate has its own ``CrossEntropyOptimizer`` over its own ``ParamLayout`` (only the
parameters its plan uses), seeded ``ce.seed + SEED_STRIDE * index``: candidate 0 draws the same
samples as a single-plan run of the same seed (when its plan binds all the task's parameters).
All candidates are realized one batch at a time in the same scene (``realize.app``), which is
valid because every rollout starts with a history-free reset.

What it doesn't: simulate (the caller passes an evaluator ``(candidate index, Z) -> EvalResult``
or drives ``ask``/``tell``), plan symbolically (``realize.pddl``), write files (``realize.app``),
or resume a halving run from a checkpoint (``to_dict`` records the states, nothing reads them).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import torch
from torch import Tensor

from realize.cross_entropy import CEConfig, CEState, CrossEntropyOptimizer, EvalResult, IterationRecord
from realize.param_layout import ParamLayout

__all__ = [
    "BudgetError",
    "HalvingBudget",
    "plan_budget",
    "CandidateSpec",
    "Candidate",
    "SuccessiveHalving",
    "candidate_key",
    "SEED_STRIDE",
]

SEED_STRIDE = 1_000_003  # candidate i's CE seed: ce.seed + SEED_STRIDE * i


class BudgetError(ValueError):
    """The sample budget cannot cover the halving rounds; the message names the keys."""


# --------------------------------------------------------------------------------------------
# budget
# --------------------------------------------------------------------------------------------


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
    the winner then runs ``final_iterations``. ``n_samples`` samples per iteration."""

    n_candidates: int
    total_iterations: int
    n_samples: int
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
        """The run's sample budget: ``total_iterations x n_samples``, as a single-plan run."""
        return self.total_iterations * self.n_samples

    def to_dict(self) -> dict[str, Any]:
        return {
            "n_candidates": self.n_candidates,
            "total_iterations": self.total_iterations,
            "n_samples_per_iteration": self.n_samples,
            "total_samples": self.total_samples,
            "round_iterations": self.round_iterations,
            "survivors_per_round": list(self.survivors),
            "final_iterations": self.final_iterations,
        }


def plan_budget(
    n_candidates: int,
    total_iterations: int,
    n_samples: int,
    round_iterations: int | None = None,
    *,
    keys: tuple[str, str, str] = ("task.planner.top_k", "ce.iterations", "task.planner.round_iterations"),
) -> HalvingBudget:
    """The halving schedule for ``n_candidates``; ``BudgetError`` naming ``keys`` (candidates,
    iterations, round iterations) if the rounds do not fit into ``total_iterations``."""
    k_key, t_key, m_key = keys
    if n_candidates < 1:
        raise BudgetError(f"{k_key} = {n_candidates} is invalid: must be >= 1")
    if total_iterations < 1 or n_samples < 1:
        raise BudgetError(f"{t_key} = {total_iterations} / n_samples = {n_samples}: both must be >= 1")
    surv = _survivors(n_candidates)
    s = sum(surv)
    if round_iterations is None:
        m = max(1, total_iterations // (s + 1))
    else:
        if round_iterations < 1:
            raise BudgetError(f"{m_key} = {round_iterations} is invalid: must be >= 1 (or null: automatic)")
        m = round_iterations
    if m * s > total_iterations:
        rounds = " + ".join(str(x) for x in surv)
        raise BudgetError(
            f"{t_key} = {total_iterations} is too small for {k_key} = {n_candidates}: the halving rounds "
            f"need {m} x ({rounds}) = {m * s} CE iterations ({m_key} = {m} per survivor and round); "
            f"raise {t_key} to >= {m * s} or lower {k_key}"
            + ("" if round_iterations is None else f" or {m_key}")
        )
    return HalvingBudget(n_candidates, total_iterations, n_samples, m, surv)


# --------------------------------------------------------------------------------------------
# candidates
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class CandidateSpec:
    """One candidate plan: its description, its parameters and its number of actions."""

    plan: str
    layout: ParamLayout
    n_actions: int


def candidate_key(state: CEState, n_actions: int) -> tuple[float, float, float, float]:
    """Sort key of a candidate's best sample (smaller is better; see the module docstring)."""
    if state.best_z is None:
        return (2.0, 0.0, 0.0, 0.0)  # never evaluated
    cost = math.inf if math.isnan(state.best_cost) else state.best_cost
    if state.best_feasible:
        return (0.0, cost, 0.0, 0.0)
    p = state.best_progress
    share = -math.inf if math.isnan(p) else p / max(n_actions, 1)
    d = math.inf if math.isnan(state.best_distance) else state.best_distance
    return (1.0, -share, d, cost)


@dataclass
class Candidate:
    """A candidate's search and bookkeeping. ``records`` are its ``IterationRecord.summary()``."""

    index: int
    spec: CandidateSpec
    optimizer: CrossEntropyOptimizer
    iterations: int = 0
    samples: int = 0
    dropped_round: int | None = None
    records: list[dict[str, Any]] = field(default_factory=list)

    @property
    def state(self) -> CEState:
        return self.optimizer.state

    @property
    def key(self) -> tuple[float, float, float, float]:
        return candidate_key(self.optimizer.state, self.spec.n_actions)

    def best_params(self) -> dict[str, dict[str, float]] | None:
        """The best sample split by parameter, ``{name: {coord: value}}`` (None before any)."""
        z = self.optimizer.state.best_z
        if z is None:
            return None
        layout = self.spec.layout
        out: dict[str, dict[str, float]] = {}
        for name, part in layout.split(z.reshape(1, -1)).items():
            coords = layout.regions[name].coord_names
            out[name] = {c: float(v) for c, v in zip(coords, part[0].tolist())}
        return out

    def summary(self) -> dict[str, Any]:
        """Plain values for result.json (non-finite cost -> None)."""
        s = self.optimizer.state
        feasible = bool(s.best_feasible)
        return {
            "index": self.index,
            "plan": self.spec.plan,
            "n_actions": self.spec.n_actions,
            "columns": self.spec.layout.column_names,
            "feasible": feasible,
            "best_cost": float(s.best_cost) if feasible and math.isfinite(s.best_cost) else None,
            "best_iteration": s.best_iteration if s.best_z is not None else None,
            "best_params": self.best_params(),
            "best_z": None if s.best_z is None else s.best_z.tolist(),
            "iterations": self.iterations,
            "samples": self.samples,
            "dropped_round": self.dropped_round,
            "converged": bool(s.converged),
        }


Evaluate = Callable[[int, Tensor], EvalResult]
OnIteration = Callable[[Candidate, IterationRecord], "bool | None"]


class SuccessiveHalving:
    """Ask/tell successive halving over candidate plans, each with its own CE search.

    ``ask()`` returns ``(candidate index, Z)`` for the next CE iteration, or ``None`` when the
    budget is spent; ``tell(result)`` gives that candidate's evaluation back and returns its
    ``IterationRecord``; rounds end (and the worse half is dropped) inside ``tell``.
    ``run(evaluate)`` loops. Candidates run one after the other within a round, ``m``
    iterations each, in the planner's order.
    """

    def __init__(
        self,
        candidates: Sequence[CandidateSpec],
        config: CEConfig,
        budget: HalvingBudget,
        device: torch.device | str | None = None,
    ) -> None:
        if not candidates:
            raise ValueError("SuccessiveHalving needs at least one candidate plan")
        if len(candidates) != budget.n_candidates:
            raise ValueError(f"budget is for {budget.n_candidates} candidates, got {len(candidates)}")
        if config.schedule != "constant":
            raise ValueError(f"successive halving needs ce.schedule = 'constant', got {config.schedule!r}")
        if config.n_samples != budget.n_samples:
            raise ValueError(f"budget is for {budget.n_samples} samples per iteration, ce has {config.n_samples}")
        self.budget = budget
        self.config = config
        self.candidates: list[Candidate] = []
        for i, spec in enumerate(candidates):
            # a candidate never runs more than the whole budget: CE's own stop is never the limit
            cfg = replace(config, iterations=budget.total_iterations, seed=config.seed + SEED_STRIDE * i)
            self.candidates.append(Candidate(i, spec, CrossEntropyOptimizer(spec.layout, cfg, device=device)))
        self.round = 0  # current halving round; == budget.n_rounds in the winner's final phase
        self.survivors: list[int] = list(range(len(candidates)))
        self._pos = 0  # position in ``survivors`` within the current round
        self._in_round = [0] * len(candidates)  # iterations in the current round
        self._current: int | None = None
        self._advance()

    # ---- state ---------------------------------------------------------------------------

    @property
    def spent_iterations(self) -> int:
        return sum(c.iterations for c in self.candidates)

    @property
    def spent_samples(self) -> int:
        return sum(c.samples for c in self.candidates)

    @property
    def done(self) -> bool:
        return self._current is None

    @property
    def in_final(self) -> bool:
        return self.round >= self.budget.n_rounds

    @property
    def winner(self) -> int | None:
        """The last survivor, once the halving rounds are over (else None)."""
        return self.survivors[0] if len(self.survivors) == 1 else None

    @property
    def leader(self) -> int:
        """The best-ranked surviving candidate so far (the winner once decided)."""
        return min(self.survivors, key=lambda i: (self.candidates[i].key, i))

    def ranking(self) -> list[int]:
        """Surviving candidates best first (ties: planner order)."""
        return sorted(self.survivors, key=lambda i: (self.candidates[i].key, i))

    # ---- ask / tell ----------------------------------------------------------------------

    def _needs(self, i: int) -> bool:
        c = self.candidates[i]
        if c.optimizer.done:
            return False
        if self.in_final:
            return self.spent_iterations < self.budget.total_iterations
        return self._in_round[i] < self.budget.round_iterations

    def _advance(self) -> None:
        """Point ``_current`` at the next candidate to iterate, ending rounds on the way."""
        while True:
            if self.in_final:
                w = self.survivors[0]
                self._current = w if self._needs(w) else None
                return
            while self._pos < len(self.survivors) and not self._needs(self.survivors[self._pos]):
                self._pos += 1
            if self._pos < len(self.survivors):
                self._current = self.survivors[self._pos]
                return
            self._end_round()

    def _end_round(self) -> None:
        order = self.ranking()
        keep = (len(order) + 1) // 2
        for i in order[keep:]:
            self.candidates[i].dropped_round = self.round
        self.survivors = sorted(order[:keep])
        self.round += 1
        self._pos = 0
        self._in_round = [0] * len(self.candidates)

    def ask(self) -> tuple[int, Tensor] | None:
        """``(candidate index, Z (N, D_i))`` for the next iteration, or ``None`` when done."""
        if self._current is None:
            return None
        return self._current, self.candidates[self._current].optimizer.ask()

    def tell(self, result: EvalResult) -> IterationRecord:
        """The evaluation of the last ``ask``'s batch; returns the candidate's record."""
        if self._current is None:
            raise RuntimeError("tell() after the budget is spent")
        c = self.candidates[self._current]
        rec = c.optimizer.tell(result)
        c.iterations += 1
        c.samples += rec.n_samples
        c.records.append(rec.summary())
        self._in_round[c.index] += 1
        self._advance()
        return rec

    def run(self, evaluate: Evaluate, on_iteration: OnIteration | None = None) -> Candidate:
        """Loop ask -> ``evaluate(index, Z)`` -> tell until done; returns the winner.
        ``on_iteration(candidate, record)`` returning True stops early (the leader is returned)."""
        while (job := self.ask()) is not None:
            i, Z = job
            rec = self.tell(evaluate(i, Z))
            if on_iteration is not None and on_iteration(self.candidates[i], rec):
                break
        return self.candidates[self.leader]

    # ---- reports -------------------------------------------------------------------------

    def summary(self) -> dict[str, Any]:
        """Plain values: budget, spending, round, winner/leader and every candidate."""
        w = self.winner
        return {
            "budget": self.budget.to_dict(),
            "spent_iterations": self.spent_iterations,
            "spent_samples": self.spent_samples,
            "round": min(self.round, self.budget.n_rounds),
            "leader": self.leader,
            "winner": None if w is None else {"index": w, "plan": self.candidates[w].spec.plan},
            "candidates": [c.summary() for c in self.candidates],
        }

    def to_dict(self) -> dict[str, Any]:
        """Every candidate's CE state and the halving position (a record; no resume reads it)."""
        return {
            "kind": "successive_halving",
            "round": self.round,
            "survivors": list(self.survivors),
            "position": self._pos,
            "in_round": list(self._in_round),
            "candidates": [
                {"iterations": c.iterations, "samples": c.samples, "dropped_round": c.dropped_round,
                 "ce_state": c.optimizer.state.to_dict()}
                for c in self.candidates
            ],
        }
