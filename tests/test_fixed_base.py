"""A fixed-base robot (``robot=panda``: ``base.joints: []``) at the config edge: what is refused
in one line before anything simulates, and where its base is in ``q``. Its kinematics are in
``test_robot_kinematics.py``, its env matrix in ``test_env_robots.py``, a three-block tower it
builds in ``test_stacking.py``."""

from __future__ import annotations

import pytest
import torch

from helpers import compose_config
from realize.spec.run_spec import build_run_spec
from realize.config import ConfigError
from realize.robot.kinematics import RobotKinematics
from realize.robot.spec import FIXED_BASE_JOINTS, load_robot_spec


def test_a_move_to_for_a_fixed_base_is_one_line() -> None:
    """The seed task's plan starts with move_to(Table1): refused naming the action and the robot."""
    with pytest.raises(ConfigError) as err:
        build_run_spec(compose_config("robot=panda"))
    msg = str(err.value)
    assert "\n" not in msg
    assert msg.startswith("task:plan[0]: move_to(Table1) drives the base, but robot 'panda' has a fixed base")


def test_a_task_without_move_to_is_accepted() -> None:
    spec = build_run_spec(compose_config("experiment=tower3_tabletop"))
    assert spec.robot.base.fixed and "move_to" not in spec.task.describe()


@pytest.mark.parametrize("override, needle", [
    ("robot.base.joints=[a,b]", "robot.base.joints = ['a', 'b'] is invalid: name three joints"),
    ("robot.base.height=0.5", "only a fixed base (joints: []) stands above the floor"),
    ("robot=panda robot.base.height=-0.1", "robot.base.height = -0.1 is invalid: must be >= 0"),
])
def test_bad_base_keys_are_one_line(override: str, needle: str) -> None:
    with pytest.raises(ConfigError) as err:
        build_run_spec(compose_config("experiment=tower3", *override.split()))
    assert needle in str(err.value) and "\n" not in str(err.value)


def test_a_fixed_base_fills_q_with_its_pose() -> None:
    """q = [x, y, yaw, arm]: the base columns place the root (height up, turned by yaw) and move
    nothing else; the TCP follows them rigidly."""
    spec = load_robot_spec("panda")
    kin = RobotKinematics(spec, dtype=torch.float64)
    assert kin.joint_names[:3] == FIXED_BASE_JOINTS and kin.n_dof == 3 + 7
    q = torch.tensor([[0.0, 0.0, 0.0, *(spec.rest_value(j) for j in spec.upper.joints)]], dtype=torch.float64)
    moved = q.clone()
    moved[0, :3] = torch.tensor([0.3, -0.2, torch.pi / 2])
    p0, p1 = kin.tcp_jacobian(q)[0][0, :3, 3], kin.tcp_jacobian(moved)[0][0, :3, 3]
    turned = torch.tensor([-p0[1], p0[0], p0[2]], dtype=torch.float64)  # p0 turned by 90 degrees about z
    assert torch.allclose(p1, turned + torch.tensor([0.3, -0.2, 0.0], dtype=torch.float64), atol=1e-12)
    assert float(p0[2]) > spec.base.height  # the rest pose holds the hand above the stand


def test_a_fixed_base_stands_at_the_scenes_fixed_base_start() -> None:
    """scene=tower3 parks a mobile robot 0.55 m from the table (robot_start) and bolts an arm at
    its edge (fixed_base_start): each robot gets its own, and the run's config says which. A
    stand that overlaps the table is refused naming the key it came from."""
    arm = build_run_spec(compose_config("robot=panda", "experiment=tower3"))
    mobile = build_run_spec(compose_config("experiment=tower3"))
    mount = tuple(arm.geometry_cfg.fixed_base_start)
    assert arm.geometry.robot_start == mount and mobile.geometry.robot_start == tuple(mobile.geometry_cfg.robot_start)
    assert mount != mobile.geometry.robot_start
    assert tuple(arm.config["scene"]["robot_start"]) == mount
    with pytest.raises(ConfigError) as err:
        build_run_spec(compose_config("robot=panda", "experiment=tower3", "scene.fixed_base_start=[-0.35,1.2,0.0]"))
    assert str(err.value).startswith("scene.fixed_base_start = (-0.35, 1.2, 0.0) is invalid: the robot's footprint")
    with pytest.raises(ConfigError) as err:  # checked for any robot: it names where an arm would stand
        build_run_spec(compose_config("experiment=tower3", "scene.fixed_base_start=[0.0,1.2,0.0]"))
    assert "scene.fixed_base_start" in str(err.value) and "inside table1" in str(err.value)
