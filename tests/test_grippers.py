"""Grippers as they come (issue 56): the SO-100's one revolute jaw builds from its robot config
alone, drives that one joint and holds a cube off the table; the grasp geometry measured from the
finger links' kinematics (``realize.robot.grip_geometry``) gives the Panda's numbers within 1 mm;
a robot config whose names its URDF lacks, or whose gripper the agent cannot build or grasp with,
is refused in one line naming the key, before anything is built. (Before: ManiSkill's "Mimic
targets dictionary is missing" for a one-joint gripper, a bare ``KeyError`` for a misspelt finger
link, a jaw in radians read as metres.)"""

from __future__ import annotations

import math

import pytest
import torch

from helpers import compose_config
from realize.spec.run_spec import build_run_spec
from realize.config import ConfigError
from realize.robot.grip_geometry import grip_geometry
from realize.robot.kinematics import RobotKinematics
from realize.robot.reach import pose_ik
from realize.robot.spec import load_robot_spec
from realize.scene.batched import BatchedScene

SO100 = ["experiment=so100_pick_place"]


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
        for _ in range(10):  # closed: at its target (or the joint's -1.1 rad limit, if past it)
            scene.step()
        assert float(scene.qpos()[0, jaw]) == pytest.approx(max(g.closed, -1.1), abs=0.02)
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


def test_the_grasp_geometry_from_finger_kinematics_gives_the_pandas_numbers() -> None:
    """Two prismatic fingers at 0.04 m each: 80 mm between the pads, centred on the TCP, the
    tips 9.5 mm beyond it and 17.5 mm wide (the numbers configs/robot/panda.yaml states), all from
    the URDF's finger meshes and joints, within 1 mm; and a pre-shape gap maps to half of it per finger."""
    spec = load_robot_spec("panda")
    geo = grip_geometry(spec)
    assert (geo.joint_type, geo.unit, geo.n_joints, geo.one_sided) == ("prismatic", "m", 2, False)
    assert geo.width_open == pytest.approx(2 * spec.gripper.open, abs=1e-3)
    assert geo.width_closed == pytest.approx(0.0, abs=1e-3)
    assert max(abs(c) for c in geo.centres) < 1e-3
    assert geo.reach == pytest.approx(spec.gripper.fingertip_reach, abs=1e-3)
    assert geo.tip_half_width == pytest.approx(spec.gripper.pad_half_width, abs=1e-3)
    gap = torch.tensor([0.0, 0.03, 0.055, 0.2])
    assert torch.equal(geo.joint_for_width(gap), (gap / 2).clamp(0.0, spec.gripper.open))


def test_the_so100_jaw_is_one_sided_in_radians_and_its_width_follows_the_tips() -> None:
    """The SO-100's revolute jaw: its width grows with the angle toward open, and the pads'
    midpoint moves with it by half the width change (the fixed jaw stays). Against
    pytorch_kinematics: the moving jaw's pose in the fixed jaw's frame is the one measured from,
    and the URDF's tip frames (Fixed_Jaw_tip, Moving_Jaw_tip, which the measurement does not read)
    close by the measured width change scaled by their distance from the jaw's pivot over the
    pads' (the tips lie 7 mm further out than the TCP's line), within 2 mm."""
    import numpy as np
    import pytorch_kinematics as pk

    from realize.robot.grip_geometry import _pose_in
    from realize.robot.urdf import parse_urdf_joints, source_urdf

    spec = load_robot_spec("so100")
    geo = grip_geometry(spec)
    assert (geo.joint_type, geo.unit, geo.one_sided) == ("revolute", "rad", True)
    w, c = torch.tensor(geo.widths), torch.tensor(geo.centres)
    assert bool((w[1:] > w[:-1]).all()) and geo.width_open > 0.05
    fixed_side = c + w / 2  # the fixed jaw's inner face, from the TCP along the closing axis
    assert float(fixed_side.max() - fixed_side.min()) < 1e-3
    path = source_urdf(spec.urdf)
    chain = pk.build_chain_from_urdf(path.read_bytes())
    names = chain.get_joint_parameter_names()
    by_child = {j.child: j for j in parse_urdf_joints(str(path)).values()}
    pivot = by_child["Moving_Jaw"]

    def frames(v: float) -> dict[str, np.ndarray]:
        th = torch.zeros(1, len(names))
        th[0, names.index("gripper")] = v
        fk = chain.forward_kinematics(th)
        inv = torch.linalg.inv(fk["Fixed_Jaw"].get_matrix()[0].double())
        return {n: (inv @ fk[n].get_matrix()[0].double()).numpy() for n in ("Moving_Jaw", "Moving_Jaw_tip", "Fixed_Jaw_tip")}

    lo, hi = geo.values[0], geo.values[-1]
    for v in (lo, hi):
        assert np.allclose(frames(v)["Moving_Jaw"], _pose_in(by_child, "Moving_Jaw", "Fixed_Jaw", {"gripper": v}), atol=1e-5)
    closing = np.asarray(spec.tcp.closing_axis)
    tip_travel = float((frames(lo)["Moving_Jaw_tip"][:3, 3] - frames(hi)["Moving_Jaw_tip"][:3, 3]) @ closing)
    origin = np.asarray(pivot.xyz)
    tcp = np.asarray(spec.tcp.offset)
    tip = frames(hi)["Moving_Jaw_tip"][:3, 3]
    radius_ratio = np.linalg.norm((tip - origin)[:2]) / np.linalg.norm((tcp - origin)[:2])
    assert (geo.width_open - geo.width_closed) * radius_ratio == pytest.approx(tip_travel, abs=0.002)
    v = geo.joint_for_width(torch.tensor([0.03]))
    assert lo < float(v) < hi and float(geo.joint_for_width(torch.tensor([1.0]))) == pytest.approx(hi)


@pytest.mark.parametrize("robot, override, needle", [
    ("panda", "robot.gripper.open=0.06", "robot.gripper.open = 0.06 m is invalid: outside panda_finger_joint1's range"),
    ("so100", "robot.gripper.open=1.5", "robot.gripper.open = 1.5 rad is invalid: outside gripper's range"),
    ("so100", "robot.gripper.open=-0.795", "robot.gripper.open = -0.795 rad is invalid: the fingers are"),
    ("so100", "robot.gripper.fingertip_reach=0.007", "robot.gripper.fingertip_reach = 0.007 m is invalid"),
    ("so100", "robot.gripper.finger_links=[Fixed_Jaw,Wrist_Pitch_Roll]",
     "robot.gripper.finger_links = ['Fixed_Jaw', 'Wrist_Pitch_Roll']: neither is moved by"),
])
def test_a_gripper_the_agent_cannot_build_is_one_line_naming_the_key(robot: str, override: str, needle: str) -> None:
    with pytest.raises(ConfigError) as e:
        build_run_spec(compose_config(f"robot={robot}", "experiment=so100_pick_place" if robot == "so100" else
                                      "experiment=tower3_tabletop", override))
    assert needle in str(e.value) and "\n" not in str(e.value)


def _grasp_and_lift(spec, scene: BatchedScene) -> tuple[RobotKinematics, list[torch.Tensor], torch.Tensor]:
    """The arm put (by its own IK, realize.robot.reach) with the open jaw around the 3 cm cube of
    scene=so100_table, top-down, the cube's centre half way between the open and the closed pads'
    midpoints (as a grasp puts it); the jaw closes; the arm lifts 5 cm. Returns the kinematics,
    the arm's targets (above, at and lifted from the cube) and the TCP at the cube."""
    kin = RobotKinematics(spec.robot, dtype=torch.float64)
    geo = grip_geometry(spec.robot)
    cube = torch.tensor(spec.geometry.object("cube").position, dtype=torch.float64)
    down, closing = torch.tensor([0.0, 0.0, -1.0], dtype=torch.float64), torch.tensor([-1.0, 0.0, 0.0], dtype=torch.float64)
    shift = 0.5 * (geo.centre_for_width(torch.tensor(0.03)) + geo.centre_for_width(torch.tensor(geo.width_open)))
    goal = cube - closing * float(shift) + torch.tensor([0.0, 0.0, 0.008], dtype=torch.float64)
    path = [goal + torch.tensor([0.0, 0.0, dz], dtype=torch.float64) for dz in (0.08, 0.0, 0.05)]
    qs = [pose_ik(kin, spec.geometry.robot_start, p, down, closing) for p in path]
    scene.reset()
    scene.set_arm_targets(qs[0][None])
    for _ in range(60):
        scene.step()
    for k in range(1, 31):  # straight down onto the cube, in joint space
        scene.set_arm_targets((qs[0] + (qs[1] - qs[0]) * k / 30)[None])
        scene.step()
    for _ in range(10):
        scene.step()
    scene.set_gripper(torch.tensor([True]))
    for _ in range(15):
        scene.step()
    for k in range(1, 31):
        scene.set_arm_targets((qs[1] + (qs[2] - qs[1]) * k / 30)[None])
        scene.step()
    for _ in range(10):
        scene.step()
    return kin, qs, goal


@pytest.mark.usefixtures("torch_single_thread")
def test_the_so100_jaw_holds_a_cube_off_the_table() -> None:
    """After _grasp_and_lift the cube has risen with the jaw, off the table, and both jaws press on it."""
    spec = build_run_spec(compose_config(*SO100))
    z0 = float(spec.geometry.object("cube").position[2])  # resting on the table
    with BatchedScene.from_spec(spec, 1) as scene:
        _grasp_and_lift(spec, scene)
        assert bool(scene.holding()[0, 0])
        assert float(scene.object_poses()[0, 0, 2]) > z0 + 0.03


@pytest.mark.usefixtures("torch_single_thread")
def test_the_so100_carries_the_cube_on_its_joint_targets() -> None:
    """Squeezing the cube, the arm still stands on its drive targets: after the lift within 0.05 rad
    of them, and turned (in joint space) to a top-down pose 8 cm above the cube's spot mirrored to
    the arm's other side (where the task places it), the TCP within 6 mm and the approach within 0.05
    rad of that pose's, by the robot's own kinematics, the cube still held. (With ManiSkill's damping
    of 100 N m s/rad the carrying arm stood 0.16 rad off after the lift, and 12.7 mm and 0.1 rad
    short of the pose: the place's 0.1 rad alignment was never met; configs/robot/so100.yaml.)"""
    spec = build_run_spec(compose_config(*SO100))
    with BatchedScene.from_spec(spec, 1) as scene:
        kin, qs, goal = _grasp_and_lift(spec, scene)
        assert bool(scene.holding()[0, 0])
        assert float((scene.whole_body_q()[0, 3:].double() - qs[2]).abs().max()) < 0.05
        spot = goal * torch.tensor([1.0, -1.0, 1.0], dtype=torch.float64) + torch.tensor([0.0, 0.0, 0.08], dtype=torch.float64)
        down = torch.tensor([0.0, 0.0, -1.0], dtype=torch.float64)
        q_place = pose_ik(kin, spec.geometry.robot_start, spot, down, torch.tensor([0.0, 1.0, 0.0], dtype=torch.float64))
        for k in range(1, 41):
            scene.set_arm_targets((qs[2] + (q_place - qs[2]) * k / 40)[None])
            scene.step()
        for _ in range(20):
            scene.step()
        tcp, approach, _ = kin.tcp_and_axes(scene.whole_body_q().double())
        assert bool(scene.holding()[0, 0])
        assert float((tcp[0] - spot).norm()) < 0.006
        assert float((approach[0] * down).sum()) > math.cos(0.05)
