"""Two objects and a cylinder in the simulator (CPU), with hand-chosen parameters.

* ``experiment=two_cubes``: the planner's plan (cube_a first) puts both cubes on table 2 (read
  back from the simulator), and while cube_a is carried cube_b moves by less than 1 mm;
* replanning from the state where cube_a is in hand and cube_b still on table 1: the rest of the
  plan puts both on table 2;
* a cylinder goes through grasp and place and ends upright on table 2.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import pytest
import torch
import yaml

from helpers import compose_config
from realize.spec.run_spec import build_run_spec
from realize.config import ConfigError
from realize.realization.rollout import PlanRealizer
from realize.scene import BatchedScene
from realize.tasks.suffix import check_suffix_start, suffix_columns, task_suffix
from realize.world.state import SceneState

pytestmark = pytest.mark.usefixtures("torch_single_thread")

# base west of each table, every grasp and place straight from above, 20 cm apart along y as the cubes
TWO_CUBES = {"Table1": [-0.85, 1.2], "CubeA_g": [0.0, 1.1, 0.8925], "CubeB_g": [0.0, 1.3, 0.8925],
             "Table2": [-0.85, -1.2], "CubeA_p": [0.0, -1.3, 0.8975], "CubeB_p": [0.0, -1.1, 0.8975],
             "Exit": [2.2, 0.0]}


def _z(spec: Any, values: dict[str, list[float]]) -> torch.Tensor:
    return torch.tensor([sum((values[n] for n in spec.task.layout.names), [])], dtype=torch.float64)


def _rests_on_table2(p: torch.Tensor, half: float) -> bool:
    """An object centre over table 2's top (0.6 x 0.6 m at (0, -1.2), 0.72 m high), resting on it."""
    x, y, z = p[:3].tolist()
    return abs(x) <= 0.3 - half and abs(y + 1.2) <= 0.3 - half and abs(z - (0.72 + half)) <= 0.005


def _upright(q: torch.Tensor, deg: float = 10.0) -> bool:
    """wxyz ``q`` turns the object's z axis by less than ``deg`` from vertical."""
    w, x, y, z = q.tolist()
    return 1 - 2 * (x * x + y * y) >= math.cos(math.radians(deg))


@pytest.fixture(scope="module")
def two_cubes() -> dict[str, Any]:
    """The whole plan once (N = 1): cube_b's largest displacement while cube_a is carried, the
    state where the drive to table 2 begins, the final poses."""
    spec = build_run_spec(compose_config("experiment=two_cubes"))
    out: dict[str, Any] = {"spec": spec, "b_moved": 0.0, "b_reads": 0}
    with BatchedScene(1, spec.geometry_cfg, spec.sim) as scene:
        realizer = PlanRealizer.from_spec(spec, None, scene)
        b0 = torch.tensor(spec.geometry.object("cube_b").position)
        action = {"now": 0}

        def on_action(a: int, rows: torch.Tensor) -> None:
            action["now"] = a
            if a == 2:
                out["state"] = scene.capture_state(0, source="two_cubes: cube_a in hand")

        def on_step(step: int) -> None:
            if 1 <= action["now"] <= 3:  # grasp(cube_a) .. place(cube_a)
                moved = float((scene.object_pose("cube_b")[0, :3] - b0).norm())
                out["b_moved"] = max(out["b_moved"], moved)
                out["b_reads"] += 1

        realizer.action_hook = on_action
        scene.add_step_hook(on_step)
        out["res"] = realizer.rollout(_z(spec, TWO_CUBES))
        out["poses"] = scene.object_poses()[0]
    return out


def test_the_planner_moves_both_cubes_one_at_a_time(two_cubes: dict[str, Any]) -> None:
    plan = two_cubes["spec"].task.describe()
    assert plan == ("move_to(Table1), grasp(cube_a, CubeA_g), move_to(Table2), place(cube_a, CubeA_p), "
                    "move_to(Table1), grasp(cube_b, CubeB_g), move_to(Table2), place(cube_b, CubeB_p), move_to(Exit)")


def test_both_cubes_end_on_table2_and_b_stays_put_while_a_is_carried(two_cubes: dict[str, Any]) -> None:
    res = two_cubes["res"]
    assert res.failure == [""] and bool(res.feasible[0]) and res.action_success.all()
    g = two_cubes["spec"].geometry
    for name in ("cube_a", "cube_b"):
        p = two_cubes["poses"][g.object_index(name)]
        assert _rests_on_table2(p, 0.0225), (name, p)
        assert _upright(p[3:]), (name, p)
    # each where its place point put it: a on table 2's -y side, b on its +y side
    pa, pb = two_cubes["poses"][0, :3], two_cubes["poses"][1, :3]
    assert float(pa[1]) < -1.2 < float(pb[1])
    # read at every control step from grasp(cube_a) to place(cube_a): cube_b sat still while a was carried
    assert two_cubes["b_reads"] > 200 and two_cubes["b_moved"] < 1e-3


def test_replan_with_one_cube_in_hand_and_the_other_on_table1(two_cubes: dict[str, Any]) -> None:
    state: SceneState = two_cubes["state"]
    spec = two_cubes["spec"]
    assert state.held == "cube_a" and state.gripper_closed
    b = torch.tensor(state.objects["cube_b"].position)
    assert (b - torch.tensor(spec.geometry.object("cube_b").position)).norm() < 1e-3  # still on table 1
    rest = task_suffix(spec.task, 2)
    check_suffix_start(rest, state)
    full = _z(spec, TWO_CUBES)[0]
    z = full[suffix_columns(spec.task, 2)][None]
    with BatchedScene(1, spec.geometry_cfg, spec.sim) as scene:
        realizer = PlanRealizer(rest, scene, spec.rollout, seed=spec.seed, start=state)
        res = realizer.rollout(z)
        assert bool(res.feasible[0]), res.failure
        poses = scene.object_poses()[0]
        for k in range(2):
            assert _rests_on_table2(poses[k], 0.0225), poses[k]
    assert float(res.cost[0]) < float(two_cubes["res"].cost[0])  # 7 actions of 9
    with pytest.raises(ConfigError, match="needs an empty hand, but cube_a is held"):
        check_suffix_start(task_suffix(spec.task, 5), state)  # grasp(cube_b) with cube_a in hand


def test_a_cylinder_through_grasp_and_place_ends_upright_on_table2(tmp_path: Path) -> None:
    """An 8 cm tall can (5 cm across), grasped from above and from 0.6 rad off vertical."""
    half = 0.04
    task = {"name": "can", "params": {
        "Table1": {"type": "annulus", "frame": "table1", "center": [0.0, 0.0], "r_min": 0.75, "r_max": 1.25},
        "Can_g": {"type": "hemisphere", "frame": "can", "center": [0.0, 0.0, 0.0], "radius": 0.15, "polar_max": 1.3},
        "Table2": {"type": "annulus", "frame": "table2", "center": [0.0, 0.0], "r_min": 0.75, "r_max": 1.25},
        "Can_p": {"type": "hemisphere", "frame": "table2", "center": [0.0, 0.0, half + 0.005], "radius": 0.15,
                  "polar_max": 1.3},
        "Exit": {"type": "box", "low": [1.8, -0.4], "high": [2.6, 0.4]}},
        "plan": ["move_to(Table1)", "grasp(can, Can_g)", "move_to(Table2)", "place(can, Can_p)", "move_to(Exit)"],
        "goal": {"rests_on": {"can": "table2"}, "base_in": "Exit"}}
    path = tmp_path / "can.yaml"
    path.write_text(yaml.safe_dump(task, sort_keys=False))
    spec = build_run_spec(compose_config(f"task_file={path}", "~scene.objects.cube",
                                         "+scene.objects.can={shape:cylinder,radius:0.025,height:0.08,"
                                         "rests_on:table1}"))
    top = 0.72 + half + 0.15
    s, c = math.sin(0.6), math.cos(0.6)
    Z = torch.tensor([[-0.85, 1.2, 0.0, 1.2, top, -0.85, -1.2, 0.0, -1.2, top + 0.005, 2.2, 0.0],
                      [-0.85, 1.2, -0.15 * s, 1.2, 0.72 + half + 0.15 * c, -0.85, -1.2, 0.0, -1.2, top + 0.005,
                       2.2, 0.0]], dtype=torch.float64)
    with BatchedScene(2, spec.geometry_cfg, spec.sim) as scene:
        res = PlanRealizer.from_spec(spec, None, scene).rollout(Z)
        assert res.failure == ["", ""] and res.feasible.all()
        for p in scene.object_pose("can"):
            assert _rests_on_table2(p, half), p
            assert _upright(p[3:], 5.0), p
