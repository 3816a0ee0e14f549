"""The world side of execution (realize/execution/): disturbances read and drawn, the one-copy
execution world and what its disturbances do in physics, belief updates the run config accepts,
the monitor's checks and the trajectory file. One-copy scenes and short simulations only."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
import torch

from helpers import compose_config
from realize.spec.run_spec import build_run_spec
from realize.config import ConfigError
from realize.execution.schedule import Schedule
from realize.execution.disturbances import (AddBox, KnockOut, MoveObject, MoveTable, PushBase, Scheduled,
                                            Trigger, draw, read_disturbances)
from realize.execution.monitor import KINDS, Deviation, check, expectation, held_by_plan
from realize.execution.settings import ExecuteSettings, Tolerance, load_preset, presets
from realize.execution.trajectory import TRAJECTORY_FORMAT, TrajectoryLog, read_trajectory
from realize.execution.layout_updates import apply_geometry_updates, geometry_changes, geometry_now, geometry_updates
from realize.execution.world import BoxSeen, ExecutionWorld, Observation, TablePose
from realize.world.geometry import build_geometry
from realize.world.state import ObjectPose, SceneState, load_state

FIXTURE = Path(__file__).parent / "fixtures" / "state_grasped.json"  # the cube in the hand above table 1
CUBE_HALF = 0.0225
TABLE_TOP = 0.72


@pytest.fixture(scope="module")
def spec():
    return build_run_spec(compose_config())


def _plan(spec) -> list[str]:
    return [str(a) for a in spec.task.plan]


def _read(spec, entries):
    return read_disturbances(entries, spec.geometry, _plan(spec))


def _drop(world: ExecutionWorld, x: float, y: float, steps: int = 30) -> float:
    """Drop the cube from 1 m at (x, y); the z where it comes to rest."""
    world.scene.place_object("cube", torch.tensor([[x, y, 1.0]]))
    for _ in range(steps):
        world.scene.step()
    return float(world.scene.object_pose("cube")[0, 2])


# ------------------------------------------------------------------------------ reading, drawing
@pytest.mark.parametrize("entry, needles", [
    ({"trigger": {"action": 0}, "move_object": {"object": "ball", "dx": 0.1}}, ["move_object.object", "'ball'", "cube"]),
    ({"trigger": {"action": 0}, "move_table": {"table": "table3", "dx": 0.1}}, ["table3", "table1", "table2"]),
    ({"trigger": {"action": 5}, "knock_out": {"object": "cube"}}, ["trigger.action = 5", "5 actions"]),
    ({"trigger": {"action": -1}, "knock_out": {"object": "cube"}}, ["trigger.action = -1", "5 actions"]),
    ({"trigger": {"action": 0}, "teleport": {"object": "cube"}}, ["unknown effect 'teleport'", "move_object"]),
    ({"trigger": {"action": 0}, "push_base": {"dx": 0.1, "spin": 1}}, ["unknown key(s) ['spin']"]),
    ({"trigger": {"action": 0, "delay": 1}, "push_base": {"dx": 0.1}}, ["unknown key(s) ['delay']"]),
    ({"trigger": {"when": "held", "object": "bowl"}, "knock_out": {"object": "cube"}}, ["trigger.object", "bowl"]),
    ({"trigger": {"when": "dropped", "object": "cube"}, "knock_out": {"object": "cube"}}, ["when = 'dropped'"]),
    ({"trigger": {"action": 0}, "move_table": {"table": "table2", "distance": [-0.1, 0.2]}}, ["distance[0]", ">= 0"]),
    ({"trigger": {"action": 0}, "move_table": {"table": "table2", "distance": [0.3, 0.2]}}, ["empty range"]),
    ({"trigger": {"action": 0}, "add_box": {"center": [0, 0], "size": [0.5, -0.5, 0.5]}}, ["size[1]", ">= 0"]),
    ({"trigger": {"action": 0}, "add_box": {"between": ["table1", "table9"], "size": [0.5, 0.5, 0.5]}}, ["table9"]),
    ({"trigger": {"action": 0, "delay_s": -1.0}, "push_base": {"dx": 0.1}}, ["delay_s = -1.0", ">= 0"]),
    ({"move_object": {"object": "cube", "dx": 0.1}}, ["no trigger"]),
])
def test_bad_disturbances_are_refused_in_one_line_before_any_simulation(spec, no_sim, entry, needles) -> None:
    with pytest.raises(ConfigError) as ei:
        _read(spec, [{"trigger": {"action": 0}, "push_base": {"dx": 0.0, "dy": 0.1}}, entry])
    msg = str(ei.value)
    assert "\n" not in msg and msg.startswith("disturbances[1]"), msg
    for n in needles:
        assert n in msg, (n, msg)


def test_a_preset_writes_no_default_twice() -> None:
    """A preset holds its disturbances and what it changes; a key at ExecuteSettings' default is
    written once, in realize/execution/settings.py (the five presets used to repeat six keys)."""
    import dataclasses

    import yaml

    from realize.execution.settings import PRESET_DIR

    defaults = dataclasses.asdict(ExecuteSettings())
    for name in presets():
        raw = yaml.safe_load((PRESET_DIR / f"{name}.yaml").read_text()) or {}
        again = sorted(k for k, v in raw.items() if k != "disturbances" and defaults.get(k) == v)
        assert not again, f"configs/execute/{name}.yaml repeats the default of {again}"


def test_presets_read_against_the_seed_task(spec, no_sim) -> None:
    assert {"none", "cube_moved", "table_moved", "knocked_out", "obstacle"} <= set(presets())
    kinds = {}
    for name in presets():
        s = load_preset(name)
        assert isinstance(s, ExecuteSettings) and s.worlds >= 1 and s.monitor_every >= 1
        if name in TOWER3_FAMILIES:  # robot=panda experiment=tower3's: test_tower3_families_read_...
            continue
        kinds[name] = [d.kind for d in _read(spec, s.disturbances)]
    assert kinds["none"] == [] and kinds["cube_moved"] == ["move_object"] and kinds["table_moved"] == ["move_table"]
    assert kinds["knocked_out"] == ["knock_out"] and kinds["obstacle"] == ["add_box"]
    with pytest.raises(ConfigError, match="unknown key"):
        ExecuteSettings.from_mapping({"worlds": 2, "replans": 1})
    with pytest.raises(ConfigError, match="execute preset 'nope' is unknown"):
        load_preset("nope")


# ------------------------------------------------------------------------------ knock_out's displacement
TOWER3_FAMILIES = ("tower_knocked", "block_moved", "grasp_slip")  # families of robot=panda experiment=tower3
TOWER3_PLAN = ["grasp(cube_b, CubeB_g)", "place(cube_b, CubeB_on_a)", "grasp(cube_c, CubeC_g)",
               "place(cube_c, CubeC_on_b)"]


@pytest.fixture(scope="module")
def tower3_geometry():
    from realize.world.geometry import GeometryCfg

    return build_geometry(GeometryCfg.from_mapping(compose_config("robot=panda", "experiment=tower3")["scene"],
                                                   "scene"))


def test_tower3_families_read_against_the_tower3_scene(tower3_geometry, no_sim) -> None:
    kinds = {n: read_disturbances(load_preset(n).disturbances, tower3_geometry, TOWER3_PLAN) for n in TOWER3_FAMILIES}
    knocked, = kinds["tower_knocked"]
    assert knocked.kind == "knock_out" and knocked.target == "cube_b" and knocked.trigger.action == 2
    assert knocked.move is not None and knocked.move.distance == (0.08, 0.12)
    moved, = kinds["block_moved"]
    assert moved.kind == "move_object" and moved.trigger.action is not None and moved.trigger.action < 2
    slip, = kinds["grasp_slip"]
    assert slip.kind == "knock_out" and slip.move is None and slip.trigger.when == "held"
    with pytest.raises(ConfigError, match="no object of that name"):
        read_disturbances(load_preset("knocked_out").disturbances, tower3_geometry, TOWER3_PLAN)


@pytest.mark.parametrize("keys, needles", [
    ({"direction_deg": [0, 90]}, ["knock_out.direction_deg", "goes with distance"]),
    ({"dx": 0.1, "distance": [0.1, 0.2]}, ["knock_out.dx = 0.1", "not both"]),
    ({"distance": [-0.1, 0.1]}, ["knock_out.distance[0]", ">= 0"]),
    ({"distance": [0.2, 0.1]}, ["knock_out.distance", "empty range"]),
    ({"distance": 0.1}, ["knock_out.distance = 0.1", "list of 2 numbers"]),
    ({"dx": "far"}, ["knock_out.dx = 'far'", "finite number"]),
    ({"distance": [0.1, 0.2], "direction_deg": [90, 0]}, ["knock_out.direction_deg", "empty range"]),
    ({"dz": 0.1}, ["unknown key(s) ['dz']"]),
])
def test_knock_out_displacement_keys_are_checked_in_one_line(spec, no_sim, keys, needles) -> None:
    with pytest.raises(ConfigError) as ei:
        _read(spec, [{"trigger": {"action": 2}, "knock_out": {"object": "cube", **keys}}])
    msg = str(ei.value)
    assert "\n" not in msg and msg.startswith("disturbances[0]"), msg
    for n in needles:
        assert n in msg, (n, msg)


def test_knock_out_displacement_is_read_and_drawn_per_world(spec) -> None:
    plain, fixed, drawn, table = _read(spec, [
        {"trigger": {"action": 2}, "knock_out": {"object": "cube"}},
        {"trigger": {"action": 2}, "knock_out": {"object": "cube", "dx": 0.1, "dy": -0.05}},
        {"trigger": {"action": 2}, "knock_out": {"object": "cube", "distance": [0.08, 0.12],
                                                 "direction_deg": [180, 270]}},
        {"trigger": {"action": 2}, "move_table": {"table": "table2", "distance": [0.2, 0.4]}}])
    assert plain.move is None  # no displacement: today's effect, and nothing drawn for it
    for seed in range(5):
        a = draw([plain, fixed, drawn, table], np.random.default_rng(seed))
        assert a[0].effect == KnockOut("cube") and a[1].effect == KnockOut("cube", 0.1, -0.05)
        k = a[2].effect
        assert isinstance(k, KnockOut) and 0.08 <= math.hypot(k.dx, k.dy) <= 0.12 and k.dx <= 1e-12 and k.dy <= 1e-12
        # the plain knock_out draws no number: the table's draw is that of a list without it
        assert draw([fixed, drawn, table], np.random.default_rng(seed))[2] == a[3]


def test_knock_out_with_a_displacement_lands_beside_upright_at_rest(spec) -> None:
    """The held cube knocked 12 cm sideways: it rests on table 1's top there, upright."""
    with ExecutionWorld(spec, 0, perturb=False) as w:
        w.scene.reset(state=load_state(FIXTURE))
        before = w.observe().state.objects["cube"].position
        line = w.apply(KnockOut("cube", 0.0, -0.12))
        assert "out of the hand by (+0.000, -0.120) m onto table1" in line
        for _ in range(20):
            w.scene.step()
        pose = w.observe().state.objects["cube"]
        p, q = pose.position, pose.quaternion
        assert p[2] == pytest.approx(TABLE_TOP + CUBE_HALF, abs=3e-3)
        assert (p[0], p[1]) == pytest.approx((before[0], before[1] - 0.12), abs=0.01)
        assert abs(q[1]) < 0.02 and abs(q[2]) < 0.02 and w.held() is None


def test_a_knocked_block_lands_on_the_block_below_it() -> None:
    """Three cubes (robot=panda experiment=tower3): cube_b knocked from 25 cm above the table to
    over cube_a lands on cube_a's top; knocked on from there sideways by 10 cm, it lands on the
    table, not inside anything."""
    tower = build_run_spec(compose_config("robot=panda", "experiment=tower3"))
    with ExecutionWorld(tower, 0, perturb=False) as w:
        a = w.start_state().objects["cube_a"].position
        w.scene.place_object("cube_b", torch.tensor([[a[0] + 0.1, a[1], 1.0]]))
        assert "onto cube_a" in w.apply(KnockOut("cube_b", -0.1, 0.0))
        for _ in range(20):
            w.scene.step()
        b = w.observe().state.objects["cube_b"].position
        assert b == pytest.approx((a[0], a[1], a[2] + 0.045), abs=3e-3)
        assert "onto table1" in w.apply(KnockOut("cube_b", 0.0, -0.1))
        for _ in range(20):
            w.scene.step()
        s = w.observe().state.objects
        assert s["cube_b"].position == pytest.approx((a[0], a[1] - 0.1, TABLE_TOP + CUBE_HALF), abs=3e-3)
        assert s["cube_a"].position == pytest.approx(a, abs=2e-3)  # untouched


def test_drawing_is_deterministic_per_seed(spec) -> None:
    ds = _read(spec, load_preset("table_moved").disturbances + load_preset("obstacle").disturbances
               + [{"trigger": {"action": 1}, "push_base": {"dx": 0.1, "dy": -0.2}}])
    a, b = draw(ds, np.random.default_rng(7)), draw(ds, np.random.default_rng(7))
    c = draw(ds, np.random.default_rng(8))
    assert a == b and a != c
    moved = a[0].effect
    assert isinstance(moved, MoveTable) and 0.2 <= math.hypot(moved.dx, moved.dy) <= 0.4
    box = a[1].effect
    assert isinstance(box, AddBox) and 0.4 <= box.at <= 0.6 and box.between == ("base", "table2")
    assert a[2].effect == PushBase(0.1, -0.2)


def test_schedule_fires_each_once_at_its_delay() -> None:
    s = Schedule([Scheduled(0, Trigger(delay_s=1.0, action=2), KnockOut("cube")),
                  Scheduled(1, Trigger(delay_s=0.5, when="held", object="cube"), PushBase(0.1, 0.0))], 0.05)
    assert s.due(10) == []  # nothing began, nothing held
    s.action_began(2, 100)
    assert s.due(119) == [] and [x.index for x in s.due(120)] == [0] and s.due(121) == []
    assert s.due(130, held="cube") == [] and [x.index for x in s.due(140, held="cube")] == [1]
    assert s.pending == []


# ------------------------------------------------------------------------------ the world
def test_world_start_is_drawn_per_seed(spec) -> None:
    with ExecutionWorld(spec, 3) as w:
        a = w.start_state()
        w.reset()
        again = w.start_state()
    with ExecutionWorld(spec, 3) as w:
        same = w.start_state()
    with ExecutionWorld(spec, 4) as w:
        other = w.start_state()
    with ExecutionWorld(spec, 3, perturb=False) as w:
        nominal = w.start_state()
    assert a.base == again.base == same.base and a.objects["cube"] == same.objects["cube"]
    assert a.base != other.base and a.objects["cube"].position != other.objects["cube"].position
    assert nominal.base[:2] == pytest.approx(spec.geometry.robot_start[:2], abs=1e-6)
    assert nominal.objects["cube"].position == pytest.approx(spec.geometry.object("cube").position, abs=1e-4)
    assert math.hypot(a.base[0] + 2.0, a.base[1]) > 1e-4  # perturbed: within the task's robot_xy (5 cm)
    assert abs(a.base[0] + 2.0) <= 0.05 and abs(a.base[1]) <= 0.05


def test_moved_table_is_moved_in_physics_and_stays_through_restores(spec) -> None:
    with ExecutionWorld(spec, 0, perturb=False) as w:
        cube0 = w.start_state().objects["cube"].position
        line = w.apply(MoveTable("table1", 0.5, 0.0))
        assert "table1" in line and "with cube" in line  # the cube on it moved along
        assert w.observe().state.objects["cube"].position[0] == pytest.approx(cube0[0] + 0.5, abs=1e-5)
        assert _drop(w, 0.5, 1.2) == pytest.approx(TABLE_TOP + CUBE_HALF, abs=2e-3)  # lands on its new top
        assert _drop(w, -0.15, 1.2) == pytest.approx(CUBE_HALF, abs=2e-3)  # nothing where it was
        state = w.observe().state
        w.scene.reset(state=state)  # a restore moves bodies and the robot, not the tables
        assert w.tables()["table1"] == TablePose(0.5, 1.2, 0.0)
        assert _drop(w, 0.6, 1.3) == pytest.approx(TABLE_TOP + CUBE_HALF, abs=2e-3)
        w.scene.reset()
        assert _drop(w, 0.6, 1.3) == pytest.approx(TABLE_TOP + CUBE_HALF, abs=2e-3)
        w.reset()  # the world's own reset puts it back
        assert _drop(w, -0.15, 1.2) == pytest.approx(TABLE_TOP + CUBE_HALF, abs=2e-3)


def test_added_box_blocks_bodies_and_the_robot(spec) -> None:
    box = AddBox("obstacle", (0.5, 0.5, 0.5), center=(-1.0, 0.0))
    with ExecutionWorld(spec, 0, perturb=False, disturbances=[Scheduled(0, Trigger(action=0), box)]) as w:
        assert _drop(w, -1.0, 0.0) == pytest.approx(CUBE_HALF, abs=2e-3)  # parked: not there yet
        w.reset()
        assert "appeared at (-1.000, 0.000)" in w.apply(box)
        assert w.observe().boxes == (BoxSeen("obstacle", (-1.0, 0.0), (0.5, 0.5, 0.5)),)
        assert _drop(w, -1.0, 0.0) == pytest.approx(0.5 + CUBE_HALF, abs=2e-3)  # stops at its top
        w.scene.reset(state=w.observe().state)
        for _ in range(60):  # drive +x at 0.5 m/s for 3 s from x = -2: 1.5 m without the box
            w.scene.set_base_velocity(torch.tensor([[0.5, 0.0, 0.0]]))
            w.scene.step()
        x = float(w.scene.base_pose()[0, 0])
        assert x < -1.25 - 0.2  # stopped at the box's face (-1.25) minus the robot's reach


def test_a_box_drawn_onto_the_robot_slides_on_until_it_is_clear(spec) -> None:
    box = AddBox("obstacle", (0.5, 0.5, 0.5), between=("base", "table2"), at=0.05)  # drawn on the base itself
    with ExecutionWorld(spec, 0, perturb=False, disturbances=[Scheduled(0, Trigger(action=0), box)]) as w:
        base = w.observe().state.base
        line = w.apply(box)
        assert "further on than drawn" in line
        (seen,) = w.observe().boxes
        for lo, hi in w._bodies_aabbs():  # PhysX's own bounds of every link and object
            apart = [lo[i] > seen.center[i] + 0.25 or hi[i] < seen.center[i] - 0.25 for i in range(2)]
            assert any(apart) or lo[2] > 0.5
        for _ in range(20):
            w.scene.step()
        assert w.observe().state.base[:2] == pytest.approx(base[:2], abs=0.01)  # nothing was thrown


def test_a_firm_grip_survives_the_shake_and_an_open_hand_does_not(spec) -> None:
    """Precheck.grip_holds restores the grip and, on the mobile base, drives it back and forth
    at the PID's top speed: the fixture's grip (the cube square between the fingers) holds
    through it; a grip of a measured world (table_moved, world 6), askew in the fingers, holds
    at rest but not through the shake, which a replan's move_to(Table2) then found in all 32
    of its rows (place: not_holding); squared in the hand and centred between the pads it holds."""
    from realize.execution.in_hand import square_in_hand
    from realize.execution.precheck import GRIP_STEPS, Precheck
    from realize.execution.settings import ExecuteSettings

    check = Precheck(spec, ExecuteSettings().precheck, 0)
    try:
        assert check.grip_holds(load_state(FIXTURE), spec.geometry_cfg)
        askew = load_state(FIXTURE.parent / "state_grip_askew.json")
        assert not check.grip_holds(askew, spec.geometry_cfg)
        scene, _ = check._scene(spec.geometry_cfg)
        scene.reset(seed=spec.seed, state=askew)
        scene.hold_still()
        for _ in range(GRIP_STEPS):
            scene.step()
        assert int(scene.held_object()[0]) == 0  # at rest it holds: only the shake tells
        hand = scene.ee_pose()[0].tolist()
        cube = spec.geometry.object("cube")
        assert not check.grip_holds(square_in_hand(askew, hand, cube), spec.geometry_cfg)  # squared is not enough
        assert check.grip_holds(square_in_hand(askew, hand, cube, spec.robot.tcp.approach_axis), spec.geometry_cfg)
    finally:
        check.close()


def test_knock_out_leaves_the_object_on_the_table_below_not_held(spec) -> None:
    with ExecutionWorld(spec, 0, perturb=False) as w:
        w.scene.reset(state=load_state(FIXTURE))
        assert w.held() == "cube"
        before = w.observe().state.objects["cube"].position
        line = w.apply(KnockOut("cube"))
        assert "out of the hand onto table1" in line and not bool(w.scene.gripper_command()[0])
        for _ in range(20):
            w.scene.step()
        p = w.observe().state.objects["cube"].position
        assert p[2] == pytest.approx(TABLE_TOP + CUBE_HALF, abs=3e-3)
        assert math.hypot(p[0] - before[0], p[1] - before[1]) < 0.03
        assert w.held() is None and w.observe().held is None


def test_move_object_and_push_base(spec) -> None:
    with ExecutionWorld(spec, 0, perturb=False) as w:
        c = w.start_state().objects["cube"].position
        w.apply(MoveObject("cube", 0.1, -0.15))
        for _ in range(10):
            w.scene.step()
        p = w.observe().state.objects["cube"].position
        assert p == pytest.approx((c[0] + 0.1, c[1] - 0.15, c[2]), abs=2e-3)
        b = w.observe().state.base
        assert "base pushed" in w.apply(PushBase(0.2, 0.1))
        assert w.observe().state.base[:2] == pytest.approx((b[0] + 0.2, b[1] + 0.1), abs=1e-4)


def test_observed_changes_become_a_belief_the_run_config_accepts(spec) -> None:
    from omegaconf import OmegaConf

    box = AddBox("obstacle", (0.5, 0.5, 0.5), between=("base", "table2"), at=0.5)
    with ExecutionWorld(spec, 1, disturbances=[Scheduled(0, Trigger(action=2), box)]) as w:
        assert geometry_changes(w.observe(), spec.geometry_cfg) == []  # nothing changed yet
        w.apply(MoveTable("table2", 0.1, -0.3))
        w.apply(box)
        obs = w.observe()
        base = obs.state.base
        now = geometry_now(w)
    assert obs.tables["table2"] == TablePose(0.1, -1.5, 0.0)
    (seen,) = obs.boxes
    assert seen.center == pytest.approx(((base[0] + 0.1) / 2, (base[1] - 1.5) / 2), abs=1e-6)  # table 2 where it is now
    changes = geometry_changes(obs, spec.geometry_cfg)
    assert changes[0] == "scene.tables.1.center=[0.1,-1.5]" and changes[1].startswith("scene.walls=[{name:obstacle,")
    s2 = build_run_spec(compose_config(*changes))  # as Hydra overrides
    assert s2.geometry.table("table2").center[:2] == pytest.approx((0.1, -1.5))
    wall = next(b for b in s2.geometry.extras if b.name == "obstacle")
    assert wall.center == pytest.approx((*seen.center, 0.25), abs=1e-6) and wall.half_size == (0.25, 0.25, 0.25)
    cfg = compose_config(plain=False)  # and as values put into a composed config
    for key, value in geometry_updates(obs, spec.geometry_cfg).items():
        OmegaConf.update(cfg, key, value, merge=False)
    s3 = build_run_spec(OmegaConf.to_container(cfg, resolve=True))
    rebuilt = build_geometry(apply_geometry_updates(spec.geometry_cfg, geometry_updates(obs, spec.geometry_cfg)))
    assert s3.geometry == s2.geometry == now == rebuilt and s3.geometry.table("table2").center[:2] == pytest.approx((0.1, -1.5))
    # the regions framed by table 2 follow it in the new spec
    assert s2.task.layout.regions["Table2"] != spec.task.layout.regions["Table2"]


# ------------------------------------------------------------------------------ monitor
def _obs(spec, *, held=None, cube=(0.0, 1.2, 0.7425), tables=None, boxes=(), base=(-2.0, 0.0, 0.0)) -> Observation:
    state = SceneState(base=base, gripper_closed=held is not None, objects={"cube": ObjectPose(cube)}, held=held)
    t = tables or {b.name: TablePose(b.center[0], b.center[1]) for b in spec.geometry.tables}
    return Observation(0, 0.0, state, t, tuple(boxes))


def test_monitor_flags_each_deviation_and_nothing_in_the_nominal_world(spec) -> None:
    task, g, tol = spec.task, spec.geometry, Tolerance()
    assert held_by_plan(task, 1) is None and held_by_plan(task, 1, done=True) == "cube"
    assert held_by_plan(task, 2) == "cube" and held_by_plan(task, 3) is None and held_by_plan(task, 4) is None
    at0, carry = expectation(task, g, 0), expectation(task, g, 2)
    assert set(at0.objects) == {"cube"} and carry.objects == {} and carry.held == "cube"
    # unperturbed: nothing, during any action
    for k in range(task.n_actions):
        held = held_by_plan(task, k)
        assert check(_obs(spec, held=held, cube=(0.0, 1.2, 0.9) if held else (0.0, 1.2, 0.7425)),
                     expectation(task, g, k), tol) == []
    def kinds(obs, exp):
        out = check(obs, exp, tol)
        assert all(isinstance(d, Deviation) and d.kind in KINDS and d.detail for d in out)
        return [d.kind for d in out]

    assert kinds(_obs(spec, held=None), carry) == ["grasp_lost"]
    assert kinds(_obs(spec, cube=(0.0, 1.2, 0.7425)), expectation(task, g, 1, done=True)) == ["grasp_lost"]
    assert kinds(_obs(spec, cube=(0.25, 1.35, 0.7425)), at0) == []  # 29 cm: the plan tracks it
    assert kinds(_obs(spec, cube=(0.35, 1.2, 0.7425)), at0) == ["object_moved"]
    moved = {"table1": TablePose(0.0, 1.2), "table2": TablePose(0.06, -1.2)}
    assert kinds(_obs(spec, held="cube", tables=moved), carry) == ["table_moved"]
    inside = BoxSeen("obstacle", (-0.5, 0.0), (0.5, 0.5, 0.5))
    outside = BoxSeen("far", (10.0, 0.0), (0.5, 0.5, 0.5))
    assert kinds(_obs(spec, held="cube", boxes=[inside, outside]), carry) == ["path_blocked"]
    s_walls = build_run_spec(compose_config("scene.walls=[{name:obstacle,center:[-0.5,0.0],size:[0.5,0.5,0.5]}]"))
    assert kinds(_obs(spec, held="cube", boxes=[inside]), expectation(task, s_walls.geometry, 2)) == []  # known
    arrived = expectation(task, g, 0, done=True, base_target=(-0.85, 1.2))
    assert kinds(_obs(spec, base=(-0.80, 1.15, 0.0)), arrived) == []
    assert kinds(_obs(spec, base=(-0.60, 1.2, 0.0)), arrived) == ["base_off"]


# ------------------------------------------------------------------------------ trajectory file
def test_trajectory_file_round_trips(tmp_path: Path) -> None:
    log = TrajectoryLog(control_freq=20)
    joints = ("torso_lift_joint", "shoulder_pan_joint")
    rows = [(0, 0, "move_to(Table1)"), (1, 0, "move_to(Table1)"), (2, 1, "grasp(cube, Cube_g)"),
            (3, 1, "grasp(cube, Cube_g)"), (4, 1, "grasp(cube, Cube_g)"), (5, 0, "move_to(Table1)")]  # a replan
    for step, a, text in rows:
        log.append(step, a, text, {n: 0.1 * step + i for i, n in enumerate(joints)}, (0.5, -0.1 * step, 0.2),
                   gripper_closed=step >= 4)
    path = log.save(tmp_path / "traj")
    t = read_trajectory(path)
    assert path.suffix == ".npz" and t.format == TRAJECTORY_FORMAT and t.control_freq == 20.0 and len(t) == 6
    assert t.joint_names == joints and t.step.tolist() == [0, 1, 2, 3, 4, 5]
    assert t.t_s.tolist() == pytest.approx([0.0, 0.05, 0.1, 0.15, 0.2, 0.25])
    assert t.joint_targets[:, 1].tolist() == pytest.approx([1 + 0.1 * s for s in range(6)])
    assert t.base_velocity[3].tolist() == pytest.approx([0.5, -0.3, 0.2])
    assert t.gripper.tolist() == [False] * 4 + [True] * 2
    assert t.action_text == ("move_to(Table1)", "grasp(cube, Cube_g)", "move_to(Table1)")
    assert t.action_boundaries.tolist() == [[0, 1], [2, 4], [5, 5]]
    assert t.action.tolist() == [0, 0, 1, 1, 1, 2] and t.plan_index.tolist() == [0, 0, 1, 1, 1, 0]
    with pytest.raises(ConfigError, match="steps must increase"):
        log.append(5, 0, "x", dict.fromkeys(joints, 0.0), (0, 0, 0), False)


def test_trajectory_from_a_scene(spec, tmp_path: Path) -> None:
    with ExecutionWorld(spec, 0, perturb=False) as w:
        log = TrajectoryLog(spec.sim.control_freq)
        for _ in range(3):
            w.scene.set_base_velocity(torch.tensor([[0.3, 0.0, 0.1]]))
            w.scene.step()
            log.from_scene(w.scene, 0, str(spec.task.plan[0]))
        t = read_trajectory(log.save(tmp_path / "t.npz"))
    assert t.joint_names == tuple(spec.robot.upper.joints) and t.step.tolist() == [1, 2, 3]
    assert t.base_velocity[0].tolist() == pytest.approx([0.3, 0.0, 0.1]) and not t.gripper.any()
