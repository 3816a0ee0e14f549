"""The one search loop (realize.run.loop) and its sinks' failure rule (realize.sinks.base), on a fake
scene: either searcher runs through the same loop, sinks see every iteration in order, a failing
non-critical sink is dropped while the search goes on, a failing critical sink fails the run
clearly, and an interrupt ends the run as ``interrupted``. No simulator."""

from __future__ import annotations

import inspect
import json
import logging
from dataclasses import dataclass
from pathlib import Path

import pytest
import torch

from realize.search.budget import plan_budget
from realize.search.candidates import CandidateSpec, SuccessiveHalving
from realize.search.ce.config import CEConfig
from realize.search.ce.optimizer import CrossEntropyOptimizer
from realize.run.loop import search_loop
from realize.tasks.param_layout import ParamLayout
from realize.tasks.regions import Box
from realize.search.ce.state import IterationRecord
from realize.search.protocol import Batch, EvalResult, SearchReport, Searcher
from realize.sinks.base import Iteration, SinkError, SinkSet

F64 = torch.float64
LAYOUT = ParamLayout({"P": Box([-1.0, -1.0], [1.0, 1.0])})


@dataclass
class FakeRollout:
    cost: torch.Tensor
    feasible: torch.Tensor

    def to_eval(self) -> EvalResult:
        return EvalResult(cost=self.cost, feasible=self.feasible)


class FakeRealizer:
    def __init__(self, name: str, calls: list) -> None:
        self.name, self.calls = name, calls

    def rollout(self, Z: torch.Tensor, record: bool = False) -> FakeRollout:
        self.calls.append((self.name, Z.shape[0], record))
        return FakeRollout((Z**2).sum(1), torch.ones(Z.shape[0], dtype=torch.bool))


class FakePool:
    """Rollout workers as the loop sees them: one realizer per candidate plan."""

    closed = False

    def __init__(self, realizers: list[FakeRealizer]) -> None:
        self.realizers = realizers

    def rollout(self, candidate: int | None, Z: torch.Tensor, record: bool = False) -> FakeRollout:
        return self.realizers[0 if candidate is None else candidate].rollout(Z, record=record)

    def close(self) -> None:
        self.closed = True


class Recorder:
    """A sink that notes what it is called with (and can be told to fail)."""

    def __init__(self, name: str, log: list, critical: bool = False, fail_at: int | None = None,
                 wants_trajectories: bool = False) -> None:
        self.name, self.log, self.critical, self.fail_at = name, log, critical, fail_at
        self.wants_trajectories = wants_trajectories

    def open(self) -> None:
        self.log.append((self.name, "open"))

    def on_iteration(self, it: Iteration) -> None:
        if it.index == self.fail_at:
            raise OSError("disk full")
        self.log.append((self.name, it.index, it.batch.candidate))

    def close(self, status: str | None, error: str | None) -> None:
        self.log.append((self.name, "close", status))


def scene_of(n_plans: int, calls: list):
    pool = FakePool([FakeRealizer(f"r{i}", calls) for i in range(n_plans)])
    return pool, (lambda: pool)


def one_plan() -> CrossEntropyOptimizer:
    return CrossEntropyOptimizer(LAYOUT, CEConfig(n_envs=8, n_elite=2, iterations=3))


def two_plans() -> SuccessiveHalving:  # T = 4: m = 1, round 0 runs each once, the winner 2 more
    return SuccessiveHalving([CandidateSpec("a", LAYOUT, 1), CandidateSpec("b", LAYOUT, 1)],
                             CEConfig(n_envs=8, n_elite=2, iterations=4), plan_budget(2, 4, 8))


@pytest.mark.parametrize("make, order", [(one_plan, [None] * 3), (two_plans, [0, 1, 0, 0])])
def test_both_searchers_keep_the_protocol(make, order: list) -> None:
    """Each searcher has the Protocol's members with its parameters (isinstance on a runtime
    Protocol only checks names), and a run driven through them alone gives what the Protocol
    says: Batches of (N, D) samples naming their candidate, records, reports, ``done`` at the
    end, and a JSON ``state_dict`` that a fresh searcher resumes from with the same samples."""
    s = make()
    assert isinstance(s, Searcher)
    for name in ("done", "iterations_done"):
        assert isinstance(inspect.getattr_static(type(s), name), property), name
    for name in ("ask", "tell", "report", "state_dict", "load_state_dict"):
        want, got = (inspect.signature(getattr(c, name)).parameters.values() for c in (Searcher, type(s)))
        assert [(p.name, p.kind, p.default is p.empty) for p in got] == \
               [(p.name, p.kind, p.default is p.empty) for p in want], name

    def evaluate(b: Batch) -> EvalResult:  # candidate 1 is worse: candidate 0 wins the halving
        return EvalResult(cost=(b.Z**2).sum(1) + 10.0 * (b.candidate == 1), feasible=torch.ones(8, dtype=torch.bool))

    Zs, seen = [], []
    assert not s.done and s.iterations_done == 0
    while (b := s.ask()) is not None:
        assert isinstance(b, Batch) and b.Z.shape == (8, 2) and b.Z.dtype == F64
        rec = s.tell(evaluate(b))
        Zs.append(b.Z.clone()), seen.append(b.candidate)
        assert isinstance(rec, IterationRecord) and rec.n_envs == 8
        assert s.iterations_done == len(seen) and isinstance(s.report(), SearchReport)
        if len(seen) == 1:
            state = json.dumps(s.state_dict(), allow_nan=False)  # plain JSON data
    assert s.done and s.ask() is None and seen == order

    again = make()
    again.load_state_dict(json.loads(state))
    assert again.iterations_done == 1 and not again.done
    rest = []
    while (b := again.ask()) is not None:
        again.tell(evaluate(b))
        rest.append(b.Z)
    assert len(rest) == len(Zs) - 1 and all(torch.equal(a, z) for a, z in zip(rest, Zs[1:]))


def test_sinks_see_every_iteration_in_order_and_close_with_the_status(tmp_path: Path) -> None:
    log: list = []
    calls: list = []
    scene, open_scene = scene_of(1, calls)
    ce = CrossEntropyOptimizer(LAYOUT, CEConfig(n_envs=8, n_elite=2, iterations=3))
    sinks = SinkSet([Recorder("a", log, critical=True), Recorder("b", log, wants_trajectories=True)])
    end = search_loop(ce, sinks, open_scene, error_file=tmp_path / "error.txt")
    assert (end.status, end.exit_code, end.iterations) == ("done", 0, 3)
    assert log == [("a", "open"), ("b", "open"),
                   ("a", 0, None), ("b", 0, None), ("a", 1, None), ("b", 1, None), ("a", 2, None), ("b", 2, None),
                   ("a", "close", "done"), ("b", "close", "done")]
    assert calls == [("r0", 8, True)] * 3  # a sink wants trajectories: the rollout records them
    assert scene.closed and not (tmp_path / "error.txt").exists()


def test_the_loop_routes_each_candidates_batch_to_its_realizer() -> None:
    calls: list = []
    _, open_scene = scene_of(3, calls)
    specs = [CandidateSpec(f"plan{i}", LAYOUT, 2) for i in range(3)]
    sh = SuccessiveHalving(specs, CEConfig(n_envs=8, n_elite=2, iterations=6), plan_budget(3, 6, 8))
    log: list = []
    end = search_loop(sh, SinkSet([Recorder("a", log)]), open_scene)
    assert end.status == "done" and end.iterations == sh.spent_iterations == 6
    assert [c[0] for c in calls[:3]] == ["r0", "r1", "r2"]  # round 0: every candidate once
    assert [(e[1], e[2]) for e in log if isinstance(e[1], int)][:3] == [(0, 0), (1, 1), (2, 2)]
    assert {c[2] for c in calls} == {False}  # no sink wants trajectories


def test_a_failing_sink_is_dropped_and_the_search_goes_on(caplog: pytest.LogCaptureFixture) -> None:
    log: list = []
    _, open_scene = scene_of(1, [])
    ce = CrossEntropyOptimizer(LAYOUT, CEConfig(n_envs=8, n_elite=2, iterations=3))
    sinks = SinkSet([Recorder("flaky", log, fail_at=1), Recorder("ok", log)])
    with caplog.at_level(logging.WARNING, logger="realize"):
        end = search_loop(ce, sinks, open_scene)
    assert end.status == "done" and end.iterations == 3
    assert ("flaky", "close", None) in log and ("flaky", 2, None) not in log  # dropped after its failure
    assert [e for e in log if e[0] == "ok" and isinstance(e[1], int)] == [("ok", 0, None), ("ok", 1, None),
                                                                          ("ok", 2, None)]
    assert "the flaky failed at iteration 1 (OSError: disk full); it stops" in caplog.text


def test_a_failing_critical_sink_fails_the_run_clearly(tmp_path: Path) -> None:
    log: list = []
    scene, open_scene = scene_of(1, [])
    ce = CrossEntropyOptimizer(LAYOUT, CEConfig(n_envs=8, n_elite=2, iterations=3))
    sinks = SinkSet([Recorder("checkpoint", log, critical=True, fail_at=1), Recorder("bar", log)])
    with pytest.raises(SinkError, match=r"the checkpoint failed at iteration 1 \(OSError: disk full\)"):
        search_loop(ce, sinks, open_scene, error_file=tmp_path / "error.txt")
    assert "SinkError" in (tmp_path / "error.txt").read_text()
    assert ("checkpoint", "close", "failed") in log and ("bar", "close", "failed") in log and scene.closed


def test_an_interrupt_ends_the_run_as_interrupted() -> None:
    log: list = []
    _, open_scene = scene_of(1, [])
    ce = CrossEntropyOptimizer(LAYOUT, CEConfig(n_envs=8, n_elite=2, iterations=5))

    def stop(i: int) -> None:
        if i == 1:
            raise KeyboardInterrupt

    end = search_loop(ce, SinkSet([Recorder("a", log)]), open_scene, after_iteration=stop)
    assert (end.status, end.exit_code, end.iterations) == ("interrupted", 130, 2)
    assert log[-1] == ("a", "close", "interrupted") and ce.iterations_done == 2
