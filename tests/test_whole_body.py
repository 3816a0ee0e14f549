"""Tests of realize.controllers.whole_body: the box-distance leaves' closed-form jets, gradients
through the whole-body fabric, batched vs per-sample stepping, and bad input.

Everything runs in float64 on the CPU, with the ramp scene (a yawed and pitched box beside the
two tables and the floor), so every branch of the box distance is exercised.
"""

from __future__ import annotations

import math

import pytest
import torch

from realize.config import ConfigError
from realize.controllers.fabric_jets import distance_jets
from realize.controllers.fabrics import fabric_acceleration
from realize.controllers.obstacles import BoxDistance
from realize.controllers.whole_body import FabricState, WholeBodyConfig, WholeBodyFabric
from realize.world.geometry import GeometryCfg, RampCfg, build_geometry
from realize.realization.config import RolloutConfig
from realize.robot.spec import load_robot_spec

ROBOT = load_robot_spec("fetch_omni")
DOF = ROBOT.n_dof

F64 = torch.float64


@pytest.fixture(scope="module")
def wb() -> WholeBodyFabric:
    return WholeBodyFabric(build_geometry(GeometryCfg(variant="ramp", ramps=[RampCfg()])), dt=0.05, dtype=F64)


def _rotation(yaw: torch.Tensor, pitch: torch.Tensor) -> torch.Tensor:
    """(..., 3, 3) box frame -> world: Rz(yaw) @ Ry(pitch), the convention of ``boxes_tensor``."""
    cy, sy, cp, sp = torch.cos(yaw), torch.sin(yaw), torch.cos(pitch), torch.sin(pitch)
    z, o = torch.zeros_like(yaw), torch.ones_like(yaw)
    rz = torch.stack([torch.stack([cy, -sy, z], -1), torch.stack([sy, cy, z], -1), torch.stack([z, z, o], -1)], -2)
    ry = torch.stack([torch.stack([cp, z, sp], -1), torch.stack([z, o, z], -1), torch.stack([-sp, z, cp], -1)], -2)
    return rz @ ry


def _near_box_points(boxes: torch.Tensor, n: int, k: int, g: torch.Generator) -> torch.Tensor:
    """(n, k, 3) points inside and around randomly chosen (non-floor) boxes of ``boxes`` (M, 9)."""
    solid = torch.nonzero(boxes[:, 8] < 0.5).flatten()
    pick = solid[torch.randint(len(solid), (n, k), generator=g)]
    b = boxes[pick]  # (n, k, 9)
    span = b[..., 3:6] + 0.15  # up to 15 cm outside every face
    local = (2.0 * torch.rand(n, k, 3, generator=g, dtype=F64) - 1.0) * span
    rot = _rotation(b[..., 6], b[..., 7])
    return b[..., :3] + (rot @ local[..., None]).squeeze(-1)


def _rest_q(n: int) -> torch.Tensor:
    return torch.tensor(ROBOT.rest_q(), dtype=F64).expand(n, -1).clone()


def _states_near_table1(n: int, seed: int) -> tuple[torch.Tensor, torch.Tensor]:
    """Configurations beside table 1 (its +x side, facing it) with random arm poses and speeds."""
    g = torch.Generator().manual_seed(seed)
    q = _rest_q(n) + 0.15 * torch.randn(n, DOF, generator=g, dtype=F64)
    q[:, 0] = 0.95 + 0.1 * torch.rand(n, generator=g, dtype=F64)
    q[:, 1] = 1.2 + 0.3 * (2 * torch.rand(n, generator=g, dtype=F64) - 1)
    q[:, 2] = math.pi + 0.3 * (2 * torch.rand(n, generator=g, dtype=F64) - 1)
    q[:, 3] = 0.1 + 0.2 * torch.rand(n, generator=g, dtype=F64)  # torso well inside its limits
    qd = 0.4 * torch.randn(n, DOF, generator=g, dtype=F64)  # non-zero: away from the sign() switches
    return q, qd


def _goals(wb: WholeBodyFabric, n: int, seed: int) -> torch.Tensor:
    """(n, 9) pose goals over table 1: TCP 6-11 cm above the top, approach near top-down."""
    g = torch.Generator().manual_seed(seed)
    pos = torch.tensor([0.0, 1.2, 0.78], dtype=F64) + torch.cat(
        [0.15 * (2 * torch.rand(n, 2, generator=g, dtype=F64) - 1), 0.05 * torch.rand(n, 1, generator=g, dtype=F64)],
        dim=1)
    tilt = 0.4 * torch.rand(n, generator=g, dtype=F64)
    phi = 2 * math.pi * torch.rand(n, generator=g, dtype=F64)
    closing = torch.stack([torch.cos(phi), torch.sin(phi), torch.zeros_like(phi)], dim=1)
    side = torch.stack([-torch.sin(phi), torch.cos(phi), torch.zeros_like(phi)], dim=1)  # z x closing
    down = torch.tensor([0.0, 0.0, -1.0], dtype=F64)
    approach = torch.cos(tilt)[:, None] * down + torch.sin(tilt)[:, None] * side
    return wb.goal_points(pos, approach, closing)


# ----------------------------------------------------------------------------- (a) leaf jets


def test_box_jets_equal_forward_ad_of_the_distance(wb: WholeBodyFabric) -> None:
    """Closed-form ``BoxDistance.jets`` == forward-mode AD of ``BoxDistance.__call__``."""
    g = torch.Generator().manual_seed(0)
    extra = torch.tensor([[0.3, -0.4, 0.6, 0.25, 0.15, 0.1, 0.7, -0.5, 0.0]], dtype=F64)  # arbitrary yaw + pitch
    boxes = torch.cat([wb.boxes, extra], dim=0)
    assert bool(((boxes[:, 6] != 0) & (boxes[:, 7] != 0) & (boxes[:, 8] < 0.5)).any()), "need a yawed+pitched box"
    N, K, n = 16, wb.map.body_radii.shape[0], DOF
    M = boxes.shape[0]
    p = _near_box_points(boxes, N, K, g)
    p[:, :3, 2] = 0.02 * torch.rand(N, 3, generator=g, dtype=F64) - 0.01  # a few near / under the floor
    Jp = torch.randn(N, K, 3, n, generator=g, dtype=F64)
    pd = torch.randn(N, K, 3, generator=g, dtype=F64)
    ap = torch.randn(N, K, 3, generator=g, dtype=F64)
    radii = wb.map.body_radii.expand(N, K)
    bx = boxes.expand(N, -1, -1)

    closed = wb.distance.jets(p, Jp, pd, ap, radii, bx)
    ad = distance_jets(wb.distance, p, Jp, pd, ap, radii, bx, vectorize=True)
    for name, a, b in zip(("value", "J", "velocity", "curvature"), closed, ad):
        assert a.shape == b.shape, name
    val_c, val_ad = closed[0], ad[0]

    # both sides of the surface, and masked (far) pairs, are covered
    inside = (val_ad < -1.0).reshape(N, K, M)
    masked = val_ad == BoxDistance.FAR
    assert int(inside.sum()) > 20 and int((~inside & ~masked.reshape(N, K, M)).sum()) > 200
    assert bool(masked.any())

    for name, a, b in zip(("J", "velocity", "curvature"), closed[1:], ad[1:]):
        torch.testing.assert_close(a, b, rtol=1e-10, atol=1e-10, msg=name)
    outside = ~inside.flatten(1)
    torch.testing.assert_close(val_c[outside], val_ad[outside], rtol=1e-12, atol=1e-12)
    # inside a box, __call__ adds the sqrt(1e-12) regulariser of its outside term to the value
    # (the jets do not); it is the only difference, below 1e-6 / radius
    off = (val_ad - val_c)[~outside]
    bound = (1e-6 / radii[:, :, None].expand(N, K, M).flatten(1)[~outside]) * (1 + 1e-6)
    assert bool((off.abs() <= bound).all()), float(off.abs().max())


def test_box_distance_signs_on_known_points(wb: WholeBodyFabric) -> None:
    """Gap to table 1 in sphere radii: 0.1 m above the top, 0.05 m inside it."""
    box_ok = torch.ones(1, dtype=torch.bool)
    dist = BoxDistance(box_ok, box_ok)
    table1 = wb.boxes[:1][None]  # (1, 1, 9)
    r = torch.full((1, 1), 0.1, dtype=F64)
    above = dist(torch.tensor([[[0.0, 1.2, 0.82]]], dtype=F64), r, table1)
    inside = dist(torch.tensor([[[0.0, 1.2, 0.67]]], dtype=F64), r, table1)
    assert float(above) == pytest.approx(0.1 / 0.1 - 1.0, abs=1e-9)
    assert float(inside) == pytest.approx(-0.05 / 0.1 - 1.0, abs=1e-4)


# ----------------------------------------------------------------------------- (b) gradients


def _gradcheck_fabric(wb: WholeBodyFabric, lower: torch.Tensor, upper: torch.Tensor) -> bool:
    N = 2
    q, qd = _states_near_table1(N, seed=3)
    goal = _goals(wb, N, seed=4)
    boxes = wb.boxes.expand(N, -1, -1)
    # the state is near the obstacles: the collision leaves carry force
    (_, sph) = wb.map.jets(q, qd)
    gap = wb.distance(sph[0], wb.map.body_radii.expand(N, -1), boxes)
    assert float(gap.min()) < 3.0

    def acc(q: torch.Tensor, goal: torch.Tensor) -> torch.Tensor:
        qdd, valid = fabric_acceleration(q, qd, goal, wb.map, wb.fabric_cfg, obstacles=boxes,
                                         lower=lower, upper=upper, obstacle_distance=wb.distance)
        assert bool(valid.all())
        return qdd

    return torch.autograd.gradcheck(acc, (q.clone().requires_grad_(True), goal.clone().requires_grad_(True)),
                                    eps=1e-6, atol=1e-5, rtol=1e-4)


def test_gradcheck_fetch_fabric_q_and_goal(wb: WholeBodyFabric) -> None:
    """gradcheck through the fabric acceleration with Fetch's pose map, box leaves (tables, a
    yawed+pitched ramp, floor) and the real joint limits (+-inf for yaw and the rolls),
    w.r.t. q and the goal."""
    assert _gradcheck_fabric(wb, wb.lower, wb.upper)


def test_gradients_through_step_are_finite(wb: WholeBodyFabric) -> None:
    """Backward through ``WholeBodyFabric.step`` itself (limits as it passes them, +-inf for
    the continuous joints): gradients w.r.t. the reference state and the goal are finite."""
    q, qd = _states_near_table1(3, seed=3)
    q.requires_grad_(True)
    goal = _goals(wb, 3, seed=4).requires_grad_(True)
    new, valid = wb.step(FabricState(q, qd), q.detach(), goal)
    assert bool(valid.all())
    (new.q.sum() + new.qd.sum()).backward()
    assert bool(torch.isfinite(q.grad).all()) and bool(torch.isfinite(goal.grad).all())


# ----------------------------------------------------------------------------- (c) batching


def test_step_batched_equals_per_sample(wb: WholeBodyFabric) -> None:
    N = 8
    q, qd = _states_near_table1(N, seed=5)
    goal = _goals(wb, N, seed=6)
    g = torch.Generator().manual_seed(7)
    q_meas = q + 0.01 * torch.randn(N, DOF, generator=g, dtype=F64)
    q_meas[2, 5] += 0.2  # beyond resync_tolerance: this row restarts from the measurement
    state = wb.start(q, qd)
    weight = torch.linspace(1.0, 4.0, N, dtype=F64)
    for w in (None, weight):
        new, valid = wb.step(state, q_meas, goal, weight=w)
        assert bool(valid.all())
        for i in range(N):
            st_i = FabricState(state.q[i:i + 1], state.qd[i:i + 1])
            one, v1 = wb.step(st_i, q_meas[i:i + 1], goal[i:i + 1], weight=None if w is None else w[i:i + 1])
            assert bool(v1.all())
            torch.testing.assert_close(new.q[i:i + 1], one.q, rtol=1e-12, atol=1e-12)
            torch.testing.assert_close(new.qd[i:i + 1], one.qd, rtol=1e-12, atol=1e-12)
    # the resynchronised row started from the measured joints at rest
    new, _ = wb.step(state, q_meas, goal)
    expect_q = q_meas[2] + wb.dt * new.qd[2]
    torch.testing.assert_close(new.q[2], torch.maximum(torch.minimum(expect_q, wb._clamp_hi), wb._clamp_lo))


# ----------------------------------------------------------------------------- (d) bad input


def test_nan_goal_row_is_invalid_and_others_unaffected(wb: WholeBodyFabric) -> None:
    N = 5
    q, qd = _states_near_table1(N, seed=10)
    goal = _goals(wb, N, seed=11)
    state = wb.start(q, qd)
    clean, ok = wb.step(state, q, goal)
    assert bool(ok.all())
    bad_goal = goal.clone()
    bad_goal[2, 4] = float("nan")
    new, valid = wb.step(state, q, bad_goal)
    assert valid.tolist() == [True, True, False, True, True]
    keep = valid
    torch.testing.assert_close(new.q[keep], clean.q[keep], rtol=0, atol=0)
    torch.testing.assert_close(new.qd[keep], clean.qd[keep], rtol=0, atol=0)
    # the invalid row holds the measured configuration at rest, nothing non-finite escapes
    torch.testing.assert_close(new.q[2], q[2], rtol=0, atol=0)
    assert bool((new.qd[2] == 0).all())
    assert bool(torch.isfinite(new.q).all() and torch.isfinite(new.qd).all())


@pytest.mark.parametrize("gamma", [0.0, -1.0, float("nan")])
def test_non_positive_gain_names_the_key(gamma: float) -> None:
    geometry = build_geometry(GeometryCfg())
    with pytest.raises(ValueError, match=r"controller\.fabric\.gamma"):
        WholeBodyFabric(geometry, WholeBodyConfig(gamma=gamma))
    with pytest.raises(ConfigError, match=r"controller\.fabric\.gamma"):
        WholeBodyConfig.from_mapping({"gamma": gamma})
    with pytest.raises(ValueError, match=r"controller\.fabric\.gamma"):
        RolloutConfig.from_mapping({"fabric": {"gamma": gamma}})


def test_unknown_fabric_keys_are_named() -> None:
    with pytest.raises(ConfigError, match="gama"):
        WholeBodyConfig.from_mapping({"gama": 1.0})
    with pytest.raises(ConfigError, match="collision_exclude"):
        WholeBodyFabric(build_geometry(GeometryCfg()), WholeBodyConfig(collision_exclude=("no_such_sphere",)))
