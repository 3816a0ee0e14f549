"""A run directory keeps the task it ran: a run from a task file, the file edited afterwards,
and the replay of the run still realizes the run's task and gets its cost bit for bit.

The task drives the base to a table and out through Exit (no contact: a 3-plan, 1-iteration
run takes seconds). The edit moves Exit and renames the task: a replay that read the live file
would judge the saved plan against the moved Exit and fail its goal.
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest
import yaml

from helpers import compose_config, load_script
from realize.run.one_run import run
from realize.spec.run_spec import build_run_spec
from realize.run_dir.names import RESULT_FILE

TASK = {
    "name": "drive_out",
    "params": {
        "Table1": {"type": "annulus", "frame": "table1", "center": [0.0, 0.0], "r_min": 0.75, "r_max": 1.25},
        "Exit": {"type": "box", "low": [1.8, -0.4], "high": [2.6, 0.4]},
    },
    "plan": ["move_to(Table1)", "move_to(Exit)"],
    "goal": {"base_in": "Exit"},
}
TINY = ["ce.n_envs=3", "ce.n_elite=1", "ce.iterations=1", "logging.progress=false", "logging.rerun=false"]


@pytest.fixture(scope="module")
def edited_run(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    """A run of TASK from a file, and the file then edited (Exit moved, another name)."""
    tmp = tmp_path_factory.mktemp("self_contained")
    task_file = tmp / "my_task.yaml"
    task_file.write_text(yaml.safe_dump(TASK))
    outcome = run(compose_config(*TINY, f"task_file={task_file}", cpu=False, plain=False), tmp / "run")
    assert outcome.feasible, "the test needs a feasible run to replay"
    edited = dict(TASK, name="edited", params=dict(TASK["params"], Exit={"type": "box", "low": [-2.6, -0.4],
                                                                         "high": [-1.8, 0.4]}))
    task_file.write_text(yaml.safe_dump(edited))
    return outcome.run_dir, task_file


def test_result_config_holds_the_task_that_ran(edited_run: tuple[Path, Path]) -> None:
    run_dir, task_file = edited_run
    d = json.loads((run_dir / RESULT_FILE).read_text())
    cfg = d["config"]
    assert cfg["task"]["name"] == "drive_out" and cfg["task"]["params"] == TASK["params"]
    assert cfg["task"]["plan"] == TASK["plan"] and cfg["task"]["goal"] == TASK["goal"]
    assert cfg["task_file"] is None and cfg["task_origin"]["path"] == str(task_file)
    assert d["task"] == {"name": "drive_out", "source": str(task_file)}
    # the saved config alone rebuilds the task that ran, whatever the file now says
    spec = build_run_spec(cfg)
    assert spec.task.name == "drive_out" and tuple(spec.task.layout.regions["Exit"].low) == (1.8, -0.4)


@pytest.mark.parametrize("exact", [False, True])
def test_replay_after_the_file_changed_gets_the_runs_cost(edited_run: tuple[Path, Path], exact: bool,
                                                          capsys: pytest.CaptureFixture[str]) -> None:
    run_dir, task_file = edited_run
    saved = json.loads((run_dir / RESULT_FILE).read_text())["best_cost"]
    code = load_script("replay").main([str(run_dir), "--json"] + (["--exact"] if exact else []))
    rep = json.loads(capsys.readouterr().out)
    assert code == 0 and rep["feasible"]
    assert rep["cost"] == saved and rep["matches"] is True  # bit for bit, as the run had it
    assert any(str(task_file) in n and "changed" in n for n in rep["notes"])
    if exact:
        assert rep["exact"]["iteration"] == 0 and rep["exact"]["shard_stop"] == 3


@pytest.mark.slow  # three runs (17 s on a busy 2-core host): make test keeps the run's copy read by replay
# (test_replay_after_the_file_changed_gets_the_runs_cost) and a resume (tests/test_app.py)
def test_resume_and_replan_config_use_the_runs_copy(tmp_path: Path) -> None:
    """Interrupted after iteration 0 of 2, the file edited, resumed: the run ends as an
    uninterrupted run of the original file does (its own copy), and a replan's config starts
    from that copy too."""
    from realize.spec.replan_from import replan_config

    task_file = tmp_path / "t.yaml"
    task_file.write_text(yaml.safe_dump(TASK))
    over = [o for o in TINY if not o.startswith("ce.iterations")] + ["ce.iterations=2", f"task_file={task_file}"]
    ref = run(compose_config(*over, cpu=False, plain=False), tmp_path / "ref")

    def stop(i: int) -> None:
        if i == 0:
            raise KeyboardInterrupt

    cut = tmp_path / "cut"
    assert run(compose_config(*over, cpu=False, plain=False), cut, after_iteration=stop).interrupted
    task_file.write_text(yaml.safe_dump(dict(TASK, goal={}, plan=["move_to(Exit)"])))
    done = run(compose_config("logging.progress=false", f"resume={cut}", cpu=False, plain=False),
               tmp_path / "elsewhere")
    a, b = (json.loads((d / RESULT_FILE).read_text()) for d in (ref.run_dir, cut))
    assert done.iterations_done == 2 and (a["best_cost"], a["best_z"]) == (b["best_cost"], b["best_z"])
    assert b["config"]["task"]["plan"] == TASK["plan"]
    cfg = replan_config({"replan_from": str(cut), "replan": {}}, [])
    assert cfg["task"] == b["config"]["task"] and cfg["task_file"] is None


def test_an_old_run_without_a_copy_says_it_read_the_live_file(edited_run: tuple[Path, Path], tmp_path: Path) -> None:
    """A run directory written before runs kept their task names the file only: replay reads
    the file as it is now, and says so."""
    from realize.validation.replay import replay

    run_dir, task_file = edited_run
    old = tmp_path / "old"
    old.mkdir()
    d = json.loads((run_dir / RESULT_FILE).read_text())
    d["config"] = dict(d["config"], task_file=str(task_file), task_origin=None, task={})
    (old / RESULT_FILE).write_text(json.dumps(d))
    rep = replay(old)
    assert any("keeps no copy" in n for n in rep.notes) and not rep.feasible  # the edited file moved Exit
