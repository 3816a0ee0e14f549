"""Perturbed worlds and the robust search over them (``realize.tasks.worlds``, ``realize.search.ce.risk``).

* worlds drawn from a task's perturbation model repeat for a seed, stay in the model's ranges,
  leave objects on the floor where they are, and world 0 is the unperturbed one on request;
* a scene whose copies are given worlds starts each copy where its world says (robot, cube,
  yaw) and gives each copy's cube its friction and mass (CPU simulator);
* folding R worlds per sample equals a per-sample loop (mean and CVaR), and the ranking puts a
  sample's success share before its cost;
* shards and batch parts keep a sample's copies together, each at its world's copy;
* a robust pool realizes each sample in every one of its R worlds, and the worlds differ (the
  same plan costs differently in them); a robust run (``ce.replicas=2``, through that pool) keeps each
  sample's share and per-world results in its history and repeats bit for bit on CPU;
  ``ce.replicas`` refuses what cannot work in one line.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
import torch

from helpers import GOOD, compose_config, realize_result
from realize.spec.run_spec import build_run_spec
from realize.scene.shards import deal_rows, shard_rows
from realize.config import ConfigError
from realize.scene import BatchedScene
from realize.search.ce.ranking import rank_samples, sort_key
from realize.search.ce.risk import fold_worlds
from realize.tasks.perturbation import Perturbation
from realize.tasks.worlds import SEARCH_STREAM, draw_worlds

pytestmark = pytest.mark.usefixtures("torch_single_thread")


def test_worlds_repeat_for_a_seed_and_stay_in_the_models_ranges() -> None:
    spec = build_run_spec(compose_config("scene=push", "task=move_and_push"))  # a stick on the floor, a cube on it
    model = Perturbation(object_xy=0.03, object_yaw=0.5, robot_xy=0.05, friction=(0.8, 1.2), mass=(0.5, 2.0))
    objs = spec.geometry.objects
    w = draw_worlds(model, objs, 50, seed=4)
    again = draw_worlds(model, objs, 50, seed=4)
    assert all(np.array_equal(getattr(w, f), getattr(again, f))
               for f in ("robot_xy", "object_xy", "object_yaw", "friction", "mass"))
    other = draw_worlds(model, objs, 50, seed=4, stream=SEARCH_STREAM)
    assert not np.array_equal(w.robot_xy, other.robot_xy)
    k = {o.name: i for i, o in enumerate(objs)}
    assert np.all(w.object_xy[:, k["stick"]] == 0) and np.all(w.object_yaw[:, k["stick"]] == 0)
    assert 0 < np.abs(w.object_xy[:, k["cube"]]).max() <= 0.03 and 0 < np.abs(w.object_yaw[:, k["cube"]]).max() <= 0.5
    assert np.abs(w.robot_xy).max() <= 0.05
    assert 0.8 <= w.friction.min() and w.friction.max() <= 1.2 and 0.5 <= w.mass.min() and w.mass.max() <= 2.0
    nominal = draw_worlds(model, objs, 5, seed=4, nominal_first=True)
    assert not nominal.select([0]).moves_start and float(nominal.friction[0].max()) == 1.0
    assert nominal.select([1, 2, 3, 4]).moves_start
    assert np.array_equal(w.tile(7, first=48).robot_xy, w.select([48, 49, 0, 1, 2, 3, 4]).robot_xy)


def test_each_copy_starts_in_its_world() -> None:
    spec = build_run_spec(compose_config())
    model = Perturbation(object_xy=0.03, object_yaw=0.6, robot_xy=0.05, friction=(0.5, 1.5), mass=(0.5, 2.0))
    w = draw_worlds(model, spec.geometry.objects, 3, seed=1)
    cube = spec.geometry.object("cube")
    with BatchedScene(3, spec.geometry_cfg, spec.sim) as scene:
        scene.reset()
        before = scene.object_pose("cube")
        scene.set_worlds(w)
        scene.reset()
        pose, base = scene.object_pose("cube"), scene.base_pose()
        expect_xy = torch.tensor(cube.position[:2]) + torch.tensor(w.object_xy[:, 0], dtype=torch.float32)
        assert torch.allclose(pose[:, :2], expect_xy, atol=1e-4)
        yaw = 2 * torch.atan2(pose[:, 6], pose[:, 3])  # wxyz after the position
        assert torch.allclose(yaw, torch.tensor(cube.yaw + w.object_yaw[:, 0], dtype=torch.float32), atol=1e-4)
        start = torch.tensor(spec.geometry.robot_start[:2]) + torch.tensor(w.robot_xy, dtype=torch.float32)
        assert torch.allclose(base[:, :2], start, atol=1e-4)
        assert np.allclose(scene.object_friction("cube")[:, 0].numpy(), cube.friction * w.friction[:, 0], rtol=1e-6)
        assert np.allclose(scene.object_mass("cube").numpy(), cube.mass * w.mass[:, 0], rtol=1e-6)
        scene.set_worlds(None)  # back to the task's own (unperturbed) resets
        scene.reset()
        assert torch.allclose(scene.object_pose("cube")[:, :3], before[:, :3], atol=1e-6)
        with pytest.raises(ConfigError, match="2 worlds for 3 copies"):
            scene.set_worlds(w.select([0, 1]))


def _fold_one(cost: list[float], ok: list[bool], risk: str, alpha: float) -> tuple[float, float]:
    good = sorted((c for c, f in zip(cost, ok) if f and math.isfinite(c)), reverse=True)
    if not good:
        return float(np.mean(cost)), 0.0
    take = good if risk == "mean" else good[:max(1, math.ceil(alpha * len(good)))]
    return float(np.mean(take)), len(good) / len(cost)


@pytest.mark.parametrize("risk, alpha", [("mean", 0.25), ("cvar", 0.25), ("cvar", 0.5), ("cvar", 1.0)])
def test_folding_worlds_equals_a_per_sample_loop(risk: str, alpha: float) -> None:
    g = torch.Generator().manual_seed(0)
    n, R = 30, 5
    cost = torch.randint(100, 900, (n * R,), generator=g).double()
    ok = torch.rand(n * R, generator=g) < 0.6
    progress, distance = torch.rand(n * R, generator=g) * 5, torch.rand(n * R, generator=g)
    w = fold_worlds(cost, ok, progress, distance, R, risk, alpha)
    for i in range(n):
        c, share = _fold_one(cost[i * R:(i + 1) * R].tolist(), ok[i * R:(i + 1) * R].tolist(), risk, alpha)
        assert float(w.cost[i]) == pytest.approx(c) and float(w.share[i]) == share
        assert bool(w.feasible[i]) == (share > 0)
        assert float(w.progress[i]) == pytest.approx(float(progress[i * R:(i + 1) * R].mean()))
    one = fold_worlds(cost, ok, progress, distance, 1, risk, alpha)  # one world: the rows themselves
    assert torch.equal(one.feasible, ok) and torch.equal(one.cost[ok], cost[ok])


def test_share_ranks_before_cost() -> None:
    cost = torch.tensor([300.0, 200.0, 250.0, 100.0])
    feasible = torch.tensor([True, True, True, False])
    share = torch.tensor([1.0, 0.5, 1.0, 0.0])
    assert rank_samples(cost, feasible, share=share).tolist() == [2, 0, 1, 3]
    assert rank_samples(cost, feasible).tolist() == [1, 2, 0, 3]  # without: cost alone, as before
    assert sort_key(True, 300.0, 0, 0, 1.0) < sort_key(True, 200.0, 0, 0, 0.5) < sort_key(False, 1.0, 5, 0)


@pytest.mark.parametrize("n, rows, unit", [(200, 50, 4), (100, 50, 2), (40, 10, 8), (100, 50, 1), (12, 5, 3)])
def test_shards_and_parts_keep_a_samples_copies_together(n: int, rows: int, unit: int) -> None:
    shards = shard_rows(n, rows, unit)
    assert shards[0].first == 0 and shards[-1].stop == n
    assert all(s.size % unit == 0 and (s.size <= rows or s.size == unit) for s in shards)
    for m in range(unit, n + 1, unit):  # every batch size a schedule may give
        parts = deal_rows(m, len(shards), unit)
        assert sum(p.stop - p.start for p in parts) == m
        for p, s in zip(parts, shards):
            assert (p.stop - p.start) % unit == 0 and p.stop - p.start <= s.size
    if unit == 1:
        assert [s.size for s in shards] == [s.size for s in shard_rows(n, rows)]


@pytest.mark.slow  # a whole run or several processes: make test-all (make test keeps a smoke test)
def test_a_robust_run_meets_its_worlds_and_repeats(tmp_path: Path) -> None:
    args = ("ce.n_envs=8", "ce.n_elite=2", "ce.iterations=1", "ce.replicas=2", "seed=2", "logging.rerun=false",
            "logging.progress=false", "controller.max_time_s=8")
    res = realize_result(*args, run_dir=tmp_path / "a")
    again = realize_result(*args, run_dir=tmp_path / "b")
    assert res["best_z"] == again["best_z"] and res["success_per_iter"] == again["success_per_iter"]
    assert res["robust"]["replicas"] == 2 and res["robust"]["risk"] == "mean"
    with np.load(tmp_path / "a" / "history.npz") as h:
        assert h["Z_000"].shape[0] == 4 and h["share_000"].shape == (4,)
        wc = h["world_cost_000"]
        assert wc.shape == (4, 2)
        assert np.array_equal(h["share_000"], h["world_feasible_000"].mean(1))


@pytest.mark.slow  # a worker process (23 s on a busy 2-core host): make test keeps the worlds per copy
# (test_each_copy_starts_in_its_world) and their folding (test_folding_worlds_equals_a_per_sample_loop)
def test_a_robust_pool_realizes_each_sample_in_every_world() -> None:
    from realize.workers.pool import open_pool

    spec = build_run_spec(compose_config("ce.n_envs=6", "ce.n_elite=1", "ce.replicas=3", "sim.shard_rows=3",
                                         "workers.n=1"))
    with_pool = open_pool(spec)
    try:
        assert with_pool.n_envs == 6
        res = with_pool.rollout(None, torch.tensor([GOOD, GOOD], dtype=torch.float64))
    finally:
        with_pool.close()
    assert res.cost.shape == (2,) and res.world_cost.shape == (2, 3)
    # both samples meet the same three worlds (two shards, each copy k in world k % 3) ...
    assert torch.equal(res.world_cost[0], res.world_cost[1]) and torch.equal(res.world_feasible[0], res.world_feasible[1])
    # ... which differ: the robot starts up to 5 cm elsewhere, the cube lies elsewhere
    assert len(set(res.world_cost[0].tolist())) > 1
    ok = res.world_feasible[0]
    assert float(res.share[0]) == float(ok.double().mean())
    if bool(ok.any()):
        assert float(res.cost[0]) == pytest.approx(float(res.world_cost[0][ok].double().mean()))


@pytest.mark.parametrize("bad, needle", [
    (["ce.replicas=3"], "ce.n_envs = 200 is invalid with ce.replicas = 3"),
    (["ce.replicas=40"], "ce.n_elite = 10 is invalid with ce.replicas = 40"),
    (["ce.replicas=0"], "ce.replicas"),
    (["ce.replicas=2", "ce.risk=worst"], "ce.risk"),
    (["ce.replicas=2", "task.planner.top_k=2", "task=carry_or_push", "scene=carry_or_push"], "robust search realizes one plan"),
])
def test_bad_robust_settings_get_one_line(bad: list[str], needle: str) -> None:
    with pytest.raises(ConfigError, match=needle):
        build_run_spec(compose_config(*bad))
