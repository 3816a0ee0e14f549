"""Tests for realize.controllers.fabrics against the reference ``fabrics`` package.

The fixtures come from ``scripts/make_fabrics_fixtures.py`` (the casadi
reference planner, default speed-controlled configuration); the forward maps
below are the torch twins of the casadi ones written there.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch

from realize.config import ConfigError
from realize.controllers.fabric_jets import Kinematics
from realize.controllers.fabrics import FabricConfig, fabric_acceleration, integrate

FIXTURES = Path(__file__).parent / "fixtures"
SYSTEMS = ("point_mass", "planar_arm")


def point_mass_forward(q: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    return q, q[:, None, :]


def planar_arm_forward(l1: float, l2: float):
    def forward(q: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        elbow = l1 * torch.stack([torch.cos(q[:, 0]), torch.sin(q[:, 0])], dim=-1)
        s = q[:, 0] + q[:, 1]
        ee = elbow + l2 * torch.stack([torch.cos(s), torch.sin(s)], dim=-1)
        return ee, torch.stack([0.5 * elbow, elbow, ee], dim=1)

    return forward


def load(system: str) -> dict:
    with np.load(FIXTURES / f"fabrics_{system}.npz", allow_pickle=False) as z:
        data = {k: torch.from_numpy(z[k]).to(torch.float64) for k in z.files}
    if system == "point_mass":
        data["forward"] = point_mass_forward
    else:
        data["forward"] = planar_arm_forward(*data["arm_lengths"].tolist())
    return data


def run(data: dict, idx=slice(None), **overrides):
    args = dict(
        q=data["q"][idx], qd=data["qdot"][idx], goal=data["goal"][idx],
        obstacles=data["obst"][idx][:, None, :], weight=data["weight"][idx],
    )
    args.update(overrides)
    kin = Kinematics(data["forward"], data["body_radii"][idx])
    return fabric_acceleration(
        args.pop("q"), args.pop("qd"), args.pop("goal"), kin,
        lower=data["lower"], upper=data["upper"], **args,
    )


@pytest.fixture(scope="module", params=SYSTEMS)
def data(request):
    return load(request.param)


def test_matches_reference_package(data):
    qdd, valid = run(data)
    ref = data["qddot"]
    assert qdd.shape == ref.shape and qdd.dtype == torch.float64
    assert bool(valid.all())
    rel = (qdd - ref).norm(dim=-1) / ref.norm(dim=-1)
    assert ref.shape[0] >= 200
    assert float(rel.max()) <= 1e-6, float(rel.max())


def test_loop_jacobian_equals_vmap(data):
    idx = slice(0, 16)
    a, _ = run(data, idx)
    b, _ = run(data, idx, vectorize=False)
    torch.testing.assert_close(a, b, rtol=1e-12, atol=1e-12)


def test_batched_equals_per_sample(data):
    idx = list(range(2, 12))
    batched, _ = run(data, idx)
    single = torch.cat([run(data, [i])[0] for i in idx])
    torch.testing.assert_close(batched, single, rtol=1e-12, atol=1e-12)


def test_gradcheck_q_and_goal():
    data = load("planar_arm")
    idx = [2, 3, 5]  # non-zero velocities: away from the sign() switches
    kin = Kinematics(data["forward"], data["body_radii"][idx])
    qd, obst, w = data["qdot"][idx], data["obst"][idx][:, None, :], data["weight"][idx]

    def f(q, goal):
        return fabric_acceleration(q, qd, goal, kin, obstacles=obst, weight=w,
                                   lower=data["lower"], upper=data["upper"])[0]

    q = data["q"][idx].clone().requires_grad_(True)
    goal = data["goal"][idx].clone().requires_grad_(True)
    assert torch.autograd.gradcheck(f, (q, goal), eps=1e-6, atol=1e-5, rtol=1e-4)


def test_nan_goal_invalidates_only_its_row():
    data = load("planar_arm")
    idx = list(range(8))
    clean, _ = run(data, idx)
    goal = data["goal"][idx].clone()
    goal[3, 0] = float("nan")
    q = data["q"][idx].clone().requires_grad_(True)
    qdd, valid = run(data, idx, goal=goal, q=q)
    assert valid.tolist() == [i != 3 for i in idx]
    assert torch.all(qdd[3] == 0)
    keep = valid
    torch.testing.assert_close(qdd[keep], clean[keep], rtol=1e-12, atol=1e-12)
    qdd.sum().backward()
    assert torch.isfinite(q.grad).all() and torch.all(q.grad[3] == 0)


def test_bad_per_plan_inputs_are_flagged():
    data = load("point_mass")
    idx = list(range(6))
    q = data["q"][idx].clone()
    q[1, 1] = float("inf")
    w = data["weight"][idx].clone()
    w[2] = -1.0
    obst = data["obst"][idx][:, None, :].clone()
    obst[4, 0, 2] = float("nan")
    qdd, valid = run(data, idx, q=q, weight=w, obstacles=obst)
    assert valid.tolist() == [True, False, False, True, False, True]
    assert torch.all(qdd[~valid] == 0) and torch.isfinite(qdd).all()


def test_non_positive_gains_raise():
    with pytest.raises(ConfigError, match="gamma"):
        FabricConfig(gamma=0.0)
    with pytest.raises(ConfigError, match="base_inertia"):
        FabricConfig(base_inertia=-0.2)
    with pytest.raises(ConfigError, match="beta_close"):
        FabricConfig(beta_close=-1.0)
    with pytest.raises(ConfigError, match="m_max"):
        FabricConfig(m_min=1.0, m_max=0.5)
    data = load("point_mass")
    with pytest.raises(ValueError, match="weight"):
        run(data, slice(0, 2), weight=-1.0)


def test_obstacle_padding_mask():
    data = load("planar_arm")
    idx = slice(0, 8)
    ref, _ = run(data, idx)
    obst = data["obst"][idx][:, None, :]
    padded = torch.cat([obst, torch.full_like(obst, float("nan"))], dim=1)
    mask = torch.tensor([[True, False]]).expand(8, 2)
    qdd, valid = run(data, idx, obstacles=padded, obstacle_mask=mask)
    assert bool(valid.all())
    torch.testing.assert_close(qdd, ref, rtol=1e-12, atol=1e-12)


def test_float32_and_integrate():
    data = load("planar_arm")
    d32 = {k: (v.float() if torch.is_tensor(v) else v) for k, v in data.items()}
    qdd32, valid = run(d32, slice(0, 32))
    ref = data["qddot"][:32].float()
    assert qdd32.dtype == torch.float32 and bool(valid.all())
    rel = (qdd32 - ref).norm(dim=-1) / ref.norm(dim=-1)
    assert float(rel.median()) < 1e-3
    q, qd = d32["q"][:32], d32["qdot"][:32]
    q1, qd1 = integrate(q, qd, qdd32, 0.02)
    torch.testing.assert_close(qd1, qd + 0.02 * qdd32)
    torch.testing.assert_close(q1, q + 0.02 * qd1)
    with pytest.raises(ValueError, match="dt"):
        integrate(q, qd, qdd32, 0.0)


def test_attractor_reaches_goal_point_mass():
    """Closed loop without obstacles: the point mass converges to its goal."""
    N = 4
    kin = Kinematics(point_mass_forward, torch.full((1,), 0.1, dtype=torch.float64))
    q = torch.zeros(N, 2, dtype=torch.float64)
    qd = torch.zeros_like(q)
    goal = torch.tensor([[1.0, 0.5], [-1.0, 0.2], [0.3, -0.8], [0.0, 1.2]], dtype=torch.float64)
    for _ in range(300):
        qdd, _ = fabric_acceleration(q, qd, goal, kin)
        q, qd = integrate(q, qd, qdd, 0.05)
    assert float((q - goal).norm(dim=-1).max()) < 0.05


class ArmWithJets:
    """Planar arm with closed-form jets (the optional fast path of FabricKinematics)."""

    def __init__(self, l1: float, l2: float, body_radii: torch.Tensor):
        self.l1, self.l2, self.body_radii = l1, l2, body_radii
        self._forward = planar_arm_forward(l1, l2)

    def __call__(self, q):
        return self._forward(q)

    def jets(self, q, qd):
        def e(t):
            return torch.stack([torch.cos(t), torch.sin(t)], dim=-1)

        def de(t):  # d e / dt
            return torch.stack([-torch.sin(t), torch.cos(t)], dim=-1)

        t1, t12 = q[:, 0], q[:, 0] + q[:, 1]
        w1, w12 = qd[:, 0], qd[:, 0] + qd[:, 1]
        zero = torch.zeros_like(q[:, :1].expand(-1, 2))
        elbow, J_elbow = self.l1 * e(t1), torch.stack([self.l1 * de(t1), zero], dim=-1)
        a_elbow = -self.l1 * e(t1) * w1[:, None] ** 2
        J_tip = self.l2 * de(t12)[..., None].expand(-1, -1, 2)
        ee, J_ee = elbow + self.l2 * e(t12), J_elbow + J_tip
        a_ee = a_elbow - self.l2 * e(t12) * w12[:, None] ** 2
        vel = lambda J: torch.einsum("ndj,nj->nd", J, qd)  # noqa: E731
        pts = torch.stack([0.5 * elbow, elbow, ee], dim=1)
        Jp = torch.stack([0.5 * J_elbow, J_elbow, J_ee], dim=1)
        ap = torch.stack([0.5 * a_elbow, a_elbow, a_ee], dim=1)
        return (ee, J_ee, vel(J_ee), a_ee), (pts, Jp, torch.einsum("nkdj,nj->nkd", Jp, qd), ap)


def test_closed_form_jets_and_generic_distance_paths():
    data = load("planar_arm")
    idx = slice(0, 64)
    ref = data["qddot"][idx]
    kin = ArmWithJets(*data["arm_lengths"].tolist(), data["body_radii"][idx])
    common = dict(obstacles=data["obst"][idx][:, None, :], weight=data["weight"][idx],
                  lower=data["lower"], upper=data["upper"])
    q, qd, goal = data["q"][idx], data["qdot"][idx], data["goal"][idx]
    fast, _ = fabric_acceleration(q, qd, goal, kin, **common)
    torch.testing.assert_close(fast, ref, rtol=1e-9, atol=1e-9)

    def my_sphere_distance(points, radii, obstacles):  # same map, generic AD path
        diff = points[:, :, None, :] - obstacles[:, None, :, :-1]
        dist = torch.sqrt((diff * diff).sum(-1))
        return dist / (obstacles[:, None, :, -1] + radii[:, :, None]) - 1.0

    generic, _ = fabric_acceleration(q, qd, goal, kin, obstacle_distance=my_sphere_distance, **common)
    torch.testing.assert_close(generic, ref, rtol=1e-9, atol=1e-9)
