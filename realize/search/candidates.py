"""Cross-entropy over the k best symbolic plans with one shared sample budget (successive halving).

The PDDL planner ranks plans by symbolic cost, but the cheapest symbolic plan need not be the
cheapest to realize. With ``task.planner.top_k = k > 1`` the run realizes up to k candidate
plans and spends one sample budget on them by successive halving (Karnin et al., 2013); the
budget rule (rounds, survivors, the winner's share) is in ``realize.search.budget``.

Ranking (after each round; ties keep the planner's order): candidates with a feasible sample
come first, by their best feasible cost; the others follow, ranked as the CE fallback ranks
infeasible samples (``realize.search.ce.ranking.rank_samples``), by their best sample's progress,
here as a share of the plan's actions (plans differ in length), descending, then its distance
to success ascending.

Each candidate has its own ``CrossEntropyOptimizer`` over its own ``ParamLayout`` (only the
parameters its plan uses), seeded ``ce.seed + SEED_STRIDE * index``: candidate 0 draws the same
samples as a single-plan run of the same seed (when its plan binds all the task's parameters).
All candidates are realized one batch at a time in the same scene (``realize.run.loop``), which is
valid because every rollout starts with a history-free reset.

What it doesn't: simulate (the caller passes an evaluator ``(candidate index, Z) -> EvalResult``
or drives ``ask``/``tell``), plan symbolically (``realize.tasks.pddl``) or write files (``realize.sinks``).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, replace
from typing import Any

import torch
from torch import Tensor

from realize.search.budget import HalvingBudget
from realize.search.ce.config import CEConfig
from realize.search.ce.optimizer import CrossEntropyOptimizer
from realize.search.ce.state import CEState, IterationRecord
from realize.tasks.param_layout import ParamLayout
from realize.run_dir.build import halving_doc
from realize.run_dir.summaries import CandidateSummary, best_params
from realize.search.protocol import Batch, EvalResult, SearchReport

__all__ = ["CandidateSpec", "Candidate", "SuccessiveHalving", "candidate_key", "SEED_STRIDE", "HALVING_KIND"]

SEED_STRIDE = 1_000_003  # candidate i's CE seed: ce.seed + SEED_STRIDE * i


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
    """A candidate's search and bookkeeping (iterations and samples spent, round dropped)."""

    index: int
    spec: CandidateSpec
    optimizer: CrossEntropyOptimizer
    iterations: int = 0
    samples: int = 0
    dropped_round: int | None = None

    @property
    def state(self) -> CEState:
        return self.optimizer.state

    @property
    def key(self) -> tuple[float, float, float, float]:
        return candidate_key(self.optimizer.state, self.spec.n_actions)

    def summary(self) -> CandidateSummary:
        """This candidate's plan, best sample (best cost ``inf`` unless feasible) and spending."""
        s = self.optimizer.state
        feasible = bool(s.best_feasible)
        return CandidateSummary(
            index=self.index,
            plan=self.spec.plan,
            n_actions=self.spec.n_actions,
            columns=self.spec.layout.column_names,
            feasible=feasible,
            best_cost=float(s.best_cost) if feasible else math.inf,
            best_iteration=s.best_iteration if s.best_z is not None else None,
            best_params=best_params(self.spec.layout, s.best_z),
            best_z=None if s.best_z is None else s.best_z.tolist(),
            iterations=self.iterations,
            samples=self.samples,
            dropped_round=self.dropped_round,
            converged=bool(s.converged),
        )


Evaluate = Callable[[int, Tensor], EvalResult]
OnIteration = Callable[[Candidate, IterationRecord], "bool | None"]
HALVING_KIND = "successive_halving"  # the "kind" of its state_dict (a checkpoint's ce_state)


class SuccessiveHalving:
    """Ask/tell successive halving over candidate plans, each with its own CE search
    (a ``realize.search.protocol.Searcher``).

    ``ask()`` returns the next CE iteration's ``Batch`` (``candidate`` = its index), or ``None``
    when the budget is spent; ``tell(result)`` gives that candidate's evaluation back and
    returns its ``IterationRecord``; rounds end (and the worse half is dropped) inside ``tell``.
    ``run(evaluate)`` loops. Candidates run one after the other within a round, ``m``
    iterations each, in the planner's order. ``state_dict``/``load_state_dict`` round-trip
    every candidate's CE state and the halving position (resuming a top-k run).
    """

    def __init__(
        self,
        candidates: Sequence[CandidateSpec],
        config: CEConfig,
        budget: HalvingBudget,
        device: torch.device | str | None = None,
        top_k: int | None = None,
    ) -> None:
        if not candidates:
            raise ValueError("SuccessiveHalving needs at least one candidate plan")
        if len(candidates) != budget.n_candidates:
            raise ValueError(f"budget is for {budget.n_candidates} candidates, got {len(candidates)}")
        if config.schedule != "constant":
            raise ValueError(f"successive halving needs ce.schedule = 'constant', got {config.schedule!r}")
        if config.n_envs != budget.n_envs:
            raise ValueError(f"budget is for {budget.n_envs} samples per iteration, ce has {config.n_envs}")
        self.budget = budget
        self.config = config
        self.top_k = len(candidates) if top_k is None else top_k  # plans asked of the planner (reports only)
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
    def iterations_done(self) -> int:
        return self.spent_iterations

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

    def ask(self) -> Batch | None:
        """The next iteration's batch (``candidate``: its index; ``Z (N, D_i)``), ``None`` when done."""
        if self._current is None:
            return None
        batch = self.candidates[self._current].optimizer.ask()
        assert batch is not None  # _advance only points at candidates whose search goes on
        batch.candidate = self._current
        return batch

    def tell(self, result: EvalResult, eval_time: float = math.nan) -> IterationRecord:
        """The evaluation of the last ``ask``'s batch; returns the candidate's record."""
        if self._current is None:
            raise RuntimeError("tell() after the budget is spent")
        c = self.candidates[self._current]
        rec = c.optimizer.tell(result, eval_time=eval_time)
        c.iterations += 1
        c.samples += rec.n_envs
        self._in_round[c.index] += 1
        self._advance()
        return rec

    def run(self, evaluate: Evaluate, on_iteration: OnIteration | None = None) -> Candidate:
        """Loop ask -> ``evaluate(index, Z)`` -> tell until done; returns the winner.
        ``on_iteration(candidate, record)`` returning True stops early (the leader is returned)."""
        while (batch := self.ask()) is not None:
            i = batch.candidate
            assert i is not None
            rec = self.tell(evaluate(i, batch.Z))
            if on_iteration is not None and on_iteration(self.candidates[i], rec):
                break
        return self.candidates[self.leader]

    # ---- reports and checkpoints ---------------------------------------------------------

    def report(self) -> SearchReport:
        lead = self.leader
        return SearchReport(lead=lead, state=self.candidates[lead].optimizer.state,
                            round=min(self.round, self.budget.n_rounds), halving=halving_doc(self, self.top_k))

    def state_dict(self) -> dict[str, Any]:
        """Every candidate's CE state and the halving position, as plain JSON data."""
        return {
            "kind": HALVING_KIND,
            "plans": [c.spec.plan for c in self.candidates],
            "round": self.round,
            "survivors": list(self.survivors),
            "position": self._pos,
            "in_round": list(self._in_round),
            "candidates": [
                {"iterations": c.iterations, "samples": c.samples, "dropped_round": c.dropped_round,
                 "ce_state": c.optimizer.state_dict()}
                for c in self.candidates
            ],
        }

    def load_state_dict(self, d: Mapping[str, Any]) -> None:
        """Continue from ``state_dict()`` output; ``ValueError`` if it is not of these candidates."""
        if d.get("kind") != HALVING_KIND:
            raise ValueError(f"not a successive-halving state (kind {d.get('kind')!r})")
        plans = [c.spec.plan for c in self.candidates]
        try:
            cands = list(d["candidates"])
            if len(cands) != len(plans) or list(d.get("plans", plans)) != plans:
                raise ValueError(f"its candidate plans {d.get('plans', len(cands))} are not this run's {plans}")
            for c, cd in zip(self.candidates, cands):
                c.optimizer.load_state_dict(cd["ce_state"])
                c.iterations, c.samples = int(cd["iterations"]), int(cd["samples"])
                c.dropped_round = None if cd["dropped_round"] is None else int(cd["dropped_round"])
            self.round, self._pos = int(d["round"]), int(d["position"])
            self.survivors = [int(i) for i in d["survivors"]]
            self._in_round = [int(i) for i in d["in_round"]]
        except (KeyError, TypeError) as e:
            raise ValueError(f"malformed successive-halving state ({type(e).__name__}: {e})") from None
        if not self.survivors or not set(self.survivors) <= set(range(len(plans))) \
                or len(self._in_round) != len(plans):
            raise ValueError("malformed successive-halving state (survivors / in_round)")
        self._current = None
        self._advance()
