"""A held box set down level (``controller.place_level``, ``realize.realization.actions.level``).

Physical facts, with the fixed-base Panda at ``experiment=tower3``, cube B already on cube A,
and hand-chosen parameters: cube C grasped 0.7 rad off vertical from the +y side and placed on
cube B down a 0.35 rad approach from the -x side. As held, the hand lets cube C go about 40
degrees askew and it lands on one edge: it knocks cube B off cube A. With ``place_level`` the
hand turns so cube C is let go within 5 degrees of level: it rests on cube B, centred within 1
cm, and cube B has not moved (the contrast as held is marked slow). The geometry of the turn is
checked on its own as well."""

from __future__ import annotations

import math

import pytest
import torch

from helpers import compose_config
from realize.spec.run_spec import build_run_spec
from realize.realization.actions.level import hand_frame, level_turn
from realize.realization.rollout import PlanRealizer
from realize.scene import BatchedScene, quat_to_matrix
from realize.tasks.suffix import task_suffix
from realize.world.state import ObjectPose, SceneState

R = 0.15  # m: the hemispheres' radius (configs/task/tower3.yaml)


def _tilt_deg(wxyz: torch.Tensor) -> float:
    """The angle between a box's axis nearest the vertical and the vertical (degrees)."""
    m = quat_to_matrix(wxyz[None].float())[0]
    return math.degrees(math.acos(min(1.0, float(m[2].abs().max()))))


def test_the_turn_brings_the_box_level_and_keeps_its_offset_rigid() -> None:
    """A box turned 30 degrees about x in a hand that stands still: the turn is 30 degrees, the
    box's axis turns vertical with the hand, and its offset from the TCP turns with it."""
    tilt = math.radians(30.0)
    c, s = math.cos(tilt), math.sin(tilt)
    box = torch.tensor([[[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]]])
    down, across = torch.tensor([[0.0, 0.0, -1.0]]), torch.tensor([[1.0, 0.0, 0.0]])
    offset = torch.tensor([[0.0, 0.01, -0.03]])
    a, cl, off, turn = level_turn(box, hand_frame(down, across), down, across, offset, max_turn=1.0)
    assert abs(float(turn[0]) - tilt) < 1e-5
    turned = hand_frame(a, cl) @ hand_frame(down, across).transpose(1, 2)
    assert abs(float((turned @ box)[0, 2].abs().max()) - 1.0) < 1e-5  # one box axis vertical
    assert torch.allclose(off, (turned @ offset[:, :, None]).squeeze(2), atol=1e-6)
    _, _, _, capped = level_turn(box, hand_frame(down, across), down, across, offset, max_turn=0.2)
    assert abs(float(capped[0]) - 0.2) < 1e-6


@pytest.mark.parametrize("level", [pytest.param(None, marks=pytest.mark.slow), 0.8], ids=["as held", "place_level"])
def test_a_box_grasped_askew_lands_level_on_the_tower(level: float | None) -> None:
    over = ["robot=panda", "experiment=tower3"] + ([f"controller.place_level={level}"] if level is not None else [])
    spec = build_run_spec(compose_config(*over))
    g = spec.geometry
    pa, pb, pc = (g.object(n).position for n in ("cube_a", "cube_b", "cube_c"))
    on_a = (pa[0], pa[1], pa[2] + 0.045)
    start = SceneState(base=g.robot_start, objects={"cube_b": ObjectPose(on_a)})
    task = task_suffix(spec.task, 2)  # grasp(cube_c, CubeC_g), place(cube_c, CubeC_on_b)
    g_pol, p_pol = 0.7, 0.35
    z = {"CubeC_g": (pc[0], pc[1] + R * math.sin(g_pol), pc[2] + R * math.cos(g_pol)),
         "CubeC_on_b": (pb[0] - R * math.sin(p_pol), pb[1], pb[2] + 0.05 + R * math.cos(p_pol))}  # cube B's config frame
    Z = torch.tensor([[v for name in task.layout.names for v in z[name]]], dtype=torch.float64)
    held: list[torch.Tensor] = []
    with BatchedScene(1, spec.geometry_cfg, spec.sim, robot=spec.robot) as scene:
        ib, ic = g.object_index("cube_b"), g.object_index("cube_c")
        scene.add_step_hook(lambda _: held.append(scene.object_poses()[0, ic].clone())
                            if bool(scene.holds("cube_c")[0]) else None)
        res = PlanRealizer(task, scene, spec.rollout, seed=spec.seed, start=start).rollout(Z)
        poses, speeds = scene.object_poses()[0], scene.object_velocities()[0, :, :3].norm(dim=1)
    b, c = poses[ib], poses[ic]
    released = _tilt_deg(held[-1][3:])  # cube C the last step the fingers held it
    if level is None:
        assert released >= 30.0, released
        assert not bool(res.goal[0]) and math.dist(b[:3].tolist(), on_a) >= 0.03  # cube B knocked off cube A
        return
    assert released <= 5.0, released
    assert bool(res.feasible[0]) and bool(res.goal[0]), res.failure
    assert math.dist(b[:3].tolist(), on_a) <= 0.005                                # cube B not pushed
    assert math.dist(b[:2].tolist(), c[:2].tolist()) <= 0.01                       # centred on it
    assert abs(float(c[2] - b[2]) - 0.045) <= 0.003 and _tilt_deg(c[3:]) <= 5.0    # flat on its top
    assert float(speeds.max()) <= 0.01


def test_repairs_level_and_avoid_only_in_a_plan_that_stacks() -> None:
    """A repair searches and executes with ``place_level`` and ``avoid_movable`` where the run's
    plan stacks a block on another (``robot=panda experiment=tower3``), not where it places on a
    table (the seed task), nor where the run's own controllers set them already."""
    from realize.repair.on_deviation import stack_changes
    from realize.execution.settings import ExecuteSettings

    st = ExecuteSettings()
    turn, avoid = st.stack_level_rad, st.stack_avoid_movable
    tower = build_run_spec(compose_config("robot=panda", "experiment=tower3"))
    assert turn is not None and avoid
    assert stack_changes(tower, turn, avoid) == [f"++controller.place_level={turn}", "++controller.avoid_movable=true"]
    assert stack_changes(tower, None, avoid) == ["++controller.avoid_movable=true"]  # stack_level_rad: null
    assert stack_changes(tower, turn, False) == [f"++controller.place_level={turn}"]  # stack_avoid_movable: false
    assert stack_changes(build_run_spec(compose_config()), turn, avoid) == []
    own = build_run_spec(compose_config("robot=panda", "experiment=tower3", "controller.place_level=0.5",
                                        "controller.avoid_movable=true"))
    assert stack_changes(own, turn, avoid) == []
