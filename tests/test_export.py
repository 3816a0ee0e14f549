"""Handing executed worlds to a robot stack (realize/execution/export.py, time_param.py,
ros2_export.py, lerobot_export.py; scripts/execute.py --export).

Checked against what does not come from the code under test: the bag is read back with the
``mcap`` reader and ``mcap_ros2``'s decoder (the message definitions stored in the file, not
rosbags'); toppra's velocities are checked on finite differences of its positions; the
LeRobot dataset with pyarrow; and the bag's arm trajectories are replayed through the
simulator's joint drives beside the executed targets (the TCP at each action's end).
"""

from __future__ import annotations

import json
import math
import subprocess
import sys
import time
from pathlib import Path

import mcap_ros2.decoder
import numpy as np
import pyarrow.parquet as pq
import pytest
from mcap.reader import make_reader

from helpers import REPO
from realize.config import ConfigError
from realize.execution.export import ExportOptions, export_formats, export_world
from realize.execution.time_param import (HOLD_DURATION_S, JointLimits, joint_limits, parameterize, segment_pieces,
                                          timed_segment)
from realize.execution.trajectory import TrajectoryLog, read_trajectory
from realize.robot.spec import load_robot_spec
from realize.robot.urdf import source_urdf

FETCH = load_robot_spec("fetch_omni")
JOINTS = FETCH.upper.joints
TOPICS = {"/realize/arm/joint_trajectory": "trajectory_msgs/msg/JointTrajectory",
          "/realize/base/cmd_vel": "geometry_msgs/msg/Twist",
          "/realize/gripper/command": "control_msgs/msg/GripperCommand",
          "/realize/events": "std_msgs/msg/String"}


def read_bag(path: Path) -> tuple[dict[str, str], list[tuple[str, int, object]]]:
    """Channels (topic -> schema name) and every decoded message (topic, log time ns, message)."""
    with open(path, "rb") as f:
        reader = make_reader(f, decoder_factories=[mcap_ros2.decoder.DecoderFactory()])
        summary = reader.get_summary()
        channels = {c.topic: summary.schemas[c.schema_id].name for c in summary.channels.values()}
        msgs = [(ch.topic, m.log_time, msg) for _, ch, m, msg in reader.iter_decoded_messages()]
    return channels, msgs


def _seconds(d: object) -> float:
    return d.sec + d.nanosec * 1e-9  # type: ignore[attr-defined]


# ------------------------------------------------------------------------------ format names
def test_export_formats_parse_and_refuse_in_one_line() -> None:
    assert export_formats("ros2,lerobot") == ("ros2", "lerobot")
    assert export_formats(" lerobot , ros2,lerobot") == ("lerobot", "ros2")
    assert export_formats("") == () and export_formats(None) == ()
    with pytest.raises(ConfigError) as ei:
        export_formats("ros2,lerobt")
    msg = str(ei.value)
    assert "\n" not in msg and "'lerobt'" in msg and "did you mean 'lerobot'" in msg and "ros2, lerobot" in msg
    with pytest.raises(ConfigError):
        ExportOptions(acceleration_limit=0.0)


def test_script_refuses_a_bad_export_before_running(tmp_path: Path) -> None:
    run = tmp_path / "run"
    run.mkdir()
    (run / "result.json").write_text("{}")  # never read: the export formats are checked first
    p = subprocess.run([sys.executable, str(REPO / "scripts" / "execute.py"), str(run), "--export", "ros2,rosbag"],
                       cwd=REPO, capture_output=True, text=True, timeout=120)
    lines = [ln for ln in p.stderr.splitlines() if ln.strip()]
    assert p.returncode == 2 and len(lines) == 1 and "'rosbag'" in lines[0], p.stderr
    assert not (run / "execution").exists()


# ------------------------------------------------------------------------------ toppra
def _limits(v: float = 1.0, a: float = 2.0, j: int = 3) -> JointLimits:
    return JointLimits(tuple(f"j{i}" for i in range(j)), np.full(j, v), np.full(j, a))


def test_toppra_respects_the_velocity_limits_and_passes_through_the_waypoints() -> None:
    s = np.linspace(0, 1, 40)[:, None]
    w = np.hstack([1.5 * np.sin(3 * s), 2.0 * s, 0.3 * np.cos(5 * s)])  # 3 joints, a curved 2.6 rad path
    lim = JointLimits(("a", "b", "c"), np.array([0.8, 1.2, 0.5]), np.array([2.0, 2.0, 2.0]))
    tp = parameterize(w, lim, sample_dt=1e-3)
    # velocity from finite differences of the positions, not toppra's own velocity output
    fd = np.diff(tp.positions, axis=0) / np.diff(tp.t_s)[:, None]
    assert (np.abs(fd) <= lim.velocity * 1.01 + 1e-3).all(), np.abs(fd).max(axis=0)
    assert (np.abs(tp.velocities) <= lim.velocity * 1.01 + 1e-3).all()
    assert np.abs(fd).max(axis=0)[0] > 0.9 * 0.8  # and it is fast: one joint runs at its limit somewhere
    # accelerations from differenced velocities: toppra holds the limit at its grid points, a few
    # per cent over it between them
    acc = np.diff(tp.velocities, axis=0) / np.diff(tp.t_s)[:, None]
    assert (np.abs(acc) <= lim.acceleration * 1.05).all(), np.abs(acc).max(axis=0)
    # through every waypoint (the dense samples come within 1 mrad of each), from the first to the last
    d = np.abs(tp.positions[None, :, :] - w[:, None, :]).max(axis=2).min(axis=1)
    assert d.max() < 1e-3, d.max()
    assert np.allclose(tp.positions[0], w[0]) and np.allclose(tp.positions[-1], w[-1], atol=1e-9)
    assert np.allclose(tp.velocities[0], 0) and np.allclose(tp.velocities[-1], 0, atol=1e-6)
    # no faster than the velocity limit allows: the slowest joint needs its distance / its limit
    assert tp.duration_s >= (np.abs(np.diff(w, axis=0)).sum(axis=0) / lim.velocity).max() - 1e-6


def test_joint_limits_come_from_the_urdf() -> None:
    lim = joint_limits(source_urdf(FETCH.urdf), JOINTS, 1.0)
    assert lim.names == JOINTS and (lim.acceleration == 1.0).all()
    assert lim.velocity[JOINTS.index("torso_lift_joint")] == pytest.approx(0.1)  # fetch.urdf's torso: 0.1 m/s
    with pytest.raises(ConfigError, match="not in"):
        joint_limits(source_urdf(FETCH.urdf), ("no_such_joint",))


def test_a_segment_keeps_its_executed_timing_and_a_still_one_is_one_point() -> None:
    f = 20.0
    lim = _limits(v=1.0, a=2.0, j=2)
    # still 10 steps, a 0.5 rad move over 40 steps, still 10 steps with the gripper closing at step 55
    q = np.concatenate([np.zeros(10), np.linspace(0, 0.5, 41)[1:], np.full(20, 0.5)])
    targets = np.stack([q, -q], axis=1)
    grip = np.arange(len(q)) >= 55
    assert [(a, b, m) for a, b, m in segment_pieces(targets, grip)] == [(0, 9, False), (9, 49, True), (49, 55, False),
                                                                        (55, 69, False)]
    seg = timed_segment(targets, grip, f, lim)
    assert seg.overrun_s == 0.0 and seg.executed_s == pytest.approx(69 / f)
    assert np.all(np.diff(seg.t_s) > 0) and seg.t_s[0] == 0 and seg.t_s[-1] == pytest.approx(69 / f)
    # the move starts and ends when it did (steps 9 and 49): in step with the base and the gripper
    moving = np.abs(seg.velocities).max(axis=1) > 1e-9
    assert seg.t_s[moving].min() >= 9 / f - 1e-9 and seg.t_s[moving].max() <= 49 / f + 1e-9
    at_end = np.interp(49 / f, seg.t_s, seg.positions[:, 0])
    assert at_end == pytest.approx(0.5, abs=1e-6)
    assert (np.abs(seg.velocities) <= 1.0 + 1e-6).all()
    still = timed_segment(np.ones((30, 2)), np.zeros(30, bool), f, lim)
    assert len(still.t_s) == 1 and still.t_s[0] == HOLD_DURATION_S and np.allclose(still.positions, 1.0)


# ------------------------------------------------------------------------------ a hand-made trajectory
@pytest.fixture(scope="module")
def hand_world(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """world-0-open.npz/.json of a made-up execution: a base move, an arm move with a grasp, a replan."""
    where = tmp_path_factory.mktemp("hand")
    log = TrajectoryLog(20.0)
    rest = np.array([FETCH.rest[j] for j in JOINTS])
    goal = rest + np.linspace(0.02, 0.3, len(JOINTS)) * np.r_[0.2, np.ones(len(JOINTS) - 1)]
    step = 1
    for k in range(30):  # move_to: the base drives, the arm holds
        log.append(step, 0, "move_to(Table1)", dict(zip(JOINTS, rest)), (0.3, 0.1, 0.05), False)
        step += 1
    for k in range(60):  # grasp: the arm moves, the gripper closes at its end
        a = min(k / 40, 1.0)
        log.append(step, 1, "grasp(cube, Cube_g)", dict(zip(JOINTS, rest + a * (goal - rest))), (0, 0, 0), k >= 50)
        step += 1
    npz = log.save(where / "world-0-open.npz")
    world = {"world": 0, "mode": "open", "replans": [{"kind": "re-parameterize", "step": 40, "wall_s": 1.5,
                                                      "plan": "grasp(cube, Cube_g)", "cost": 2.0}],
             "deviations": [{"step": 39, "action": 1, "what": ["cube moved"]}], "disturbances": []}
    (where / "world-0-open.json").write_text(json.dumps(world))
    assert npz.name == "world-0-open.npz"
    return where


def test_the_bag_opens_with_the_mcap_reader_and_has_the_topics(hand_world: Path) -> None:
    obs = [(0.5, {"cube": (1.0, 2.0, 0.8, 1.0, 0.0, 0.0, 0.0)}),
           (1.0, {"cube": (1.1, 2.0, 0.8, 1.0, 0.0, 0.0, 0.0), "2nd box": (0.0, 0.0, 0.1, 1.0, 0.0, 0.0, 0.0)})]
    res = export_world(hand_world / "world-0-open.npz", hand_world / "world-0-open.json", hand_world, ["ros2"], FETCH,
                       observations=obs)
    assert res.files == ["world-0-open.mcap"]
    channels, msgs = read_bag(hand_world / "world-0-open.mcap")
    assert channels == {**TOPICS, "/realize/observed/cube": "geometry_msgs/msg/PoseStamped",
                        "/realize/observed/_2nd_box": "geometry_msgs/msg/PoseStamped"}  # a topic name's characters
    by = {t: [(ns, m) for tt, ns, m in msgs if tt == t] for t in channels}
    t = read_trajectory(hand_world / "world-0-open.npz")
    # the base: one Twist per control step at its control time, the command as executed
    assert [ns for ns, _ in by["/realize/base/cmd_vel"]] == [round(s * 1e9) for s in t.t_s]
    assert [(m.linear.x, m.linear.y, m.angular.z) for _, m in by["/realize/base/cmd_vel"]] == \
        [tuple(v) for v in t.base_velocity.tolist()]
    # the gripper: open at the start, closed at the change (step 81), with the robot config's values
    assert [(ns, m.position, m.max_effort) for ns, m in by["/realize/gripper/command"]] == \
        [(50_000_000, FETCH.gripper.open, FETCH.gripper.force), (4_050_000_000, FETCH.gripper.closed, FETCH.gripper.force)]
    # the arm: one JointTrajectory per action, stamped at its first step, ending at its last targets
    arm = by["/realize/arm/joint_trajectory"]
    assert [ns for ns, _ in arm] == [50_000_000, 1_550_000_000]
    for (ns, m), (first, last) in zip(arm, t.action_boundaries):
        assert list(m.joint_names) == list(JOINTS) and _seconds(m.header.stamp) == pytest.approx(t.t_s[first])
        assert np.allclose(m.points[-1].positions, t.joint_targets[last])
        assert all(len(p.velocities) == len(JOINTS) for p in m.points)
    assert len(arm[0][1].points) == 1  # the arm held still through move_to
    times = [_seconds(p.time_from_start) for p in arm[1][1].points]
    assert np.all(np.diff(times) > 0) and times[-1] == pytest.approx(59 / 20)
    # events: each action's start, the deviation and the replan, as JSON at their steps' times
    events = [(ns, json.loads(m.data)) for ns, m in by["/realize/events"]]
    assert [(e["event"], ns) for ns, e in events] == [("action", 50_000_000), ("action", 1_550_000_000),
                                                       ("deviation", 1_950_000_000), ("replan", 2_000_000_000)]
    assert events[3][1]["kind"] == "re-parameterize" and events[3][1]["cost"] == 2.0
    poses = by["/realize/observed/cube"]
    assert [ns for ns, _ in poses] == [500_000_000, 1_000_000_000] and poses[1][1].pose.position.x == 1.1
    assert poses[0][1].header.frame_id == "world" and poses[0][1].pose.orientation.w == 1.0


def test_the_lerobot_dataset_reads_back_with_pyarrow(hand_world: Path) -> None:
    export_world(hand_world / "world-0-open.npz", None, hand_world, ["lerobot"], FETCH)
    root = hand_world / "lerobot" / "open"
    info = json.loads((root / "meta" / "info.json").read_text())
    assert info["codebase_version"] == "v3.0" and info["fps"] == 20 and info["total_episodes"] == 1
    assert info["total_frames"] == 90 and info["total_tasks"] == 2 and info["splits"] == {"train": "0:1"}
    n = len(JOINTS) + 4
    assert info["features"]["action"]["shape"] == [n] and info["features"]["observation.state"]["shape"] == [n]
    data = pq.read_table(root / info["data_path"].format(chunk_index=0, file_index=0)).to_pydict()
    t = read_trajectory(hand_world / "world-0-open.npz")
    act = np.array(data["action"])
    assert act.shape == (90, n) and np.allclose(act[:, :len(JOINTS)], t.joint_targets, atol=1e-6)
    assert np.allclose(act[:, -1], t.gripper) and data["frame_index"] == list(range(90))
    assert np.allclose(data["timestamp"], np.arange(90) / 20)
    state = np.array(data["observation.state"])  # commanded: the previous step's targets
    assert np.allclose(state[1:, :len(JOINTS)], t.joint_targets[:-1], atol=1e-6)
    assert state[30, len(JOINTS)] == pytest.approx(30 * 0.3 / 20, rel=1e-5)  # base x integrated from vx
    tasks = pq.read_table(root / "meta" / "tasks.parquet")
    assert tasks.column("__index_level_0__").to_pylist() == ["move_to(Table1)", "grasp(cube, Cube_g)"]
    assert json.loads(tasks.schema.metadata[b"pandas"])["index_columns"] == ["__index_level_0__"]
    ep = pq.read_table(root / "meta" / "episodes" / "chunk-000" / "file-000.parquet").to_pylist()
    assert [(e["episode_index"], e["length"], e["dataset_from_index"], e["dataset_to_index"]) for e in ep] == [(0, 90, 0, 90)]
    assert ep[0]["stats/action/count"] == [90]


# ------------------------------------------------------------------------------ the physical check
@pytest.fixture(scope="module")
def executed(tmp_path_factory: pytest.TempPathFactory):
    """One open-loop world of the seed task's known plan, executed and exported (ros2, lerobot)."""
    from realize.repair.study import execute
    from realize.execution.settings import ExecuteSettings
    from helpers import write_known_run

    run = write_known_run(tmp_path_factory.mktemp("export") / "run")
    s = ExecuteSettings.from_mapping({"worlds": 1, "seed": 0, "max_replans": 0, "disturbances": []})
    out = run / "execution" / "export"
    t0 = time.perf_counter()
    summary = execute(run, s, name="export", worlds=1, closed_loop=False, rerun=False, progress=False,
                      export=("ros2", "lerobot"))
    return run, s, out, summary, time.perf_counter() - t0


@pytest.fixture(scope="module")
def executed_closed(executed):
    """The same run's world closed loop, table 2 moved 12 cm 1 s into move_to(Table2): the monitor
    sees it and the robot holds while it decides (a hold segment, the move_to resumed after it)."""
    from realize.repair.study import execute
    from realize.run.planner import ReplanBudget
    from realize.execution.settings import ExecuteSettings

    run = executed[0]
    # nudged 12 cm: past the monitor's tolerance, the plan checked and gone on with; the replays below run in the
    # undisturbed world, where the same commands still end every action as in the executed one
    moved = {"trigger": {"action": 2, "delay_s": 1.0}, "move_table": {"table": "table2", "dx": 0.0, "dy": -0.12}}
    s = ExecuteSettings.from_mapping({"worlds": 1, "seed": 0, "max_replans": 3, "think": 40, "disturbances": [moved]})
    budget = ReplanBudget(n_envs=8, n_elite=2, iterations=2, shard_rows=None, workers=1)
    summary = execute(run, s, name="closed", worlds=1, open_loop=False, rerun=False, progress=False, budget=budget,
                      export=("ros2",))
    return run, s, run / "execution" / "closed", summary, 0.0


def test_execute_writes_the_bag_and_the_dataset(executed) -> None:
    _, _, out, summary, _ = executed
    assert summary.open_successes == 1
    assert {"world-0-open.mcap", "lerobot/open"} <= set(summary.files)
    channels, _ = read_bag(out / "world-0-open.mcap")
    assert channels == TOPICS
    assert json.loads((out / "lerobot" / "open" / "meta" / "info.json").read_text())["total_episodes"] == 1


def test_the_world_file_has_what_the_robot_measured_and_the_dataset_uses_it(executed) -> None:
    """The executed world's file carries the measured joints and base beside the commands; the
    joints track their targets (PD drives, within a few degrees of lag) and the LeRobot state
    is the measurement of the step before (``realize.state_source`` = measured)."""
    _, _, out, _, _ = executed
    t = read_trajectory(out / "world-0-open.npz")
    assert t.joint_positions is not None and t.base_pose is not None
    assert t.joint_positions.shape == t.joint_targets.shape and t.base_pose.shape == (len(t), 3)
    lag = np.abs(t.joint_positions - t.joint_targets)
    assert np.median(lag) < 0.02 and not np.allclose(t.joint_positions, t.joint_targets, atol=1e-6)
    moved = np.linalg.norm(t.base_pose[-1, :2] - t.base_pose[0, :2])
    assert moved > 1.0  # the base drove from its start past table 1 and table 2
    root = out / "lerobot" / "open"
    info = json.loads((root / "meta" / "info.json").read_text())
    assert info["realize.state_source"] == ["measured"]
    data = pq.read_table(root / info["data_path"].format(chunk_index=0, file_index=0)).to_pydict()
    state = np.array(data["observation.state"])
    j = len(t.joint_names)
    assert np.allclose(state[1:, :j], t.joint_positions[:-1], atol=1e-6)
    assert np.allclose(state[1:, j:j + 3], t.base_pose[:-1], atol=1e-6)


def test_a_log_has_measurements_at_every_step_or_none() -> None:
    log = TrajectoryLog(20.0)
    log.append(0, 0, "a", {"j": 0.0}, (0.0, 0.0, 0.0), False, measured=[0.0, 1.0, 2.0, 0.1])
    with pytest.raises(ConfigError, match="every step or never"):
        log.append(1, 0, "a", {"j": 0.0}, (0.0, 0.0, 0.0), False)
    with pytest.raises(ConfigError, match="expected 4"):
        log.append(1, 0, "a", {"j": 0.0}, (0.0, 0.0, 0.0), False, measured=[0.0])


def test_a_closed_loop_bag_holds_what_the_monitor_saw(executed_closed) -> None:

    """The executor hands what its monitor decided from to the bag: the base, the cube and both
    tables as PoseStamped, one message per check, in time order; table 2's last pose is where
    the disturbance moved it (12 cm in -y)."""
    _, _, out, _, _ = executed_closed
    channels, msgs = read_bag(out / "world-0-closed.mcap")
    for name in ("base", "cube", "table1", "table2"):
        assert channels[f"/realize/observed/{name}"] == "geometry_msgs/msg/PoseStamped", name
    t2 = [(t, m) for topic, t, m in msgs if topic == "/realize/observed/table2"]
    assert len(t2) > 10 and [t for t, _ in t2] == sorted(t for t, _ in t2)
    first, last = t2[0][1].pose.position, t2[-1][1].pose.position  # type: ignore[attr-defined]
    assert math.isclose(last.y - first.y, -0.12, abs_tol=1e-6) and math.isclose(last.x, first.x, abs_tol=1e-6)


def _replay(world, rows: int, command) -> list[np.ndarray]:
    """Step ``world``'s scene through ``rows`` rows, ``command(r)`` -> (arm q, arm qd, base v, closed)
    before each; the TCP position after each row."""
    import torch

    scene = world.scene
    tcp = []
    for r in range(rows):
        q, qd, v, closed = command(r)
        scene.set_arm_targets(torch.as_tensor(q)[None], None if qd is None else torch.as_tensor(qd)[None])
        scene.set_base_velocity(torch.as_tensor(v)[None])
        scene.set_gripper(torch.tensor([bool(closed)]))
        scene.step()
        tcp.append(scene.ee_pose()[0, :3].double().numpy().copy())
    return tcp


@pytest.mark.parametrize("which", ["executed", pytest.param("executed_closed", marks=pytest.mark.slow)])
def test_the_bag_replayed_through_the_joint_drives_reaches_every_action_end_within_1cm(which: str, request) -> None:
    """The physical check: the executed targets and the bag's messages (arm trajectories sampled
    at the control rate, Twists, gripper commands at their stamps) drive the same simulated world
    from its start; the TCP at each action's last step agrees within 1 cm. (The closed-loop
    world's table move is not replayed: both replays run in the undisturbed world.)"""
    import dataclasses

    from realize.repair.study import SEED_STRIDE
    from realize.repair.executor import EXECUTION_BACKEND
    from realize.validation.replay import build_replay_spec, returned_z, saved_plan
    from realize.execution.world import ExecutionWorld

    run, s, out, summary, _ = request.getfixturevalue(which)
    stem = "world-0-open" if which == "executed" else "world-0-closed"
    t = read_trajectory(out / f"{stem}.npz")
    _, msgs = read_bag(out / f"{stem}.mcap")
    arm = [(ns * 1e-9, np.array([_seconds(p.time_from_start) for p in m.points]),
            np.array([p.positions for p in m.points]), np.array([p.velocities for p in m.points]))
           for topic, ns, m in msgs if topic == "/realize/arm/joint_trajectory"]
    twist = {ns: (m.linear.x, m.linear.y, m.angular.z) for topic, ns, m in msgs if topic == "/realize/base/cmd_vel"}
    grip = [(ns * 1e-9, m.position) for topic, ns, m in msgs if topic == "/realize/gripper/command"]
    half = (FETCH.gripper.open + FETCH.gripper.closed) / 2

    def from_bag(r: int):
        now = t.t_s[r]
        t0, ts, q, qd = [a for a in arm if a[0] <= now + 1e-9][-1]  # the latest trajectory started
        tau = now - t0
        qi = np.array([np.interp(tau, ts, q[:, j]) for j in range(q.shape[1])])
        qdi = np.array([np.interp(tau, ts, qd[:, j]) for j in range(q.shape[1])]) if tau < ts[-1] else np.zeros(len(qi))
        closed = [p for tg, p in grip if tg <= now + 1e-9][-1] < half
        return qi, qdi, twist[round(now * 1e9)], closed

    run_saved = saved_plan(run)
    spec = build_replay_spec(dataclasses.replace(run_saved, best_z=returned_z(run_saved).z), EXECUTION_BACKEND)
    world = ExecutionWorld(spec, s.seed * SEED_STRIDE + 0)
    try:
        executed_tcp = _replay(world, len(t), lambda r: (t.joint_targets[r], None, t.base_velocity[r], t.gripper[r]))
        world.reset()
        bag_tcp = _replay(world, len(t), from_bag)
    finally:
        world.close()
    ends = [int(last) for _, last in t.action_boundaries]
    gaps = [float(np.linalg.norm(executed_tcp[e] - bag_tcp[e])) for e in ends]
    assert max(gaps) < 0.01, dict(zip(t.action_text, np.round(gaps, 4)))
    # 1 cm is small against where the TCP went: from action end to action end, metres
    assert sum(np.linalg.norm(executed_tcp[b] - executed_tcp[a]) for a, b in zip(ends, ends[1:])) > 1.0
    assert f"{stem}.mcap" in summary.files


def test_the_docs_bag_example_runs(executed) -> None:
    """docs/execution_format.md's bag-reading example, on the executed world's bag: one line per
    action segment, its start time, points and duration."""
    import contextlib
    import io

    from helpers import doc_block

    _, _, out, _, _ = executed
    code = doc_block("docs/execution_format.md", "python", 1).text.replace('"world-0-closed.mcap"',
                                                                          repr(str(out / "world-0-open.mcap")))
    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        exec(compile(code, "docs/execution_format.md", "exec"), {})
    t = read_trajectory(out / "world-0-open.npz")
    lines = buf.getvalue().splitlines()
    assert [float(ln.split()[0]) for ln in lines] == pytest.approx([t.t_s[a] for a, _ in t.action_boundaries])
    assert [float(ln.split()[2]) for ln in lines[1::2]] == pytest.approx([(b - a) / 20 for a, b in t.action_boundaries[1::2]])
