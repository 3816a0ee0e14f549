"""Re-sequencing in the blocks domain (realize/repair/resequence.py): the symbolic state read off a
hand-made scene state of the three-block tower (robot=panda experiment=tower3), and the new plan
Fast Downward finds from it. No simulation: geometry and PDDL only."""

from __future__ import annotations

import math
from pathlib import Path

import pytest

from helpers import REPO, compose_config
from realize.repair.pddl_text import domain_predicates
from realize.repair.resequence import resequence_task, symbolic_facts
from realize.repair.resequence_blocks import blocks_facts, is_blocks_domain
from realize.config import ConfigError
from realize.world.geometry import GeometryCfg, build_geometry
from realize.world.state import ObjectPose, SceneState

BLOCKS = ["cube_a", "cube_b", "cube_c"]
TABLES = ["table1"]
Z0 = 0.72 + 0.0225  # a 4.5 cm cube's centre on table 1 (top 0.72 m)
H = 0.045  # the cube's height: one level of the tower
PLAN = ["grasp(cube_b, CubeB_g)", "place(cube_b, CubeB_on_a)", "grasp(cube_c, CubeC_g)", "place(cube_c, CubeC_on_b)"]


@pytest.fixture(scope="module")
def tower3() -> tuple[dict, object]:
    """The tower3 task mapping (as a run's saved config has it: the planner on, no plan written)
    and its scene."""
    cfg = compose_config("robot=panda", "experiment=tower3")
    task = dict(cfg["task"])
    assert task["planner"]["enabled"] and "plan" not in task
    return task, build_geometry(GeometryCfg.from_mapping(cfg["scene"], "scene"))


def _yawed(yaw: float) -> tuple[float, float, float, float]:
    return (math.cos(yaw / 2), 0.0, 0.0, math.sin(yaw / 2))


def _state(held: str | None = None, **poses) -> SceneState:
    objects = {k: ObjectPose(*v) if isinstance(v[0], tuple) else ObjectPose(v) for k, v in poses.items()}
    return SceneState(base=(-0.42, 1.2, 0.0), objects=objects, held=held, gripper_closed=held is not None)


def _facts(geometry, state: SceneState) -> tuple[set[tuple[str, ...]], list[str]]:
    facts, notes = blocks_facts(state, geometry, BLOCKS, TABLES)
    return set(facts), notes


# ------------------------------------------------------------------------------ which convention
def test_the_convention_is_read_from_the_domains_predicates() -> None:
    pddl = REPO / "configs" / "pddl"
    assert is_blocks_domain(domain_predicates(pddl / "blocks_domain.pddl"))
    for other in ("pick_place_domain.pddl", "carry_or_push_domain.pddl"):
        preds = domain_predicates(pddl / other)
        assert "item-at" in preds and not is_blocks_domain(preds), (other, preds)


# ------------------------------------------------------------------------------ the facts
def test_a_finished_tower(tower3) -> None:
    _, g = tower3
    facts, notes = _facts(g, _state(cube_a=(0.0, 1.2, Z0), cube_b=(0.004, 1.203, Z0 + H),
                                    cube_c=(0.0, 1.198, Z0 + 2 * H)))
    assert facts == {("hand-empty",), ("on", "cube_a", "table1"), ("ontable", "cube_a"), ("on", "cube_b", "cube_a"),
                     ("on", "cube_c", "cube_b"), ("clear", "cube_c"), ("clear", "table1")}
    assert notes == []


def test_a_block_knocked_off_the_tower_rests_on_the_table(tower3) -> None:
    _, g = tower3
    facts, _ = _facts(g, _state(cube_a=(0.0, 1.2, Z0), cube_b=(0.05, 1.11, Z0 + 0.001), cube_c=(0.0, 1.4, Z0)))
    assert facts == {("hand-empty",), *[(p, b, *t) for b in BLOCKS for p, t in (("on", ("table1",)), ("ontable", ()))],
                     *[("clear", s) for s in BLOCKS + TABLES]}


def test_a_held_block_and_one_on_a_turned_block(tower3) -> None:
    """cube_b stands 2.8 cm off cube_a's centre along x: over cube_a's top only because cube_a is
    turned 45 degrees (its corner reaches 3.2 cm along x; square it reaches 2.25 cm)."""
    _, g = tower3
    state = _state("cube_c", cube_a=((0.0, 1.2, Z0), _yawed(math.pi / 4)), cube_b=(0.028, 1.2, Z0 + H),
                   cube_c=(0.1, 1.3, 0.95))
    facts, _ = _facts(g, state)
    assert facts == {("holding", "cube_c"), ("on", "cube_a", "table1"), ("ontable", "cube_a"),
                     ("on", "cube_b", "cube_a"), ("clear", "cube_b"), ("clear", "cube_c"), ("clear", "table1")}
    square = _state("cube_c", cube_a=(0.0, 1.2, Z0), cube_b=(0.028, 1.2, Z0 + H), cube_c=(0.1, 1.3, 0.95))
    facts, notes = _facts(g, square)
    assert not any(f[:2] == ("on", "cube_b") for f in facts) and notes and "cube_b" in notes[0]


def test_a_block_on_the_floor_or_in_the_air_gets_no_on_fact(tower3) -> None:
    _, g = tower3
    for where in ((0.6, 1.2, 0.0225), (0.0, 1.2, Z0 + H + 0.03)):  # the floor; above cube_a, not resting
        facts, notes = _facts(g, _state(cube_a=(0.0, 1.2, Z0), cube_b=where, cube_c=(0.0, 1.4, Z0)))
        assert not any(f[0] in ("on", "ontable") and f[1] == "cube_b" for f in facts), facts
        assert ("clear", "cube_b") in facts and len(notes) == 1 and notes[0].startswith("cube_b at")


# ------------------------------------------------------------------------------ the new plans
def test_a_knocked_off_block_is_stacked_again_with_the_tasks_regions(tower3, tmp_path: Path) -> None:
    task, g = tower3
    new = resequence_task(task, g, _state(cube_a=(0.0, 1.2, Z0), cube_b=(0.05, 1.11, Z0), cube_c=(0.0, 1.4, Z0)),
                          tmp_path)
    assert new["plan"] == PLAN and new["params"] == task["params"] and new["goal"] == task["goal"]
    assert new["planner"]["enabled"] is False  # a run of it takes that plan, not the problem's own again
    held = resequence_task(task, g, _state("cube_b", cube_a=(0.0, 1.2, Z0), cube_b=(0.0, 1.1, 0.9),
                                           cube_c=(0.0, 1.4, Z0)), tmp_path / "held")
    assert held["plan"] == PLAN[1:]
    text = (tmp_path / "held" / "resequence.pddl").read_text()
    assert "(holding cube_b)" in text and "(hand-empty)" not in text and "(grasps CubeB_g cube_b)" in text


def test_a_restack_of_a_planner_chosen_plan_is_a_replan_of_it(tower3, tmp_path: Path) -> None:
    """The run's saved task has no plan (the PDDL planner chose it): the re-sequence is matched
    against the plan its result.json names, so the search is warm-started from the run."""
    import json

    from realize.run.planner import realized_task
    from realize.tasks.suffix import tail_index

    task, g = tower3
    new = resequence_task(task, g, _state("cube_b", cube_a=(0.0, 1.2, Z0), cube_b=(0.0, 1.1, 0.9),
                                          cube_c=(0.0, 1.4, Z0)), tmp_path / "new")
    assert tail_index(task, new) is None  # the saved config alone names no plan
    (tmp_path / "result.json").write_text(json.dumps({"plan": ", ".join(PLAN)}))
    assert realized_task(task, tmp_path)["plan"] == PLAN
    assert tail_index(realized_task(task, tmp_path), new) == 1
    other = dict(new, plan=PLAN[:1] + PLAN[2:])
    assert tail_index(realized_task(task, tmp_path), other) is None


@pytest.mark.parametrize("b_at", [(0.05, 1.11), (0.0, 1.4)])
def test_a_block_stacked_on_a_knocked_off_one_is_set_down_on_a_free_spot_first(tower3, tmp_path: Path, b_at) -> None:
    """cube_c went onto the knocked-off cube_b: it must go down on the table first, and the task
    has no place region for cube_c on the table: one is made like the task's own place region
    (a hemisphere, radius 0.15, within 0.35 rad of straight down, the placed cube's centre 5 mm
    above resting height), framed by table 1 (centre (0, 1.2)) over a free spot near cube_c.
    With cube_b at (0.05, 1.11) that is cube_b's own start spot (0, 1.0) (configs/scene/
    tower3.yaml), 12 cm away: every ring point 10 cm around is too near cube_b below. With cube_b
    on cube_c's start spot (0, 1.4) it is a point 14 cm around, clear of both other cubes."""
    task, g = tower3
    state = _state(cube_a=(0.0, 1.2, Z0), cube_b=(*b_at, Z0), cube_c=(*b_at, Z0 + H))
    new = resequence_task(task, g, state, tmp_path)
    assert new["plan"] == ["grasp(cube_c, CubeC_g)", "place(cube_c, Re_cube_c_on_table1)", *PLAN]
    made = dict(new["params"]["Re_cube_c_on_table1"])
    sx, sy, sz = made.pop("center")
    assert made == {"type": "hemisphere", "frame": "table1", "radius": 0.15, "polar_max": 0.35}
    assert sz == pytest.approx(0.0225 + 0.005)
    x, y = sx, 1.2 + sy
    if b_at == (0.05, 1.11):
        assert (x, y) == pytest.approx((0.0, 1.0))
    else:
        assert math.hypot(x - b_at[0], y - b_at[1]) == pytest.approx(0.14)
    clear = 2 * math.hypot(0.0225, 0.0225) + 0.04  # both cubes' radii and the fingers' room
    assert math.hypot(x, y - 1.2) >= clear and math.hypot(x - b_at[0], y - b_at[1]) >= clear
    assert abs(x) <= 0.25 and abs(y - 1.2) <= 0.25  # on the 60 cm top, 5 cm in from its edges
    assert {k: v for k, v in new["params"].items() if k != "Re_cube_c_on_table1"} == task["params"]


def test_a_plan_that_needs_a_region_that_cannot_be_made_is_refused_in_one_line(tower3, tmp_path: Path) -> None:
    """The same, with the task's place regions fixed in the world frame (nothing to make a region
    framed by a support like): the refusal names the region the plan needs."""
    task, g = tower3
    params = dict(task["params"])
    for name, at in (("CubeB_on_a", (0.0, 1.2, Z0 + H + 0.005)), ("CubeC_on_b", (0.0, 1.2, Z0 + 2 * H + 0.005))):
        params[name] = {"type": "hemisphere", "center": list(at), "radius": 0.15, "polar_max": 0.35}
    state = _state(cube_a=(0.0, 1.2, Z0), cube_b=(0.05, 1.11, Z0), cube_c=(0.05, 1.11, Z0 + H))
    with pytest.raises(ConfigError) as ei:
        resequence_task(dict(task, params=params), g, state, tmp_path)
    msg = str(ei.value)
    assert "\n" not in msg and msg.endswith("none could be made like its own: cube_c placed on table1"), msg


def test_a_block_the_domain_cannot_say_makes_the_planner_say_unsolvable_in_one_line(tower3, tmp_path: Path) -> None:
    task, g = tower3
    state = _state(cube_a=(0.0, 1.2, Z0), cube_b=(0.6, 1.2, 0.0225), cube_c=(0.0, 1.4, Z0))
    with pytest.raises(ConfigError) as ei:
        resequence_task(task, g, state, tmp_path)
    msg = str(ei.value)
    assert "\n" not in msg and "unsolvable" in msg.lower() and "cube_b at (0.600, 1.200" in msg, msg


def test_the_pick_place_facts_are_unchanged() -> None:
    """The pick-place path (symbolic_facts) still reads item-at off a table top."""
    from realize.spec.task_plans import build_task

    cfg = compose_config()
    g = build_geometry(GeometryCfg.from_mapping(cfg["scene"], "scene"))
    task = build_task(dict(cfg["task"], planner=dict(cfg["task"]["planner"], enabled=False)), g, "test")
    cube = g.object("cube")
    state = SceneState(base=(-2.0, 0.0, 0.0), objects={"cube": ObjectPose(cube.position)})
    facts = symbolic_facts(state, g, task, [], "start")
    assert ("hand-empty",) in facts and ("item-at", "cube", f"loc_{cube.rests_on}") in facts


def test_the_monitor_sees_the_block_a_remaining_place_stacks_on_knocked_off(tower3) -> None:
    """During grasp(cube_c) the plan still places cube_c on cube_b: cube_b knocked off cube_a onto
    the table (5 cm lower, 10 cm aside, far within object_m) is a support_moved deviation; cube_b
    where the plan left it is none; and the repair is a re-sequence (a new pose cannot rebuild)."""
    from realize.repair.on_deviation import _restack
    from realize.spec.task_plans import build_task
    from realize.execution.monitor import check, expectation
    from realize.execution.settings import Tolerance
    from realize.execution.world import Observation

    task_cfg, geometry = tower3
    task = build_task({**task_cfg, "plan": ["grasp(cube_b, CubeB_g)", "place(cube_b, CubeB_on_a)",
                                           "grasp(cube_c, CubeC_g)", "place(cube_c, CubeC_on_b)"],
                       "planner": {**task_cfg["planner"], "enabled": False}}, geometry, "test")
    a = geometry.object("cube_a").position
    on_a = (a[0], a[1], a[2] + 0.05)
    start = _state(cube_a=a, cube_b=on_a, cube_c=geometry.object("cube_c").position)
    exp = expectation(task, geometry, 2, objects_at={n: p.position for n, p in start.objects.items()})
    assert set(exp.supports) == {"cube_b"}
    ok = Observation(0, 0.0, start, {}, ())
    assert [d.kind for d in check(ok, exp, Tolerance())] == []
    knocked = _state(cube_a=a, cube_b=(a[0], a[1] - 0.10, a[2]), cube_c=geometry.object("cube_c").position)
    devs = check(Observation(0, 0.0, knocked, {}, ()), exp, Tolerance())
    assert [d.kind for d in devs] == ["support_moved"] and "cube_b" in devs[0].detail
    assert _restack([str(d) for d in devs])


def test_the_monitor_leaves_a_block_the_plan_itself_carries(tower3) -> None:
    """While grasp(cube_b) lifts cube_b, the later place of cube_c on cube_b watches nothing:
    the plan moves cube_b itself before it stacks on it (cube_a, which nothing moves, is watched)."""
    from realize.spec.task_plans import build_task
    from realize.execution.monitor import expectation

    task_cfg, geometry = tower3
    task = build_task({**task_cfg, "plan": ["grasp(cube_b, CubeB_g)", "place(cube_b, CubeB_on_a)",
                                           "grasp(cube_c, CubeC_g)", "place(cube_c, CubeC_on_b)"],
                       "planner": {**task_cfg["planner"], "enabled": False}}, geometry, "test")
    assert set(expectation(task, geometry, 0).supports) == {"cube_a"}
    assert set(expectation(task, geometry, 1).supports) == {"cube_a"}  # cube_b in hand, placed on cube_a
    assert set(expectation(task, geometry, 2).supports) == {"cube_b"}
    # cube_b, stacked by the plan itself, is checked against cube_a's top wherever cube_a stands
    at2 = expectation(task, geometry, 2)
    assert "cube_b" not in at2.support_z and at2.stacked == {"cube_b": "cube_a"}


def test_a_pick_place_resequence_turns_the_tasks_planner_off(tmp_path) -> None:
    """The seed task with its PDDL planner on (task.planner.enabled=true): the cube knocked onto
    table 1 after the grasp gives the plan from that state, and the returned task has the
    planner off, so the replan's run realizes that plan rather than plan the problem again."""
    cfg = compose_config("task.planner.enabled=true")
    task_cfg = dict(cfg["task"])
    geometry = build_geometry(GeometryCfg.from_mapping(cfg["scene"], "scene"))
    cube = geometry.object("cube").position
    state = SceneState(base=(-0.8, 1.2, 0.0), objects={"cube": ObjectPose(cube)})
    new = resequence_task(task_cfg, geometry, state, tmp_path)
    assert new["plan"][0].startswith("grasp(cube") and new["planner"]["enabled"] is False
    assert task_cfg["planner"]["enabled"] is True  # the caller's mapping is left as it was


def test_a_cube_tipped_against_a_tables_edge_is_picked_up_where_it_lies(tmp_path) -> None:
    """knocked_out's world 9 (2026-12-07): the cube dropped in a place and came to rest tipped
    against table 2's edge, its centre 1 cm past the top, 8 mm above resting height. It is on no
    table's top and not on the floor; it gets a site of its own where it lies (as one on the
    floor does), so the planner picks it up from there instead of calling the problem
    unsolvable."""
    from realize.repair.resequence import lying_site, on_floor, pickup_region

    cfg = compose_config("task.planner.enabled=true")
    geometry = build_geometry(GeometryCfg.from_mapping(cfg["scene"], "scene"))
    t2 = geometry.table("table2")
    edge = (t2.center[0] + 0.09, t2.center[1] + t2.half_size[1] + 0.01, t2.top_z + 0.0225 + 0.008)
    state = SceneState(base=(0.1, -0.2, 0.0), objects={"cube": ObjectPose(edge)})
    assert not on_floor(state, geometry, "cube")
    new = resequence_task(dict(cfg["task"]), geometry, state, tmp_path)
    assert new["plan"][:2] == [f"move_to({pickup_region('cube')})", "grasp(cube, Cube_g)"], new["plan"]
    assert pickup_region("cube") in new["params"]
    assert f"(item-at cube {lying_site('cube')})" in (tmp_path / "resequence.pddl").read_text()


def test_a_new_plan_that_starts_by_placing_the_held_block_builds_from_a_state_that_holds_it(tower3, tmp_path) -> None:
    """A re-sequence from a state that holds cube B (grasp_slip's worlds 10 and 13: cube C in
    hand, cube B knocked down) begins with a place: its task builds where the plan starts with
    the block in hand, and is refused in one line where it starts empty."""
    from realize.spec.task_plans import build_task_candidates

    task, g = tower3
    new = resequence_task(task, g, _state("cube_b", cube_a=(0.0, 1.2, Z0), cube_b=(0.0, 1.1, 0.9),
                                          cube_c=(0.0, 1.4, Z0)), tmp_path)
    assert new["plan"][0].startswith("place(cube_b")
    built, _ = build_task_candidates(new, g, "task", held="cube_b")
    assert str(built.plan[0]).startswith("place(cube_b")
    with pytest.raises(ConfigError, match=r"task:plan\[0\]: .* places cube_b, but the hand is empty there"):
        build_task_candidates(new, g, "task")
