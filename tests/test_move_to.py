"""The base follows A* paths around the tables and the wall (issue 3's must-show), in the
simulated ``wall`` scene on CPU, through the rollout itself (``PlanRealizer`` with move_to-only
plans, trajectories recorded every control step).

Goals are uniform points of the seed task's annuli around table 1 and table 2 where the robot
fits (its footprint disc, the robot spec's ``base.footprint_radius``, clears every table and the wall by 5 cm;
annulus points closer than that, e.g. on the wall, are not places the base can be). Two zones:
``clear`` goals also lie outside A*'s padded obstacles (robot radius + ``controller.astar.padding``),
``padded`` goals lie inside the padding, where A* snaps the goal cell to the nearest free one
and move_to must still finish at the parameter itself. Checked: every move_to succeeds (base
within ``move_tolerance`` of the goal), the recorded base centre never comes closer to a table
or wall footprint than the robot's radius (minus 2 cm of slack for the simulated base's
tracking), and the leg from table 1's side to table 2's side crosses the wall's line only
beyond the wall's ends.
"""

from __future__ import annotations

from typing import Callable

import pytest
import torch

from realize.world.geometry import SceneGeometry
from realize.realization.actions import TEMPLATES
from realize.realization.config import RolloutConfig
from realize.realization.result import RolloutResult
from realize.realization.rollout import PlanRealizer
from realize.tasks.regions import Annulus
from realize.scene import BatchedScene, SimSettings
from realize.tasks.spec import task_from_dict
from realize.robot.spec import DEFAULT_ROBOT, load_robot_spec

TABLE1 = {"type": "annulus", "center": [0.0, 1.2], "r_min": 0.75, "r_max": 1.25}  # the seed task's
TABLE2 = {"type": "annulus", "center": [0.0, -1.2], "r_min": 0.75, "r_max": 1.25}
FIT_MARGIN = 0.05  # m: goals where the robot's disc clears every footprint by this much
TRACK_SLACK = 0.02  # m: the simulated base may cut a corner of the A* path by this much
FOOTPRINT = load_robot_spec(DEFAULT_ROBOT).base.footprint_radius  # m: the robot's disc (wall_scene: the default robot)
WIDE = dict(bounds_low=(-3.0, -3.0), bounds_high=(3.2, 3.0))  # the world bounds of these tests (wall_scene)
N_PLANS = 12



def footprint_clearance(xy: torch.Tensor, geometry: SceneGeometry) -> torch.Tensor:
    """(..., B) distance (m) from floor points xy (..., 2) to every obstacle footprint
    (rectangles in their yawed frames); 0 inside."""
    boxes = geometry.obstacles
    c = torch.tensor([b.center[:2] for b in boxes], dtype=xy.dtype)
    h = torch.tensor([b.footprint_half_size() for b in boxes], dtype=xy.dtype)
    yaw = torch.tensor([b.yaw for b in boxes], dtype=xy.dtype)
    d = xy[..., None, :] - c
    cy, sy = torch.cos(yaw), torch.sin(yaw)
    local = torch.stack([cy * d[..., 0] + sy * d[..., 1], -sy * d[..., 0] + cy * d[..., 1]], dim=-1)
    return (local.abs() - h).clamp(min=0.0).norm(dim=-1)


def sample_goals(spec: dict, n: int, geometry: SceneGeometry, zone: str, g: torch.Generator,
                 keep: Callable[[torch.Tensor], torch.Tensor] | None = None) -> torch.Tensor:
    """n uniform points of the annulus ``spec`` where the robot fits, in ``zone`` ("clear" of
    A*'s padding or inside the "padded" band), and where ``keep`` holds; by rejection."""
    region = Annulus(spec["center"], spec["r_min"], spec["r_max"])
    astar = RolloutConfig().astar
    fit = FOOTPRINT + FIT_MARGIN
    pad = FOOTPRINT + astar.padding + astar.resolution  # beyond every padded cell
    out = torch.empty(0, 2)
    for _ in range(100):
        xy = region.sample_uniform(8 * n, g, torch.float32)
        clear = footprint_clearance(xy, geometry).min(dim=-1).values
        ok = (clear >= pad) if zone == "clear" else (clear >= fit) & (clear < pad - 2 * astar.resolution)
        if keep is not None:
            ok &= keep(xy)
        out = torch.cat([out, xy[ok]])
        if len(out) >= n:
            return out[:n]
    raise AssertionError(f"too few {zone} goals in {spec}")


@pytest.fixture(scope="module")
def wall_scene():
    # wider than configs/scene/ (y +-2.5): with 1 m between a table and the world's edge, the
    # padded grid has no way behind the tables, and these tests drive there
    scene = BatchedScene(N_PLANS, geometry=dict(variant="wall", walls=[{}], **WIDE), sim=SimSettings(backend="cpu"))
    yield scene
    scene.close()


def _realize(scene: BatchedScene, params: dict, plan: list[str], Z: torch.Tensor) -> RolloutResult:
    task = task_from_dict({"name": "move_only", "params": params, "plan": plan, "goal": {}},
                          scene.geometry, TEMPLATES, source="test_move_to")
    realizer = PlanRealizer(task, scene, RolloutConfig(record_every=1), seed=0)
    return realizer.rollout(Z, record=True)


def _check_paths(res: RolloutResult, geometry: SceneGeometry) -> float:
    """Every move succeeded; the base centre kept the robot's radius off every footprint."""
    assert bool(res.feasible.all()), res.failure
    assert res.traj_base is not None and res.traj_base.shape[1] > 50
    clearance = footprint_clearance(res.traj_base, geometry).min(dim=-1).values  # (N, T)
    worst = float(clearance.min())
    assert worst >= FOOTPRINT - TRACK_SLACK, (
        f"base came within {worst:.3f} m of an obstacle footprint (robot radius {FOOTPRINT})")
    return worst


@pytest.mark.parametrize("zone", ["clear", "padded"])
def test_move_to_table2_annulus_from_the_start(wall_scene: BatchedScene, zone: str) -> None:
    """move_to(Table2) from the start pose to points all around table 2 (also behind it)."""
    g = torch.Generator().manual_seed(0)
    geometry = wall_scene.geometry
    Z = sample_goals(TABLE2, wall_scene.n_envs, geometry, zone, g)
    res = _realize(wall_scene, {"Table2": TABLE2}, ["move_to(Table2)"], Z)
    worst = _check_paths(res, geometry)
    final = res.traj_base[:, -1]
    assert float((final - Z).norm(dim=1).max()) <= RolloutConfig().move_tolerance + 1e-6
    print(f"move_to(Table2) x{wall_scene.n_envs} ({zone} goals): all reached, min footprint clearance {worst:.3f} m, "
          f"{res.sim_steps} steps, {res.wall_time_s:.1f} s")


def test_move_around_the_wall_between_the_tables(wall_scene: BatchedScene) -> None:
    """move_to(Table1) to the far side of table 1, then move_to(Table2) to the far side of
    table 2: the second leg has to go around table 1, the wall and table 2."""
    g = torch.Generator().manual_seed(1)
    geometry = wall_scene.geometry
    wall = next(b for b in geometry.extras if b.name == "wall")
    n = wall_scene.n_envs
    z1 = sample_goals(TABLE1, n, geometry, "clear", g, keep=lambda xy: xy[:, 1] > TABLE1["center"][1] + 0.3)
    z2 = sample_goals(TABLE2, n, geometry, "clear", g, keep=lambda xy: xy[:, 1] < TABLE2["center"][1] - 0.3)
    res = _realize(wall_scene, {"Table1": TABLE1, "Table2": TABLE2}, ["move_to(Table1)", "move_to(Table2)"],
                   torch.cat([z1, z2], dim=1))
    worst = _check_paths(res, geometry)
    # where the path crosses the wall's line it is beyond the wall's ends (plus the robot)
    base = res.traj_base
    y0 = wall.center[1]
    cross = (base[:, 1:, 1] - y0) * (base[:, :-1, 1] - y0) <= 0  # (N, T-1)
    assert bool(cross.any(dim=1).all()), "every plan crosses from table 1's side to table 2's"
    x_at = base[:, 1:, 0][cross]
    beyond = (x_at - wall.center[0]).abs() - wall.half_size[0]
    assert float(beyond.min()) >= FOOTPRINT - TRACK_SLACK, float(beyond.min())
    # and the detour is real: longer than the straight line between the two goals
    length = (base[:, 1:] - base[:, :-1]).norm(dim=-1).sum(dim=1)
    assert bool((length > (z2 - z1).norm(dim=1)).all())
    print(f"move_to(Table1), move_to(Table2) x{n}: all reached, min footprint clearance {worst:.3f} m, "
          f"wall passed {float(beyond.min()):.2f} m beyond its end at the closest, {res.wall_time_s:.1f} s")
