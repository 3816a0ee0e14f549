"""Tests of realize.robot.kinematics on Fetch (fetch_omni): FK against pytorch_kinematics and SAPIEN,
the TCP at the pad centre, torch.func compatibility, closed-form Jacobians, sphere coverage of the
collision meshes. (Both robots against pytorch_kinematics: tests/test_robot_kinematics.py.)"""

from __future__ import annotations

import os
import xml.etree.ElementTree as ET

import gymnasium as gym
import mani_skill.envs  # noqa: F401  (registers the ManiSkill environments with gymnasium)
import pytest
import pytorch_kinematics as pk
import torch
import trimesh
from torch.func import jacfwd, jvp, vmap

from realize.controllers import fabric_jets as fabrics
from realize.robot.kinematics import RobotKinematics
from realize.robot.spec import load_robot_spec
from helpers import full_qpos, random_q

F64 = torch.float64
FETCH = load_robot_spec("fetch_omni")


@pytest.fixture(scope="module")
def kin64() -> RobotKinematics:
    return RobotKinematics(FETCH, dtype=F64)


# ----------------------------------------------------------------------------- reference FK


def test_matches_pytorch_kinematics(kin64: RobotKinematics) -> None:
    with open(kin64.urdf_path, "rb") as f:
        chain = pk.build_chain_from_urdf(f.read()).to(dtype=F64)
    q = random_q(kin64, 64, seed=1)
    # the full tree: head and finger joints at this model's fixed values
    full = full_qpos(kin64, q, chain.get_joint_parameter_names())
    ref = chain.forward_kinematics(full)
    links = [n for n in ref if n in kin64.link_names]
    assert "gripper_link" in links and "l_gripper_finger_link" in links and "head_tilt_link" in links
    ours = kin64.link_poses(q, links)
    for i, name in enumerate(links):
        torch.testing.assert_close(ours[:, i], ref[name].get_matrix(), atol=1e-6, rtol=0, msg=name)


def test_tcp_is_pad_centre(kin64: RobotKinematics) -> None:
    q = random_q(kin64, 8, seed=2)
    tcp, approach, closing = kin64.tcp_and_axes(q)
    pads = kin64.link_poses(q, ["r_gripper_finger_link", "l_gripper_finger_link"])
    # pad centres in finger-link frames (from the collision meshes, see module docstring)
    r_pad = pads[:, 0, :3, :3] @ torch.tensor([0.001, -0.0086, 0.0], dtype=F64) + pads[:, 0, :3, 3]
    l_pad = pads[:, 1, :3, :3] @ torch.tensor([0.001, 0.0086, 0.0], dtype=F64) + pads[:, 1, :3, 3]
    torch.testing.assert_close(tcp, (r_pad + l_pad) / 2, atol=2e-4, rtol=0)
    torch.testing.assert_close(approach.norm(dim=-1), torch.ones(8, dtype=F64))
    # fingers close along the closing axis
    gap = ((r_pad - l_pad) * closing).sum(-1)
    assert torch.all(gap.abs() > 0.1 - 0.02)
    pose = kin64.ee_pose(q)
    torch.testing.assert_close(pose[:, :3, 3], tcp)
    torch.testing.assert_close(pose[:, :3, 0], approach)


# ----------------------------------------------------------------------------- SAPIEN


@pytest.fixture(scope="module")
def maniskill_fetch():
    # SAPIEN needs a Vulkan device; scripts/setup.sh installs one, so its absence fails here
    env = gym.make("PickCube-v1", robot_uids="fetch", num_envs=1, sim_backend="cpu")
    env.reset(seed=0)
    yield env.unwrapped.agent.robot
    env.close()


def test_matches_sapien(maniskill_fetch) -> None:
    kin = RobotKinematics(FETCH, dtype=F64, held={"head_pan_joint": 0.3, "head_tilt_joint": -0.2}, finger_opening=0.03)
    robot = maniskill_fetch
    names = [j.name for j in robot.get_active_joints()]
    wb = [names.index(n) for n in kin.joint_names]
    links = [lk.name for lk in robot.get_links()]
    for q in random_q(kin, 4, seed=3):
        robot.set_qpos(full_qpos(kin, q, names).float().unsqueeze(0))
        root = robot.get_root_pose().to_transformation_matrix()[0].to(F64)
        sim = torch.stack([lk.pose.to_transformation_matrix()[0] for lk in robot.get_links()]).to(F64)
        ours = kin.link_poses(q, links, root_pose=root)
        err = (sim - ours).abs().amax(dim=(-1, -2))
        assert err.max() < 1e-4, f"{links[int(err.argmax())]}: {err.max():.2e}"
        # the simulator's state maps back to q
        torch.testing.assert_close(robot.get_qpos()[0].to(F64)[wb], q, atol=1e-6, rtol=0)


# ----------------------------------------------------------------------------- torch.func


def _tcp6(kin: RobotKinematics):
    def f(q: torch.Tensor) -> torch.Tensor:
        p, a, _ = kin.tcp_and_axes(q)
        return torch.cat([p, a], dim=-1)

    return f


def test_jacfwd_matches_finite_differences(kin64: RobotKinematics) -> None:
    f = _tcp6(kin64)
    q = random_q(kin64, 1, seed=4)[0]
    jac = jacfwd(f)(q)  # (6, 11)
    eps = 1e-6
    eye = torch.eye(11, dtype=F64)
    fd = torch.stack([(f(q + eps * eye[j]) - f(q - eps * eye[j])) / (2 * eps) for j in range(11)], dim=-1)
    torch.testing.assert_close(jac, fd, atol=1e-7, rtol=0)


def test_vmap_equals_batch_and_loop(kin64: RobotKinematics) -> None:
    q = random_q(kin64, 16, seed=5)
    batched = kin64.ee_pose(q)
    torch.testing.assert_close(vmap(kin64.ee_pose)(q), batched)
    torch.testing.assert_close(torch.stack([kin64.ee_pose(qi) for qi in q]), batched)
    c, _ = kin64.collision_spheres(q)
    torch.testing.assert_close(vmap(lambda x: kin64.collision_spheres(x)[0])(q), c)
    # extra leading dims
    torch.testing.assert_close(kin64.ee_pose(q.reshape(4, 4, 11)).reshape(16, 4, 4), batched)


def test_closed_form_jacobians_match_autodiff(kin64: RobotKinematics) -> None:
    q = random_q(kin64, 6, seed=6)
    qd = torch.randn(6, 11, dtype=F64, generator=torch.Generator().manual_seed(7))
    root = torch.eye(4, dtype=F64)
    root[:3, :3] = torch.tensor([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]], dtype=F64)
    root[:3, 3] = torch.tensor([1.0, -2.0, 0.3], dtype=F64)

    # TCP: linear rows vs jacfwd of the position; angular rows through the approach axis
    pose, jac = kin64.tcp_jacobian(q, root_pose=root)
    jp = vmap(jacfwd(lambda x: kin64.tcp_and_axes(x, root_pose=root)[0]))(q)
    ja = vmap(jacfwd(lambda x: kin64.tcp_and_axes(x, root_pose=root)[1]))(q)
    torch.testing.assert_close(jac[:, :3], jp)
    a = pose[:, :3, 0]
    torch.testing.assert_close(torch.linalg.cross(jac[:, 3:].transpose(-1, -2), a.unsqueeze(1)).transpose(-1, -2), ja)

    # J' q' = second directional derivative of the map along q'
    def second(f):
        return jvp(lambda x: jvp(f, (x,), (qd,))[1], (q,), (qd,))[1]

    acc = kin64.tcp_jdot_qdot(q, qd, root_pose=root)
    torch.testing.assert_close(acc[:, :3], second(lambda x: kin64.tcp_and_axes(x, root_pose=root)[0]))
    # angular: d/dt (J_w q') checked through the approach axis: a'' = w' x a + w x (w x a)
    w = (jac[:, 3:] @ qd.unsqueeze(-1)).squeeze(-1)
    a_dd = torch.linalg.cross(acc[:, 3:], a) + torch.linalg.cross(w, torch.linalg.cross(w, a))
    torch.testing.assert_close(a_dd, second(lambda x: kin64.tcp_and_axes(x, root_pose=root)[1]))

    # spheres
    centres, radii, jsph = kin64.sphere_jacobians(q, root_pose=root)
    sph = lambda x: kin64.collision_spheres(x, root_pose=root)[0]  # noqa: E731
    torch.testing.assert_close(centres, sph(q))
    torch.testing.assert_close(jsph, vmap(jacfwd(sph))(q))
    torch.testing.assert_close(kin64.sphere_jdot_qdot(q, qd, root_pose=root), second(sph))


def test_gradients_flow_float32() -> None:
    kin = RobotKinematics(FETCH)  # float32 default
    q = random_q(kin, 3, seed=8).requires_grad_(True)
    tcp, a, _ = kin.tcp_and_axes(q)
    c, r = kin.collision_spheres(q)
    ((tcp**2).sum() + a[:, 2].sum() + c[..., 2].sum()).backward()
    assert q.grad is not None and torch.isfinite(q.grad).all()
    assert tcp.dtype == torch.float32


# ----------------------------------------------------------------------------- spheres, limits


def test_spheres_cover_collision_meshes(kin64: RobotKinematics) -> None:
    assert 15 <= kin64.n_spheres <= 25
    base = os.path.dirname(kin64.urdf_path)
    pts: dict[str, torch.Tensor] = {}
    for link in ET.parse(kin64.urdf_path).getroot().findall("link"):
        for col in link.findall("collision"):
            mesh = trimesh.load(os.path.join(base, col.find("geometry/mesh").get("filename")))
            origin = col.find("origin")
            off = torch.tensor([float(v) for v in origin.get("xyz").split()], dtype=F64) if origin is not None else 0.0
            verts = torch.as_tensor(mesh.vertices, dtype=F64)
            samples = torch.as_tensor(trimesh.sample.sample_surface(mesh, 1000, seed=0)[0], dtype=F64)
            pts[link.get("name")] = torch.cat([verts, samples]) + off
    links = list(pts)
    assert {"base_link", "torso_lift_link", "gripper_link", "bellows_link2"} <= set(links)
    q = random_q(kin64, 24, seed=9)
    q[:8, 3] = 0.0
    q[8:16, 3] = kin64.upper[3]
    poses = kin64.link_poses(q, links)
    centres, radii = kin64.collision_spheres(q)
    for i, name in enumerate(links):
        world = torch.einsum("nij,pj->npi", poses[:, i, :3, :3], pts[name]) + poses[:, i, None, :3, 3]
        outside = (torch.cdist(world, centres) - radii).min(dim=-1).values.max()
        assert outside < 1e-3, f"{name} sticks out of the spheres by {outside * 1000:.1f} mm"


def test_limits_and_names(kin64: RobotKinematics) -> None:
    assert kin64.joint_names == FETCH.whole_body_joints
    assert kin64.lower.shape == kin64.upper.shape == (11,)
    assert not kin64.limited[2] and torch.isinf(kin64.lower[2])  # yaw is continuous
    assert kin64.lower[0] <= -20 and kin64.upper[1] >= 20
    torch.testing.assert_close(kin64.upper[3], torch.tensor(0.38615, dtype=F64))
    assert bool(kin64.sphere_floor_mask.sum() == kin64.n_spheres - 1)


def test_fabrics_protocol_jets_match_autodiff(kin64: RobotKinematics) -> None:
    """``kin.jets`` (closed form) equals the fabric's own forward-mode jets of ``kin(q)``."""
    q = random_q(kin64, 5, seed=11)
    qd = torch.randn(5, 11, dtype=F64, generator=torch.Generator().manual_seed(12))
    ours = kin64.jets(q, qd)
    plain = fabrics.Kinematics(forward=kin64.__call__, body_radii=kin64.body_radii)
    ref = fabrics.kinematic_jets(plain, q, qd, d=3)
    for group_ours, group_ref in zip(ours, ref):
        for a, b in zip(group_ours, group_ref):
            torch.testing.assert_close(a, b)
    tcp, centres = kin64(q)
    torch.testing.assert_close(tcp, kin64.tcp_and_axes(q)[0])
    torch.testing.assert_close(centres, kin64.collision_spheres(q)[0])
