"""The move-and-push scenario (scene=push, task=move_and_push) on the CPU simulator.

* a hand-chosen push plan (base on the stick's far side from the box, push the upper part
  towards the box) makes the cube physically end in the box, read from the simulator's cube pose;
* the same push from the side (towards -y) knocks the stick over too, but the cube misses the box;
* a batch of both equals each plan alone (N = 1);
* the scene resets deterministically: a second rollout in the same (used) scene and one in a
  fresh scene give bit-identical results, stick included;
* bad push regions and push settings fail with an error naming the key;
* carry-or-push: both PDDL skeletons realize with hand-chosen parameters, carry cheaper.
"""

from __future__ import annotations

import copy
from typing import Any

import numpy as np
import pytest
import torch

from helpers import blas_batch_invariant, compose_config as _compose, run_alone, run_fresh
from realize.config import ConfigError
from realize.tasks.goals import object_in_container
from realize.realization.result import RolloutResult
from realize.realization.rollout import PlanRealizer
from realize.spec.run_spec import RunSpec, build_run_spec
from realize.spec.task_plans import build_task
from realize.scene import BatchedScene

# columns: PushSide.x, PushSide.y, Stick_p.x, Stick_p.y, Stick_p.z
TOWARDS_BOX = [-0.75, 0.0, 0.0, 0.0, 0.55]  # the box is at +x: push from -x
SIDEWAYS = [0.0, 0.75, 0.0, 0.0, 0.55]  # push towards -y: the cube lands beside the box
VECTORS = torch.tensor([TOWARDS_BOX, SIDEWAYS], dtype=torch.float64)


def compose_config(*overrides: str, experiment: str = "move_and_push") -> dict[str, Any]:
    return _compose(f"experiment={experiment}", *overrides)


pytestmark = pytest.mark.usefixtures("torch_single_thread")


@pytest.fixture(scope="module")
def cfg() -> dict[str, Any]:
    return compose_config()


@pytest.fixture(scope="module")
def spec(cfg: dict[str, Any]) -> RunSpec:
    return build_run_spec(cfg)


def _readback(scene: BatchedScene) -> dict[str, torch.Tensor]:
    poses = [s._bodies[0].get_entity_pose() for s in scene.u.object_actors["stick"]]
    stick = torch.from_numpy(np.array([np.concatenate([p.p, p.q]) for p in poses], dtype=np.float32))
    stick[:, :2] -= torch.as_tensor(scene.u.offsets, dtype=torch.float32)
    return dict(cube=scene.object_pose("cube"), speed=scene.object_velocity("cube")[:, :3].norm(dim=1), stick=stick)


@pytest.fixture(scope="module")
def batch(spec: RunSpec) -> list[dict[str, Any]]:
    """VECTORS realized together, twice in the same scene."""
    return run_fresh(spec, VECTORS, _readback, record=True, repeat=2)


@pytest.fixture(scope="module")
def alone(spec: RunSpec) -> list[dict[str, Any]]:
    """Each of VECTORS realized on its own (N = 1)."""
    return run_alone(spec, VECTORS, _readback)


def test_push_towards_the_box_drops_the_cube_in(spec: RunSpec, batch: list[dict[str, Any]]) -> None:
    res: RolloutResult = batch[0]["res"]
    assert res.action_success[0].tolist() == [True, True]
    assert res.feasible[0] and res.failure[0] == ""
    # the physical fact, from the simulator: the cube lies on the box's floor, inside its walls
    g = spec.geometry
    box = g.container("box")
    cube = batch[0]["cube"][0]
    assert abs(float(cube[0]) - box.center[0]) <= box.half_size[0] - g.container_wall("box")
    assert abs(float(cube[1]) - box.center[1]) <= box.half_size[1] - g.container_wall("box")
    assert float(cube[2]) < 2 * box.half_size[2]
    assert object_in_container(batch[0]["cube"][:1, :3], batch[0]["speed"][:1], g, "box").item()
    # the stick lies on its side (it was pushed over), no longer upright
    stick = batch[0]["stick"][0]
    assert float(stick[2]) < 0.5 * g.object("stick").position[2]
    # push cost is the counted steps (drive + push), well under the horizon
    assert 150 <= float(res.cost[0]) <= 600


def test_push_from_the_wrong_side_misses(spec: RunSpec, batch: list[dict[str, Any]]) -> None:
    res: RolloutResult = batch[0]["res"]
    assert not res.feasible[1]
    assert not object_in_container(batch[0]["cube"][1:2, :3], batch[0]["speed"][1:2], spec.geometry, "box").item()
    # both actions were carried out; the cube simply is not in the box
    assert res.action_success[1].tolist() == [True, True]
    assert res.failure[1] == "2:goal:goal_not_reached"
    assert float(batch[0]["cube"][1, 1]) < spec.geometry.container("box").center[1] - 0.5  # fell towards -y


def test_batched_equals_per_sample(batch: list[dict[str, Any]], alone: list[dict[str, Any]]) -> None:
    b: RolloutResult = batch[0]["res"]
    for i, out in enumerate(alone):
        a: RolloutResult = out["res"]
        assert a.feasible[0] == b.feasible[i] and a.goal[0] == b.goal[i]
        assert torch.equal(a.action_success[0], b.action_success[i]) and a.failure[0] == b.failure[i]
        assert a.cost[0] == b.cost[i]
        if i == 0:  # copy 0 sits at the origin in both scenes: bit-identical
            n_rec = a.traj_objects.shape[1]
            assert torch.equal(a.traj_objects[0], b.traj_objects[0, :n_rec])
            assert torch.equal(out["cube"][0], batch[0]["cube"][0])
        # tiled copies round their world coordinates differently (see tests/test_rollout.py); where
        # the batched products also depend on the batch's other rows, the cube that tumbles off
        # the stick onto the floor (copy 1) lands up to ~7 cm apart (measured on an AMD EPYC)
        tol = 0.03 if blas_batch_invariant() else 0.1
        assert (out["cube"][0, :3] - batch[0]["cube"][i, :3]).abs().max() < tol


def test_reset_is_deterministic(spec: RunSpec, batch: list[dict[str, Any]]) -> None:
    """The second rollout in the used scene and one in a fresh scene equal the first, bit for bit:
    reset takes the cubes and the sticks out of the PhysX scene and back in, in an order that
    gives every body its own internal handle back (the cube resting on the stick is solved in
    the same order; out-and-in one by one was measured ~1 cm apart after a push)."""
    fresh = run_fresh(spec, VECTORS, _readback, record=True)[0]
    first = batch[0]
    for other in (batch[1], fresh):
        r1, r2 = first["res"], other["res"]
        for name in ("cost", "feasible", "action_success", "goal", "steps", "distance", "traj_objects", "traj_ee",
                     "traj_base"):
            assert torch.equal(getattr(r1, name), getattr(r2, name)), name
        assert torch.equal(first["cube"], other["cube"]) and torch.equal(first["stick"], other["stick"])


def test_reset_puts_the_stick_back_upright(spec: RunSpec) -> None:
    with BatchedScene(2, spec.geometry_cfg, spec.sim) as scene:
        scene.reset()
        start = _readback(scene)
        PlanRealizer(spec.task, scene, spec.rollout).rollout(VECTORS[:1])
        assert float(_readback(scene)["stick"][0, 2]) < 0.2  # knocked over
        scene.reset()
        again = _readback(scene)
        assert torch.equal(start["stick"], again["stick"]) and torch.equal(start["cube"], again["cube"])


# ---------------------------------------------------------------------------------- bad input


def _task(cfg: dict[str, Any], **params: Any) -> dict[str, Any]:
    d = copy.deepcopy(cfg["task"])
    d["params"].update(params)
    return d


def test_push_bound_to_a_planar_region_names_the_key(cfg: dict[str, Any], spec: RunSpec) -> None:
    d = _task(cfg, Stick_p={"type": "box", "low": [-0.04, -0.04], "high": [0.04, 0.04]})
    with pytest.raises(ConfigError) as e:
        build_task(d, spec.geometry, "push_task.yaml")
    msg = str(e.value)
    assert "push_task.yaml:plan[1]" in msg and "Stick_p" in msg and "push" in msg


def test_bad_push_region_names_the_key(cfg: dict[str, Any], spec: RunSpec) -> None:
    d = _task(cfg, Stick_p={"type": "box", "low": [0.04, -0.04, 0.35], "high": [-0.04, 0.04, 0.68]})
    with pytest.raises(ConfigError) as e:
        build_task(d, spec.geometry, "push_task.yaml")
    assert "push_task.yaml:params.Stick_p" in str(e.value)
    d = _task(cfg, Stick_p={"type": "hemisphere", "center": [0, 0, 0.72], "radius": 0.15})
    with pytest.raises(ConfigError, match=r"plan\[1\].*Stick_p.*push"):
        build_task(d, spec.geometry, "push_task.yaml")


@pytest.mark.parametrize("key,value", [("push_depth", -0.1), ("push_speed", 0.0), ("push_pre_distance", float("nan")),
                                       ("goal_settle_s", -1.0)])
def test_bad_push_setting_names_the_key(key: str, value: float) -> None:
    from realize.realization.config import RolloutConfig

    with pytest.raises(ConfigError, match=rf"controller\.{key} = "):
        RolloutConfig.from_mapping({key: value})


def test_goal_names_unknown_container(cfg: dict[str, Any], spec: RunSpec) -> None:
    d = copy.deepcopy(cfg["task"])
    d["goal"] = {"rests_in": {"cube": "crate"}}
    with pytest.raises(ConfigError, match=r"goal\.rests_in\.cube = 'crate' names no container.*\['box'\]"):
        build_task(d, spec.geometry, "push_task.yaml")


# ---------------------------------------------------------------------------------- carry or push

# columns: PushSide.xy, Stick_p.xyz, StickSide.xy, BoxSide.xy (unused here), Cube_g.xyz (top-down),
#          Cube_p.xyz (top-down)
CARRY_OR_PUSH = [-0.75, 0.0, 0.0, 0.0, 0.55, 0.45, -0.85, 1.1, -0.8, 0.0, 0.0, 0.8725, 0.8, 0.0, 0.57]


def test_carry_or_push_both_skeletons_realize_and_carry_is_cheaper() -> None:
    """The two skeletons of configs/pddl/carry_or_push_*.pddl, realized with hand-chosen
    parameters in scene=carry_or_push: both put the cube in the box, and carry (3 actions)
    costs fewer control steps than push (2 actions, but a long drive round the box)."""
    d = compose_config("task.planner.enabled=false", experiment="carry_or_push")
    assert d["scene"]["robot_start"][:2] == [0.45, -0.85]
    cost = {}
    for name, plan in (("push", ["move_to(PushSide)", "push(stick, Stick_p)"]),
                       ("carry", ["move_to(StickSide)", "grasp(cube, Cube_g)", "place(cube, Cube_p)"])):
        d["task"]["plan"] = plan
        spec = build_run_spec(d)
        res = run_fresh(spec, torch.tensor([CARRY_OR_PUSH], dtype=torch.float64), _readback)[0]
        assert res["res"].feasible.tolist() == [True], (name, res["res"].failure)
        assert object_in_container(res["cube"][:, :3], res["speed"], spec.geometry, "box").item()
        cost[name] = float(res["res"].cost[0])
    # measured: push 523, carry 437 control steps
    assert cost["carry"] < cost["push"], cost
