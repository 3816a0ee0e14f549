"""The CUDA path's device placement, checked without a GPU on PyTorch's ``meta`` device.

``meta`` tensors have shapes and dtypes but no values, and every op refuses a tensor of another
device ("Tensor on device cpu is not on the expected device meta!"), as CUDA refuses a CPU
tensor. So the whole-body fabric (``realize.controllers.whole_body``) and the rollout context's
fabric bookkeeping (``realize.realization.context``) are built and stepped on ``meta`` here: a
constant made on the CPU and combined with a device tensor fails these tests with the device
mix named. On the CPU the constants built there (each point's last moving dof, the gripper points) are checked
against a search of the masks and the robot's TCP offsets.
What it doesn't: check values on a device (``scripts/gpu_check.py`` does that on CUDA).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import pytest
import torch

DOF = 11  # the default robot's whole-body joints (fetch_omni: base 3 + torso + 7 arm)
from realize.controllers.whole_body import WholeBodyFabric
from realize.world.geometry import GeometryCfg, RampCfg, build_geometry
from realize.realization.config import RolloutConfig
from realize.realization.context import StepContext

META = torch.device("meta")
N = 5


def _on_meta(what: str, fn: Callable[[], Any]) -> Any:
    """Run ``fn``; a device mix becomes a test failure that names it (and ``what`` did it)."""
    try:
        return fn()
    except (RuntimeError, NotImplementedError) as e:
        pytest.fail(f"{what} on the meta device: {type(e).__name__}: {e}", pytrace=True)


@pytest.fixture(scope="module")
def geometry():
    return build_geometry(GeometryCfg(variant="ramp", ramps=[RampCfg()]))  # tables, the ramp (a pitched box) and the floor


def _meta_fabric(geometry) -> WholeBodyFabric:
    return _on_meta("building WholeBodyFabric", lambda: WholeBodyFabric(geometry, device=META))


def test_whole_body_fabric_builds_and_steps_on_meta(geometry) -> None:
    fab = _meta_fabric(geometry)
    q = torch.zeros(N, DOF, dtype=torch.float64, device=META)
    axis = torch.zeros(N, 3, dtype=torch.float64, device=META)
    goal = fab.goal_points(axis, axis, axis)
    new, valid = _on_meta("WholeBodyFabric.step", lambda: fab.step(fab.start(q, q), q, goal))
    assert new.q.device == META and new.qd.device == META and valid.device == META
    assert new.q.shape == (N, DOF) and valid.shape == (N,) and valid.dtype == torch.bool
    assert _on_meta("pose_points", lambda: fab.pose_points(q)).shape == (N, 9)


class _MetaScene:
    """What ``StepContext`` reads from a ``BatchedScene``, as meta tensors of the scene's shapes."""

    n_envs, device, control_dt = N, META, 0.05

    def whole_body_q(self) -> torch.Tensor:
        return torch.zeros(N, DOF, device=META)

    whole_body_qd = whole_body_q

    def object_poses(self) -> torch.Tensor:  # one object (the seed scene's cube)
        return torch.zeros(N, 1, 7, device=META)

    def object_velocities(self) -> torch.Tensor:
        return torch.zeros(N, 1, 6, device=META)


def test_rollout_context_fabric_bookkeeping_on_meta(geometry) -> None:
    fab = _meta_fabric(geometry)
    occupancy = torch.zeros(4, 4, dtype=torch.bool, device=META)
    ctx = _on_meta("building StepContext", lambda: StepContext(_MetaScene(), RolloutConfig(), fab, None, occupancy))
    rows = torch.tensor([0, 2, 3], device=META)
    goal = torch.zeros(3, 3, device=META)

    def one_step() -> None:
        ctx.read()
        ctx.begin_step()
        ctx.start_fabric(rows)
        ctx.fabric_goal(rows, goal, goal, goal)
        ctx.run_fabric()

    _on_meta("StepContext start_fabric/run_fabric", one_step)
    assert ctx.fab_state.q.device == META and ctx.base_cmd.device == META and ctx.fab_invalid.device == META


def _last_moving_dof(mask: torch.Tensor) -> torch.Tensor:
    """Per point, the highest dof index whose mask entry is set (-1: none): by search, not by count."""
    idx = torch.arange(mask.shape[-1]).expand_as(mask)
    return torch.where(mask > 0.5, idx, torch.full_like(idx, -1)).amax(-1)


def test_prefix_ends_built_on_the_cpu_are_each_points_last_moving_dof() -> None:
    fab = WholeBodyFabric(build_geometry(GeometryCfg()), dtype=torch.float64)
    n_dof = fab.kin._jets_mask.shape[-1]
    for ends, mask in ((fab.kin._jets_ends, fab.kin._jets_mask), (fab.map._ends, fab.map._mask)):
        assert ends.device.type == "cpu" and ends.dtype == torch.long
        assert torch.equal(ends, _last_moving_dof(mask))
    # the gripper hangs at the end of the one serial chain: every dof moves it, the last one last
    assert int(fab.kin._jets_ends[0]) == n_dof - 1 and torch.equal(fab.map._ends[:3], torch.full((3,), n_dof - 1))
    assert int(fab.kin._jets_ends.min()) < n_dof - 1  # and some sphere (the base's) is not moved by the arm
    # the three attracted gripper points: the TCP, one behind it, one beside it
    L = fab.cfg.axis_length
    expected = fab.kin.tcp_offset + torch.tensor([[0.0, 0.0, 0.0], [-L, 0.0, 0.0], [0.0, L, 0.0]], dtype=torch.float64)
    assert torch.equal(fab.map._offsets, expected)


class _MetaSceneWithGeometry(_MetaScene):
    """``_MetaScene`` with the geometry whose one movable object (the cube) ``avoid_movable`` reads."""

    def __init__(self, geometry) -> None:
        self.geometry = geometry


def test_rollout_context_fabric_with_movable_objects_on_meta(geometry) -> None:
    """``controller.avoid_movable``: the movable boxes, the rows' left-out objects and the held
    object's sphere are built and stepped on the device too."""
    fab = _meta_fabric(geometry)
    occupancy = torch.zeros(4, 4, dtype=torch.bool, device=META)
    cfg = RolloutConfig(avoid_movable=True)
    ctx = _on_meta("building StepContext", lambda: StepContext(_MetaSceneWithGeometry(geometry), cfg, fab, None, occupancy))
    rows = torch.tensor([0, 2, 3], device=META)
    goal = torch.zeros(3, 3, device=META)
    ignore = torch.zeros(3, 1, dtype=torch.bool, device=META)
    held = torch.zeros(3, dtype=torch.long, device=META)

    def one_step() -> None:
        ctx.read()
        ctx.begin_step()
        ctx.start_fabric(rows)
        ctx.fabric_goal(rows[:2], goal[:2], goal[:2], goal[:2], ignore[:2], held[:2])
        ctx.fabric_goal(rows[2:], goal[2:], goal[2:], goal[2:])
        ctx.run_fabric()

    _on_meta("StepContext run_fabric with avoid_movable", one_step)
    assert ctx.fab_state.q.device == META and ctx.base_cmd.device == META
