"""Carrying a plan out and repairing it (realize/repair/study.py, scripts/execute.py), on CPU.

The run executed is written by hand once per module (as tests/test_replay.py writes its runs):
the seed task's default config and its known feasible plan ``GOOD`` as the returned plan and
the final distribution the replans warm-start from. No search runs to make it. Each study is
one world with small replans (8 copies, 2 elites, at most 2 iterations, one worker).
"""

from __future__ import annotations

import contextlib
import io
import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from helpers import REPO, TABLE_MOVED, closed_loop_world, doc_block, execute_budget, one_world, write_known_run
from realize.repair.study import execute
from realize.config import ConfigError
from realize.execution.trajectory import read_trajectory

BUDGET = execute_budget()
# the cube knocked out of the hand onto table 1 just after the grasp (the knocked_out preset's timing)
KNOCKED = {"trigger": {"action": 2, "delay_s": 0.1}, "knock_out": {"object": "cube"}}


@pytest.fixture(scope="module")
def run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return write_known_run(tmp_path_factory.mktemp("execute") / "run")


@pytest.fixture(scope="module")
def table_study(run: Path):
    """Open and closed loop in one world where table 2 moves mid-transport."""
    summary = execute(run, one_world(TABLE_MOVED, precheck={"copies": 0}), name="table", worlds=1, budget=BUDGET,
                      rerun=False, progress=False)
    return summary, run / "execution" / "table"


def _log(where: Path, mode: str) -> dict:
    return json.loads((where / f"world-0-{mode}.json").read_text())


# ------------------------------------------------------------------------------ a moved table
def test_moved_table_fails_open_loop_and_is_repaired_closed_loop(table_study) -> None:
    summary, where = table_study
    opened, closed = _log(where, "open"), _log(where, "closed")
    assert opened["success"] is False and opened["failure"] and opened["replans"] == []
    assert [d["effect"] for d in opened["disturbances"]] == ["MoveTable"]
    assert closed["success"] is True, closed["failure"]
    kinds = [r["kind"] for r in closed["replans"]]
    assert len(kinds) >= 1 and "re-parameterize" in kinds
    first = closed["replans"][0]
    assert first["feasible"] and first["from_action"] == 2 and any("table" in c for c in first["changes"])
    assert any(d["what"] and "table_moved" in d["what"][0] for d in closed["deviations"])
    assert summary.open_loop_success == 0.0 and summary.closed_loop_success == 1.0
    assert summary.replans == [len(kinds)] and len(summary.replan_s) == len(kinds)


def test_summary_json_has_the_study_keys(table_study) -> None:
    summary, where = table_study
    doc = json.loads((where / "summary.json").read_text())
    for key in ("worlds", "closed_loop_success", "open_loop_success", "replans", "replan_s"):
        assert key in doc, key
    assert doc["worlds"] == 1 and doc["closed_loop_success"] == 1.0 and doc["open_loop_success"] == 0.0
    assert isinstance(doc["replans"], list) and len(doc["replans"]) == 1
    assert all(isinstance(s, float) and s > 0 for s in doc["replan_s"]) and len(doc["replan_s"]) == doc["replans"][0]
    for f in ("world-0-open.json", "world-0-closed.json", "world-0-open.npz", "world-0-closed.npz"):
        assert (where / f).is_file(), f


def test_the_table_script_prints_the_studys_row(table_study) -> None:
    """scripts/execution_table.py: the header and one row with the study's numbers."""
    summary, where = table_study
    r = subprocess.run([sys.executable, str(REPO / "scripts" / "execution_table.py"), str(where)], capture_output=True,
                       text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    header, _, line = r.stdout.strip().splitlines()
    cells = [c.strip() for c in line.strip("|").split("|")]
    assert header.startswith("| study | open loop | closed loop") and cells[:3] == ["table", "0/1", "1/1"]
    assert cells[3].startswith(f"{sum(summary.replans)} (") and cells[4] == "0 / 0"


def test_the_docs_trajectory_example_runs(table_study) -> None:
    """docs/execution_format.md's reading example, on the closed-loop world's trajectory: one line
    per action segment, its text and its first and last times."""
    _, where = table_study
    path = where / "world-0-closed.npz"
    code = doc_block("docs/execution_format.md", "python").text.replace('"trajectory.npz"', repr(str(path)))
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        exec(compile(code, "docs/execution_format.md", "exec"), {})
    t = read_trajectory(path)
    lines = out.getvalue().splitlines()
    assert len(lines) == len(t.action_text) >= 5
    assert [ln.rsplit(" ", 2)[0] for ln in lines] == list(t.action_text)


@pytest.mark.slow  # a second closed-loop world (24 s on a busy 2-core host), beside the noisy world's repeat
# (tests/test_closed_loop.py); make test keeps the study (table_study) and the golden runs' bit for bit
def test_same_seed_and_disturbances_execute_the_same(table_study, run: Path, tmp_path: Path) -> None:
    """A second execution of the closed-loop world (a new planner) repeats the study's, bit for bit."""
    _, where = table_study
    wl = closed_loop_world(run, one_world(TABLE_MOVED, precheck={"copies": 0}), tmp_path, trajectory=tmp_path / "again.npz")
    first = _log(where, "closed")
    assert (wl.steps, wl.success, wl.final_plan) == (first["steps"], first["success"], first["final_plan"])
    assert [(a.index, a.text, a.begin_step, a.end_step, a.outcome) for a in wl.actions] == \
        [(a["index"], a["text"], a["begin_step"], a["end_step"], a["outcome"]) for a in first["actions"]]
    assert [(r.kind, r.step, r.from_action, r.feasible, r.cost, r.plan) for r in wl.replans] == \
        [(r["kind"], r["step"], r["from_action"], r["feasible"], r["cost"], r["plan"]) for r in first["replans"]]
    assert [d["step"] for d in wl.disturbances] == [d["step"] for d in first["disturbances"]]
    a, b = read_trajectory(where / "world-0-closed.npz"), read_trajectory(tmp_path / "again.npz")
    assert len(a) == len(b) > 0
    for name in ("step", "t_s", "action", "plan_index", "joint_targets", "base_velocity", "gripper",
                 "action_boundaries"):
        assert np.array_equal(getattr(a, name), getattr(b, name)), name
    assert a.joint_names == b.joint_names and a.action_text == b.action_text


# ------------------------------------------------------------------------------ a knocked-out cube
def test_knocked_out_cube_is_resequenced_with_a_second_grasp(run: Path, tmp_path: Path) -> None:
    wl = closed_loop_world(run, one_world(KNOCKED), tmp_path)
    assert [r.kind for r in wl.replans][:1] == ["re-sequence"], [(r.kind, r.reason) for r in wl.replans]
    assert wl.final_plan.startswith("grasp(") and "grasp(" in wl.replans[0].plan
    grasps = [a for a in wl.actions if a.text.startswith("grasp(") and a.outcome == "done"]
    assert len(grasps) == 2, [(a.text, a.outcome) for a in wl.actions]
    assert wl.success, wl.failure


# ------------------------------------------------------------------------------ refusals
@pytest.mark.parametrize("entry, needles", [
    ({"trigger": {"action": 0}, "move_object": {"object": "ball", "dx": 0.1}}, ["'ball'", "cube"]),
    ({"trigger": {"action": 0}, "move_table": {"table": "table7", "dx": 0.1}}, ["table7", "table2"]),
    ({"trigger": {"action": 9}, "knock_out": {"object": "cube"}}, ["trigger.action = 9", "5 actions"]),
])
def test_bad_disturbances_are_refused_before_anything_is_simulated(run: Path, no_sim, monkeypatch, entry,
                                                                  needles) -> None:
    import realize.run.planner as planner_mod

    def no_planner(*a, **k):
        raise AssertionError("a planner was started for an invalid execution")

    monkeypatch.setattr(planner_mod.Planner, "from_run", classmethod(no_planner))
    with pytest.raises(ConfigError) as ei:
        execute(run, one_world(entry), name="bad", budget=BUDGET, rerun=False, progress=False)
    msg = str(ei.value)
    assert "\n" not in msg, msg
    for n in needles:
        assert n in msg, (n, msg)
    assert not (run / "execution" / "bad" / "summary.json").exists()


def test_script_refuses_an_unknown_family_in_one_line(run: Path) -> None:
    p = subprocess.run([sys.executable, str(REPO / "scripts" / "execute.py"), str(run), "--disturbance", "nope"],
                       cwd=REPO, capture_output=True, text=True, timeout=120)
    assert p.returncode == 2, (p.stdout, p.stderr)
    lines = [ln for ln in p.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("error:") and "'nope'" in lines[0], p.stderr
