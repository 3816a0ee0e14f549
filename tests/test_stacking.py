"""Stacking in the simulator (``experiment=stack_two``: cube B from table 1 onto cube A on
table 2), with hand-chosen parameters: the robot parks in front of each table, grasps cube B
top-down and puts it 5 cm above cube A's centre. Physical facts checked on the state the
simulator ends in: cube B rests on cube A's top, upright within 5 degrees, centred within 1 cm,
both settled, and the rollout's goal (``rests_on: {cube_b: cube_a}``) holds. The same with
cube A started 2 cm off its configured place: the place region follows cube A (it is framed
by it) and so does the goal."""

from __future__ import annotations

import math

import pytest
import torch

from helpers import compose_config
from realize.spec.run_spec import build_run_spec
from realize.realization.rollout import PlanRealizer
from realize.scene import BatchedScene
from realize.world.state import ObjectPose, SceneState

UP = 0.15  # m: the pre-poses straight above the grasp and place points


def _plan(spec, a_shift: tuple[float, float]) -> torch.Tensor:
    """The hand-chosen parameters (task columns): the place point is written in cube A's
    configured frame (the rollout moves it to where cube A is seen); the base parks in front of
    where cube A stands (``a_shift`` off its configured place)."""
    g = spec.geometry
    ax, ay, az = g.object("cube_a").position
    bx, by, bz = g.object("cube_b").position
    z = {"Table1": (-0.85, by), "CubeB_g": (bx, by, bz + UP), "Table2": (-0.85, ay + a_shift[1]),
         "CubeB_on_a": (ax, ay, az + 0.05 + UP), "Exit": (2.2, 0.0)}  # regions framed by cube A: config frame
    return torch.tensor([[v for name in spec.task.layout.names for v in z[name]]])


def _tilt_deg(wxyz: torch.Tensor) -> float:
    """The angle between an object's up axis and the world's (degrees)."""
    w, x, y, _ = (float(v) for v in wxyz)
    up_z = 1.0 - 2.0 * (x * x + y * y)
    return math.degrees(math.acos(max(-1.0, min(1.0, up_z))))


@pytest.mark.parametrize("a_shift", [(0.0, 0.0), (0.02, 0.0)], ids=["as configured", "cube A 2 cm off"])
def test_cube_b_ends_square_on_cube_a(a_shift: tuple[float, float]) -> None:
    spec = build_run_spec(compose_config("experiment=stack_two"))
    g = spec.geometry
    ia, ib = g.object_index("cube_a"), g.object_index("cube_b")
    configured = g.object("cube_a").position
    start = SceneState(base=g.robot_start, objects={"cube_a": ObjectPose(
        (configured[0] + a_shift[0], configured[1] + a_shift[1], configured[2]))})
    with BatchedScene(1, spec.geometry_cfg, spec.sim) as scene:
        realizer = PlanRealizer(spec.task, scene, spec.rollout, seed=spec.seed, start=start)
        res = realizer.rollout(_plan(spec, a_shift))
        poses, speeds = scene.object_poses(), scene.object_velocities()[:, :, :3].norm(dim=2)
    a, b = poses[0, ia], poses[0, ib]
    assert bool(res.feasible[0]) and bool(res.goal[0]), res.failure
    assert math.dist(a[:2].tolist(), b[:2].tolist()) <= 0.01                       # centred within 1 cm
    assert abs(float(b[2] - a[2]) - 0.045) <= 0.003                                 # on its top face
    assert _tilt_deg(b[3:]) <= 5.0 and _tilt_deg(a[3:]) <= 5.0                      # both upright
    assert float(speeds[0, ia]) <= 0.01 and float(speeds[0, ib]) <= 0.01            # settled
    assert math.dist(a[:2].tolist(), (configured[0] + a_shift[0], configured[1] + a_shift[1])) <= 0.005  # not pushed


# make test stacks with the mobile robot, and the fixed-base Panda places cube C on its tower in
# tests/test_level_place.py; the Panda's whole tower here and at scene=tabletop (14 and 19 s on a busy
# 2-core host) in make test-slow
@pytest.mark.parametrize("overrides", ["experiment=tower3",
                                       pytest.param("robot=panda experiment=tower3", marks=pytest.mark.slow),
                                       pytest.param("experiment=tower3_tabletop", marks=pytest.mark.slow)])
def test_three_blocks_end_in_a_tower(overrides: str) -> None:
    """``experiment=tower3`` for the mobile robot parked at table 1, and for the fixed-base Panda
    bolted at the table's edge (the scene's ``fixed_base_start``), and for the Panda at
    ``scene=tabletop`` (``experiment=tower3_tabletop``), the plan from the blocks domain,
    hand-chosen top-down grasps and places: cube C ends on cube B on cube A, each centred within
    1 cm and upright within 5 degrees, all settled. Cube C's place region is framed by cube B, so
    it is read where cube B stands once stacked, not where cube B started. A fixed base ends
    where it started."""
    spec = build_run_spec(compose_config(*overrides.split()))
    g = spec.geometry
    assert spec.task.describe() == ("grasp(cube_b, CubeB_g), place(cube_b, CubeB_on_a), grasp(cube_c, CubeC_g), "
                                    "place(cube_c, CubeC_on_b)")
    pos = {n: g.object(n).position for n in ("cube_a", "cube_b", "cube_c")}
    z = {"CubeB_g": (pos["cube_b"][0], pos["cube_b"][1], pos["cube_b"][2] + UP),
         "CubeB_on_a": (pos["cube_a"][0], pos["cube_a"][1], pos["cube_a"][2] + 0.05 + UP),
         "CubeC_g": (pos["cube_c"][0], pos["cube_c"][1], pos["cube_c"][2] + UP),
         "CubeC_on_b": (pos["cube_b"][0], pos["cube_b"][1], pos["cube_b"][2] + 0.05 + UP)}  # cube B's config frame
    Z = torch.tensor([[v for name in spec.task.layout.names for v in z[name]]])
    with BatchedScene(1, spec.geometry_cfg, spec.sim, robot=spec.robot) as scene:
        res = PlanRealizer(spec.task, scene, spec.rollout, seed=spec.seed).rollout(Z)
        poses, speeds = scene.object_poses()[0], scene.object_velocities()[0, :, :3].norm(dim=1)
        base, root = scene.base_pose()[0], scene.u.agents[0].robot.pose.p[0]
    if spec.robot.base.fixed:
        assert torch.allclose(base, torch.tensor(g.robot_start, dtype=base.dtype), atol=1e-6)
        assert torch.allclose(root, torch.tensor([*g.robot_start[:2], spec.robot.base.height]), atol=1e-6)
    a, b, c = (poses[g.object_index(n)] for n in ("cube_a", "cube_b", "cube_c"))
    assert bool(res.feasible[0]) and bool(res.goal[0]), res.failure
    for lower, upper in ((a, b), (b, c)):
        assert math.dist(lower[:2].tolist(), upper[:2].tolist()) <= 0.01
        assert abs(float(upper[2] - lower[2]) - 0.045) <= 0.003
    assert all(_tilt_deg(p[3:]) <= 5.0 for p in (a, b, c)) and float(speeds.max()) <= 0.01


def _yaw_off_square_deg(lower: torch.Tensor, upper: torch.Tensor) -> float:
    """How far two upright boxes' yaws are from square to each other (0..45 degrees)."""
    def yaw(wxyz: torch.Tensor) -> float:
        w, x, y, z = (float(v) for v in wxyz)
        return math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))
    d = math.degrees(yaw(upper) - yaw(lower)) % 90.0
    return min(d, 90.0 - d)


@pytest.mark.parametrize("align", [False, True], ids=["as held", "place_align_yaw"])
def test_a_placed_box_lands_square_on_a_turned_support(align: bool) -> None:
    """stack_two with cube A turned 30 degrees on table 2 and cube B grasped square to the
    world: placed as held, cube B sits about 30 degrees off square on cube A; with
    ``controller.place_align_yaw`` the hand turns it about the approach and it lands within 5
    degrees of square, centred within 1 cm, settled, both upright."""
    spec = build_run_spec(compose_config("experiment=stack_two", f"controller.place_align_yaw={align}"))
    g = spec.geometry
    ia, ib = g.object_index("cube_a"), g.object_index("cube_b")
    turn = math.radians(30.0)
    start = SceneState(base=g.robot_start, objects={"cube_a": ObjectPose(
        g.object("cube_a").position, (math.cos(turn / 2), 0.0, 0.0, math.sin(turn / 2)))})
    with BatchedScene(1, spec.geometry_cfg, spec.sim) as scene:
        res = PlanRealizer(spec.task, scene, spec.rollout, seed=spec.seed, start=start).rollout(_plan(spec, (0.0, 0.0)))
        poses, speeds = scene.object_poses()[0], scene.object_velocities()[0, :, :3].norm(dim=1)
    a, b = poses[ia], poses[ib]
    assert bool(res.feasible[0]) and bool(res.goal[0]), res.failure
    off = _yaw_off_square_deg(a[3:], b[3:])
    if align:
        assert off <= 5.0, off
    else:
        assert off >= 20.0, off  # the lever is what squares it
    assert math.dist(a[:2].tolist(), b[:2].tolist()) <= 0.01
    assert _tilt_deg(a[3:]) <= 5.0 and _tilt_deg(b[3:]) <= 5.0 and float(speeds.max()) <= 0.01
