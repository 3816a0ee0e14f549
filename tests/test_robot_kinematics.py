"""Every robot's kinematics against pytorch_kinematics (an independent implementation, and one of
the project's declared dependencies): on 1,000 random configurations in float64, the TCP pose,
every collision-sphere centre, and their Jacobians agree within 1e-9. The URDF goes to
pytorch_kinematics through ``realize.robot.urdf.urdf_for_pytorch_kinematics`` (its parser needs
``effort`` and ``velocity`` on every limit), so a URDF without them, as ManiSkill's Koch arm
(``tests/_koch.py``), is checked the same way."""

from __future__ import annotations


from pathlib import Path

import pytest
import pytorch_kinematics as pk
import torch

from realize.robot.kinematics import RobotKinematics
from realize.robot.sphere_file import SphereSpec
from realize.robot.spec import RobotSpec, known_robots, load_robot_spec
from realize.robot.urdf import urdf_for_pytorch_kinematics
from _koch import koch_spec
from helpers import full_qpos, random_q

F64 = torch.float64
N = 1000
TOL = 1e-9


@pytest.fixture(autouse=True)
def float64_urdf_origins(monkeypatch: pytest.MonkeyPatch) -> None:
    """pytorch_kinematics 0.7.6 reads URDF origins (xyz, rpy) in float32 (~1e-8 m off); its
    kinematics are compared here in float64, so its origin reader is made to keep float64."""
    import pytorch_kinematics.transforms as tf
    import pytorch_kinematics.urdf as pk_urdf

    def convert(origin):
        if origin is None:
            return tf.Transform3d(dtype=F64)
        rpy = torch.tensor(origin.rpy, dtype=F64)
        return tf.Transform3d(rot=tf.quaternion_from_euler(rpy, "sxyz"), pos=torch.tensor(origin.xyz, dtype=F64),
                              dtype=F64)

    monkeypatch.setattr(pk_urdf, "_convert_transform", convert)


def _with_planar_base(urdf: bytes, names: tuple[str, ...], height: float) -> bytes:
    """A fixed-base robot's URDF with the planar base our model puts ahead of its root, written
    as URDF joints (x, y prismatic, yaw continuous from a ``world`` link; the root ``height`` up),
    so that pytorch_kinematics computes the base columns too."""
    import xml.etree.ElementTree as ET

    root = ET.fromstring(urdf)
    children = {j.find("child").get("link") for j in root.iter("joint")}
    (base,) = [lk.get("name") for lk in root.iter("link") if lk.get("name") not in children]
    links = ["world", f"{names[0]}_link", f"{names[1]}_link", base]
    for name, parent, child, kind, axis, z in zip(names, links, links[1:], ("prismatic", "prismatic", "continuous"),
                                                  ("1 0 0", "0 1 0", "0 0 1"), (0.0, 0.0, height)):
        if child != base:
            ET.SubElement(root, "link", name=child)
        j = ET.SubElement(root, "joint", name=name, type=kind)
        ET.SubElement(j, "origin", xyz=f"0 0 {z!r}", rpy="0 0 0")
        ET.SubElement(j, "parent", link=parent)
        ET.SubElement(j, "child", link=child)
        ET.SubElement(j, "axis", xyz=axis)
        ET.SubElement(j, "limit", lower="-1000", upper="1000", effort="0", velocity="1")
    ET.SubElement(root, "link", name="world")
    return ET.tostring(root)


def _point(t: torch.Tensor, offset: torch.Tensor) -> torch.Tensor:
    """(N, 3) the point ``offset`` of a link whose poses are ``t`` (N, 4, 4)."""
    return t[:, :3, :3] @ offset + t[:, :3, 3]


@pytest.mark.parametrize("robot", known_robots())
def test_tcp_spheres_and_jacobians_match_pytorch_kinematics(robot: str) -> None:
    spec = load_robot_spec(robot)
    _check_against_pytorch_kinematics(spec, RobotKinematics(spec, dtype=F64))


def test_a_urdf_without_effort_or_velocity_limits_matches_pytorch_kinematics() -> None:
    """The Koch's URDF gives no effort or velocity on its limits: read as it comes, pytorch_kinematics'
    parser refuses it; through ``urdf_for_pytorch_kinematics`` it agrees with ours (spheres: one on
    each arm link, off its origin). Batched rows equal the same configurations one at a time."""
    spec = koch_spec()
    links = ("link_2", "link_3", "link_4", "link_5", "link_6", "gripper")
    spheres = [SphereSpec(f"{lk}_0", lk, (0.01, -0.02, 0.03), 0.02) for lk in links]
    kin = RobotKinematics(spec, dtype=F64, spheres=spheres)
    with open(kin.urdf_path, "rb") as f:
        with pytest.raises(Exception, match="velocity|effort"):
            pk.build_chain_from_urdf(f.read())
    _check_against_pytorch_kinematics(spec, kin)
    q = random_q(kin, 5, seed=3)
    pose, jac = kin.tcp_jacobian(q)
    for i in range(len(q)):
        one_pose, one_jac = kin.tcp_jacobian(q[i:i + 1])
        torch.testing.assert_close(one_pose[0], pose[i], atol=1e-12, rtol=0)
        torch.testing.assert_close(one_jac[0], jac[i], atol=1e-12, rtol=0)


def _check_against_pytorch_kinematics(spec: RobotSpec, kin: RobotKinematics) -> None:
    """TCP pose, sphere centres and their Jacobians of ``kin`` against pytorch_kinematics (module docstring)."""
    robot = spec.name
    urdf = urdf_for_pytorch_kinematics(kin.urdf_path)
    if spec.base.fixed:
        urdf = _with_planar_base(urdf, spec.whole_body_joints[:3], spec.base.height)
    q = random_q(kin, N, seed=7)
    chain = pk.build_chain_from_urdf(urdf).to(dtype=F64)
    ref = {k: v.get_matrix() for k, v in chain.forward_kinematics(full_qpos(kin, q, chain.get_joint_parameter_names())).items()}

    pose, jac = kin.tcp_jacobian(q)
    tcp_ref = _point(ref[kin.ee_link], kin.tcp_offset)
    assert (pose[:, :3, 3] - tcp_ref).abs().max() < TOL
    assert (pose[:, :3, :3] - ref[kin.ee_link][:, :3, :3]).abs().max() < TOL
    centres, _, sjac = kin.sphere_jacobians(q)
    for k, s in enumerate(kin.spheres):
        err = (centres[:, k] - _point(ref[s.link], kin.sphere_offsets[k])).abs().max()
        assert err < TOL, f"{robot}: sphere {s.name}: {err:.2e}"

    # Jacobians: pytorch_kinematics' serial chain from the root to each link, its columns mapped
    # to q's joints by name (joints on the path that are not in q are held: no column of ours)
    points = [(kin.ee_link, kin.tcp_offset, jac, "tcp")] + [
        (s.link, kin.sphere_offsets[k], sjac[:, k], s.name) for k, s in enumerate(kin.spheres)]
    serial: dict[str, object] = {}
    for link, offset, ours, name in points:
        sc = serial.get(link)
        if sc is None:
            sc = serial[link] = pk.build_serial_chain_from_urdf(urdf, link).to(dtype=F64)
        names = sc.get_joint_parameter_names()
        jref = sc.jacobian(full_qpos(kin, q, names), locations=offset.expand(N, 3))
        rows = ours.shape[1]  # 6 for the TCP (linear and angular), 3 for a sphere centre
        expected = torch.zeros_like(ours)
        for i, joint in enumerate(names):
            if joint in kin.joint_names:
                expected[:, :, kin.joint_names.index(joint)] = jref[:, :rows, i]
        err = (ours - expected).abs().max()
        assert err < TOL, f"{robot}: Jacobian of {name}: {err:.2e}"


def test_the_onboard_draft_of_the_koch_matches_pytorch_kinematics(tmp_path: Path) -> None:
    """The Koch as ``python -m realize.robot.onboard`` drafts it (tests/test_onboard.py checks the
    draft's choices), through ``RobotKinematics`` against pytorch_kinematics, as every committed robot."""
    from realize.robot.onboard import onboard_robot
    from realize.robot.robot_spheres import FitSettings

    for sub in ("c", "s"):
        (tmp_path / sub).mkdir()
    spec = onboard_robot("koch_draft", "mani_skill:robots/koch/follower_arm_v1.1.urdf", tmp_path / "c", tmp_path / "s",
                         fit=FitSettings(samples=200, max_spheres=1)).spec
    _check_against_pytorch_kinematics(spec, RobotKinematics(spec, dtype=F64))
