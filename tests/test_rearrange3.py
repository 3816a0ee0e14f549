"""``experiment=rearrange3`` (issue 57): three cubes from table 1 to given spots on table 2 with the
mobile robot. The preset composes (Fetch, three cubes on table 1, the goal's spots on table 2), the
PDDL planner returns one trip per cube (12 actions, every region bound once), and
``stitch.cut=after_each_place`` cuts it into three trips whose tasks bind disjoint parameters. The
slow tests simulate: a hand-chosen plan (the seed task's trip, shifted along y to each cube and its
spot) puts all three cubes on their spots, and a tiny search runs end to end."""

from __future__ import annotations

from pathlib import Path

import pytest

import torch

from helpers import compose_config, realize_result
from realize.spec.run_spec import build_run_spec, read_ce, read_stitch
from realize.realization.rollout import PlanRealizer
from realize.scene import BatchedScene
from realize.spec.task_plans import PlannerSettings, build_task_candidates
from realize.config import as_mapping
from realize.tasks.split import chain_tasks
from realize.world.geometry import GeometryCfg, build_geometry

CUBES = "abc"


def _task(*overrides: str):
    """The composed config, its geometry and its task, planned (as ``build_run_spec`` reads them)."""
    d = compose_config(*overrides)
    geometry = build_geometry(GeometryCfg.from_mapping(as_mapping(d["scene"], "scene"), "scene"))
    planner = PlannerSettings.from_mapping(d["task"]["planner"], "task:planner")
    task, _ = build_task_candidates(d["task"], geometry, "task", planner)
    return d, geometry, task


@pytest.fixture(scope="module")
def planned():
    return _task("experiment=rearrange3")


def test_the_preset_plans_one_trip_per_cube(planned) -> None:
    d, geometry, task = planned
    assert d["robot"]["name"] == "fetch_omni" and d["ce"]["n_envs"] == 200 and d["ce"]["iterations"] == 10
    assert sorted(geometry.object_names) == [f"cube_{c}" for c in CUBES]
    assert all(geometry.object(f"cube_{c}").position[1] > 0.5 for c in CUBES)  # all three on table 1 (y = 1.2)
    expected = []
    for c in CUBES:
        u = c.upper()
        expected += [f"move_to(Table1{u})", f"grasp(cube_{c}, Cube{u}_g)", f"move_to(Table2{u})",
                     f"place(cube_{c}, Cube{u}_p)"]
    assert task.n_actions == 12 and task.describe() == ", ".join(expected)
    bound = [p for a in task.plan for p in a.params]
    assert len(bound) == len(set(bound)) == 12  # every region once: a chain may cut after any place
    assert {o: a.region for o, a in task.goal.at.items()} == {f"cube_{c}": f"Spot{c.upper()}" for c in CUBES}
    assert not task.goal.on and task.goal.base_in is None


def test_after_each_place_cuts_the_plan_into_three_trips(planned) -> None:
    _, _, task = planned
    d = compose_config("experiment=rearrange3", "levers=stitched", "stitch.cut=after_each_place", "stitch.credit=3")
    st = read_stitch(d["stitch"], read_ce(d["ce"], d["seed"]), task)
    assert st is not None and st.chain and st.cuts == (4, 8)
    parts, cols = chain_tasks(task, list(st.cuts))
    assert [p.n_actions for p in parts] == [4, 4, 4]
    assert sorted(c for cs in cols for c in cs) == list(range(task.layout.dim))
    assert parts[-1].goal == task.goal and not parts[0].goal.at


@pytest.mark.slow  # a 12-action rollout (about 5 s on a CPU core)
def test_a_hand_chosen_plan_puts_every_cube_on_its_spot() -> None:
    spec = build_run_spec(compose_config("experiment=rearrange3"))
    table_top, half = 0.72, 0.0225
    world = {}  # each region's value in the world frame: the seed task's trip (tests/helpers.py GOOD), shifted by dy
    for c, dy in zip("ABC", (-0.2, 0.0, 0.2)):
        world |= {f"Table1{c}": [-0.85, 1.2 + dy], f"Cube{c}_g": [0.0, 1.2 + dy, table_top + half + 0.15],
                  f"Table2{c}": [-0.85, -1.2 + dy], f"Cube{c}_p": [0.0, -1.2 + dy, table_top + half + 0.155],
                  f"Spot{c}": [0.0, -1.2 + dy, table_top + half]}
    z = torch.tensor([[v for n in spec.task.layout.names for v in world[n]]], dtype=torch.float64)
    assert z.shape[1] == spec.task.layout.dim
    with BatchedScene(1, spec.geometry_cfg, spec.sim) as scene:
        scene.reset()
        res = PlanRealizer(spec.task, scene, spec.rollout, seed=0).rollout(z)
    assert bool(res.feasible[0]) and bool(res.action_success.all()), res.failure
    assert 800 < float(res.cost[0]) < 1500  # 1076 control steps when written


@pytest.mark.slow  # a (tiny) whole run: make test-all
def test_a_tiny_run_goes_end_to_end(tmp_path: Path) -> None:
    res = realize_result("experiment=rearrange3", "ce.n_envs=8", "ce.n_elite=2", "ce.iterations=1",
                         "validation=off", "logging.rerun=false", "logging.progress=false", "workers.n=1",
                         run_dir=tmp_path / "run")
    assert res["status"] == "done" and len(res["success_per_iter"]) == 1
