"""Successive halving over candidate plans (realize.search.candidates) on fake evaluators: the halving
schedule, the budget rule and its errors, ranking (feasible before infeasible, progress share),
bookkeeping of dropped rounds and spent samples. No simulator."""

from __future__ import annotations

import math

import pytest
import torch

from realize.search.budget import plan_budget
from realize.search.candidates import SEED_STRIDE, CandidateSpec, SuccessiveHalving, candidate_key
from realize.search.ce.config import CEConfig
from realize.search.ce.optimizer import CrossEntropyOptimizer
from realize.search.ce.state import CEState
from realize.config import ConfigError
from realize.tasks.param_layout import ParamLayout
from realize.tasks.regions import Box
from realize.search.protocol import EvalResult

F64 = torch.float64


def layout(*names: str, dim: int = 2) -> ParamLayout:
    return ParamLayout({n: Box([-1.0] * dim, [1.0] * dim) for n in names})


def specs(n: int) -> list[CandidateSpec]:
    # candidates use different parameter subsets, as plans from a planner do
    return [CandidateSpec(f"plan{i}", layout(*[f"P{j}" for j in range(i + 1)]), n_actions=3 + i)
            for i in range(n)]


def fake(base: list[float], feasible: list[bool] | None = None, progress: list[float] | None = None,
         calls: list[tuple[int, int]] | None = None):
    """Candidate i costs ``base[i] + ||Z||^2`` (known minimum ``base[i]``); optionally never
    feasible, with a fixed progress (actions completed)."""

    def evaluate(i: int, Z: torch.Tensor) -> EvalResult:
        if calls is not None:
            calls.append((i, Z.shape[0]))
        n = Z.shape[0]
        ok = True if feasible is None else feasible[i]
        prog = torch.full((n,), 0.0 if progress is None else progress[i], dtype=F64)
        return EvalResult(cost=base[i] + (Z**2).sum(1), feasible=torch.full((n,), ok),
                          progress=prog, distance=(Z**2).sum(1))

    return evaluate


CE = CEConfig(n_envs=16, n_elite=4, iterations=10, seed=3, patience=None)  # no stopping rule: halving's budget


# ---------------------------------------------------------------- the budget rule


@pytest.mark.parametrize(
    "k, T, m, survivors, m_auto, final",
    [
        (1, 10, None, (), 10, 10),  # one plan: a plain CE run
        (2, 10, None, (2,), 3, 4),  # floor(10 / 3) = 3; rounds 6, winner 4
        (3, 10, None, (3, 2), 1, 5),  # floor(10 / 6) = 1; rounds 5, winner 5
        (4, 12, 2, (4, 2), 2, 0),  # explicit m: rounds 12, winner nothing more
        (5, 20, None, (5, 3, 2), 1, 10),
        (2, 2, None, (2,), 1, 0),  # auto m never below 1
    ],
)
def test_schedule(k: int, T: int, m: int | None, survivors: tuple, m_auto: int, final: int) -> None:
    b = plan_budget(k, T, 16, m)
    assert b.survivors == survivors and b.round_iterations == m_auto and b.final_iterations == final
    assert b.round_total + b.final_iterations == T and b.total_samples == T * 16


def test_budget_errors_name_the_keys() -> None:
    with pytest.raises(ConfigError, match=r"ce.iterations = 4 is too small for task.planner.top_k = 3.*1 x \(3 \+ 2\) = 5"):
        plan_budget(3, 4, 16)
    with pytest.raises(ConfigError, match=r"task.planner.round_iterations = 3.*or task.planner.round_iterations"):
        plan_budget(2, 5, 16, 3)
    with pytest.raises(ConfigError, match=r"round_iterations = 0 is invalid"):
        plan_budget(2, 5, 16, 0)
    with pytest.raises(ConfigError, match=r"top_k = 0 is invalid"):
        plan_budget(0, 5, 16)


# ---------------------------------------------------------------- halving on a fake evaluator


def test_cheapest_realized_candidate_wins_even_when_not_first() -> None:
    base = [50.0, 10.0, 30.0]  # the planner's first plan is the most expensive to realize
    calls: list[tuple[int, int]] = []
    b = plan_budget(3, 10, CE.n_envs)
    sh = SuccessiveHalving(specs(3), CE, b)
    won = sh.run(fake(base, calls=calls))
    assert won.index == 1 and sh.winner == 1 and sh.done
    # round 0: everyone one iteration, in planner order; the worst (0) is dropped;
    # round 1: 1 and 2 one iteration each, 2 is dropped; the winner runs the remaining 5
    assert [i for i, _ in calls] == [0, 1, 2, 1, 2] + [1] * 5
    assert {n for _, n in calls} == {CE.n_envs}
    c = sh.candidates
    assert [x.dropped_round for x in c] == [0, None, 1]
    assert [x.iterations for x in c] == [1, 7, 2]
    assert [x.samples for x in c] == [16, 112, 32]
    # budget accounting: exactly the single-plan budget
    assert sh.spent_iterations == 10 and sh.spent_samples == b.total_samples == 10 * 16
    assert c[1].optimizer.iterations_done == 7
    rep = sh.report()
    s = rep.halving
    assert rep.lead == 1 and s.winner.to_json() == {"index": 1, "plan": "plan1"} and s.spent_samples == 160
    assert [x.dropped_round for x in s.candidates] == [0, None, 1]
    assert s.candidates[1].feasible and 10.0 <= s.candidates[1].best_cost < 10.5
    assert set(s.candidates[1].best_params) == {"P0", "P1"}  # its own parameters
    assert len(s.candidates[2].best_z) == 6


def test_survivor_continues_its_own_search() -> None:
    """A candidate that survives a round picks up its CE where it stopped: its samples are those
    of one uninterrupted CE run (candidate 0 with the run's seed, others with their own)."""
    b = plan_budget(2, 6, CE.n_envs, 2)  # rounds 2 x 2, winner 2 more
    sh = SuccessiveHalving(specs(2), CE, b)
    seen: dict[int, list[torch.Tensor]] = {0: [], 1: []}

    def evaluate(i: int, Z: torch.Tensor) -> EvalResult:
        seen[i].append(Z.clone())
        return fake([5.0, 1.0])(i, Z)

    sh.run(evaluate)
    assert len(seen[0]) == 2 and len(seen[1]) == 4
    for i in (0, 1):
        cfg = CEConfig(n_envs=16, n_elite=4, iterations=6, seed=CE.seed + SEED_STRIDE * i)
        ref = CrossEntropyOptimizer(specs(2)[i].layout, cfg)
        for Z in seen[i]:
            assert torch.equal(ref.ask().Z, Z)
            ref.tell(fake([5.0, 1.0])(i, Z))


def test_feasible_before_infeasible_and_progress_share() -> None:
    # candidate 0 is never feasible; 1 and 2 are infeasible with progress 2 of 3 vs 3 of 5 actions;
    # candidate 3 is feasible but expensive: it must rank first anyway
    feas = [False, False, False, True]
    prog = [0.0, 2.0, 3.0, 0.0]
    sh = SuccessiveHalving(specs(4), CE, plan_budget(4, 10, CE.n_envs))
    sh.run(fake([0.0, 0.0, 0.0, 1000.0], feasible=feas, progress=prog))
    c = sh.candidates
    # n_actions are 3, 4, 5, 6: progress shares 0, 2/4, 3/5 -> round 0 keeps 3 and 2
    assert c[3].dropped_round is None and sh.winner == 3
    assert c[0].dropped_round == 0 and c[1].dropped_round == 0 and c[2].dropped_round == 1
    assert c[3].summary().best_cost >= 1000.0
    assert c[0].summary().to_json()["best_cost"] is None and c[0].summary().feasible is False


def test_candidate_key() -> None:
    def st(feasible: bool, cost: float, progress: float = math.nan, distance: float = math.nan) -> CEState:
        return CEState(iteration=1, rng_state=torch.zeros(1, dtype=torch.uint8), best_z=torch.zeros(2),
                       best_cost=cost, best_feasible=feasible, best_progress=progress, best_distance=distance)

    assert candidate_key(st(True, 900.0), 5) < candidate_key(st(False, 10.0, 5.0, 0.0), 5)
    assert candidate_key(st(False, 1.0, 2.0, 0.1), 3) < candidate_key(st(False, 1.0, 3.0, 0.1), 5)  # 2/3 > 3/5
    assert candidate_key(st(False, 1.0, 2.0, 0.1), 4) < candidate_key(st(False, 1.0, 2.0, 0.2), 4)
    never = CEState(iteration=0, rng_state=torch.zeros(1, dtype=torch.uint8))
    assert candidate_key(st(False, math.inf), 3) < candidate_key(never, 3)


def test_fewer_candidates_than_top_k_and_a_single_one() -> None:
    # the planner returned one plan although top_k asked for more: a plain CE run of the budget
    sh = SuccessiveHalving(specs(1), CE, plan_budget(1, 4, CE.n_envs))
    assert sh.winner == 0 and sh.in_final
    won = sh.run(fake([2.0]))
    assert won.index == 0 and won.iterations == 4 and won.dropped_round is None
    assert sh.spent_samples == 4 * CE.n_envs


def test_ties_keep_planner_order_and_stop_callback() -> None:
    sh = SuccessiveHalving(specs(2), CE, plan_budget(2, 4, CE.n_envs, 1))
    sh.run(lambda i, Z: EvalResult(cost=torch.full((Z.shape[0],), 7.0, dtype=F64),
                                   feasible=torch.ones(Z.shape[0], dtype=torch.bool)))
    assert sh.winner == 0 and sh.candidates[1].dropped_round == 0

    sh = SuccessiveHalving(specs(3), CE, plan_budget(3, 10, CE.n_envs))
    seen = []
    sh.run(fake([3.0, 2.0, 1.0]), on_iteration=lambda c, rec: seen.append(c.index) or len(seen) == 2)
    assert seen == [0, 1] and not sh.done and sh.winner is None and sh.spent_iterations == 2
    assert sh.report().halving.winner is None and sh.leader == 1


def test_converged_candidates_leave_their_iterations_to_the_winner() -> None:
    """Only the loser converges (after its first iteration); the budget rule gives the winner the
    nominal final iterations plus the loser's unspent round iterations: the run spends T in all."""
    cfg = CEConfig(n_envs=16, n_elite=4, iterations=10, seed=0, converge_std=0.5, min_std=0.01, patience=None)
    # the winner: parameters over +-100, a cost that ignores them (seeded noise in [1, 1.1)), so its
    # elites are random draws and their std (~58 at first) stays far above converge_std
    wide = CandidateSpec("wide", ParamLayout({"P0": Box([-100.0] * 2, [100.0] * 2)}), n_actions=3)
    noise = torch.Generator().manual_seed(0)
    loser = fake([0.0, 2.0])  # 2 + ||Z||^2 over [-1, 1]^4: elites near 0, converged at once

    def evaluate(i: int, Z: torch.Tensor) -> EvalResult:
        calls.append(i)
        if i == 1:
            return loser(i, Z)
        n = Z.shape[0]
        return EvalResult(cost=1.0 + 0.1 * torch.rand(n, generator=noise, dtype=F64),
                          feasible=torch.ones(n, dtype=torch.bool))

    b = plan_budget(2, 10, 16)
    assert (b.round_iterations, b.final_iterations) == (3, 4)  # round 0: 3 each; winner 4 more
    calls: list[int] = []
    sh = SuccessiveHalving([wide, specs(2)[1]], cfg, b)
    won = sh.run(evaluate)
    w, l = sh.candidates
    assert l.state.converged and l.iterations == 1 and l.dropped_round == 0  # 2 of its 3 unspent
    assert not w.state.converged and won.index == 0 and sh.winner == 0
    # the winner: its 3 round iterations + 4 nominal final ones + the loser's 2 unspent ones
    assert w.iterations == b.total_iterations - l.iterations == 3 + 4 + 2
    assert calls == [0, 0, 0, 1] + [0] * 6
    assert sh.spent_iterations == b.total_iterations and sh.spent_samples == b.total_samples == 160
    assert w.samples == 16 * 9 and l.samples == 16


def test_bad_construction() -> None:
    with pytest.raises(ValueError, match="budget is for 3 candidates"):
        SuccessiveHalving(specs(2), CE, plan_budget(3, 10, 16))
    lin = CEConfig(n_envs=16, n_elite=4, iterations=10, schedule="linear", n_envs_end=8)
    with pytest.raises(ValueError, match="schedule"):
        SuccessiveHalving(specs(2), lin, plan_budget(2, 10, 16))
    with pytest.raises(ValueError, match="at least one"):
        SuccessiveHalving([], CE, plan_budget(1, 10, 16))


def test_state_dict_round_trip_resumes_the_halving_exactly() -> None:
    """A halving run paused after any iteration and restored from its JSON state into a fresh
    ``SuccessiveHalving`` asks for the same batches and ends with the same winner and numbers."""
    import json

    base = [50.0, 10.0, 30.0]
    b = plan_budget(3, 10, CE.n_envs)
    ref_calls: list[tuple[int, torch.Tensor]] = []
    ref = SuccessiveHalving(specs(3), CE, b)
    ref.run(lambda i, Z: ref_calls.append((i, Z.clone())) or fake(base)(i, Z))
    for pause in (1, 3, 4, 7):
        sh = SuccessiveHalving(specs(3), CE, b)
        for _ in range(pause):
            batch = sh.ask()
            sh.tell(fake(base)(batch.candidate, batch.Z))
        again = SuccessiveHalving(specs(3), CE, b)
        again.load_state_dict(json.loads(json.dumps(again_state := sh.state_dict())))
        assert again.state_dict() == again_state and again.iterations_done == pause
        k = pause
        while (batch := again.ask()) is not None:
            i, Z = ref_calls[k]
            assert batch.candidate == i and torch.equal(batch.Z, Z)
            again.tell(fake(base)(batch.candidate, batch.Z))
            k += 1
        assert k == len(ref_calls) and again.winner == ref.winner
        assert again.report().halving.to_json() == ref.report().halving.to_json()
    other = SuccessiveHalving(specs(2), CE, plan_budget(2, 10, CE.n_envs))
    with pytest.raises(ValueError, match="not this run's"):
        other.load_state_dict(ref.state_dict())
