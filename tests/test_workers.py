"""Rollout workers (realize.workers): shards fix the numbers, workers only where they run.

Checks: the shard and group arithmetic; the config edge (a worker count the shards cannot
carry is refused before anything is built); a run gives the same numbers in one process and in
two worker processes (the issue's must-show: best_cost, success_per_iter, best_cost_per_iter,
best_z); a worker killed mid-rollout is replaced and its rows re-run to the same result, a
second death stops with an error naming the worker; Ctrl-C and a killed run leave no process
behind (the process table is read).
"""

from __future__ import annotations

import json
import signal
import subprocess
import time
from pathlib import Path
from typing import Callable

import pytest
import torch

from helpers import KEYS, RUN16, compose_config, kill_on_rollout, realize_cli, realize_result
from realize.config import ConfigError
from realize.realization.result import RolloutResult
from realize.spec.run_spec import build_run_spec
from realize.scene.shards import deal_rows, group_shards, shard_rows, split_rows
from realize.workers.blocks import join_results, worker_parts
from realize.workers.errors import WorkerFailed
from realize.spec.workers_settings import WorkersSettings, physx_threads, worker_count

# RUN16: the issue's must-show run (slow); RUN8: a smaller one of the same kind for every CI run
RUN8 = ["ce.n_envs=8", "ce.n_elite=2", "ce.iterations=2", "seed=3", "sim.shard_rows=4", "controller.max_time_s=12",
        "logging.progress=false", "logging.rerun=false"]


# ------------------------------------------------------------------------------ arithmetic
@pytest.mark.parametrize("n,rows", [(1, 100), (16, 8), (200, 100), (201, 100), (7, 3), (3000, 100)])
def test_shards_cover_the_copies_in_order(n: int, rows: int) -> None:
    shards = shard_rows(n, rows)
    assert shards[0].first == 0 and shards[-1].stop == n
    assert all(a.stop == b.first for a, b in zip(shards, shards[1:]))
    assert all(1 <= s.size <= rows for s in shards)
    assert len(shards) == -(-n // rows) and max(s.size for s in shards) - min(s.size for s in shards) <= 1


def test_groups_are_consecutive_whole_shards() -> None:
    shards = shard_rows(300, 100)
    groups = group_shards(shards, 2)
    assert [len(g) for g in groups] == [2, 1] and [s for g in groups for s in g] == shards
    with pytest.raises(ValueError, match=r"cannot split 3 rows into 4 blocks"):
        split_rows(3, 4)


@pytest.mark.parametrize("n,rows", [(16, 8), (200, 100), (3000, 100), (201, 100), (7, 3)])
def test_a_short_batch_is_dealt_to_every_shard_and_fits(n: int, rows: int) -> None:
    shards = shard_rows(n, rows)
    for m in range(0, n + 1, max(1, n // 37)):
        parts = deal_rows(m, len(shards))
        assert parts[0].start == 0 and parts[-1].stop == m and all(a.stop == b.start for a, b in zip(parts, parts[1:]))
        assert all(p.stop - p.start <= s.size for p, s in zip(parts, shards))
        assert max(p.stop - p.start for p in parts) - min(p.stop - p.start for p in parts) <= 1
    Z = torch.arange(10.0)[:, None]
    per_worker = worker_parts(Z, group_shards(shard_rows(16, 4), 2))
    assert [[p[:, 0].tolist() for p in w] for w in per_worker] == [[[0, 1, 2], [3, 4, 5]], [[6, 7], [8, 9]]]


def _result(rows: range, steps: int, frames: int) -> RolloutResult:
    n = len(rows)
    v = torch.tensor(list(rows), dtype=torch.float32)
    return RolloutResult(cost=v, feasible=v > 3, action_success=torch.ones(n, 2, dtype=torch.bool), goal=v > 3,
                         steps=v.long(), progress=v, distance=-v, failure=[f"r{i}" for i in rows], sim_steps=steps,
                         horizon_cost=9.0, traj_t=torch.arange(frames, dtype=torch.float32),
                         traj_base=v[:, None, None].expand(n, frames, 2) + torch.arange(frames)[None, :, None],
                         traj_ee=torch.zeros(n, frames, 3),
                         traj_objects=v[:, None, None, None].expand(n, frames, 2, 3) + torch.arange(frames)[None, :, None, None])


def test_join_keeps_row_order_and_pads_trajectories() -> None:
    a, b = _result(range(0, 3), 10, 4), _result(range(3, 5), 12, 6)
    j = join_results([a, b])
    assert j.cost.tolist() == [0, 1, 2, 3, 4] and j.failure == [f"r{i}" for i in range(5)]
    assert j.sim_steps == 12 and j.traj_base.shape == (5, 6, 2) and len(j.traj_t) == 6
    assert torch.equal(j.traj_base[0, 4:], a.traj_base[0, 3:4].expand(2, 2))  # last frame held
    assert torch.equal(j.traj_base[3:], b.traj_base)
    assert j.traj_objects.shape == (5, 6, 2, 3)  # (N, T, m, 3): padded along T only
    assert torch.equal(j.traj_objects[0, 4:], a.traj_objects[0, 3:4].expand(2, 2, 3))
    assert torch.equal(j.traj_objects[3:], b.traj_objects)


def test_worker_count_and_threads() -> None:
    auto = WorkersSettings()
    assert worker_count(auto, 2, True, cores=2) == 2 and worker_count(auto, 30, True, cores=16) == 16
    assert worker_count(auto, 1, True, cores=16) == 1 and worker_count(auto, 4, False, cores=16) == 1
    with pytest.raises(ConfigError, match="more than the 2 shard"):
        worker_count(WorkersSettings(n=3), 2, True, cores=8)
    with pytest.raises(ConfigError, match="GPU backend holds every copy"):
        worker_count(WorkersSettings(n=2), 4, False, cores=8)
    assert physx_threads(None, 2, cores=2) == 0 and physx_threads(None, 2, cores=8) == 4
    assert physx_threads(None, 1, cores=8) is None and physx_threads(3, 2, 2) == 3  # sim.cpu_workers=3


def test_config_edge_refuses_more_workers_than_shards() -> None:
    with pytest.raises(ConfigError, match=r"workers.n = 3 is more than the 2 shard\(s\)"):
        build_run_spec(compose_config(*RUN16, "workers.n=3"))
    spec = build_run_spec(compose_config(*RUN16, "workers.n=2"))
    assert spec.workers.n == 2 and spec.sim.shard_rows == 8


# ------------------------------------------------------------------------------ same numbers
@pytest.fixture(scope="module")
def one_process(tmp_path_factory: pytest.TempPathFactory) -> dict:
    return realize_result(*RUN16, "workers.n=1", run_dir=tmp_path_factory.mktemp("w1") / "run")


@pytest.mark.slow  # make test's multi-process smoke test is the golden run seed_paper_default (two workers)
def test_two_worker_processes_give_the_numbers_of_one_process(tmp_path: Path) -> None:
    one = realize_result(*RUN8, "workers.n=1", run_dir=tmp_path / "one")
    two = realize_result(*RUN8, "workers.n=2", "workers.backend=process", run_dir=tmp_path / "two")
    assert one["workers"] == 1 and two["workers"] == 2
    for k in KEYS:
        assert two[k] == one[k], k
    assert (tmp_path / "two" / "workers" / "worker-1.log").read_text().count("rollout of 4 rows") == 2


@pytest.mark.slow
def test_the_issue_run_gives_the_same_numbers_with_two_worker_processes(one_process: dict, tmp_path: Path) -> None:
    two = realize_result(*RUN16, "workers.n=2", "workers.backend=process", run_dir=tmp_path / "run")
    assert one_process["workers"] == 1 and two["workers"] == 2
    for k in KEYS:
        assert two[k] == one_process[k], k


@pytest.mark.slow
def test_a_run_resumed_with_other_workers_gives_the_same_numbers(one_process: dict, tmp_path: Path) -> None:
    from omegaconf import OmegaConf

    from realize.run.one_run import run

    def stop(i: int) -> None:
        if i == 0:
            raise KeyboardInterrupt

    cfg = OmegaConf.create(compose_config(*RUN16, "workers.n=2"))
    out = run(cfg, tmp_path / "run", after_iteration=stop)
    assert out.status == "interrupted" and out.iterations_done == 1
    done = realize_result(f"resume={tmp_path / 'run'}", "workers.n=1", run_dir=tmp_path / "run")
    assert done["segments"] == 2 and done["workers"] == 1
    for k in KEYS:
        assert done[k] == one_process[k], k


@pytest.mark.slow
def test_top_k_halving_gives_the_same_numbers_with_workers(tmp_path: Path) -> None:
    top_k = ["experiment=carry_or_push", "task.planner.top_k=2", "ce.n_envs=8", "ce.n_elite=2", "ce.iterations=3",
             "seed=0", "sim.shard_rows=4", "logging.progress=false", "logging.rerun=false"]
    one = realize_result(*top_k, "workers.n=1", run_dir=tmp_path / "one")
    two = realize_result(*top_k, "workers.n=2", run_dir=tmp_path / "two")
    assert two["workers"] == 2
    for k in ("best_cost", "success_per_iter", "best_z", "winner"):
        assert two[k] == one[k], k
    assert [c["best_cost"] for c in two["candidates"]] == [c["best_cost"] for c in one["candidates"]]


# ------------------------------------------------------------------------------ faults
def _pool(tmp_path: Path):
    from realize.workers.pool import run_shards
    from realize.workers.process import ProcessPool

    spec = build_run_spec(compose_config("ce.n_envs=8", "ce.n_elite=2", "sim.shard_rows=4", "controller.max_time_s=4"))
    shards = run_shards(spec)
    Z = spec.task.layout.sample_uniform(8, generator=torch.Generator().manual_seed(0))
    return spec, ProcessPool(spec, [spec.task], group_shards(shards, 2), physx_threads=0, log_dir=tmp_path), Z


def _worker_1_in_rollout(pool, log: Path) -> Callable[[list[int]], int | None]:
    """``kill_on_rollout``'s victim: worker 1's pid each time its log (``log``: one file for the
    worker and its replacements) shows one more rollout started than it was killed."""

    def victim(killed: list[int]) -> int | None:
        if log.is_file() and log.read_text().count("rollout of") > len(killed):
            return pool.slots[1].pid
        return None

    return victim


@pytest.mark.slow  # a whole run or several processes: make test-all (make test keeps a smoke test)
def test_a_killed_worker_is_replaced_and_its_rows_rerun(tmp_path: Path) -> None:
    from realize.workers.pool import InProcessPool, run_shards

    spec, pool, Z = _pool(tmp_path / "logs")
    with pool:
        first_pids = pool.pids()
        killer = kill_on_rollout(_worker_1_in_rollout(pool, tmp_path / "logs" / "worker-1.log"), times=1)
        res = pool.rollout(None, Z)
        killer.join(timeout=5)
        assert pool.pids()[0] == first_pids[0] and pool.pids()[1] != first_pids[1]
    with InProcessPool(spec, [spec.task], run_shards(spec)) as ref:
        want = ref.rollout(None, Z)  # fresh scenes, as the replacement worker's
    for k in ("cost", "feasible", "steps", "distance", "progress"):
        assert torch.equal(getattr(res, k), getattr(want, k)), k
    assert res.failure == want.failure


@pytest.mark.slow
def test_a_worker_that_dies_twice_stops_the_run_with_its_name(tmp_path: Path) -> None:
    _, pool, Z = _pool(tmp_path / "logs")
    with pool:
        kill_on_rollout(_worker_1_in_rollout(pool, tmp_path / "logs" / "worker-1.log"), times=2)
        with pytest.raises(WorkerFailed) as e:
            pool.rollout(None, Z)
    msg = str(e.value)
    assert "worker 1 (rows 4-7" in msg and "died again on the same rows" in msg and "SIGKILL" in msg
    assert "rollout of 4 rows" in msg  # its last log lines


# ------------------------------------------------------------------------------ no orphans
def _children(pid: int) -> list[int]:
    out = []
    for d in Path("/proc").iterdir():
        if d.name.isdigit():
            try:
                fields = (d / "stat").read_text().rsplit(")", 1)[1].split()
            except OSError:
                continue
            if int(fields[1]) == pid:
                out.append(int(d.name))
    return out


def _alive(pid: int) -> bool:
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except OSError:
        return False
    return state != "Z"


def _start_run(tmp_path: Path) -> tuple[subprocess.Popen, list[int], Path]:
    run_dir = tmp_path / "run"
    p = realize_cli(*RUN16, "ce.iterations=5", "workers.n=2", f"hydra.run.dir={run_dir}", cwd=tmp_path,
                    background=True, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    log = run_dir / "workers" / "worker-1.log"
    deadline = time.monotonic() + 240
    while not (log.is_file() and "rollout of" in log.read_text()):
        assert p.poll() is None and time.monotonic() < deadline, "the run ended before its workers rolled out"
        time.sleep(0.2)
    workers = [c for c in _children(p.pid) if _alive(c)]
    assert len(workers) >= 2
    return p, workers, run_dir


def _gone(pids: list[int], within: float) -> bool:
    deadline = time.monotonic() + within
    while any(_alive(c) for c in pids) and time.monotonic() < deadline:
        time.sleep(0.1)
    return not any(_alive(c) for c in pids)


@pytest.mark.slow  # a whole run or several processes: make test-all (make test keeps a smoke test)
def test_ctrl_c_stops_every_worker(tmp_path: Path) -> None:
    p, workers, run_dir = _start_run(tmp_path)
    p.send_signal(signal.SIGINT)
    assert p.wait(timeout=60) == 130
    assert _gone(workers, 10), f"worker processes left: {[c for c in workers if _alive(c)]}"
    res = json.loads((run_dir / "result.json").read_text())
    assert res["interrupted"] is True


@pytest.mark.slow
def test_workers_do_not_outlive_a_killed_run(tmp_path: Path) -> None:
    p, workers, _ = _start_run(tmp_path)
    p.kill()
    p.wait(timeout=30)
    assert _gone(workers, 10), f"worker processes left: {[c for c in workers if _alive(c)]}"
