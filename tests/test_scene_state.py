"""Scene states as JSON, a plan's remaining actions as a task, and the replan config (no simulator)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from realize.config import ConfigError
from realize.spec.replan_from import replan_config
from realize.spec.run_spec import build_run_spec
from realize.run_dir.jsonio import atomic_write_json
from realize.run_dir.names import RESULT_FILE
from realize.robot.spec import load_robot_spec
from realize.world.state import ObjectPose, SceneState, load_state, save_state

FETCH = load_robot_spec("fetch_omni")
STATE_JOINTS = [n for n in FETCH.rest if n not in FETCH.base.joints]  # every active joint but the base's
from realize.tasks.suffix import check_suffix_start, suffix_columns, task_suffix
from helpers import compose_config

FIXTURE = Path(__file__).parent / "fixtures" / "state_grasped.json"  # the first format: cube, cube_held
MOVED = ["scene.tables.1.center=[0.3,-1.2]"]  # Table2 and Cube_p follow table 2 (frame: table2)


def _held() -> SceneState:
    return SceneState(base=(1.0, 2.0, 0.5), gripper_closed=True, objects={"cube": ObjectPose((1.0, 2.5, 0.9))},
                      held="cube")


def _empty() -> SceneState:
    return SceneState(base=(0.0, 0.0, 0.0), objects={"cube": ObjectPose((0.0, 1.2, 0.7425))})


def test_round_trip_and_defaults(tmp_path: Path) -> None:
    s = _held()
    assert s.joints == {}  # unspecified joints: the robot's rest pose when restored
    back = load_state(save_state(s, tmp_path / "a" / "s.json"))
    assert back.base == s.base and back.joints == s.joints and back.held == "cube" and back.gripper_closed
    assert back.objects == s.objects and back.objects["cube"].quaternion == (1.0, 0.0, 0.0, 0.0)
    assert json.loads((tmp_path / "a" / "s.json").read_text())["format"] == "realize.scene_state/2"
    fixture = load_state(FIXTURE)
    assert fixture.held == "cube" and set(fixture.joints) == set(STATE_JOINTS)


def test_left_out_joints_take_the_robots_rest_pose_and_unknown_joints_are_refused() -> None:
    """A hand-written state restored in a scene: left-out joints start at the robot's rest pose
    (its config's ``rest``), a joint the robot does not have is one line naming it."""
    from realize.config import ConfigError
    from realize.scene import BatchedScene, SimSettings

    with BatchedScene(1, None, SimSettings(backend="cpu")) as scene:
        state = SceneState(base=(-2.0, 0.0, 0.0), joints={"shoulder_pan_joint": 0.2},
                           objects={"cube": ObjectPose(tuple(scene.geometry.object("cube").position))})
        scene.reset(state=state)
        got = scene.capture_state()
        assert set(got.joints) == set(STATE_JOINTS)
        assert abs(got.joints["shoulder_pan_joint"] - 0.2) < 1e-3
        assert abs(got.joints["elbow_flex_joint"] - FETCH.rest["elbow_flex_joint"]) < 1e-3
        with pytest.raises(ConfigError, match="no_such_joint"):
            scene.reset(state=SceneState(base=(-2.0, 0.0, 0.0), joints={"no_such_joint": 0.0}))


@pytest.mark.parametrize("edit, message", [
    (lambda d: d.pop("base"), "missing key"),
    (lambda d: d.update(speed=1), "unknown key"),
    (lambda d: d.update(base=[0, 0]), "base has 2 values, expected 3"),
    (lambda d: d["cube"].update(quaternion=[1, 1, 0, 0]), "not a unit quaternion"),
    (lambda d: d["joints"].update(torso_lift_joint="up"), "joints.torso_lift_joint"),
    (lambda d: d.update(gripper_closed=False), "needs a closed gripper"),
    (lambda d: d.update(cube_held="yes"), "cube_held"),
])
def test_bad_state_files(tmp_path: Path, edit, message: str) -> None:
    d = json.loads(FIXTURE.read_text())  # the first format
    edit(d)
    p = tmp_path / "bad.json"
    p.write_text(json.dumps(d))
    with pytest.raises(ConfigError, match=message):
        load_state(p)


@pytest.mark.parametrize("edit, message", [
    (lambda d: d.pop("base"), "missing key"),
    (lambda d: d.pop("objects"), "missing key"),
    (lambda d: d.update(speed=1), "unknown key"),
    (lambda d: d.update(cube_held=True), "unknown key"),  # a first-format key in a second-format file
    (lambda d: d.update(base=[0, 0]), "base has 2 values, expected 3"),
    (lambda d: d["objects"]["cube"].update(quaternion=[1, 1, 0, 0]), "not a unit quaternion"),
    (lambda d: d["joints"].update(torso_lift_joint="up"), "joints.torso_lift_joint"),
    (lambda d: d.update(gripper_closed=False), "needs a closed gripper"),
    (lambda d: d.update(held="yes"), "held = 'yes' is invalid"),
    (lambda d: d.update(held=1), "held = 1 is invalid"),
])
def test_bad_state_files_second_format(tmp_path: Path, edit, message: str) -> None:
    d = load_state(FIXTURE).to_json()
    assert d["format"] == "realize.scene_state/2" and d["held"] == "cube"
    edit(d)
    p = tmp_path / "bad.json"
    p.write_text(json.dumps(d))
    with pytest.raises(ConfigError, match=message):
        load_state(p)


def test_missing_and_unreadable_files(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match="replan.state = .*no such file"):
        load_state(tmp_path / "nope.json", "replan.state")
    (tmp_path / "x.json").write_text("{not json")
    with pytest.raises(ConfigError, match="not a readable JSON"):
        load_state(tmp_path / "x.json")


def test_task_suffix() -> None:
    task = build_run_spec(compose_config()).task
    sub = task_suffix(task, 2)
    assert sub.describe() == "move_to(Table2), place(cube, Cube_p), move_to(Exit)"
    assert sub.layout.names == ["Table2", "Cube_p", "Exit"]
    assert [task.layout.column_names[i] for i in suffix_columns(task, 2)] == sub.layout.column_names
    assert task_suffix(task, 0).describe() == task.describe()
    for k in (5, -1):
        with pytest.raises(ConfigError, match="replan.action = .* the plan has 5 actions"):
            task_suffix(task, k)
    held, empty = _held(), _empty()
    check_suffix_start(sub, held)
    with pytest.raises(ConfigError, match=r"plan\[1\]: place\(cube, Cube_p\) places cube, but the hand is empty"):
        check_suffix_start(sub, empty)
    check_suffix_start(task_suffix(task, 1), empty)
    with pytest.raises(ConfigError, match=r"plan\[0\]: grasp\(cube, Cube_g\) needs an empty hand, but cube is held"):
        check_suffix_start(task_suffix(task, 1), held)


def _run_dir(tmp_path: Path) -> Path:
    run = tmp_path / "run"
    run.mkdir()
    atomic_write_json(run / RESULT_FILE, {"status": "done", "config": compose_config("seed=3", "ce.n_envs=50")})
    return run


def _replan(run: Path, *overrides: str, action: int = 2, state: Path = FIXTURE) -> dict:
    extra = [f"replan_from={run}", f"replan.action={action}", f"replan.state={state}"]
    current = compose_config(*extra, *overrides)
    return replan_config(current, [*extra, *overrides])


def test_replan_config_and_spec(tmp_path: Path) -> None:
    run = _run_dir(tmp_path)
    cfg = _replan(run, *MOVED, "ce.iterations=3")
    assert cfg["seed"] == 3 and cfg["ce"]["n_envs"] == 50  # the earlier run's config ...
    assert cfg["ce"]["iterations"] == 3 and cfg["scene"]["tables"][1]["center"] == [0.3, -1.2]  # ... changed
    assert cfg["scene"]["tables"][0]["center"] == [0.0, 1.2]
    spec = build_run_spec(cfg)
    assert spec.task.describe() == "move_to(Table2), place(cube, Cube_p), move_to(Exit)"
    assert spec.task.layout.regions["Table2"].center == (0.3, -1.2)
    assert spec.geometry.table("table2").center[:2] == (0.3, -1.2)
    assert spec.start is not None and spec.start.held == "cube"
    assert spec.replan is not None and spec.replan.to_json()["action"] == 2
    assert spec.replan.columns == tuple(spec.task.layout.column_names)


def test_replan_errors(tmp_path: Path) -> None:
    run = _run_dir(tmp_path)
    with pytest.raises(ConfigError, match="would change the plan"):
        _replan(run, "task.goal.rests_on.cube=table1")
    with pytest.raises(ConfigError, match="replan.action = 7 is invalid"):
        build_run_spec(_replan(run, action=7))
    with pytest.raises(ConfigError, match="replan.state = .*no such file"):
        build_run_spec(_replan(run, state=tmp_path / "none.json"))
    with pytest.raises(ConfigError, match="places cube, but the hand is empty"):
        empty = save_state(_empty(), tmp_path / "e.json")
        build_run_spec(_replan(run, state=empty))
    with pytest.raises(ConfigError, match=r"replan.state .*unknown joint\(s\) \['knee_joint'\] of robot 'fetch_omni'"):
        d = json.loads(FIXTURE.read_text())
        d["joints"]["knee_joint"] = 0.1
        bad = tmp_path / "knee.json"
        bad.write_text(json.dumps(d))
        build_run_spec(_replan(run, state=bad))  # refused at the config edge, before anything is simulated
    with pytest.raises(ConfigError, match="replan_from = .*not a directory"):
        _replan(tmp_path / "missing")
    with pytest.raises(ConfigError, match="replan_from is not"):
        build_run_spec(compose_config("replan.action=2"))
