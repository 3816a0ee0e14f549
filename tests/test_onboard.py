"""``realize.robot.onboard``: a robot config drafted from a URDF against the committed ones.

* ManiSkill's fixed Panda and the SO-100: the draft names the committed arm joints, gripper
  joints, finger links, TCP link and axes; its TCP point lies near the committed one (tolerances
  at each test);
* the Koch (no committed config; ``tests/_koch.py`` is one by hand): the draft loads and passes
  ``check_urdf_names`` and ``grip_geometry``;
* the mobile Panda: a mobile base (x, y, yaw), the lift first in ``upper``, its shipped .glb meshes;
* the Koch draft's TCP and spheres against pytorch_kinematics (in ``tests/test_robot_kinematics.py``, beside every committed robot's);
* a URDF without gripper joints, two equal arms (``--gripper-joints`` picks one), an existing config
  without ``--force``: one line each.

Drafts go to tmp folders; the sphere fit is capped (200 samples, one sphere a link) to keep the
file fast: the fit itself is ``tests/test_sphere_fit.py``'s.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from realize.config import ConfigError
from realize.robot.grip_geometry import grip_geometry
from realize.robot.onboard import Onboarded, main, onboard_robot
from realize.robot.robot_spheres import FitSettings
from realize.robot.sphere_file import load_spheres
from realize.robot.spec import load_robot_spec
from realize.robot.urdf import source_urdf
from realize.robot.urdf_names import check_urdf_names
from realize.robot.urdf_survey import survey_urdf
from _koch import FINGERS, KOCH_URDF

FAST = FitSettings(samples=200, max_spheres=1)


def _draft(tmp: Path, name: str, urdf: str) -> Onboarded:
    (tmp / "c").mkdir(exist_ok=True)
    (tmp / "s").mkdir(exist_ok=True)
    return onboard_robot(name, urdf, tmp / "c", tmp / "s", fit=FAST)


@pytest.fixture(scope="module")
def panda(tmp_path_factory: pytest.TempPathFactory) -> Onboarded:
    return _draft(tmp_path_factory.mktemp("panda"), "panda_draft", load_robot_spec("panda").urdf)


@pytest.fixture(scope="module")
def so100(tmp_path_factory: pytest.TempPathFactory) -> Onboarded:
    return _draft(tmp_path_factory.mktemp("so100"), "so100_draft", load_robot_spec("so100").urdf)


def _same_names(done: Onboarded, robot: str) -> None:
    got, want = done.spec, load_robot_spec(robot)
    assert got.urdf == want.urdf
    assert got.base.joints == want.base.joints == () and got.base.link == want.base.link
    assert got.upper.joints == want.upper.joints
    assert got.gripper.joints == want.gripper.joints
    assert got.gripper.finger_links == want.gripper.finger_links
    assert got.tcp.link == want.tcp.link
    assert got.tcp.approach_axis == want.tcp.approach_axis and got.tcp.closing_axis == want.tcp.closing_axis


def test_panda_draft_matches_the_committed_config(panda: Onboarded) -> None:
    _same_names(panda, "panda")
    # the TCP frame panda_hand_tcp is the fingertips' centre: the draft's point between the pads' last
    # 2 cm lies within 2 mm of it (measured 0.9 mm; the rubber tips are 17.5 mm wide, so 2 mm is well inside)
    assert np.linalg.norm(np.subtract(panda.spec.tcp.offset, load_robot_spec("panda").tcp.offset)) < 0.002
    g = panda.spec.gripper
    assert (g.open, g.closed) == (0.04, -0.01)  # the committed targets: the upper limit, a quarter past the lower
    assert abs(panda.geometry.width_open - 0.08) < 1e-3
    assert panda.spec.collision.ignore_pairs == load_robot_spec("panda").collision.ignore_pairs  # the SRDF's
    spheres = load_spheres(panda.spec.spheres_file)
    assert {s.link for s in spheres} >= {"panda_link0", "panda_hand", "panda_leftfinger"}
    assert set(panda.spec.fabric_exclude) == {s.name for s in spheres if s.link in panda.spec.collision.hand_links}
    text = panda.config_path.read_text()
    assert "NOT calibrated" in text and "experiment=tower3" in panda.report()


def test_so100_draft_matches_the_committed_config(so100: Onboarded) -> None:
    _same_names(so100, "so100")
    # A one-sided jaw's pad middle moves with the opening (docs/robots.md, Grippers: -15 mm open, +12 mm
    # closed along the closing axis). The committed TCP is the middle at a 3 cm grip (-0.75 rad), the
    # draft's at mid-way between the closed limit and its open target (-0.55 rad): 8.1 mm apart
    # (6.9 mm along the closing axis, 4.2 along the approach). Within 10 mm, and the committed TCP lies
    # between the draft's open pads (the gripper check passes with it).
    want = load_robot_spec("so100")
    assert np.linalg.norm(np.subtract(so100.spec.tcp.offset, want.tcp.offset)) < 0.010
    g = so100.spec.gripper
    assert so100.geometry.unit == "rad" and g.closed == -1.1 and -1.1 < g.open <= 1.1
    assert so100.geometry.width_open > 0.03 > so100.geometry.width_closed
    assert "experiment=so100_pick_place" in so100.report()


def test_koch_draft_loads_and_passes_the_checks(tmp_path: Path) -> None:
    done = _draft(tmp_path, "koch_draft", KOCH_URDF)
    spec = done.spec
    assert spec.upper.joints == ("joint_1", "joint_2", "joint_3", "joint_4", "joint_5")
    assert spec.gripper.joints == ("joint_6",) and spec.gripper.finger_links == FINGERS
    check_urdf_names(spec)
    geo = grip_geometry(spec)
    assert geo.width_open > geo.width_closed + 0.02
    assert spec.gripper.fingertip_reach >= geo.reach - 1e-3


def test_tcp_link_picks_the_tcp_frame() -> None:
    """The Koch's hand link_6 has two *tcp* frames: the draft takes the one nearer the pads' middle
    (gripper_tcp, 12.6 mm; back_tcp is 4 cm behind it); ``--tcp-link`` takes link_6 itself, the
    point the same; a link not fixed to the hand is one line."""
    path = source_urdf(KOCH_URDF)
    auto, mine = survey_urdf(path), survey_urdf(path, tcp_link="link_6")
    assert auto.tcp.link == "gripper_tcp" and mine.tcp.link == "link_6"
    gripper_tcp_in_link_6 = np.array([-0.008, 0.0, -0.065])  # the URDF's gripper_tcp_joint origin
    assert np.abs(np.add(auto.tcp.offset, gripper_tcp_in_link_6) - mine.tcp.offset).max() < 2e-4  # rounding
    with pytest.raises(ConfigError, match="--tcp-link 'link_2' is not link_6 or a link fixed to it"):
        survey_urdf(path, tcp_link="link_2")


def test_mobile_panda_draft_finds_its_base_lift_and_shipped_meshes(tmp_path: Path) -> None:
    want = load_robot_spec("mobile_panda")
    done = _draft(tmp_path, "mobile_panda_draft", want.urdf)
    got = done.spec
    assert got.base.joints == want.base.joints and got.base.link == want.base.link and got.base.height == 0.0
    assert got.upper.joints == want.upper.joints and got.gripper.joints == want.gripper.joints
    assert got.tcp.link == want.tcp.link
    assert got.visual_mesh_ext == want.visual_mesh_ext == {".dae": ".glb"}  # .dae named, .glb shipped
    assert "realize robot=mobile_panda_draft ce.n_envs=40 ce.iterations=1" in done.report()  # the mobile smoke run


ARM = """<?xml version="1.0"?>
<robot name="bare_arm">
  <link name="base"><collision><geometry><box size="0.1 0.1 0.05"/></geometry></collision></link>
  <link name="upper"><collision><origin xyz="0 0 0.15"/><geometry><box size="0.04 0.04 0.3"/></geometry></collision></link>
  <link name="lower"><collision><origin xyz="0 0 0.15"/><geometry><box size="0.04 0.04 0.3"/></geometry></collision></link>
  <joint name="shoulder" type="revolute"><parent link="base"/><child link="upper"/><origin xyz="0 0 0.03"/>
    <axis xyz="0 0 1"/><limit lower="-2" upper="2" effort="1" velocity="1"/></joint>
  <joint name="elbow" type="{kind}"><parent link="upper"/><child link="lower"/><origin xyz="0 0 0.32"/>
    <axis xyz="0 1 0"/><limit lower="-1" upper="1" effort="1" velocity="1"/></joint>
</robot>
"""


@pytest.mark.parametrize("kind", ["continuous", "revolute"])  # no candidate; a candidate that never closes
def test_a_urdf_without_gripper_joints_is_one_line(kind: str, tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    urdf = tmp_path / "bare_arm.urdf"
    urdf.write_text(ARM.format(kind=kind))
    with pytest.raises(ConfigError, match="no gripper joints found") as e:
        survey_urdf(urdf)
    assert "\n" not in str(e.value) and str(urdf) in str(e.value) and "--gripper-joints" in str(e.value)
    assert main(["bare", "--urdf", str(urdf), "--out", str(tmp_path / "c"), "--spheres-out", str(tmp_path / "s")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("error: ") and "no gripper joints found" in err and "\n" not in err
    assert not (tmp_path / "c" / "bare.yaml").exists()


def test_two_equal_arms_are_one_line_and_gripper_joints_picks_one() -> None:
    """ManiSkill's two-armed mobile Panda: two grippers at the end of equally long chains."""
    urdf = source_urdf("mani_skill:robots/panda/mobile_panda_dual_arm.urdf")
    with pytest.raises(ConfigError, match="several candidate grippers.*--gripper-joints") as e:
        survey_urdf(urdf)
    assert "\n" not in str(e.value) and str(urdf) in str(e.value)
    s = survey_urdf(urdf, ["left_panda_finger_joint1", "left_panda_finger_joint2"])
    assert s.upper[0] == "linear_actuator_height" and s.upper[1:] == tuple(f"left_panda_joint{i}" for i in range(1, 8))
    assert s.tcp.link == "left_panda_hand_tcp" and "right_panda_joint1" in s.held  # the other arm is held


def test_an_existing_config_is_kept_without_force(tmp_path: Path) -> None:
    (tmp_path / "c").mkdir()
    (tmp_path / "c" / "koch.yaml").write_text("name: koch\n")
    with pytest.raises(ConfigError, match="exists: pass --force"):
        onboard_robot("koch", KOCH_URDF, tmp_path / "c", tmp_path / "s", fit=FAST)
