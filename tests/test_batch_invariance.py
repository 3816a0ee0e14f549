"""A plan's whole-body fabric step and its TCP read do not depend on the other plans of the batch.

The fabric runs every control step on the changing subset of plans that asked for it, so its
result for one plan must be a function of that plan's inputs alone, bit for bit. Batched BLAS
products do not guarantee that (MKL on an AMD EPYC gives a row different last bits depending on
the other rows and its position); the fabric and the kinematics are written so that they do.
Checked here on random subsets, in shuffled order, against the full batch, in float32 (the
rollout's dtype) and float64, with torch on one thread as in the rollout and on several.
"""

from __future__ import annotations

import math
import os

import pytest
import torch

from realize.controllers.whole_body import FabricState, WholeBodyFabric
from realize.world.geometry import GeometryCfg, build_geometry
from realize.robot.spec import load_robot_spec

ROBOT = load_robot_spec("fetch_omni")
DOF = ROBOT.n_dof

N = 96


def _subsets(seed: int, count: int = 12) -> list[torch.Tensor]:
    g = torch.Generator().manual_seed(seed)
    sizes = [1, 2, 7, 8, 9, N - 1] + torch.randint(3, N, (count - 6,), generator=g).tolist()
    return [torch.randperm(N, generator=g)[:k] for k in sizes]


def _states(dtype: torch.dtype, seed: int) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Whole-body states in front of table 1 (some arms near it, some far), random speeds, goals."""
    g = torch.Generator().manual_seed(seed)
    q = torch.tensor(ROBOT.rest_q(), dtype=torch.float64).expand(N, -1).clone()
    q = q + 0.3 * torch.randn(N, DOF, generator=g, dtype=torch.float64)
    q[:, 0] = 0.7 + 0.5 * torch.rand(N, generator=g, dtype=torch.float64)
    q[:, 1] = 1.2 + 0.4 * (2 * torch.rand(N, generator=g, dtype=torch.float64) - 1)
    q[:, 2] = math.pi + 0.3 * torch.randn(N, generator=g, dtype=torch.float64)
    qd = 0.4 * torch.randn(N, DOF, generator=g, dtype=torch.float64)
    pos = torch.tensor([0.0, 1.2, 0.82], dtype=torch.float64) + 0.2 * torch.randn(N, 3, generator=g,
                                                                                  dtype=torch.float64)
    return q.to(dtype), qd.to(dtype), pos.to(dtype)


@pytest.fixture(params=[1, "many"], ids=["1-thread", "many-threads"])
def threads(request):
    """torch on one thread, or on several (set here: a CPU scene built earlier in this process
    leaves torch on one thread, so "the default" would be one thread too)."""
    before = torch.get_num_threads()
    torch.set_num_threads(1 if request.param == 1 else min(8, max(2, os.cpu_count() or 2)))
    assert (torch.get_num_threads() > 1) == (request.param != 1)
    yield
    torch.set_num_threads(before)


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_fabric_step_of_a_plan_ignores_its_batch_mates(dtype: torch.dtype, threads) -> None:
    fab = WholeBodyFabric(build_geometry(GeometryCfg()), dt=0.05, dtype=dtype)
    q, qd, pos = _states(dtype, seed=1)
    approach = torch.tensor([0.0, 0.0, -1.0], dtype=dtype).expand(N, 3)
    closing = torch.tensor([0.0, 1.0, 0.0], dtype=dtype).expand(N, 3)
    goal = fab.goal_points(pos, approach, closing)
    q_meas = q.clone()
    q_meas[::5, 4] += 0.2  # some rows re-synchronise from the measurement
    weight = torch.linspace(1.0, 4.0, N, dtype=dtype)
    state = fab.start(q, qd)
    for w in (None, weight):
        full, valid = fab.step(state, q_meas, goal, weight=w)
        assert bool(valid.all())
        for rows in _subsets(seed=2):
            sub = FabricState(state.q[rows], state.qd[rows])
            part, v = fab.step(sub, q_meas[rows], goal[rows], weight=None if w is None else w[rows])
            assert torch.equal(part.q, full.q[rows]) and torch.equal(part.qd, full.qd[rows]), len(rows)
            assert torch.equal(v, valid[rows])


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_tcp_and_axes_of_a_plan_ignore_its_batch_mates(dtype: torch.dtype, threads) -> None:
    fab = WholeBodyFabric(build_geometry(GeometryCfg()), dt=0.05, dtype=dtype)
    q, qd, _ = _states(dtype, seed=3)
    full = fab.kin.tcp_and_axes(q)
    jets = fab.map.jets(q, qd)
    for rows in _subsets(seed=4):
        for a, b in zip(fab.kin.tcp_and_axes(q[rows]), full):
            assert torch.equal(a, b[rows]), len(rows)
        for part, whole in zip(fab.map.jets(q[rows], qd[rows]), jets):
            for a, b in zip(part, whole):
                assert torch.equal(a, b[rows]), len(rows)
