"""Stitched segments in the simulator (CPU): a prefix's captured end state, restored per copy,
lets the suffix go on where the prefix stopped, and the two costs add up to the whole plan's.

``FULL_Z`` is a seed-paper run's best plan (``tests/helpers.py``): move_to(Table1),
grasp(cube, Cube_g) | move_to(Table2), place(cube, Cube_p), move_to(Exit).
"""

from __future__ import annotations

import pytest
import torch

from realize.workers.realizers import open_realization
from realize.spec.run_spec import build_run_spec
from realize.tasks.split import default_split, split_task
from realize.config import ConfigError
from realize.world.state import SceneState
from helpers import FULL_Z, STATE_GRASPED, compose_config, on_table2
from realize.world.state import load_state


def test_split_task_cuts_the_seed_plan_after_the_grasp() -> None:
    task = build_run_spec(compose_config()).task
    k = default_split(task)
    prefix, suffix, pcols, scols = split_task(task, k)
    assert k == 2 and [a.template for a in prefix.plan] == ["move_to", "grasp"]
    assert [a.template for a in suffix.plan] == ["move_to", "place", "move_to"]
    assert prefix.layout.names == ["Table1", "Cube_g"] and not prefix.goal.reads_objects and prefix.final_cost == 0
    assert suffix.goal == task.goal and pcols + scols == list(range(task.layout.dim))
    for bad in (0, 5, True):
        with pytest.raises(ConfigError, match="stitch.split"):
            split_task(task, bad)


def test_per_copy_restore_puts_each_copy_in_its_own_state(torch_single_thread: None) -> None:
    held = load_state(STATE_GRASPED)
    start = SceneState(base=(-2.0, 0.0, 0.0), source="start")
    scene, _ = open_realization(build_run_spec(compose_config()), n_envs=3)
    with scene:
        scene.reset(state=[held, start])  # copy 2, past the list, takes the first state
        assert scene.holds("cube").tolist() == [True, False, True]
        assert scene.gripper_command().tolist() == [True, False, True]
        base = scene.base_pose()
        assert torch.allclose(base[0], torch.tensor(held.base), atol=1e-4)
        assert torch.allclose(base[1], torch.tensor(start.base), atol=1e-4)


def test_prefix_end_state_continues_into_the_suffix(torch_single_thread: None) -> None:
    spec = build_run_spec(compose_config())
    prefix, suffix, pcols, scols = split_task(spec.task, 2)
    Z = torch.tensor([FULL_Z], dtype=torch.float64)
    scene, (whole, pre, suf) = open_realization(spec, [spec.task, prefix, suffix], n_envs=1)
    with scene:
        full = whole.rollout(Z)
        first = pre.rollout(Z[:, pcols], capture_end=True)
        (end,) = first.end_states
        assert bool(first.feasible[0]) and end is not None and end.held == "cube" and end.gripper_closed
        rest = suf.rollout(Z[:, scols], starts=[end])
        assert bool(rest.feasible[0]) and on_table2(scene.object_pose("cube")[0]), rest.failure
        assert rest.end_states is None  # only asked for
    # the cut costs a few control steps (the restored copy starts at rest, its grip made anew):
    # measured 456 stitched against 445 whole, which is why a stitched plan is confirmed whole
    stitched, whole_cost = float(first.cost[0] + rest.cost[0]), float(full.cost[0])
    assert bool(full.feasible[0]) and abs(stitched - whole_cost) <= 0.03 * whole_cost, (stitched, whole_cost)
    assert 150 < float(first.cost[0]) < 250 and 200 < float(rest.cost[0]) < 300  # two and three actions


@pytest.mark.slow  # a whole run or several processes: make test-all (make test keeps a smoke test)
def test_worker_processes_carry_starts_and_end_states(tmp_path) -> None:
    """Two worker processes, one copy per shard: each row's end state, and the suffix realized
    from it, equal a fresh one-copy scene's that realized the same two rollouts, bit for bit.
    (Restores are history-free, ``test_a_restore_is_history_free``, so the histories need not
    match; they do here all the same.)"""
    from realize.scene.shards import group_shards
    from realize.workers.pool import run_shards
    from realize.workers.process import ProcessPool

    spec = build_run_spec(compose_config("ce.n_envs=2", "ce.n_elite=1", "sim.shard_rows=1"))
    prefix, suffix, pcols, scols = split_task(spec.task, 2)
    Z = torch.tensor([FULL_Z, FULL_Z], dtype=torch.float64)
    Z[1, pcols[0]] += 0.01  # another base position around table 1
    Z[1, scols[0]] += 0.01  # and around table 2
    with ProcessPool(spec, [spec.task, prefix, suffix], group_shards(run_shards(spec), 2), physx_threads=0,
                     log_dir=tmp_path) as pool:
        first = pool.rollout(1, Z[:, pcols], capture_end=True)
        rest = pool.rollout(2, Z[:, scols], starts=first.end_states)
    assert first.end_states[0] != first.end_states[1]
    for i in range(2):
        scene, (_, pre, suf) = open_realization(spec, [spec.task, prefix, suffix], n_envs=1)
        with scene:
            one = pre.rollout(Z[i:i + 1, pcols], capture_end=True)
            again = suf.rollout(Z[i:i + 1, scols], starts=one.end_states)
        assert bool(one.feasible[0]) and one.end_states == [first.end_states[i]]
        assert bool(again.feasible[0]) and torch.equal(again.cost, rest.cost[i:i + 1])


def test_a_restore_is_history_free(torch_single_thread: None) -> None:
    """The same captured state, restored after different histories, gives the same suffix bit
    for bit, and a plain rollout after restores equals the first one. Before every reset got a
    fresh PhysX system (``CpuTiledBackend._fresh_physx``), the seed plan's suffix from one
    captured state cost 276 after a prefix rollout and 265 right after a suffix rollout: the
    cube settled in one of two grasps by the order of contacts PhysX kept from before."""
    spec = build_run_spec(compose_config())
    prefix, suffix, pcols, scols = split_task(spec.task, 2)
    Z = torch.tensor([FULL_Z], dtype=torch.float64)
    other = Z.clone()
    other[0, scols[0]] += 0.05  # another base position around table 2
    scene, (whole, pre, suf) = open_realization(spec, [spec.task, prefix, suffix], n_envs=1)
    with scene:
        first_whole = whole.rollout(Z, record=True)
        (end,) = pre.rollout(Z[:, pcols], capture_end=True).end_states
        runs = [suf.rollout(Z[:, scols], starts=[end], record=True)]  # right after the prefix
        runs.append(suf.rollout(Z[:, scols], starts=[end], record=True))  # right after the same suffix
        suf.rollout(other[:, scols], starts=[end])
        runs.append(suf.rollout(Z[:, scols], starts=[end], record=True))  # after another suffix
        again_whole = whole.rollout(Z, record=True)  # a plain rollout after restores
    assert bool(runs[0].feasible[0])
    for r in runs[1:]:
        assert torch.equal(r.cost, runs[0].cost) and torch.equal(r.traj_q, runs[0].traj_q)
    assert torch.equal(again_whole.cost, first_whole.cost)
    assert torch.equal(again_whole.traj_q, first_whole.traj_q)
    assert torch.equal(again_whole.traj_objects, first_whole.traj_objects)
