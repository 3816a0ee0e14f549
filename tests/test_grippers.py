"""Grippers as they come (issue 56): the SO-100's one revolute jaw builds from its robot config
alone and drives that one joint, and a robot config whose names its URDF lacks is refused in one
line naming the key, before anything is built. (Before: ManiSkill's "Mimic targets dictionary is
missing" for a one-joint gripper, a bare ``KeyError`` for a misspelt finger link.)"""

from __future__ import annotations

import pytest
import torch

from helpers import compose_config
from realize.app.run_config import build_run_spec
from realize.config import ConfigError
from realize.scene.batched import BatchedScene

SO100 = ["robot=so100", "experiment=tower3"]


@pytest.mark.usefixtures("torch_single_thread")
def test_the_so100s_one_revolute_jaw_builds_and_is_driven() -> None:
    spec = build_run_spec(compose_config(*SO100))
    g = spec.robot.gripper
    assert g.joints == ("gripper",) and spec.robot.base.fixed
    with BatchedScene.from_spec(spec, 1) as scene:
        jaw = scene.joint_names.index("gripper")
        scene.reset()
        scene.hold_still()
        arm0 = scene.qpos()[0, :jaw].clone()
        for _ in range(10):
            scene.step()
        assert float(scene.qpos()[0, jaw]) == pytest.approx(g.open, abs=0.02)  # rad
        scene.set_gripper(torch.tensor([True]))
        for _ in range(10):  # closed: past the joint's -1.1 rad limit, so it rests at the limit
            scene.step()
        assert float(scene.qpos()[0, jaw]) == pytest.approx(-1.1, abs=0.02)
        assert torch.allclose(scene.qpos()[0, :jaw], arm0, atol=0.02)  # the arm held still meanwhile


@pytest.mark.parametrize("override, needle", [
    ("robot.gripper.finger_links=[Fixed_Jaw,Moving_jaw]",
     "robot.gripper.finger_links: link 'Moving_jaw' is not in so100.urdf (did you mean 'Moving_Jaw'"),
    ("robot.tcp.link=jaw", "robot.tcp.link: link 'jaw' is not in so100.urdf"),
    ("robot.collision.hand_links=[Fixed_Jaw,Wrist]", "robot.collision.hand_links: link 'Wrist' is not in so100.urdf"),
    ("+robot.held.wrist_rol=0.0", "robot.held: movable joint 'wrist_rol' is not in so100.urdf (did you mean 'wrist_roll'"),
])
def test_a_name_the_urdf_lacks_is_one_line_before_anything_is_built(override: str, needle: str) -> None:
    with pytest.raises(ConfigError) as e:
        build_run_spec(compose_config(*SO100, override))
    assert needle in str(e.value) and "\n" not in str(e.value)
