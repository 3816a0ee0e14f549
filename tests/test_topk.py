"""Top-k runs (``task.planner.top_k > 1``): config checks before any simulation, candidate tasks
over their own parameters, fewer plans than asked for, and a real tiny run on the pick_place
PDDL files (result.json ``candidates``/``winner``/``budget``, per-candidate files, budget
accounting, interrupt and resume, replay of the leading candidate's plan)."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest
import yaml

import realize.tasks.pddl
from helpers import cfg_of, expect_config_error, plain, tiny_with
from realize.paths import CONFIG_DIR
from realize.validation.replay import build_replay_spec, saved_plan
from realize.run.one_run import run
from realize.spec.run_spec import build_run_spec
from realize.run_dir.checkpoint import load_checkpoint
from realize.run_dir.directory import RunDir
from realize.run_dir.names import CHECKPOINT_FILE, RESULT_FILE
from realize.run_dir.result_doc import ResultDoc

TOPK = ["task.planner.enabled=true", "task.planner.top_k=2"]
SEED_PLAN = "move_to(Table1), grasp(cube, Cube_g), move_to(Table2), place(cube, Cube_p), move_to(Exit)"

BAD = [
    (["task.planner.top_k=0"], ["task:planner.top_k = 0", ">= 1"]),
    (["task.planner.top_k=2"], ["task:planner.top_k = 2", "task:planner.enabled"]),
    (TOPK + ["ce.iterations=1"], ["ce.iterations = 1 is too small", "task:planner.top_k = 2", "(2) = 2"]),
    (["task.planner.enabled=true", "task.planner.top_k=3", "task.planner.round_iterations=2", "ce.iterations=9"],
     ["ce.iterations = 9", "2 x (3 + 2) = 10", "task:planner.round_iterations"]),
    (TOPK + ["task.planner.round_iterations=0"], ["task:planner.round_iterations = 0"]),
    (TOPK + ["ce.schedule=linear", "ce.n_envs_end=4"], ["ce.schedule = 'linear'", "task:planner.top_k = 2"]),
    (["+task.planner.k=2"], ["task:planner", "'k'", "top_k"]),
]


@pytest.mark.parametrize("overrides, needles", BAD, ids=[" ".join(o) for o, _ in BAD])
def test_bad_top_k_config_fails_before_simulation(overrides: list[str], needles: list[str], tmp_path: Path,
                                                  no_sim: None, monkeypatch: pytest.MonkeyPatch) -> None:
    def no_planner(*a, **k):
        raise AssertionError("the planner ran for a config that fails its budget check")

    if "too small" in needles[0] or "schedule" in needles[0]:
        monkeypatch.setattr(realize.tasks.pddl, "plan_from_pddl", no_planner)
    _, res = expect_config_error(overrides, needles, tmp_path)
    assert res["status"] == "failed" and res["simulated"] is False


def test_top_k_1_is_a_single_plan(no_sim: None) -> None:
    spec = build_run_spec(plain(["task.planner.enabled=true"]))
    assert not spec.halving and spec.budget is None and spec.candidates == [spec.task]
    assert spec.task.describe() == SEED_PLAN


def test_candidates_use_only_their_parameters(tmp_path: Path, no_sim: None) -> None:
    task = yaml.safe_load((CONFIG_DIR / "task" / "pick_place.yaml").read_text())
    task["params"]["Spare"] = {"type": "box", "low": [0.0, 0.0], "high": [1.0, 1.0]}  # no plan uses it
    task["planner"].update(enabled=True, top_k=3)
    path = tmp_path / "spare.yaml"
    path.write_text(yaml.safe_dump(task, sort_keys=False))
    spec = build_run_spec(plain(tiny_with([f"task_file={path}", "ce.iterations=10"])))
    assert spec.halving and len(spec.candidates) == 3 and spec.budget is not None
    assert spec.budget.survivors == (3, 2) and spec.budget.round_iterations == 1
    assert "Spare" in spec.task.layout.names  # the task keeps every parameter ...
    for t in spec.candidates:  # ... each candidate only those its plan binds
        assert t.layout.names == ["Table1", "Cube_g", "Table2", "Cube_p", "Exit"]
        assert t.goal == spec.task.goal
    assert spec.candidates[0].describe() == SEED_PLAN
    assert len({t.describe() for t in spec.candidates}) == 3


def test_fewer_plans_than_top_k(monkeypatch: pytest.MonkeyPatch, no_sim: None) -> None:
    real = realize.tasks.pddl.plan_from_pddl
    asked = []

    def one_plan(*a, top_k: int = 1, **k):
        asked.append(top_k)
        return real(*a, top_k=top_k, **k)[:1]

    monkeypatch.setattr(realize.tasks.pddl, "plan_from_pddl", one_plan)
    spec = build_run_spec(plain(tiny_with(["task.planner.enabled=true", "task.planner.top_k=5",
                                           "ce.iterations=10"])))
    assert asked == [5]
    assert len(spec.candidates) == 1 and spec.candidates[0].describe() == SEED_PLAN
    assert spec.budget is not None and spec.budget.survivors == () and spec.budget.final_iterations == 10


# --------------------------------------------------------------------------------------------
# a real tiny run
# --------------------------------------------------------------------------------------------

RUN = tiny_with(TOPK + ["ce.iterations=3", "seed=2", "logging.rerun=true"])


@pytest.fixture(scope="module")
def topk_run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    d = tmp_path_factory.mktemp("topk")
    out = run(cfg_of(RUN), d)
    assert out.status == "done" and out.iterations_done == 3
    return d


def test_topk_run_writes_candidates(topk_run: Path) -> None:
    res = json.loads((topk_run / RESULT_FILE).read_text())
    assert res["status"] == "done" and res["top_k"] == 2 and res["n_candidates"] == 2
    cands = res["candidates"]
    assert [c["index"] for c in cands] == [0, 1] and cands[0]["plan"] == SEED_PLAN
    assert cands[1]["plan"] != SEED_PLAN
    b = res["budget"]
    assert b == {"n_candidates": 2, "total_iterations": 3, "n_envs_per_iteration": 4, "total_samples": 12,
                 "round_iterations": 1, "survivors_per_round": [2], "final_iterations": 1}
    # budget accounting: one round of 1 iteration each, the winner 1 more: 3 x 4 samples in all
    assert sum(c["samples"] for c in cands) == res["spent_samples"] == 12 == b["total_samples"]
    assert sorted(c["iterations"] for c in cands) == [1, 2] and res["spent_iterations"] == 3
    w = res["winner"]["index"]
    assert res["winner"]["plan"] == cands[w]["plan"] and res["leader"]["index"] == w
    assert cands[w]["dropped_round"] is None and cands[1 - w]["dropped_round"] == 0
    # the top level is the winner's, as for a single-plan run
    assert res["plan"] == cands[w]["plan"] and res["best_params"] == cands[w]["best_params"]
    assert res["feasible"] == cands[w]["feasible"] and res["best_cost"] == cands[w]["best_cost"]
    assert res["iterations_done"] == cands[w]["iterations"] == len(res["success_per_iter"])
    assert res["columns"] == cands[w]["columns"] and len(res["best_z"]) == len(res["columns"])
    for c in cands:
        with np.load(topk_run / c["history"], allow_pickle=False) as h:
            assert len(h["iteration"]) == c["iterations"] and list(h["column_names"]) == c["columns"]
            assert h["Z_000"].shape == (4, len(c["columns"]))
            assert h["action_success_000"].shape[1] == c["n_actions"]
        assert (topk_run / f"realize_c{c['index']}.rrd").stat().st_size > 0
    ck = load_checkpoint(topk_run)
    assert ck.iteration == 3 and [r.candidate for r in ck.records][:2] == [0, 1]
    assert ck.ce_state["kind"] == "successive_halving" and len(ck.ce_state["candidates"]) == 2


def test_topk_run_reads_back_typed(topk_run: Path) -> None:
    rd = RunDir(topk_run)
    doc = rd.result()
    assert isinstance(doc, ResultDoc) and doc.halving is not None
    assert doc.to_json() == json.loads((topk_run / RESULT_FILE).read_text())
    h = doc.halving
    assert h.winner is not None and h.leader == h.winner and h.n_candidates == 2
    w = h.candidates[h.winner.index]
    assert doc.plan == w.plan and doc.best_z == w.best_z and doc.columns == w.columns
    assert rd.best_plan().leader == h.leader
    for c in h.candidates:
        assert len(rd.load_history(candidate=c.index)) == c.iterations


@pytest.mark.slow  # a whole run or several processes: make test-all (make test keeps a smoke test)
@pytest.mark.parametrize("stop_at", [0, 1])
def test_topk_interrupted_then_resumed_equals_uninterrupted(topk_run: Path, tmp_path: Path, stop_at: int) -> None:
    """Interrupted mid-round (after candidate 0's first iteration) or at the end of round 0, then
    resumed: the halving state comes back from the checkpoint and the run ends exactly as the
    uninterrupted one (same winner, candidates, series and history files)."""
    def stop(i: int) -> None:
        if i == stop_at:
            raise KeyboardInterrupt

    cut = tmp_path / "cut"
    out = run(cfg_of(RUN), cut, after_iteration=stop)
    assert out.interrupted and out.iterations_done == stop_at + 1
    done = run(cfg_of(["logging.progress=false", f"resume={cut}"]), tmp_path / "hydra_dir")
    assert done.status == "done" and done.run_dir == cut and done.iterations_done == 3
    a, b = (json.loads((d / RESULT_FILE).read_text()) for d in (topk_run, cut))
    for k in ("best_z", "best_cost", "feasible", "best_iteration", "plan", "success_per_iter", "best_cost_per_iter",
              "n_feasible_per_iter", "elite_per_iter", "final_mean", "final_std", "iterations_done", "winner",
              "leader", "candidates", "spent_samples", "spent_iterations", "halving_round", "budget"):
        assert a[k] == b[k], k
    assert b["status"] == "done" and b["segments"] == 2 and b["resumed_from_iteration"] == stop_at + 1
    for c in a["candidates"]:
        with np.load(topk_run / c["history"], allow_pickle=False) as ha, \
                np.load(cut / c["history"], allow_pickle=False) as hb:
            assert sorted(ha.files) == sorted(hb.files)
            for k in ha.files:
                np.testing.assert_array_equal(ha[k], hb[k], err_msg=f"{c['history']}:{k}")
    ck = load_checkpoint(cut)
    assert ck.iteration == 3 and [r.candidate for r in ck.records] == [r.candidate for r in load_checkpoint(topk_run).records]
    # candidate 0 went on after the interruption: its next segment has its own recording
    assert (cut / "realize_c0.from-it1.rrd").stat().st_size > 0


def test_resumed_topk_that_is_complete_runs_nothing(topk_run: Path, tmp_path: Path, no_sim: None) -> None:
    copy = tmp_path / "copy"
    shutil.copytree(topk_run, copy)
    before = json.loads((copy / RESULT_FILE).read_text())
    out = run(cfg_of([f"resume={copy}", "logging.progress=false"]), copy, cli_overrides=[f"resume={copy}"])
    assert out.status == "done" and out.iterations_done == 3
    after = json.loads((copy / RESULT_FILE).read_text())
    assert after["winner"] == before["winner"] and after["candidates"] == before["candidates"]


def test_topk_replay_spec_is_the_leaders_plan(topk_run: Path, no_sim: None) -> None:
    saved = saved_plan(topk_run)
    spec = build_replay_spec(saved)
    assert spec.task.describe() == saved.leader.plan
    assert spec.task.layout.column_names == saved.columns


@pytest.mark.slow  # a second top-k run (10 s on a busy 2-core host): make test keeps the whole top-k run
# (topk_run) and an interrupted run resumed (tests/test_app.py)
def test_topk_interrupted_in_round_0(tmp_path: Path) -> None:
    def stop(i: int) -> None:
        if i == 0:
            raise KeyboardInterrupt

    out = run(cfg_of(tiny_with(TOPK + ["ce.iterations=3"])), tmp_path, after_iteration=stop)
    assert out.status == "interrupted" and out.iterations_done == 1
    res = json.loads((tmp_path / RESULT_FILE).read_text())
    assert res["interrupted"] is True and res["winner"] is None and res["leader"]["index"] == 0
    assert [c["iterations"] for c in res["candidates"]] == [1, 0] and res["spent_samples"] == 4
    assert res["candidates"][1]["best_params"] is None
    assert (tmp_path / CHECKPOINT_FILE).is_file()


@pytest.mark.slow  # a second whole run (8 s on a busy 2-core host): make test keeps the top-k run and
# history-free restores (tests/test_stitched_segments.py, test_a_restore_is_history_free)
def test_candidate_0_equals_a_single_plan_run_in_the_shared_scene(topk_run: Path, tmp_path: Path) -> None:
    """Candidate 0 (the planner's first plan, the run's seed) draws the samples of a single-plan
    run; its second iteration runs after candidate 1 used the same scene, and still gives the
    single-plan run's numbers bit for bit (CPU resets are history-free)."""
    res = json.loads((topk_run / RESULT_FILE).read_text())
    assert res["winner"]["index"] == 0 and res["candidates"][0]["iterations"] == 2  # seed 2: c0, c1, c0
    assert load_checkpoint(topk_run).records[1].candidate == 1
    single = tmp_path / "single"
    run(cfg_of(tiny_with(["task.planner.enabled=true", "ce.iterations=2", "seed=2"])), single)
    with np.load(topk_run / "history_c0.npz", allow_pickle=False) as a, \
            np.load(single / "history.npz", allow_pickle=False) as b:
        for k in ("Z_000", "Z_001", "cost_000", "cost_001", "feasible_001", "progress_001", "distance_001",
                  "action_success_001", "steps_001"):
            np.testing.assert_array_equal(a[k], b[k], err_msg=k)
