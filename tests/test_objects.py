"""Objects as data, without the simulator: scene entries, plans and goals by object name.

* ``scene.objects`` entries place objects on their supports (tables, the floor, other
  objects) with the same numbers the one-cube scene had; bad entries (a support that does not
  exist, two objects in one place, a cylinder with a size) are one ``ConfigError`` naming the key;
* plans name the object an action handles, the hand holds at most one object (checked before
  anything runs), and PDDL plans map their items to scene objects by name;
* goals by object: every condition is checked against the scene, and ``rests_at`` states
  "put it back, 15 cm further" (which ``rests_on: table1`` could not: it holds before anything moves);
* scene states hold every object and the held one; first-format files still read.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest
import torch

from envs.goal_check import goal_info
from helpers import REPO, compose_config
from realize.spec.run_spec import build_run_spec
from realize.config import ConfigError
from realize.realization.actions import TEMPLATES
from realize.tasks.goals import goal_reached, object_at
from realize.tasks.pddl import plan_from_pddl
from realize.tasks.regions import Fixed
from realize.tasks.spec import check_hand, parse_action, task_from_dict
from realize.world.geometry import ContainerCfg, GeometryCfg, build_geometry
from realize.world.objects import ObjectCfg
from realize.world.state import SceneState, load_state


def _error(*overrides: str) -> str:
    """The one-line ConfigError a run with ``overrides`` stops with (no scene is built)."""
    with pytest.raises(ConfigError) as ei:
        build_run_spec(compose_config(*overrides))
    msg = str(ei.value)
    assert "\n" not in msg
    return msg


# ------------------------------------------------------------------------------- scene objects


def test_the_seed_cube_rests_where_it_did() -> None:
    g = build_geometry(GeometryCfg())
    (cube,) = g.objects
    t1 = g.table("table1")
    # the numbers of the one-cube scene: on table 1's centre, half its 4.5 cm edge above the top
    assert cube.name == "cube" and cube.rests_on == "table1" and cube.half_size == (0.0225, 0.0225, 0.0225)
    assert cube.position == (t1.center[0], t1.center[1], 2 * t1.half_size[2] + 0.045 / 2)
    assert g.object_index("cube") == 0 and g.floor_objects == ()


def test_objects_stack_on_objects_and_floor_objects_are_obstacles() -> None:
    stick = ObjectCfg(size=(0.04, 0.04, 0.7), rests_on="floor")
    g = build_geometry(GeometryCfg(variant="push", tables=[], objects={"cube": ObjectCfg(rests_on="stick"),
                                                                     "stick": stick}, containers=[ContainerCfg()]))
    assert g.object("stick").position == (0.0, 0.0, 0.35) and g.object("stick").top_z == 0.7
    assert g.object("cube").position[2] == pytest.approx(0.7 + 0.0225)
    assert [b.name for b in g.floor_objects] == ["stick"] and "stick" in [b.name for b in g.obstacles]
    assert "stick" not in [b.name for b in g.static_obstacles]  # pushed, not a fabric obstacle


def test_a_cylinder_is_an_upright_solid() -> None:
    can = ObjectCfg(shape="cylinder", radius=0.025, height=0.08)
    o = build_geometry(GeometryCfg(objects={"can": can})).object("can")
    assert o.half_size == (0.025, 0.025, 0.04) and o.position[2] == pytest.approx(0.72 + 0.04)
    assert o.volume() == pytest.approx(math.pi * 0.025 ** 2 * 0.08)


@pytest.mark.parametrize("overrides, needles", [
    (["scene.objects.cube.rests_on=table9"], ["scene.objects.cube.rests_on", "table9", "table1"]),
    (["+scene.objects.cube_b={rests_on:table1,offset:[0.01,0.0]}"], ["scene.objects.cube_b", "overlaps cube"]),
    (["scene.objects.cube.offset=[0.5,0.0]"], ["scene.objects.cube.offset", "table1"]),
    (["+scene.objects.can={shape:cylinder,radius:0.02}"], ["scene.objects.can", "height"]),
    (["+scene.objects.can={shape:cylinder,size:[0.1,0.1,0.1],radius:0.02,height:0.1}"], ["scene.objects.can.size"]),
    (["scene.objects.cube.shape=sphere"], ["scene.objects.cube.shape", "sphere"]),
    (["+scene.objects.table2={rests_on:table1}"], ["table2", "own name"]),
    (["scene=push", "scene.containers=[]"], ["scene.containers", "open box"]),
    (["scene=ramp", "scene.ramps.0.low_table=table7"], ["scene.ramps[0].low_table", "table7"]),
    (["scene=ramp", "scene.ramps.0.drop=0.9"], ["scene.ramps", "drop", "length"]),
])
def test_bad_objects_are_one_line_naming_the_key(overrides: list[str], needles: list[str]) -> None:
    msg = _error(*overrides)
    for n in needles:
        assert n in msg, msg


# ------------------------------------------------------------------------------- plans


def _task(plan: list[str], goal: dict | None = None, scene: GeometryCfg | None = None) -> object:
    g = build_geometry(scene or GeometryCfg())
    params = {"Table1": {"type": "annulus", "center": [0.0, 1.2], "r_min": 0.75, "r_max": 1.25},
              "Cube_g": {"type": "hemisphere", "frame": "cube", "center": [0, 0, 0], "radius": 0.15},
              "Cube_p": {"type": "hemisphere", "frame": "table2", "center": [0, 0, 0.0275], "radius": 0.15},
              "Spot": {"type": "fixed", "frame": "table1", "value": [0.15, 0.0, 0.0225]}}
    return task_from_dict({"params": params, "plan": plan, "goal": goal or {"rests_on": {"cube": "table2"}}},
                          g, TEMPLATES, source="t.yaml")


def test_actions_name_their_object() -> None:
    t = _task(["move_to(Table1)", "grasp(cube, Cube_g)", "place(cube, Cube_p)"])
    assert [a.obj for a in t.plan] == [None, "cube", "cube"] and [a.params for a in t.plan][1] == ("Cube_g",)
    assert t.describe() == "move_to(Table1), grasp(cube, Cube_g), place(cube, Cube_p)"


@pytest.mark.parametrize("plan, needles", [
    (["grasp(Cube_g)"], ["t.yaml:plan[0]", "grasp(<object>, <Param>)", "cube"]),
    (["grasp(mug, Cube_g)"], ["t.yaml:plan[0]", "unknown object 'mug'"]),
    (["place(cube, Cube_p)"], ["t.yaml:plan[0]", "places cube", "hand is empty"]),
    (["grasp(cube, Cube_g)", "grasp(cube, Cube_g)"], ["t.yaml:plan[1]", "empty hand", "cube is held"]),
    (["move_to(cube, Table1)"], ["t.yaml:plan[0]", "move_to takes 1 parameter"]),
])
def test_bad_plans_are_refused_before_anything_runs(plan: list[str], needles: list[str]) -> None:
    with pytest.raises(ConfigError) as ei:
        _task(plan)
    for n in needles:
        assert n in str(ei.value), str(ei.value)


def test_the_hand_holds_one_object_at_a_time() -> None:
    a, b = parse_action("grasp(cube_a, G)", "p"), parse_action("place(cube_b, P)", "p")
    from realize.tasks.spec import ActionSpec
    grasp_a, place_b = ActionSpec("grasp", ("G",), "cube_a"), ActionSpec("place", ("P",), "cube_b")
    assert a.params == ("cube_a", "G") and b.template == "place"  # split by bind_objects later
    check_hand([grasp_a, ActionSpec("place", ("P",), "cube_a")], "p")
    with pytest.raises(ConfigError, match="places cube_b, but cube_a is in hand"):
        check_hand([grasp_a, place_b], "p")
    check_hand([place_b], "p", held="cube_b")  # a replan that starts with cube_b in hand
    with pytest.raises(ConfigError, match="pushes with the closed gripper"):
        check_hand([ActionSpec("push", ("P",), "stick")], "p", held="cube_a")


def test_pddl_items_become_the_actions_objects() -> None:
    pddl = REPO / "configs" / "pddl"
    plans = plan_from_pddl(pddl / "pick_place_domain.pddl", pddl / "two_cubes_problem.pddl", list(TEMPLATES),
                           ["Table1", "Table2", "Exit", "CubeA_g", "CubeB_g", "CubeA_p", "CubeB_p"],
                           objects=["cube_a", "cube_b"], top_k=2)
    assert len(plans) == 2
    firsts = {next(a.obj for a in p if a.template == "grasp") for p in plans}
    assert firsts == {"cube_a", "cube_b"}  # both orders
    for p in plans:
        assert len(p) == 9 and [a.template for a in p].count("grasp") == 2
        held = None
        for a in p:  # every place puts down the cube its grasp picked up
            if a.template == "grasp":
                held = a.obj
            elif a.template == "place":
                assert a.obj == held and a.params[0] == {"cube_a": "CubeA_p", "cube_b": "CubeB_p"}[held]


# ------------------------------------------------------------------------------- goals


def test_goals_are_checked_against_the_scene() -> None:
    for goal, needles in [({"rests_on": {"mug": "table2"}}, ["goal.rests_on.mug", "unknown object"]),
                          ({"rests_on": {"cube": "table9"}}, ["goal.rests_on.cube", "table9"]),
                          ({"rests_in": {"cube": "box"}}, ["goal.rests_in.cube", "no container"]),
                          ({"rests_at": {"cube": {"region": "Nowhere"}}}, ["goal.rests_at.cube.region", "Nowhere"]),
                          ({"rests_at": {"cube": {"region": "Cube_g"}}}, ["goal.rests_at.cube.region", "fixed point"]),
                          ({"cube_on": "table2"}, ["goal.cube_on", "rests_on: {cube: <table>}"]),
                          ({True: {"cube": "table2"}}, ["rests_on", "YAML"])]:
        with pytest.raises(ConfigError) as ei:
            _task(["grasp(cube, Cube_g)"], goal)
        for n in needles:
            assert n in str(ei.value), str(ei.value)


def test_put_it_back_15cm_further_is_not_done_before_anything_moves() -> None:
    """``rests_on: {cube: table1}`` holds where the cube starts; ``rests_at`` a spot 15 cm away does not."""
    t = _task(["grasp(cube, Cube_g)", "place(cube, Cube_p)"], {"rests_at": {"cube": {"region": "Spot", "tol": 0.02}}})
    g = build_geometry(GeometryCfg())
    start = torch.tensor([[g.object("cube").position]])  # (N=1, m=1, 3)
    still = torch.zeros(1, 1)
    base = torch.zeros(1, 2)
    ok, dist = goal_reached(t.goal, g, t.layout.regions, start, still, base)
    assert not bool(ok[0]) and float(dist[0]) == pytest.approx(0.15 - 0.02, abs=1e-6)
    there = start + torch.tensor([0.15, 0.0, 0.0])
    ok, dist = goal_reached(t.goal, g, t.layout.regions, there, still, base)
    assert bool(ok[0]) and float(dist[0]) == 0.0
    on_t1 = _task(["grasp(cube, Cube_g)"], {"rests_on": {"cube": "table1"}}).goal
    assert bool(goal_reached(on_t1, g, t.layout.regions, start, still, base)[0][0])
    # still moving: not at rest there
    assert not bool(object_at(there[:, 0], torch.tensor([0.2]), Fixed(value=(0.15, 1.2, 0.7425)), 0.02)[0])


def _cube_a_on_table2() -> object:
    """cube_a (4.5 cm) on table 2, cube_b on table 1."""
    a_cfg = ObjectCfg(size=(0.045, 0.045, 0.045), rests_on="table2", offset=(0.0, -0.1))
    b_cfg = ObjectCfg(size=(0.045, 0.045, 0.045), rests_on="table1", offset=(0.0, 0.1))
    return build_geometry(GeometryCfg(objects={"cube_a": a_cfg, "cube_b": b_cfg}))


def test_rests_on_an_object_holds_on_its_top_where_it_stands() -> None:
    """``rests_on: {cube_b: cube_a}``: on cube_a's top where cube_a stands (2 cm off its
    configured place, turned), centred within its inscribed circle, both still; beside it, or
    with cube_a still sliding, it does not hold. The env's predicate says the same."""
    g = _cube_a_on_table2()
    params = {"G": {"type": "hemisphere", "frame": "cube_b", "center": [0, 0, 0], "radius": 0.15},
              "P": {"type": "hemisphere", "frame": "cube_a", "center": [0, 0, 0.05], "radius": 0.15}}
    t = task_from_dict({"params": params, "plan": ["grasp(cube_b, G)", "place(cube_b, P)"],
                        "goal": {"rests_on": {"cube_b": "cube_a"}}}, g, TEMPLATES, source="t.yaml")
    ia, ib = g.object_index("cube_a"), g.object_index("cube_b")
    a_there = torch.tensor(g.object("cube_a").position) + torch.tensor([0.02, 0.0, 0.0])
    objects = torch.zeros(4, 2, 3)
    objects[:, ia] = a_there
    objects[0, ib] = a_there + torch.tensor([0.015, 0.0, 0.045])   # on top, 1.5 cm off centre (inside 2.25 cm)
    objects[1, ib] = a_there + torch.tensor([0.035, 0.0, 0.045])   # hanging off: 1.25 cm past the circle
    objects[2, ib] = a_there + torch.tensor([0.0, 0.0, 0.045 + 0.03])  # 3 cm above the top: not resting
    objects[3, ib] = a_there + torch.tensor([0.0, 0.0, 0.045])
    speeds = torch.zeros(4, 2)
    speeds[3, ia] = 0.2  # cube_a still sliding
    ok, dist = goal_reached(t.goal, g, t.layout.regions, objects, speeds, torch.zeros(4, 2))
    assert ok.tolist() == [True, False, False, False]
    assert float(dist[0]) == 0.0 and float(dist[1]) == pytest.approx(0.0125, abs=1e-6)
    assert float(dist[2]) == pytest.approx(0.03 - 0.02, abs=1e-6) and float(dist[3]) == 0.0
    info = goal_info(t.goal, g, t.layout.regions, objects, speeds, torch.zeros(4, 2))
    assert info["cube_b_on_cube_a"].tolist() == [True, False, False, False]


@pytest.mark.parametrize("goal, needles", [
    ({"rests_on": {"cube_b": "cube_b"}}, ["rests_on.cube_b", "cannot rest on itself"]),
    ({"rests_on": {"cube_b": "cube_a", "cube_a": "cube_b"}}, ["rests_on", "would rest on itself"]),
    ({"rests_on": {"cube_b": "cube_aa"}}, ["names no table or object", "did you mean 'cube_a'"]),
])
def test_a_stack_goal_that_cannot_hold_is_refused(goal: dict, needles: list[str]) -> None:
    params = {"G": {"type": "hemisphere", "frame": "cube_b", "center": [0, 0, 0], "radius": 0.15}}
    with pytest.raises(ConfigError) as e:
        task_from_dict({"params": params, "plan": ["grasp(cube_b, G)"], "goal": goal}, _cube_a_on_table2(),
                       TEMPLATES, source="t.yaml")
    for n in needles:
        assert n in str(e.value), str(e.value)


def test_a_spot_framed_by_a_movable_object_is_where_that_object_stands() -> None:
    """cube_b placed on cube_a (``rests_at`` a spot framed by cube_a, 4.5 cm above its centre),
    with cube_a started 2 cm off its configured place: the goal holds on top of cube_a where it
    stands, not at the configured spot (the goal without frames, as before, says the opposite)."""
    g = _cube_a_on_table2()
    params = {"On_a": {"type": "fixed", "frame": "cube_a", "value": [0.0, 0.0, 0.045]},
              "G": {"type": "hemisphere", "frame": "cube_b", "center": [0, 0, 0], "radius": 0.15},
              "P": {"type": "hemisphere", "frame": "cube_a", "center": [0, 0, 0.045], "radius": 0.15}}
    t = task_from_dict({"params": params, "plan": ["grasp(cube_b, G)", "place(cube_b, P)"],
                        "goal": {"rests_at": {"cube_b": {"region": "On_a", "tol": 0.01}}}}, g, TEMPLATES,
                       source="t.yaml")
    a_there = torch.tensor(g.object("cube_a").position) + torch.tensor([0.02, 0.0, 0.0])
    on_top = a_there + torch.tensor([0.0, 0.0, 0.045])
    configured_spot = torch.tensor(g.object("cube_a").position) + torch.tensor([0.0, 0.0, 0.045])
    order = [g.object_index("cube_a"), g.object_index("cube_b")]
    objects = torch.zeros(2, 2, 3)
    objects[:, order[0]] = a_there
    objects[0, order[1]], objects[1, order[1]] = on_top, configured_spot  # copy 0: on cube_a; 1: in the air beside it
    still, base = torch.zeros(2, 2), torch.zeros(2, 2)
    ok, dist = goal_reached(t.goal, g, t.layout.regions, objects, still, base, frames=t.frames)
    assert ok.tolist() == [True, False] and float(dist[0]) == 0.0
    assert float(dist[1]) == pytest.approx(0.02 - 0.01, abs=1e-6)
    unframed, _ = goal_reached(t.goal, g, t.layout.regions, objects, still, base)
    assert unframed.tolist() == [False, True]  # the spot where cube_a was configured


# ------------------------------------------------------------------------------- states


def test_state_holds_every_object_and_first_format_files_read(tmp_path: Path) -> None:
    old = load_state(Path(__file__).parent / "fixtures" / "state_grasped.json")  # format 1: cube, cube_held
    assert set(old.objects) == {"cube"} and old.held == "cube" and old.gripper_closed
    again = SceneState.from_json(json.loads(json.dumps(old.to_json())), "again")
    assert again.objects == old.objects and again.held == "cube" and again.to_json()["format"].endswith("/2")
    d = old.to_json()
    d["held"] = "mug"
    with pytest.raises(ConfigError, match="held = 'mug'"):
        SceneState.from_json(d, "s.json")
    d["held"], d["gripper_closed"] = "cube", False
    with pytest.raises(ConfigError, match="gripper_closed is false"):
        SceneState.from_json(d, "s.json")
    d = old.to_json()
    d["objects"]["cube"]["quaternion"] = [2.0, 0.0, 0.0, 0.0]
    with pytest.raises(ConfigError, match="objects.cube.quaternion"):
        SceneState.from_json(d, "s.json")
