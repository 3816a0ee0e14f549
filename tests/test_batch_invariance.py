"""A plan's whole-body fabric step and its TCP read do not depend on the other plans of the batch.

The fabric runs every control step on the changing subset of plans that asked for it, so its
result for one plan must be a function of that plan's inputs alone, bit for bit. Batched BLAS
products do not guarantee that (MKL on an AMD EPYC gives a row different last bits depending on
the other rows and its position); the fabric and the kinematics are written so that they do.
Checked here on random subsets, in shuffled order, against the full batch, in float32 (the
rollout's dtype) and float64, with torch on one thread as in the rollout and on several.
"""

from __future__ import annotations

import os

import pytest
import torch

from realize.controllers.whole_body import FabricState, WholeBodyFabric
from realize.world.geometry import GeometryCfg, build_geometry
from realize.robot.spec import load_robot_spec
from helpers import FABRIC_ROWS, fabric_states, row_subsets

ROBOT = load_robot_spec("fetch_omni")

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
    q, qd, pos = fabric_states(ROBOT, dtype, seed=1)
    approach = torch.tensor([0.0, 0.0, -1.0], dtype=dtype).expand(FABRIC_ROWS, 3)
    closing = torch.tensor([0.0, 1.0, 0.0], dtype=dtype).expand(FABRIC_ROWS, 3)
    goal = fab.goal_points(pos, approach, closing)
    q_meas = q.clone()
    q_meas[::5, 4] += 0.2  # some rows re-synchronise from the measurement
    weight = torch.linspace(1.0, 4.0, FABRIC_ROWS, dtype=dtype)
    state = fab.start(q, qd)
    for w in (None, weight):
        full, valid = fab.step(state, q_meas, goal, weight=w)
        assert bool(valid.all())
        for rows in row_subsets(seed=2):
            sub = FabricState(state.q[rows], state.qd[rows])
            part, v = fab.step(sub, q_meas[rows], goal[rows], weight=None if w is None else w[rows])
            assert torch.equal(part.q, full.q[rows]) and torch.equal(part.qd, full.qd[rows]), len(rows)
            assert torch.equal(v, valid[rows])


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_tcp_and_axes_of_a_plan_ignore_its_batch_mates(dtype: torch.dtype, threads) -> None:
    fab = WholeBodyFabric(build_geometry(GeometryCfg()), dt=0.05, dtype=dtype)
    q, qd, _ = fabric_states(ROBOT, dtype, seed=3)
    full = fab.kin.tcp_and_axes(q)
    jets = fab.map.jets(q, qd)
    for rows in row_subsets(seed=4):
        for a, b in zip(fab.kin.tcp_and_axes(q[rows]), full):
            assert torch.equal(a, b[rows]), len(rows)
        for part, whole in zip(fab.map.jets(q[rows], qd[rows]), jets):
            for a, b in zip(part, whole):
                assert torch.equal(a, b[rows]), len(rows)
