"""realize.run_dir without a simulator: the one inf/NaN encoding, the documents' JSON round trips
(including files written before the n_envs naming rule), checkpoints, and RunDir's errors. The
real tiny runs of test_app.py / test_topk.py check RunDir on real run directories."""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest

from realize.run_dir.checkpoint import Checkpoint, CheckpointError, load_checkpoint, save_checkpoint
from realize.run_dir.directory import RunDir, RunDirError
from realize.run_dir.jsonio import decode_float, decode_floats, encode_float, encode_floats, json_safe
from realize.run_dir.names import RESULT_FILE, candidate_file
from realize.run_dir.result_doc import EliteStats, FailureDoc, HalvingDoc, PlanRef, ResultDoc, read_result_doc
from realize.run_dir.summaries import CandidateSummary, IterationSummary, JobStatusDoc

INF, NAN = math.inf, math.nan


def strict(d: dict) -> dict:
    """Through strict JSON text and back, as a file would."""
    return json.loads(json.dumps(d, allow_nan=False))


def test_float_encoding_round_trip() -> None:
    assert [encode_float(v) for v in (1.5, INF, -INF, NAN, None)] == [1.5, None, None, None, None]
    assert decode_float(None, INF) == INF and math.isnan(decode_float(None)) and decode_float(2) == 2.0
    # the strings of checkpoints written before this encoding
    assert decode_float("inf") == INF and decode_float("-inf") == -INF and math.isnan(decode_float("nan"))
    with pytest.raises(ValueError, match=r"expected a number, got True"):  # a bool is no number in JSON
        decode_float(True)
    with pytest.raises(ValueError, match=r"expected a number, got \[1\.0\]"):
        decode_float([1.0])
    assert encode_floats([[1.0, NAN], [INF, 2.0]]) == [[1.0, None], [None, 2.0]]
    back = decode_floats([[1.0, None], None])  # a null entry is a float without a value
    assert back[0][0] == 1.0 and math.isnan(back[0][1]) and math.isnan(back[1])
    assert decode_floats(None) is None  # ... a null list is no list
    assert json_safe({"a": (1, NAN), 2: Path("x")}) == {"a": [1, None], "2": "x"}


def _summary(**kw) -> IterationSummary:
    base = dict(iteration=1, n_envs=8, sampled_from="gaussian", refit="fallback_progress", n_feasible=0,
                success_share=0.0, best_cost=INF, iteration_best_cost=INF, elite_cost_min=NAN,
                elite_cost_mean=NAN, elite_cost_max=NAN, n_elite=2, mean=[0.5, 1.0], std=[0.1, 0.2],
                eval_time=NAN, wall_time=0.25, converged=False)
    base.update(kw)
    return IterationSummary(**base)


def test_iteration_summary_round_trip() -> None:
    s = _summary()
    j = strict(s.to_json())
    assert j["best_cost"] is None and j["elite_cost_mean"] is None and j["eval_time"] is None
    assert "weights" not in j and "candidate" not in j and j["n_envs"] == 8
    back = IterationSummary.from_json(j)
    assert back.best_cost == INF and back.iteration_best_cost == INF  # null: no feasible cost yet
    assert math.isnan(back.elite_cost_min) and math.isnan(back.eval_time)  # null: no value
    assert back.to_json() == j
    mix = _summary(best_cost=412.0, mean=[[0.0, 1.0], [2.0, 3.0]], weights=[0.25, 0.75], candidate=1)
    j = strict(mix.to_json())
    assert j["weights"] == [0.25, 0.75] and j["candidate"] == 1 and j["best_cost"] == 412.0
    assert IterationSummary.from_json(j) == mix


def test_iteration_summary_reads_old_records() -> None:
    old = {"iteration": 0, "n_samples": 4, "sampled_from": "uniform", "refit": "elite", "n_feasible": 0,
           "success_share": 0.0, "best_cost": "inf", "iteration_best_cost": "inf", "elite_cost_min": "nan",
           "elite_cost_mean": "nan", "elite_cost_max": "nan", "n_elite": 2, "mean": [1.0], "std": [0.5],
           "eval_time": 1.0, "wall_time": 1.5, "converged": False}
    s = IterationSummary.from_json(old)
    assert s.n_envs == 4 and s.best_cost == INF and math.isnan(s.elite_cost_max)
    assert strict(s.to_json())["best_cost"] is None


def _result(**kw) -> ResultDoc:
    cand = [CandidateSummary(0, "move_to(A)", 1, ["A.x", "A.y"], feasible=True, best_cost=300.0, best_iteration=0,
                             best_params={"A": {"x": 1.0, "y": 2.0}}, best_z=[1.0, 2.0], iterations=2, samples=8),
            CandidateSummary(1, "move_to(B)", 1, ["B.x"], iterations=1, samples=4, dropped_round=0)]
    base = dict(status="done", feasible=True, best_cost=300.0, best_iteration=0,
                best_params={"A": {"x": 1.0, "y": 2.0}}, best_z=[1.0, 2.0], columns=["A.x", "A.y"],
                iterations_done=2, iterations=3, success_per_iter=[0.25, 0.5], best_cost_per_iter=[INF, 300.0],
                iteration_best_cost_per_iter=[INF, 300.0], n_envs_per_iter=[4, 4], n_feasible_per_iter=[0, 2],
                elite_per_iter=[EliteStats(2, "fallback_progress"), EliteStats(2, "elite", 300.0, 310.0, 320.0)],
                iteration_time_s=[1.0, 1.5], final_mean=[1.0, 2.0], final_std=[0.1, 0.1], wall_time_s=3.0,
                seed=2, task_name="t", task_source="configs/task/t.yaml", plan="move_to(A)",
                config={"ce": {"n_envs": 4}}, versions={"torch": "2"}, run_dir="/x", backend="cpu", n_envs=4,
                setup_time_s=0.5,
                halving=HalvingDoc(2, PlanRef(0, "move_to(A)"), PlanRef(0, "move_to(A)"), {"total_iterations": 3},
                                   3, 12, 1, cand),
                extra={"validation": {"replicas": 4}})
    base.update(kw)
    return ResultDoc(**base)


def test_a_pruned_runs_finished_share_is_beside_the_share_of_all_rows() -> None:
    """With ce.prune a stopped row counts as failed in success_per_iter; finished_success_per_iter
    is the share of the rows that ran to their end, derived from the counts and never read back."""
    doc = _result(n_envs_per_iter=[10, 10, 4], n_feasible_per_iter=[2, 3, 0], n_stopped_per_iter=[5, 0, 4],
                  success_per_iter=[0.2, 0.3, 0.0], iterations_done=3)
    j = strict(doc.to_json())
    assert j["finished_success_per_iter"] == [0.4, 0.3, None] and j["success_per_iter"] == [0.2, 0.3, 0.0]
    back = ResultDoc.from_json(j)
    assert "finished_success_per_iter" not in back.extra  # derived, not stored twice
    back.n_feasible_per_iter = [4, 3, 0]
    assert back.to_json()["finished_success_per_iter"] == [0.8, 0.3, None]
    assert "finished_success_per_iter" not in _result().to_json()  # pruning off: no such key


def test_result_doc_round_trip() -> None:
    doc = _result()
    j = strict(doc.to_json())
    assert j["best_cost_per_iter"] == [None, 300.0] and j["elite_per_iter"][0]["cost_min"] is None
    assert j["files"]["history"] == ["history_c0.npz", "history_c1.npz"] and j["n_candidates"] == 2
    assert [c["history"] for c in j["candidates"]] == [candidate_file("history.npz", i) for i in (0, 1)]
    assert j["candidates"][1]["best_cost"] is None and j["winner"] == {"index": 0, "plan": "move_to(A)"}
    assert j["validation"] == {"replicas": 4} and j["interrupted"] is False and j["n_envs"] == 4
    back = ResultDoc.from_json(j)
    assert back.best_cost_per_iter == [INF, 300.0] and back.halving is not None
    assert back.halving.candidates[1].best_cost == INF and back.extra == {"validation": {"replicas": 4}}
    assert back.to_json() == j
    single = strict(_result(halving=None, extra={}, status="interrupted", feasible=False).to_json())
    assert "candidates" not in single and single["files"]["history"] == "history.npz"
    assert single["best_cost"] is None and single["interrupted"] is True


def test_result_doc_reads_partial_and_old_documents() -> None:
    doc = ResultDoc.from_json({"success_per_iter": [0.1], "best_cost_per_iter": [None], "n_envs_scene": 16,
                               "n_samples_per_iter": [16], "plan": ["move_to(A)", "grasp(B)"]})
    assert doc.status is None and doc.best_cost_per_iter == [INF] and doc.iterations_done == 1
    assert doc.n_envs == 16 and doc.n_envs_per_iter == [16] and doc.plan == "move_to(A), grasp(B)"
    assert doc.extra == {}


def test_failure_doc() -> None:
    f = FailureDoc("ce.n_elite = 9 is invalid", config={"ce": {"n_elite": 9}}, versions={"torch": "2"})
    j = strict(f.to_json())
    assert j["status"] == "failed" and j["simulated"] is False and j["best_cost"] is None
    back = read_result_doc(j)
    assert isinstance(back, FailureDoc) and back.to_json() == j and back.iterations_done == 0
    assert isinstance(read_result_doc({"status": "done"}), ResultDoc)


def test_checkpoint_round_trip(tmp_path: Path) -> None:
    recs = [_summary(iteration=0), _summary(iteration=1, best_cost=5.0, candidate=1)]
    save_checkpoint(tmp_path, Checkpoint(2, {"best_cost": "inf"}, {"seed": 1}, recs, 12.5, 2))
    back = load_checkpoint(tmp_path)
    assert back.iteration == 2 and back.segments == 2 and back.wall_time_s == 12.5
    assert back.ce_state == {"best_cost": "inf"}  # the optimizer's own form, kept verbatim
    assert [r.to_json() for r in back.records] == [strict(r.to_json()) for r in recs]
    assert back.records[0].best_cost == INF and back.records[1].candidate == 1
    d = json.loads((tmp_path / "checkpoint.json").read_text())
    d["records"][1] = {"iteration": 1}
    (tmp_path / "checkpoint.json").write_text(json.dumps(d))
    with pytest.raises(CheckpointError, match="malformed iteration record"):
        load_checkpoint(tmp_path)


def test_run_dir_errors_and_job_status(tmp_path: Path) -> None:
    rd = RunDir(tmp_path)
    assert rd.result() is None and rd.status() is None and rd.config() is None
    with pytest.raises(RunDirError, match="not found"):
        rd.best_plan()
    with pytest.raises(FileNotFoundError, match="not a realize run directory"):
        RunDir.existing(tmp_path)
    (tmp_path / RESULT_FILE).write_text(json.dumps({"config": {}, "best_z": None}))
    assert rd.status() == "unknown"
    with pytest.raises(RunDirError, match="best_z"):
        rd.best_plan()
    (tmp_path / RESULT_FILE).write_text(json.dumps({"best_z": [1.0]}))
    with pytest.raises(RunDirError, match="config"):
        rd.best_plan()
    rd.write_result(_result())
    plan = rd.best_plan()
    assert plan.best_z == [1.0, 2.0] and plan.best_cost == 300.0 and plan.n_envs == 4
    assert plan.leader == PlanRef(0, "move_to(A)") and plan.backend == "cpu"
    rd.add_to_result("validation", {"replicas": 8})
    assert rd.result_json()["validation"] == {"replicas": 8}
    # a failure never overwrites a directory that holds a run
    (tmp_path / "checkpoint.json").write_text("{}")
    assert not rd.write_failure(FailureDoc("boom"))
    assert rd.status() == "done"
    rd.write_job_status(JobStatusDoc(3, ["seed=1"], "done", ""))
    assert rd.job_status() == JobStatusDoc(3, ["seed=1"], "done", "")
