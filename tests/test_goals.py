"""The goal predicates of ``realize.tasks.goals``, and the ManiSkill tasks' ``evaluate()``
built on them: every copy of a tiled scene is read, not copy 0 only.

* unit checks of each predicate and of ``goal_reached`` (conditions AND-ed, distances summed);
* ``RealizePickPlace-v1`` with 3 tiled copies: nothing done / cube on table 2 only / cube on
  table 2 and base in the exit -> success only for the last copy;
* ``RealizeMoveAndPush-v1`` with 2 tiled copies: the cube in the box in one copy only.
"""

from __future__ import annotations

import math

import pytest
import torch
import yaml

from realize.paths import CONFIG_DIR
from realize.world.geometry import ContainerCfg, GeometryCfg, build_geometry
from realize.tasks.goals import (
    HEIGHT_TOL,
    base_in_rectangle,
    base_rectangle_distance,
    goal_reached,
    object_in_container,
    object_on_table,
    object_on_table_distance,
)
from realize.tasks.regions import Box as BoxRegion
from realize.scene import BatchedScene, SimSettings
from realize.tasks.spec import GoalSpec


def _on_top(geometry, table: str, dx: float = 0.0, dz: float = 0.0) -> list[float]:
    t = geometry.table(table)
    return [t.center[0] + dx, t.center[1], 2 * t.half_size[2] + geometry.object("cube").half_height + dz]


def test_cube_on_table_and_its_distance() -> None:
    g = build_geometry(GeometryCfg())
    t2 = g.table("table2")
    p = torch.tensor([_on_top(g, "table2"), _on_top(g, "table2", dz=HEIGHT_TOL + 0.01),
                      _on_top(g, "table2", dx=t2.half_size[0] + 0.3), _on_top(g, "table2")])
    speed = torch.tensor([0.0, 0.0, 0.0, 0.2])
    assert object_on_table(p, speed, g, "cube", "table2").tolist() == [True, False, False, False]
    d = object_on_table_distance(p, g, "cube", "table2")
    assert d[0] == 0 and d[3] == 0
    assert float(d[1]) == pytest.approx(0.01, abs=1e-5) and float(d[2]) == pytest.approx(0.3, abs=1e-5)


def test_cube_in_container() -> None:
    g = build_geometry(GeometryCfg(variant="push", containers=[ContainerCfg()]))
    box = g.containers[0]
    inside = [box.center[0], box.center[1], g.object("cube").half_height + 0.01]
    beside = [box.center[0] + box.half_size[0] + 0.1, box.center[1], g.object("cube").half_height]
    p = torch.tensor([inside, beside, inside])
    ok = object_in_container(p, torch.tensor([0.0, 0.0, 1.0]), g, box.name)
    assert ok.tolist() == [True, False, False]


def test_base_rectangle_and_goal_reached_sums_distances() -> None:
    g = build_geometry(GeometryCfg())
    exit_ = BoxRegion([1.8, -0.4], [2.6, 0.4])
    base = torch.tensor([[2.2, 0.0], [1.5, 0.0], [2.2, 0.0]])
    assert base_in_rectangle(base, exit_.low, exit_.high).tolist() == [True, False, True]
    assert base_rectangle_distance(base, exit_.low, exit_.high).tolist() == pytest.approx([0.0, 0.3, 0.0])
    cube = torch.tensor([_on_top(g, "table2"), _on_top(g, "table2"), _on_top(g, "table1")])
    speed = torch.zeros(3)
    goal = GoalSpec(on={"cube": "table2"}, base_in="Exit")
    ok, dist = goal_reached(goal, g, {"Exit": exit_}, cube[:, None], speed[:, None], base)
    assert ok.tolist() == [True, False, False]
    t1, t2 = g.table("table1"), g.table("table2")
    gap = abs(t1.center[1] - t2.center[1]) - t2.half_size[1]  # table 1's centre to table 2's edge
    assert dist.tolist() == pytest.approx([0.0, 0.3, gap], abs=1e-5)
    # no condition: the goal holds everywhere, at distance 0
    ok, dist = goal_reached(GoalSpec(), g, {}, cube[:, None], speed[:, None], base)
    assert ok.all() and (dist == 0).all()


def _teleport_base(scene: BatchedScene, copy: int, xy: list[float]) -> None:
    """Put one copy's base at ``xy`` (local frame), at rest (planar joints are relative to the start)."""
    agent = scene.u.agents[copy]
    qpos = agent.robot.get_qpos().clone()
    qpos[0, 0:2] = torch.tensor(xy) - torch.tensor(scene.geometry.robot_start[:2])
    agent.robot.set_qpos(qpos)
    agent.robot.set_qvel(torch.zeros_like(qpos))


def test_pick_place_evaluate_reads_every_copy() -> None:
    with BatchedScene(3, GeometryCfg(), SimSettings(backend="cpu")) as scene:
        g = scene.geometry
        scene.reset(seed=0)
        start = list(g.object("cube").position)
        scene.place_object("cube", torch.tensor([start, _on_top(g, "table2"), _on_top(g, "table2")]))
        # the exit is the default task's region (configs/task/pick_place.yaml), not the scene's
        task = yaml.safe_load((CONFIG_DIR / "task" / "pick_place.yaml").read_text())
        low, high = task["params"]["Exit"]["low"], task["params"]["Exit"]["high"]
        _teleport_base(scene, 2, [(low[0] + high[0]) / 2, (low[1] + high[1]) / 2])
        info = scene.u.evaluate()
    assert info["cube_on_table2"].tolist() == [False, True, True]
    assert info["base_in_Exit"].tolist() == [False, False, True]
    assert info["success"].tolist() == [False, False, True]


def test_move_and_push_evaluate_reads_every_copy() -> None:
    with BatchedScene(2, GeometryCfg(variant="push", containers=[ContainerCfg()]), SimSettings(backend="cpu")) as scene:
        g = scene.geometry
        scene.reset(seed=0)
        box = g.containers[0]
        inside = [box.center[0], box.center[1], 2 * g.container_wall(box.name) + g.object("cube").half_height]
        scene.place_object("cube", torch.tensor([list(g.object("cube").position), inside]))
        info = scene.u.evaluate()
    assert not math.isclose(g.object("cube").position[0], box.center[0])
    assert info["cube_in_box"].tolist() == [False, True]
    assert info["success"].tolist() == [False, True]
