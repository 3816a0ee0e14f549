"""Batched PID waypoint tracker on a simulated kinematic omni base."""

from __future__ import annotations

import math

import pytest
import torch

from realize.config import ConfigError
from realize.controllers.pid import PIDConfig, PIDState, pid_init, pid_step, wrap_angle

DT = 0.05


def integrate(pose: torch.Tensor, cmd: torch.Tensor, dt: float = DT) -> torch.Tensor:
    """Kinematic omni base: robot-frame (vx, vy) and yaw rate -> next world pose."""
    c, s = torch.cos(pose[:, 2]), torch.sin(pose[:, 2])
    vx = c * cmd[:, 0] - s * cmd[:, 1]
    vy = s * cmd[:, 0] + c * cmd[:, 1]
    return pose + dt * torch.stack([vx, vy, cmd[:, 2]], dim=-1)


def seg_dist(p: torch.Tensor, a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    ab = b - a
    t = (((p - a) * ab).sum(-1) / (ab * ab).sum()).clamp(0, 1)
    return (p - (a + t[..., None] * ab)).norm(dim=-1)


def run(cfg, pose, wps, lengths, steps=600, target_yaw=None):
    st = pid_init(cfg, pose, wps, lengths, target_yaw)
    cmds, traj = [], [pose]
    for _ in range(steps):
        out = pid_step(cfg, st, pose, wps, lengths, DT)
        st = out.state
        cmds.append(out.cmd)
        pose = integrate(pose, out.cmd)
        traj.append(pose)
        if bool(out.done.all()):
            break
    return pose, out, torch.stack(cmds), torch.stack(traj)


L_PATH = torch.tensor([[0.0, 0.0], [2.0, 0.0], [2.0, 1.5]])


def test_follows_l_path_within_tolerance_and_limits():
    cfg = PIDConfig(max_lin_speed=0.5, max_yaw_rate=0.8, max_lin_accel=1.0, goal_tolerance=0.03)
    n = 4
    wps = L_PATH.expand(n, 3, 2).clone()
    lengths = torch.full((n,), 3)
    pose = torch.tensor([[0.0, 0.0, 0.0], [0.1, -0.1, 1.0], [-0.2, 0.1, -2.5], [0.0, 0.05, math.pi]])
    final, out, cmds, traj = run(cfg, pose, wps, lengths)
    assert out.done.all()
    assert ((final[:, :2] - L_PATH[-1]).norm(dim=-1) <= cfg.goal_tolerance + 1e-6).all()
    # heading held (default mode)
    assert (wrap_angle(final[:, 2] - pose[:, 2]).abs() <= cfg.yaw_tolerance).all()
    speed = cmds[..., :2].norm(dim=-1)
    assert (speed <= cfg.max_lin_speed + 1e-6).all()
    assert (cmds[..., 2].abs() <= cfg.max_yaw_rate + 1e-6).all()
    # acceleration limit on the linear command (robot frame rotates only with yaw, held here)
    c, s = torch.cos(traj[:-1, :, 2]), torch.sin(traj[:-1, :, 2])
    vw = torch.stack([c * cmds[..., 0] - s * cmds[..., 1], s * cmds[..., 0] + c * cmds[..., 1]], -1)
    acc = (vw[1:] - vw[:-1]).norm(dim=-1) / DT
    assert (acc <= cfg.max_lin_accel + 1e-4).all()
    # it goes around the corner: never far from the L (cross-track error small)
    p = traj[..., :2]
    d = torch.minimum(seg_dist(p, L_PATH[0], L_PATH[1]), seg_dist(p, L_PATH[1], L_PATH[2]))
    assert d[5:].max() < 0.25


def test_batched_equals_per_sample():
    cfg = PIDConfig(ki=0.2, kd=0.1, max_lin_accel=2.0, max_yaw_accel=3.0, heading="face_goal")
    gen = torch.Generator().manual_seed(0)
    n, lmax = 6, 5
    wps = torch.rand(n, lmax, 2, generator=gen) * 3
    lengths = torch.tensor([5, 3, 1, 0, 4, 2])
    pose = torch.cat([torch.rand(n, 2, generator=gen), (torch.rand(n, 1, generator=gen) - 0.5) * 6], -1)
    st = pid_init(cfg, pose, wps, lengths)
    singles = [pid_init(cfg, pose[i:i + 1], wps[i:i + 1], lengths[i:i + 1]) for i in range(n)]
    p = pose
    ps = [pose[i:i + 1] for i in range(n)]
    for _ in range(80):
        out = pid_step(cfg, st, p, wps, lengths, DT)
        st, p = out.state, integrate(p, out.cmd)
        for i in range(n):
            o = pid_step(cfg, singles[i], ps[i], wps[i:i + 1], lengths[i:i + 1], DT)
            singles[i], ps[i] = o.state, integrate(ps[i], o.cmd)
            assert torch.allclose(o.cmd[0], out.cmd[i], atol=1e-6)
            assert bool(o.done[0]) == bool(out.done[i])
            assert int(o.state.index[0]) == int(out.state.index[i])


@pytest.mark.parametrize("heading", ["face_goal", "target"])
def test_heading_modes_reach_their_yaw(heading):
    cfg = PIDConfig(heading=heading)
    wps = L_PATH.expand(2, 3, 2).clone()
    lengths = torch.tensor([3, 3])
    pose = torch.tensor([[0.0, 0.0, 0.0], [0.0, 0.0, 3.0]])
    target = torch.tensor([1.0, -2.0])
    final, out, _, _ = run(cfg, pose, wps, lengths, target_yaw=target if heading == "target" else None)
    assert out.done.all()
    want = torch.full((2,), math.atan2(1.5, 2.0)) if heading == "face_goal" else target
    assert (wrap_angle(final[:, 2] - want).abs() <= cfg.yaw_tolerance).all()


def test_command_is_in_robot_frame():
    cfg = PIDConfig()
    wps = torch.tensor([[[5.0, 0.0]]])
    pose = torch.tensor([[0.0, 0.0, math.pi / 2]])  # facing +y; target along world +x = robot -y
    st = pid_init(cfg, pose, wps, torch.tensor([1]))
    out = pid_step(cfg, st, pose, wps, torch.tensor([1]), DT)
    assert abs(float(out.cmd[0, 0])) < 1e-6 and float(out.cmd[0, 1]) == pytest.approx(-cfg.max_lin_speed)


def test_empty_path_done_and_nan_pose_flagged():
    cfg = PIDConfig()
    wps = torch.tensor([[[1.0, 1.0]], [[1.0, 1.0]], [[2.0, 0.0]]])
    lengths = torch.tensor([0, 1, 1])
    pose = torch.tensor([[0.0, 0.0, 0.0], [float("nan"), 0.0, 0.0], [0.0, 0.0, 0.0]])
    st = pid_init(cfg, pose, wps, lengths)
    out = pid_step(cfg, st, pose, wps, lengths, DT)
    assert out.done.tolist() == [True, False, False]
    assert out.valid.tolist() == [True, False, True]
    assert torch.equal(out.cmd[:2], torch.zeros(2, 3)) and torch.isfinite(out.cmd).all()
    assert float(out.cmd[2, 0]) > 0


def test_bad_config_and_inputs_raise_naming_the_parameter():
    for kw, name in [({"kp": 0.0}, "kp"), ({"kp": -1.0}, "kp"), ({"kd": -0.1}, "kd"),
                     ({"ki": float("nan")}, "ki"), ({"kp_yaw": 0.0}, "kp_yaw"),
                     ({"max_lin_speed": 0.0}, "max_lin_speed"), ({"max_lin_accel": -1.0}, "max_lin_accel"),
                     ({"heading": "spin"}, "heading")]:
        with pytest.raises(ConfigError, match=rf"controller\.pid\.{name} = "):
            PIDConfig(**kw)
    cfg = PIDConfig()
    pose = torch.zeros(2, 3)
    wps = torch.zeros(2, 3, 2)
    lengths = torch.tensor([3, 3])
    # the tracker's inputs are checked once, when it starts; pid_step (the hot path) trusts them
    with pytest.raises(ValueError, match="lengths"):
        pid_init(cfg, pose, wps, torch.tensor([4, 3]))
    with pytest.raises(ValueError, match="pose"):
        pid_init(cfg, pose[:, :2], wps, lengths)
    with pytest.raises(ValueError, match="target_yaw"):
        pid_init(PIDConfig(heading="target"), pose, wps, lengths)


def test_gradients_flow_through_a_step():
    cfg = PIDConfig(ki=0.1, kd=0.1, max_lin_accel=2.0)
    pose = torch.tensor([[0.0, 0.0, 0.2], [1.0, 1.0, 0.0]], requires_grad=True)
    wps = torch.tensor([[[1.0, 0.0], [1.0, 1.0]], [[1.0, 1.0], [1.0, 1.0]]], requires_grad=True)
    lengths = torch.tensor([2, 2])
    st = pid_init(cfg, pose.detach(), wps.detach(), lengths)
    out = pid_step(cfg, st, pose, wps, lengths, DT)
    out2 = pid_step(cfg, out.state, integrate(pose, out.cmd), wps, lengths, DT)
    out2.cmd.sum().backward()
    assert torch.isfinite(pose.grad).all() and torch.isfinite(wps.grad).all()
    assert pose.grad.abs().sum() > 0
    assert isinstance(out2.state, PIDState)
