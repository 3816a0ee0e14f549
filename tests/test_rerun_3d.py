"""The run in 3-D in its rerun recording: read a tiny run's ``.rrd`` back and find the robot's
link poses on the ``control_step`` timeline (checked against the trajectories the figure sink
writes independently), the world's boxes, the robot's meshes and the samples' failure labels."""

from __future__ import annotations

import numpy as np
import pytest
from hydra import compose, initialize_config_dir
from scipy.spatial.transform import Rotation

from realize.paths import CONFIG_DIR
from realize.recording.world3d import STEP_STRIDE
from realize.recording.read import read_rrd_3d
from realize.recording.robot import MAX_MESH_BYTES, link_meshes, matrix_to_quat_xyzw
from realize.run.one_run import run
from realize.run_dir.directory import RunDir

# 3 plans, 2 iterations, 8 s: the base drives to table 1 and the arm starts to reach
TINY = ["ce.n_envs=3", "ce.n_elite=1", "ce.iterations=2", "controller.max_time_s=8", "seed=1",
        "logging.progress=false"]


def test_quaternions_match_scipy() -> None:
    r = Rotation.random(200, random_state=3)
    q = matrix_to_quat_xyzw(r.as_matrix())
    ref = r.as_quat()  # x, y, z, w
    ref = np.where(ref[:, 3:] < 0, -ref, ref)
    np.testing.assert_allclose(q, ref, atol=1e-9)


def test_fetch_meshes_are_stl_and_small() -> None:
    from realize.robot.spec import load_robot_spec
    from realize.robot.urdf import resolve_urdf

    spec = load_robot_spec("fetch_omni")
    meshes = link_meshes(resolve_urdf(spec.urdf, spec.visual_mesh_ext))
    assert {"base_link", "shoulder_pan_link", "gripper_link", "l_gripper_finger_link"} <= set(meshes)
    assert all(m.path.suffix.lower() == ".stl" and m.path.stat().st_size <= MAX_MESH_BYTES for m in meshes.values())
    assert "estop_link" not in meshes  # its only readable mesh is 0.4 MB


@pytest.fixture(scope="module")
def tiny_run(tmp_path_factory: pytest.TempPathFactory):
    with initialize_config_dir(config_dir=str(CONFIG_DIR), version_base="1.3", job_name="test_rerun_3d"):
        cfg = compose(config_name="config", overrides=TINY)
    out = run(cfg, tmp_path_factory.mktemp("rr3d") / "run")
    return out.run_dir, read_rrd_3d(out.run_dir / "realize.rrd")


def test_link_poses_on_the_control_step_timeline(tiny_run) -> None:
    run_dir, rrd = tiny_run
    base, grip = "/world3d/best/robot/base_link", "/world3d/best/robot/gripper_link"
    assert base in rrd.steps and grip in rrd.steps
    for it in (0, 1):
        tr = RunDir(run_dir).trajectories(it)  # written by the figure sink, from the same rollout
        best = int(RunDir(run_dir).history_arrays()[f"elite_idx_{it:03d}"][0])  # the iteration's best sample
        rows = [j for j, i in enumerate(rrd.iterations[base]) if i == it]
        steps = np.array([rrd.steps[base][j] for j in rows])
        assert len(rows) >= 10 and (steps // STEP_STRIDE == it).all() and (np.diff(steps) > 0).all()
        t = tr["traj_t"][: len(rows)]
        np.testing.assert_array_equal(steps % STEP_STRIDE, np.round(t * 20).astype(int))  # 20 Hz control
        xy = np.array([rrd.translations[base][j][:2] for j in rows])
        np.testing.assert_allclose(xy, tr["traj_base"][best, : len(rows)], atol=1e-4)
        # the gripper link is within a few mm of the recorded TCP (1 mm ahead of it along its x)
        g = np.array([rrd.translations[grip][j] for j in rows if rrd.iterations[grip][j] == it])
        assert np.abs(g - tr["traj_ee"][best, : len(g)]).max() < 0.005
        qn = np.linalg.norm(np.array([rrd.quaternions[base][j] for j in rows]), axis=1)
        np.testing.assert_allclose(qn, 1.0, atol=1e-5)


def test_world_boxes_meshes_and_failure_labels(tiny_run) -> None:
    _, rrd = tiny_run
    assert rrd.boxes["/world3d/obstacles"] == 2  # the two tables
    assert rrd.boxes["/world3d/best/objects/cube"] == 1 and rrd.boxes["/world3d/objects_start/cube"] == 1
    assert "/world3d/best/robot/base_link/mesh" in rrd.assets and len(rrd.assets) >= 15
    labels = rrd.labels["/world3d/best/action"]
    assert labels and labels[0] == "1/5 move_to(Table1)"
    reasons = [x for k, v in rrd.labels.items() if k.startswith("/world3d/samples/") for x in v if x]
    assert reasons and all(":" in r for r in reasons)  # e.g. "grasp: timeout"
