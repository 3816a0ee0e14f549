"""Rollout workers as Ray actors (realize.workers.ray_pool), on a local Ray instance.

Checks: actor CPUs fit the nodes; a run with two Ray actors gives the numbers of one process
(the issue's must-show, against a live one-process run: best_cost, success_per_iter,
best_cost_per_iter, best_z); an exception inside an actor stops with its remote traceback and
no re-run; an actor killed mid-rollout is replaced and its rows re-run to the same result; a
second kill stops with an error naming the worker, Ray's cause and its last log lines; closing
the pool, Ctrl-C and a killed run leave no Ray process (raylet, gcs_server, actors: the
process table is read). Skipped where Ray is not installed (``pip install -e '.[ray]'``).
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest
import torch

from _compose import compose_config
from realize.run_config import build_run_spec
from realize.workers.errors import WorkerFailed

pytest.importorskip("ray")

from realize.workers.ray_pool import actor_cpus  # noqa: E402

REPO = Path(__file__).resolve().parents[1]
RUN16 = ["ce.n_envs=16", "ce.n_elite=4", "ce.iterations=2", "seed=3", "sim.shard_rows=8",
         "logging.progress=false", "logging.rerun=false"]
KEYS = ("best_cost", "success_per_iter", "best_cost_per_iter", "best_z", "n_feasible_per_iter", "final_mean",
        "final_std")


# ------------------------------------------------------------------------------ process table
def _procs() -> dict[int, tuple[int, str]]:
    """Every live process: pid -> (parent pid, command line)."""
    out = {}
    for d in Path("/proc").iterdir():
        if not d.name.isdigit():
            continue
        try:
            fields = (d / "stat").read_text().rsplit(")", 1)[1].split()
            cmd = (d / "cmdline").read_bytes().replace(b"\0", b" ").decode(errors="replace").strip()
        except OSError:
            continue
        if fields[0] != "Z":
            out[int(d.name)] = (int(fields[1]), cmd)
    return out


def _descendants(pid: int) -> dict[int, str]:
    procs, out, todo = _procs(), {}, [pid]
    while todo:
        p = todo.pop()
        for c, (parent, cmd) in procs.items():
            if parent == p and c not in out:
                out[c] = cmd
                todo.append(c)
    return out


def _left(pids: dict[int, str], within: float) -> dict[int, str]:
    """Those of ``pids`` still alive after ``within`` seconds (waiting while any is)."""
    deadline = time.monotonic() + within
    while True:
        live = _procs()
        left = {p: c for p, c in pids.items() if p in live}
        if not left or time.monotonic() > deadline:
            return left
        time.sleep(0.2)


def _session_procs(session: str) -> dict[int, str]:
    """Processes whose command line names a Ray session directory (its raylet, gcs_server, agents)."""
    return {p: c for p, (_, c) in _procs().items() if session in c}


def _ray_processes(tree: dict[int, str]) -> set[str]:
    return {c.split()[0].rsplit("/", 1)[-1] for c in tree.values() if "ray" in c}


# ------------------------------------------------------------------------------ arithmetic
def test_actor_cpus_fit_the_nodes() -> None:
    assert actor_cpus([2], 2, 1) == 1 and actor_cpus([16], 2, 8) == 8
    assert actor_cpus([16, 16], 3, 10) == 8  # 10 CPUs each would fit only two actors on two nodes
    assert actor_cpus([16, 8], 4, 6) == 5 and actor_cpus([4, 4, 4], 3, 4) == 4
    assert actor_cpus([2], 4, 1) == 0.5 and actor_cpus([2, 1], 7, 1) == pytest.approx(1 / 3)


# ------------------------------------------------------------------------------ same numbers
def _realize(*args: str, run_dir: Path, timeout: float = 600) -> tuple[dict, float]:
    env = dict(os.environ, PYTHONPATH=str(REPO) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    t0 = time.perf_counter()
    p = subprocess.run([sys.executable, "-m", "realize", *args, f"hydra.run.dir={run_dir}"], cwd=run_dir.parent,
                       env=env, capture_output=True, text=True, timeout=timeout)
    assert p.returncode == 0, p.stderr[-3000:]
    return json.loads((run_dir / "result.json").read_text()), time.perf_counter() - t0


def test_two_ray_actors_give_the_numbers_of_one_process(tmp_path: Path) -> None:
    one, t1 = _realize(*RUN16, "workers.n=1", run_dir=tmp_path / "one")
    two, t2 = _realize(*RUN16, "workers.n=2", "workers.backend=ray", run_dir=tmp_path / "ray")
    print(f"one process {t1:.1f} s, two Ray actors {t2:.1f} s (Ray start included)")
    assert one["workers"] == 1 and two["workers"] == 2
    for k in KEYS:
        assert two[k] == one[k], k
    assert one["best_cost"] == 597.0 and one["success_per_iter"] == [0.0625, 0.0]  # the coordinator's numbers


# ------------------------------------------------------------------------------ faults
@pytest.fixture(scope="module")
def pool_and_batch():
    """Two actors (rows 0-3, 4-7) on a local Ray instance started by ``open_pool``, a batch,
    and every process the instance started (read while it runs)."""
    from realize.workers.pool import open_pool

    spec = build_run_spec(compose_config("ce.n_envs=8", "ce.n_elite=2", "sim.shard_rows=4", "controller.max_time_s=4",
                                         "workers.n=2", "workers.backend=ray"))
    Z = spec.task.layout.sample_uniform(8, generator=torch.Generator().manual_seed(0))
    pool = open_pool(spec)
    try:
        assert pool.kind == "ray" and pool.n_workers == 2 and pool.cpus == 1.0
        yield spec, pool, Z, _descendants(os.getpid())
    finally:
        pool.close()


def _log_of(slot) -> Path:
    return Path(slot.info["logs"][0])  # the actor's stderr: its log lines


def _kill_on_rollout(pool, times: int) -> threading.Thread:
    """SIGKILL the process of worker 1 once it starts a rollout, ``times`` actors in a row."""

    def run() -> None:
        killed: set[int] = set()
        deadline = time.monotonic() + 300
        while len(killed) < times and time.monotonic() < deadline:
            s = pool.slots[1] if len(pool.slots) > 1 else None
            if s is not None and s.info and s.info["pid"] not in killed and "rollout of" in _log_of(s).read_text():
                os.kill(s.info["pid"], signal.SIGKILL)
                killed.add(s.info["pid"])
            time.sleep(0.05)

    t = threading.Thread(target=run, daemon=True)
    t.start()
    return t


def test_an_exception_in_an_actor_stops_with_its_traceback_and_no_rerun(pool_and_batch) -> None:
    _, pool, Z, _ = pool_and_batch
    pids = pool.pids()
    with pytest.raises(WorkerFailed) as e:
        pool.rollout(7, Z)  # no candidate 7: the realizer lookup raises inside the actor
    msg = str(e.value)
    assert "raised during a rollout" in msg and "IndexError" in msg and "worker.py" in msg
    assert pool.pids() == pids  # a bug is not re-run


def test_a_killed_actor_is_replaced_and_its_rows_rerun(pool_and_batch) -> None:
    from realize.workers.pool import InProcessPool, run_shards

    spec, pool, Z, _ = pool_and_batch
    first = pool.pids()
    killer = _kill_on_rollout(pool, times=1)
    res = pool.rollout(None, Z)
    killer.join(timeout=5)
    assert pool.pids()[0] == first[0] and pool.pids()[1] != first[1]
    assert _log_of(pool.slots[1]).read_text().count("rollout of 4 rows") == 1  # the fresh actor re-ran them
    with InProcessPool(spec, [spec.task], run_shards(spec)) as ref:
        want = ref.rollout(None, Z)  # fresh scenes, as the replacement actor's
    for k in ("cost", "feasible", "steps", "distance", "progress"):
        assert torch.equal(getattr(res, k), getattr(want, k)), k
    assert res.failure == want.failure


def test_an_actor_killed_twice_stops_the_run_with_its_name(pool_and_batch) -> None:
    _, pool, Z, _ = pool_and_batch
    _kill_on_rollout(pool, times=2)
    with pytest.raises(WorkerFailed) as e:
        pool.rollout(None, Z)
    msg = str(e.value)
    print(msg)
    assert "worker 1 (rows 4-7, node " in msg and ", pid " in msg and "died again on the same rows" in msg
    assert "Ray says:" in msg and "died" in msg.split("Ray says:")[1]  # Ray's cause of death
    assert "rollout of 4 rows" in msg.split("last log lines:")[1]  # the actor's own log, read on its node


def test_close_leaves_no_ray_process(pool_and_batch) -> None:
    _, pool, _, tree = pool_and_batch
    assert {"raylet", "gcs_server"} <= _ray_processes(tree), tree
    tree.update(_descendants(os.getpid()))  # the actors started since
    pool.close()
    left = _left(tree, 15)
    assert not left, f"left after close: {left}"


# ------------------------------------------------------------------------------ Ctrl-C, kill
def _start_run(tmp_path: Path) -> tuple[subprocess.Popen, dict[int, str], str]:
    """A ray-backed run, once both actors roll out: the process, its process tree, its Ray session."""
    env = dict(os.environ, PYTHONPATH=str(REPO) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    p = subprocess.Popen([sys.executable, "-m", "realize", *RUN16, "ce.iterations=5", "workers.n=2",
                          "workers.backend=ray", f"hydra.run.dir={tmp_path / 'run'}"], cwd=tmp_path, env=env,
                         stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True, start_new_session=True)
    deadline = time.monotonic() + 300
    while True:
        tree = _descendants(p.pid)
        if sum(c.startswith("ray::ShardActor.rollout") for c in tree.values()) == 2:
            break
        assert p.poll() is None, p.stderr.read()[-3000:] if p.stderr else ""
        assert time.monotonic() < deadline, "the actors did not start rolling out"
        time.sleep(0.2)
    session = next(w for c in tree.values() for w in c.split() if "session_" in w)
    session = session[session.index("session_"):].split("/")[0]
    return p, tree, session


def test_ctrl_c_stops_every_ray_process(tmp_path: Path) -> None:
    p, tree, session = _start_run(tmp_path)
    assert {"raylet", "gcs_server"} <= _ray_processes(tree), tree
    os.killpg(p.pid, signal.SIGINT)  # as a terminal's Ctrl-C: the run's whole process group
    assert p.wait(timeout=60) == 130, p.stderr.read()[-3000:] if p.stderr else ""
    print(p.stderr.read()[-3000:] if p.stderr else "")
    left = _left(tree, 15)
    assert not left, f"left after Ctrl-C: {left}"
    assert not _session_procs(session)
    res = json.loads((tmp_path / "run" / "result.json").read_text())
    assert res["interrupted"] is True


@pytest.mark.slow
def test_ray_processes_do_not_outlive_a_killed_run(tmp_path: Path) -> None:
    p, tree, session = _start_run(tmp_path)
    p.kill()
    p.wait(timeout=30)
    # raylet and gcs_server die with the run (Linux parent-death signal), the actors with the
    # raylet; Ray's two agents see the raylet gone at once but wait 60 s reporting it to the
    # dead gcs_server before they exit
    left = _left(tree, 90)
    assert not left, f"left after the run was killed: {left}"
    assert not _session_procs(session)
