"""The batched rollout on the seed task (issue 4's must-shows), on the CPU simulator.

* a hand-chosen parameter vector succeeds: the cube physically ends on table 2 and the base in
  Exit (read back from the simulator, not from the state machine);
* a grasp region centred 30 cm from the cube fails at grasp with flags [1, 0, 0, 0, 0]: where the
  pose is reachable the gripper closes on air and the plan stops as soon as the grip is found
  empty; where it is not, the plan stops exactly at its grasp timeout; either way it is not
  simulated afterwards;
* cost == counted control steps + final cost; a batch of 3 equals each plan alone (N = 1);
  two fresh scenes given the same input give bit-identical tensors (fresh: PhysX promises
  determinism for a newly created scene; a scene that already ran other rollouts was measured to
  give the same costs and flags but trajectories a few mm apart, so reuse is not compared here);
* bad input (regions, plan, goal, YAML, Z shape) fails with a message naming file and key.

Speed: torch runs single-threaded here (beside PhysX, as ``BatchedScene`` does for N >= 8;
with torch's default pool the same small rollouts ran 3-4x slower on 2 busy cores).
"""

from __future__ import annotations

import copy
import dataclasses
import math
from pathlib import Path
from typing import Any, Iterator

import pytest
import torch
import yaml

from helpers import (FAR_SIDE, GOOD, SEED_TASK, SIDE, StepCounter, blas_batch_invariant, compose_config, run_alone,
                     run_fresh)
from realize.config import ConfigError
from realize.realization.result import RolloutResult
from realize.realization.rollout import PlanRealizer
from realize.spec.run_spec import RunSpec, build_run_spec
from realize.spec.task_plans import build_task, load_task_file
from realize.scene import BatchedScene, quat_to_matrix

VECTORS = torch.tensor([GOOD, SIDE, FAR_SIDE])  # two feasible plans of the seed task, one infeasible


# ---------------------------------------------------------------------------------- fixtures


pytestmark = pytest.mark.usefixtures("torch_single_thread")


@pytest.fixture(scope="module")
def plain_cfg() -> dict[str, Any]:
    return compose_config(f"task_file={SEED_TASK}")


@pytest.fixture(scope="module")
def spec(plain_cfg: dict[str, Any]) -> RunSpec:
    return build_run_spec(plain_cfg)


@pytest.fixture(scope="module")
def seed_task_dict() -> dict[str, Any]:
    d, _ = load_task_file(str(SEED_TASK))
    return d


def task_variant(spec: RunSpec, base: dict[str, Any], name: str, **changes: Any) -> Any:
    """The seed task with top-level keys replaced (deep copy), checked like a task file."""
    d = copy.deepcopy(base)
    d.update(copy.deepcopy(changes))
    return build_task(d, spec.geometry, name)


def _readback(scene: BatchedScene) -> dict[str, torch.Tensor]:
    """The cube's and the base's poses, read from the simulator."""
    return dict(cube=scene.object_pose("cube"), base=scene.base_pose())


@pytest.fixture(scope="module")
def alone(spec: RunSpec) -> list[dict[str, Any]]:
    """Each of VECTORS realized on its own (N = 1)."""
    return run_alone(spec, VECTORS, _readback)


@pytest.fixture(scope="module")
def batch(spec: RunSpec) -> dict[str, Any]:
    """VECTORS realized together (N = 3) in a fresh scene."""
    return run_fresh(spec, VECTORS, _readback, record=True)[0]


@pytest.fixture(scope="module")
def scene3(spec: RunSpec) -> Iterator[BatchedScene]:
    """A shared 3-copy scene for the tests that compare within one rollout."""
    with BatchedScene(3, spec.geometry_cfg, spec.sim) as s:
        yield s


# ---------------------------------------------------------------------------------- must-shows


def test_good_vector_succeeds_in_the_simulator(spec: RunSpec, alone: list[dict[str, Any]]) -> None:
    out = alone[0]
    res: RolloutResult = out["res"]
    assert res.failure == [""]
    assert res.action_success.tolist() == [[True] * 5]
    assert bool(res.goal[0]) and bool(res.feasible[0])
    g = spec.geometry
    # the cube, read from the simulator: on table 2's top, resting at its height, upright
    t2 = g.table("table2")
    cube = out["cube"][0]
    h = g.object("cube").half_height
    assert abs(float(cube[0]) - t2.center[0]) < t2.half_size[0] - h
    assert abs(float(cube[1]) - t2.center[1]) < t2.half_size[1] - h
    assert float(cube[2]) == pytest.approx(t2.top_z + h, abs=2e-3)
    assert abs(float(cube[3])) > math.cos(math.radians(10) / 2)  # tilt + yaw under ~10 deg
    # and not on table 1 any more
    t1 = g.table("table1")
    assert abs(float(cube[1]) - t1.center[1]) > t1.half_size[1]
    # the base, read from the simulator: inside Exit
    exit_ = spec.task.layout.regions["Exit"]
    base = out["base"][0]
    assert exit_.low[0] <= float(base[0]) <= exit_.high[0]
    assert exit_.low[1] <= float(base[1]) <= exit_.high[1]
    # about 490 control steps (24.5 s of robot time at 20 Hz)
    assert 400 <= int(res.steps[0]) <= 600


def test_cost_is_the_counted_steps(spec: RunSpec, alone: list[dict[str, Any]], batch: dict[str, Any]) -> None:
    for out in [*alone, batch]:
        res: RolloutResult = out["res"]
        assert torch.equal(res.cost, res.steps.float() + spec.task.final_cost)
        # the longest plan ran for every physics step the rollout took; a plan that finished all
        # its actions then let the cube settle for goal_settle_s before psi_g was read (not counted)
        settle = round(spec.rollout.goal_settle_s * spec.sim.control_freq)
        finished = res.action_success.all(dim=1)
        last = max(int(k) + (settle if f else 0) for k, f in zip(res.steps, finished))
        assert last == res.sim_steps == out["calls"]
    # plans that stop early count only their own steps
    res = batch["res"]
    assert int(res.steps[2]) < res.sim_steps


def test_final_cost_is_added(spec: RunSpec, seed_task_dict: dict[str, Any], scene3: BatchedScene,
                             monkeypatch: pytest.MonkeyPatch) -> None:
    task = task_variant(spec, seed_task_dict, "move_only.yaml", plan=["move_to(Table1)"], goal={}, final_cost=12.5)
    counter = StepCounter(scene3, monkeypatch)
    res = PlanRealizer(task, scene3, spec.rollout).rollout(torch.tensor([GOOD]))
    assert res.feasible.tolist() == [True]
    assert res.cost.tolist() == [float(res.steps[0]) + 12.5]
    assert int(res.steps[0]) == counter.calls


def test_a_rollout_leaves_ordinary_tensors_behind(spec: RunSpec, seed_task_dict: dict[str, Any],
                                                  scene3: BatchedScene) -> None:
    # rollouts run in inference mode; neither their result nor the scene they used may be left
    # with tensors that refuse in-place changes outside it
    task = task_variant(spec, seed_task_dict, "move_only.yaml", plan=["move_to(Table1)"], goal={})
    realizer = PlanRealizer(task, scene3, spec.rollout)
    res = realizer.rollout(torch.tensor([GOOD]))
    tensors = [getattr(res, f.name) for f in dataclasses.fields(res) if isinstance(getattr(res, f.name), torch.Tensor)]
    assert tensors and not any(t.is_inference() for t in tensors)
    res.cost += 1.0  # a caller may edit a result in place
    scene3.reset()
    scene3.freeze(torch.ones(scene3.n_envs, dtype=torch.bool))
    scene3.reset()
    again = realizer.rollout(torch.tensor([GOOD]))
    assert bool(again.feasible[0]) and torch.equal(again.cost, res.cost - 1.0)


def test_batched_equals_per_sample(alone: list[dict[str, Any]], batch: dict[str, Any]) -> None:
    b: RolloutResult = batch["res"]
    assert b.feasible.tolist() == [True, True, False]
    assert b.failure[2] == "1:grasp:timeout"
    for i, out in enumerate(alone):
        a: RolloutResult = out["res"]
        assert a.feasible[0] == b.feasible[i] and a.goal[0] == b.goal[i]
        assert torch.equal(a.action_success[0], b.action_success[i])
        assert a.failure[0] == b.failure[i]
        # measured: the same step counts, hence the same costs, also for copies 1 and 2
        assert a.cost[0] == b.cost[i] and a.steps[0] == b.steps[i]
        n_rec = a.traj_base.shape[1]
        if i == 0 and blas_batch_invariant():
            # copy 0 sits at the origin in both scenes: bit-identical while its plan runs (where
            # the controllers' batched products do not depend on the batch's other rows)
            assert torch.equal(a.distance[0], b.distance[i])
            for name in ("traj_base", "traj_ee", "traj_objects"):
                assert torch.equal(getattr(a, name)[0], getattr(b, name)[i, :n_rec]), name
        else:
            # copies 1 and 2 are tiled 9 m / 8 m from the origin: float32 world coordinates
            # round differently there (and, on a machine whose batched products depend on the
            # batch, copy 0 too), and the controllers' feedback carries the ulp-level
            # differences on. Measured max deviation over whole plans: base 1.9 cm / ee 0.8 cm
            # (copy 2, whose grasp pushes against its reach limit until the timeout), cube 0.2 mm.
            assert (a.traj_base[0] - b.traj_base[i, :n_rec]).abs().max() < 0.05
            assert (a.traj_ee[0] - b.traj_ee[i, :n_rec]).abs().max() < 0.05
            assert (a.traj_objects[0] - b.traj_objects[i, :n_rec]).abs().max() < 0.005
        # where everything ended, read from the simulator (a finished plan's robot still moves
        # during the physics step in which it is frozen: ~1 mm for copy 0)
        assert (out["cube"][0, :3] - batch["cube"][i, :3]).abs().max() < 0.005
        assert (out["base"][0, :2] - batch["base"][i, :2]).abs().max() < 0.02


def test_same_seed_same_numbers(spec: RunSpec, batch: dict[str, Any]) -> None:
    again = run_fresh(spec, VECTORS, _readback, record=True)[0]
    r1, r2 = batch["res"], again["res"]
    for name in ("cost", "feasible", "action_success", "goal", "steps", "progress", "distance",
                 "traj_t", "traj_base", "traj_ee", "traj_objects", "traj_object_quats"):
        assert torch.equal(getattr(r1, name), getattr(r2, name)), name
    assert r1.failure == r2.failure
    assert torch.equal(batch["cube"], again["cube"]) and torch.equal(batch["base"], again["base"])


def test_recorded_orientations_are_the_objects_own(spec: RunSpec, batch: dict[str, Any]) -> None:
    """Each recorded frame has every object's orientation beside its centre: unit quaternions;
    the first frame the cube as the scene set it (upright); the last frame of a plan that
    reached the goal the orientation the simulator reads at the end (the cube at rest by then)."""
    res, end = batch["res"], batch["cube"]
    q = res.traj_object_quats
    assert q is not None and q.shape == (*res.traj_objects.shape[:3], 4)
    assert torch.allclose(q.norm(dim=-1), torch.ones(q.shape[:3]), atol=1e-4)
    k = spec.geometry.object_index("cube")
    up = quat_to_matrix(q[:, 0, k].float())[:, 2, 2]  # the cube's z axis against the world's
    assert (up > 0.999).all(), up
    for i in torch.nonzero(res.feasible).flatten().tolist():
        dot = float((q[i, -1, k] * end[i, 3:7]).sum().abs())  # q and -q are one orientation
        assert dot > math.cos(math.radians(1.0) / 2), dot


# ---- a grasp pose 30 cm from the cube


def _move_steps(spec: RunSpec, seed_task: dict[str, Any], scene: BatchedScene, Z: torch.Tensor) -> list[int]:
    """Control steps the first move_to (to Table1) takes on its own, for each row of Z."""
    task = task_variant(spec, seed_task, "move_only.yaml", plan=["move_to(Table1)"], goal={})
    res = PlanRealizer(task, scene, spec.rollout).rollout(Z)
    assert res.feasible.all()
    return res.steps.tolist()


def _far_grasp(spec: RunSpec, seed_task: dict[str, Any], offset: tuple[float, float]) -> tuple[Any, list[float]]:
    """The seed task with the Cube_g hemisphere centred ``offset`` (m, xy) away from the cube."""
    params = copy.deepcopy(seed_task["params"])
    cube = spec.geometry.object("cube").position
    centre = [cube[0] + offset[0], cube[1] + offset[1], cube[2]]
    params["Cube_g"]["center"] = centre
    params["Cube_g"]["frame"] = "world"  # the seed task writes it relative to the cube
    task = task_variant(spec, seed_task, "far_grasp.yaml", params=params)
    return task, centre


def _with_grasp(vec: list[float], centre: list[float], table1: list[float]) -> list[float]:
    """``vec`` with Table1 replaced and the top-down point of the (moved) Cube_g hemisphere."""
    return table1 + [centre[0], centre[1], centre[2] + 0.15] + vec[5:]


def test_reachable_grasp_pose_30cm_away_fails_when_the_grip_is_empty(
        spec: RunSpec, seed_task_dict: dict[str, Any], scene3: BatchedScene) -> None:
    task, centre = _far_grasp(spec, seed_task_dict, (0.0, 0.3))  # over table 1's edge, beside the cube
    assert math.dist(centre, spec.geometry.object("cube").position) == pytest.approx(0.3)
    table1 = [[-0.85, 1.2], [0.9, 1.5]]  # the second base pose is past table 1: a longer drive
    Z = torch.tensor([_with_grasp(GOOD, centre, t) for t in table1])
    assert task.layout.contains(Z.double()).all()
    res = PlanRealizer(task, scene3, spec.rollout).rollout(Z, record=True)
    cube_after, width_after = scene3.object_pose("cube"), scene3.finger_width()
    move = _move_steps(spec, seed_task_dict, scene3, Z)
    timeout = round(spec.rollout.manip_timeout_s * scene3.sim.control_freq)
    grip = round(spec.rollout.grip_s * scene3.sim.control_freq)
    descend = math.ceil(0.15 / (spec.rollout.approach_speed / scene3.sim.control_freq))
    assert res.action_success.int().tolist() == [[1, 0, 0, 0, 0]] * 2
    assert res.goal.tolist() == [False, False] and res.feasible.tolist() == [False, False]
    assert res.failure == ["1:grasp:grasp_not_held"] * 2
    for i in range(2):
        grasp_steps = int(res.steps[i]) - move[i]
        # approach + straight descent + the full grip time, and well before the timeout
        assert descend + grip <= grasp_steps < timeout
        # the fingers closed on air (narrower than the cube), the cube was never touched
        assert float(width_after[i]) < 2 * spec.geometry.object("cube").half_height
        assert (cube_after[i, :3] - torch.tensor(spec.geometry.object("cube").position)).abs().max() < 1e-3
    # the plan that failed first was not simulated afterwards: its robot froze in place
    first = int(res.steps.argmin())
    assert int(res.steps[first]) < res.sim_steps
    k = int(res.steps[first]) // spec.rollout.record_every  # first record after its last step
    for traj in (res.traj_base, res.traj_ee):
        after = traj[first, k:]
        assert len(after) > 5 and torch.equal(after, after[:1].expand_as(after))


def test_unreachable_grasp_pose_30cm_away_stops_at_the_grasp_timeout(
        spec: RunSpec, seed_task_dict: dict[str, Any], scene3: BatchedScene) -> None:
    task, centre = _far_grasp(spec, seed_task_dict, (0.3, 0.0))  # 30 cm beyond the cube, seen from the robot
    table1 = [[-0.85, 1.2]]
    Z = torch.tensor([_with_grasp(GOOD, centre, t) for t in table1])
    res = PlanRealizer(task, scene3, spec.rollout).rollout(Z)
    cube_after = scene3.object_pose("cube")
    move = _move_steps(spec, seed_task_dict, scene3, Z)
    timeout = round(spec.rollout.manip_timeout_s * scene3.sim.control_freq)
    assert res.action_success.int().tolist() == [[1, 0, 0, 0, 0]]
    assert res.goal.tolist() == [False] and res.feasible.tolist() == [False]
    assert res.failure == ["1:grasp:timeout"]
    # stopped exactly at the grasp timeout: nothing of the plan after it was simulated
    assert int(res.steps[0]) == move[0] + timeout == res.sim_steps
    assert float(res.cost[0]) == move[0] + timeout
    assert float(res.distance[0]) > 0.05  # the TCP never got near its target
    assert (cube_after[0, :3] - torch.tensor(spec.geometry.object("cube").position)).abs().max() < 1e-3


# ---------------------------------------------------------------------------------- bad input


def _bad_task(tmp_path: Path, plain_cfg: dict[str, Any], seed_task: dict[str, Any], name: str,
              edit: Any = None, text: str | None = None) -> tuple[str, Path]:
    """Write a broken task file, build the run spec a run builds from it, return the error."""
    path = tmp_path / f"{name}.yaml"
    if text is None:
        d = copy.deepcopy(seed_task)
        edit(d)
        text = yaml.safe_dump(d, sort_keys=False)
    path.write_text(text)
    with pytest.raises(ConfigError) as e:
        build_run_spec(dict(plain_cfg, task_file=str(path)))
    msg = str(e.value)
    assert "\n" not in msg
    return msg, path


def test_negative_radius(tmp_path: Path, plain_cfg: dict[str, Any], seed_task_dict: dict[str, Any]) -> None:
    msg, path = _bad_task(tmp_path, plain_cfg, seed_task_dict, "neg_radius",
                          lambda d: d["params"]["Cube_g"].update(radius=-0.15))
    assert f"{path}:params.Cube_g" in msg and "radius" in msg and "-0.15" in msg
    msg, path = _bad_task(tmp_path, plain_cfg, seed_task_dict, "neg_annulus",
                          lambda d: d["params"]["Table1"].update(r_min=-0.2))
    assert f"{path}:params.Table1" in msg and "r_min" in msg


@pytest.mark.parametrize("low,high", [([2.6, -0.4], [1.8, 0.4]), ([1.8, 0.4], [2.6, 0.4])])
def test_empty_box(tmp_path: Path, plain_cfg: dict[str, Any], seed_task_dict: dict[str, Any],
                   low: list[float], high: list[float]) -> None:
    msg, path = _bad_task(tmp_path, plain_cfg, seed_task_dict, "empty_box",
                          lambda d: d["params"]["Exit"].update(low=low, high=high))
    assert f"{path}:params.Exit" in msg and "low" in msg and "high" in msg and "empty" in msg


def test_action_bound_to_undefined_parameter(tmp_path: Path, plain_cfg: dict[str, Any],
                                             seed_task_dict: dict[str, Any]) -> None:
    msg, path = _bad_task(tmp_path, plain_cfg, seed_task_dict, "undefined_param",
                          lambda d: d["plan"].__setitem__(1, "grasp(cube, Cube_x)"))
    assert f"{path}:plan[1]" in msg and "'Cube_x'" in msg and "undefined parameter" in msg


def test_unknown_action_template(tmp_path: Path, plain_cfg: dict[str, Any], seed_task_dict: dict[str, Any]) -> None:
    msg, path = _bad_task(tmp_path, plain_cfg, seed_task_dict, "unknown_template",
                          lambda d: d["plan"].__setitem__(3, "throw(Cube_p)"))
    assert f"{path}:plan[3]" in msg and "'throw'" in msg and "unknown action template" in msg


def test_goal_names_unknown_object(tmp_path: Path, plain_cfg: dict[str, Any], seed_task_dict: dict[str, Any]) -> None:
    msg, path = _bad_task(tmp_path, plain_cfg, seed_task_dict, "unknown_table",
                          lambda d: d["goal"]["rests_on"].update(cube="table3"))
    assert f"{path}:goal.rests_on.cube" in msg and "'table3'" in msg
    msg, path = _bad_task(tmp_path, plain_cfg, seed_task_dict, "unknown_exit",
                          lambda d: d["goal"].update(base_in="Exit2"))
    assert f"{path}:goal.base_in" in msg and "'Exit2'" in msg


def test_malformed_yaml(tmp_path: Path, plain_cfg: dict[str, Any], seed_task_dict: dict[str, Any]) -> None:
    text = SEED_TASK.read_text().replace("Exit: {type: box, low: [1.8, -0.4], high: [2.6, 0.4]}",
                                         "Exit: {type: box, low: [1.8, -0.4], high: [2.6, 0.4]")
    assert text != SEED_TASK.read_text()
    msg, path = _bad_task(tmp_path, plain_cfg, seed_task_dict, "malformed", text=text)
    assert "task_file" in msg and str(path) in msg and "not valid YAML" in msg and "line" in msg


@pytest.mark.parametrize("shape", [(3, 11), (3, 13), (12,), (4, 12)])
def test_wrong_z_shape(spec: RunSpec, scene3: BatchedScene, shape: tuple[int, ...],
                      monkeypatch: pytest.MonkeyPatch) -> None:
    realizer = PlanRealizer(spec.task, scene3, spec.rollout)
    counter = StepCounter(scene3, monkeypatch)
    with pytest.raises(ValueError) as e:
        realizer.rollout(torch.zeros(shape))
    msg = str(e.value)
    if shape == (4, 12):
        assert "4 samples" in msg and "3 copies" in msg and "ce.n_envs" in msg
    else:
        assert "Z must be (M, 12)" in msg and str(tuple(shape)) in msg
    assert counter.calls == 0  # nothing simulated


def test_place_takes_a_box_of_release_points_grasp_does_not() -> None:
    from realize.realization.actions.grasp import Grasp
    from realize.realization.actions.place import Place
    from realize.tasks.regions import Box as BoxRegion

    box3 = BoxRegion([-0.1, -1.4, 0.76], [0.1, -0.1, 1.15])
    assert Place.accepts(box3) and not Grasp.accepts(box3)
    assert not Place.accepts(BoxRegion([0.0, 0.0], [1.0, 1.0]))


# wide-region ramp task (configs/experiment/ramp.yaml), two plans found by CE (ramp study, seed 0):
# columns: Table1.x, Table1.y, Cube_g.x, Cube_g.y, Cube_g.z, Drop.x, Drop.y,
#          Cube_p.x, Cube_p.y, Cube_p.z, Exit.x, Exit.y
RAMP_SLIDE = [-0.734, 1.046, -0.047, 1.177, 0.883, -0.379, -0.049, 0.024, -0.459, 1.037, 2.454, 0.176]
RAMP_CARRY = [-0.893, 1.843, 0.067, 1.219, 0.875, 0.755, -0.459, 0.064, -1.005, 0.881, 2.106, 0.023]


def test_ramp_slide_and_carry_both_put_the_cube_on_table2() -> None:
    """The journal's ramp scenario, both modes: released over the ramp (y = -0.46, 45 cm short of
    table 2) the cube slides down onto table 2; carried, it is set down on table 2's edge. Read
    back from the simulator's cube pose at the end, not from the state machine."""
    spec = build_run_spec(compose_config("experiment=ramp"))
    with BatchedScene(2, spec.geometry_cfg, spec.sim) as scene:
        realizer = PlanRealizer(spec.task, scene, spec.rollout, seed=0)
        res = realizer.rollout(torch.tensor([RAMP_SLIDE, RAMP_CARRY], dtype=torch.float64))
        cube = scene.object_pose("cube")[:, :3]
    assert res.feasible.tolist() == [True, True], res.failure
    t2 = scene.geometry.table("table2")
    assert ((cube[:, 1] - t2.center[1]).abs() <= t2.half_size[1]).all()
    assert ((cube[:, 2] - (2 * t2.half_size[2] + scene.geometry.object("cube").half_height)).abs() < 0.01).all()
    ramp = next(b for b in scene.geometry.obstacles if b.name == "ramp")
    assert ramp.contains_xy(RAMP_SLIDE[7], RAMP_SLIDE[8]) and not t2.contains_xy(RAMP_SLIDE[7], RAMP_SLIDE[8])


# wide-region task, plain scene: the seed grasp, then the cube let go over the floor between the tables
FLOOR_DROP = [-0.85, 1.2, 0.0, 1.2, 0.8925, -0.8, -0.5, 0.0, -0.5, 0.9, 2.2, 0.0]


def test_goal_failure_ranks_by_distance_to_the_goal() -> None:
    """A plan whose actions all succeed but whose cube ends on the floor fails at the goal, and
    its distance-to-success (the CE fallback's tie-break) is the cube's distance to table 2's
    top, computed here independently from the simulator's final cube pose."""
    spec = build_run_spec(compose_config("task=pick_place_wide"))
    with BatchedScene(1, spec.geometry_cfg, spec.sim) as scene:
        res = PlanRealizer(spec.task, scene, spec.rollout, seed=0).rollout(
            torch.tensor([FLOOR_DROP], dtype=torch.float64))
        cube = scene.object_pose("cube")[0, :3]
    assert res.failure == ["5:goal:goal_not_reached"] and res.action_success.all()
    t2 = scene.geometry.table("table2")
    top = 2 * t2.half_size[2] + scene.geometry.object("cube").half_height
    dx = max(abs(float(cube[0]) - t2.center[0]) - t2.half_size[0], 0.0)
    dy = max(abs(float(cube[1]) - t2.center[1]) - t2.half_size[1], 0.0)
    dz = max(abs(float(cube[2]) - top) - 0.02, 0.0)
    assert float(res.distance[0]) == pytest.approx(math.sqrt(dx * dx + dy * dy + dz * dz), abs=1e-4)
    assert float(res.distance[0]) > 0.5
