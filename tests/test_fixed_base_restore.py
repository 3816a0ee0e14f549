"""A fixed base restored from a state stands where the state has it (``realize.scene.state_rows.
reset_offsets``): a state captured where the base stood off the task's start (an executed world's
``robot_xy`` draw, the localizer's yaw error) puts the hand, and what it holds, back where they
were, in a plain scene and in one whose copies have perturbed worlds of their own. Before, the base
stayed at the scene's own start and a cube held in the captured hand was restored up to 5 cm beside
the fingers (grasp_slip worlds 6, 13 and 14 at seed 0: every row of their restack replans failed
at step 0 with ``place:not_holding``)."""

from __future__ import annotations

import dataclasses
import math

import pytest
import torch

from helpers import compose_config
from realize.spec.run_spec import build_run_spec
from realize.scene import BatchedScene
from realize.tasks.worlds import draw_worlds


@pytest.fixture(scope="module")
def spec():
    s = build_run_spec(compose_config("robot=panda", "experiment=tower3"))
    assert s.robot.base.fixed
    return s


def test_a_state_captured_off_the_start_is_restored_with_the_base_and_hand_where_they_were(spec) -> None:
    g = spec.geometry
    with BatchedScene(3, spec.geometry_cfg, spec.sim, robot=spec.robot) as scene:
        scene.set_worlds(draw_worlds(spec.task.perturbation, g.objects, 3, seed=1))
        scene.reset(seed=0)
        bases = scene.base_pose()[:, :2]
        k = int((bases - torch.tensor(g.robot_start[:2])).norm(dim=1).argmax())
        assert float((bases[k] - torch.tensor(g.robot_start[:2])).norm()) > 0.01  # this copy stands off the start
        state, hand = scene.capture_state(k), scene.ee_pose()[k, :3].clone()
        turned = dataclasses.replace(state, base=(state.base[0], state.base[1], state.base[2] + 0.03))
        for restore in (state, turned):
            scene.reset(seed=0, state=restore)  # the perturbed worlds' own offsets give way to the state's base
            assert torch.allclose(scene.base_pose(), torch.tensor([restore.base] * 3, dtype=torch.float32), atol=1e-5)
        ee_turned = scene.ee_pose()[0, :3]
    with BatchedScene(2, spec.geometry_cfg, spec.sim, robot=spec.robot) as plain:
        plain.reset(seed=0, state=state)
        assert torch.allclose(plain.base_pose(), torch.tensor([state.base] * 2, dtype=torch.float32), atol=1e-5)
        assert torch.allclose(plain.ee_pose()[:, :3], hand.expand(2, 3), atol=1e-4)  # the hand where it was captured
        plain.reset(seed=0)  # without a state: the scene's own start again
        assert torch.allclose(plain.base_pose()[:, :2], torch.tensor([g.robot_start[:2]] * 2, dtype=torch.float32))
    # turned by 0.03 rad about the base's vertical axis, the hand's xy turns with it
    bx, by = state.base[0], state.base[1]
    dx, dy = float(hand[0]) - bx, float(hand[1]) - by
    c, s = math.cos(0.03), math.sin(0.03)
    want = torch.tensor([bx + c * dx - s * dy, by + s * dx + c * dy, float(hand[2])])
    assert torch.allclose(ee_turned, want, atol=1e-4)
