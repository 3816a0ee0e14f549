"""Rollout workers as Ray actors (realize.workers.ray_pool), on a local Ray instance and on a
cluster started with ``ray start --head``.

Checks: without Ray the backend is a config error; actor CPUs fit the nodes; a run with two
Ray actors gives the numbers of one process (the issue's must-show, against a live
one-process run: best_cost, success_per_iter, best_cost_per_iter, best_z); an exception
inside an actor stops with its remote traceback and no re-run; an actor killed mid-rollout is
replaced and its rows re-run to the same result; a second kill stops with an error naming the
worker, Ray's cause and its last log lines; closing the pool, Ctrl-C (exit 130), SIGTERM (exit
143) and a killed run leave no Ray process (raylet, gcs_server, agents, actors: the process
table is read); a run on a running cluster puts its actors there and leaves the cluster
running. Ray is part of the install (``scripts/setup.sh`` installs the ``ray`` extra): without it
this file fails instead of skipping.
"""

from __future__ import annotations

import json
import re
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import Callable

import pytest
import ray
import torch

from helpers import KEYS, RUN16, compose_config, kill_on_rollout, realize_cli, realize_result
from realize.spec.run_spec import build_run_spec
from realize.workers.errors import WorkerFailed

from realize.config import ConfigError
from realize.workers.ray_pool import actor_cpus, ray_cores


REPO = Path(__file__).resolve().parents[1]


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
def test_without_ray_the_backend_is_a_config_error(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setitem(sys.modules, "ray", None)  # import ray -> ImportError
    with pytest.raises(ConfigError, match=re.escape("pip install -e '.[ray]'")):
        ray_cores(None)


def test_actor_cpus_fit_the_nodes() -> None:
    assert actor_cpus([2], 2, 1) == 1 and actor_cpus([16], 2, 8) == 8
    assert actor_cpus([16, 16], 3, 10) == 8  # 10 CPUs each would fit only two actors on two nodes
    assert actor_cpus([16, 8], 4, 6) == 5 and actor_cpus([4, 4, 4], 3, 4) == 4
    assert actor_cpus([2], 4, 1) == 0.5 and actor_cpus([2, 1], 7, 1) == pytest.approx(1 / 3)


# ------------------------------------------------------------------------------ same numbers
def _realize(*args: str, run_dir: Path, timeout: float = 600, env: dict[str, str] | None = None) -> tuple[dict, float]:
    t0 = time.perf_counter()
    return realize_result(*args, run_dir=run_dir, timeout=timeout, env=env), time.perf_counter() - t0


@pytest.mark.slow  # two runs, about 100 s on a 2-core machine
def test_two_ray_actors_give_the_numbers_of_one_process(tmp_path: Path) -> None:
    one, t1 = _realize(*RUN16, "workers.n=1", run_dir=tmp_path / "one")
    two, t2 = _realize(*RUN16, "workers.n=2", "workers.backend=ray", run_dir=tmp_path / "ray")
    print(f"one process {t1:.1f} s, two Ray actors {t2:.1f} s (Ray start included)")
    assert one["workers"] == 1 and two["workers"] == 2
    for k in KEYS:
        assert two[k] == one[k], k


# ------------------------------------------------------------------------------ faults
@pytest.fixture(scope="module")
def pool_and_batch():
    """Two actors (rows 0-3, 4-7) on a local Ray instance started by ``open_pool``, a batch,
    and every process the instance started (read while it runs)."""
    from realize.workers.pool import open_pool

    spec = build_run_spec(compose_config("ce.n_envs=8", "ce.n_elite=2", "sim.shard_rows=4", "controller.max_time_s=4",
                                         "workers.n=2", "workers.backend=ray"))
    Z = spec.task.layout.sample_uniform(8, generator=torch.Generator().manual_seed(0))
    sigterm = signal.getsignal(signal.SIGTERM)
    before = set(_descendants(os.getpid()))  # e.g. multiprocessing's resource tracker of earlier tests
    pool = open_pool(spec)
    try:
        assert pool.kind == "ray" and pool.n_workers == 2 and pool.cpus == 1.0
        assert signal.getsignal(signal.SIGTERM) is sigterm  # ray.init's own handler (sys.exit) undone
        yield spec, pool, Z, (before, {p: c for p, c in _descendants(os.getpid()).items() if p not in before})
    finally:
        pool.close()


def _log_of(slot) -> Path:
    return Path(slot.info["logs"][0])  # the actor's stderr: its log lines


def _actor_1_in_rollout(pool) -> Callable[[list[int]], int | None]:
    """``kill_on_rollout``'s victim: the pid of worker 1's actor once its own log shows a
    rollout started, each actor once (a replacement actor has a new pid and a new log)."""

    def victim(killed: list[int]) -> int | None:
        s = pool.slots[1] if len(pool.slots) > 1 else None
        if s is not None and s.info and s.info["pid"] not in killed and "rollout of" in _log_of(s).read_text():
            return s.info["pid"]
        return None

    return victim


@pytest.mark.slow  # starts Ray (about 9 s); make test keeps the config checks above
def test_an_exception_in_an_actor_stops_with_its_traceback_and_no_rerun(pool_and_batch) -> None:
    _, pool, Z, _ = pool_and_batch
    pids = pool.pids()
    with pytest.raises(WorkerFailed) as e:
        pool.rollout(7, Z)  # no candidate 7: the realizer lookup raises inside the actor
    msg = str(e.value)
    assert "raised during a rollout" in msg and "IndexError" in msg and "worker.py" in msg
    assert pool.pids() == pids  # a bug is not re-run


@pytest.mark.slow  # starts Ray; make test keeps the config checks above
def test_a_killed_actor_is_replaced_and_its_rows_rerun(pool_and_batch) -> None:
    from realize.workers.pool import InProcessPool, run_shards

    spec, pool, Z, _ = pool_and_batch
    first = pool.pids()
    killer = kill_on_rollout(_actor_1_in_rollout(pool), times=1)
    res = pool.rollout(None, Z)
    killer.join(timeout=5)
    assert pool.pids()[0] == first[0] and pool.pids()[1] != first[1]
    assert _log_of(pool.slots[1]).read_text().count("rollout of 4 rows") == 1  # the fresh actor re-ran them
    with InProcessPool(spec, [spec.task], run_shards(spec)) as ref:
        want = ref.rollout(None, Z)  # fresh scenes, as the replacement actor's
    for k in ("cost", "feasible", "steps", "distance", "progress"):
        assert torch.equal(getattr(res, k), getattr(want, k)), k
    assert res.failure == want.failure


@pytest.mark.slow  # starts Ray; make test keeps the config checks above
def test_an_actor_killed_twice_stops_the_run_with_its_name(pool_and_batch) -> None:
    _, pool, Z, _ = pool_and_batch
    kill_on_rollout(_actor_1_in_rollout(pool), times=2)
    with pytest.raises(WorkerFailed) as e:
        pool.rollout(None, Z)
    msg = str(e.value)
    print(msg)
    assert "worker 1 (rows 4-7, node " in msg and ", pid " in msg and "died again on the same rows" in msg
    assert "Ray says:" in msg and "died" in msg.split("Ray says:")[1]  # Ray's cause of death
    assert "rollout of 4 rows" in msg.split("last log lines:")[1]  # the actor's own log, read on its node


@pytest.mark.slow  # starts Ray (about 9 s); make test keeps the config checks above
def test_close_leaves_no_ray_process(pool_and_batch) -> None:
    _, pool, _, (before, tree) = pool_and_batch
    assert {"raylet", "gcs_server"} <= _ray_processes(tree), tree
    tree.update({p: c for p, c in _descendants(os.getpid()).items() if p not in before})  # the actors started since
    pool.close()
    left = _left(tree, 15)
    assert not left, f"left after close: {left}"


# ------------------------------------------------------------------------------ Ctrl-C, kill
def _start_run(tmp_path: Path) -> tuple[subprocess.Popen, dict[int, str], str]:
    """A ray-backed run, once both actors roll out: the process, its process tree, its Ray session."""
    p = realize_cli(*RUN16, "ce.iterations=5", "workers.n=2", "workers.backend=ray",
                    f"hydra.run.dir={tmp_path / 'run'}", cwd=tmp_path, background=True, stdout=subprocess.DEVNULL,
                    stderr=subprocess.PIPE, start_new_session=True)
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


@pytest.mark.slow  # a whole run in Ray actors
@pytest.mark.parametrize("how", ["ctrl-c", "sigterm"])
def test_ctrl_c_stops_every_ray_process(tmp_path: Path, how: str) -> None:
    p, tree, session = _start_run(tmp_path)
    assert {"raylet", "gcs_server"} <= _ray_processes(tree), tree
    if how == "ctrl-c":
        os.killpg(p.pid, signal.SIGINT)  # as a terminal's: the run's whole process group
    else:
        p.send_signal(signal.SIGTERM)
    assert p.wait(timeout=60) == (130 if how == "ctrl-c" else 143), p.stderr.read()[-3000:] if p.stderr else ""
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


# ------------------------------------------------------------------------------ a running cluster
def _free_port() -> int:
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _stop_cluster(temp_dir: str) -> None:
    """End the processes of the cluster started under ``temp_dir`` (and theirs), by pid."""
    procs, mine, p = _procs(), set(), os.getpid()
    while p in procs and p not in mine:  # this process and its parents: never
        mine.add(p)
        p = procs[p][0]
    roots = [p for p, (_, c) in procs.items() if temp_dir in c and p not in mine]
    pids = {p: "" for p in roots}
    for r in roots:
        pids.update(_descendants(r))
    for sig in (signal.SIGTERM, signal.SIGKILL):
        for p in _left(pids, 0):
            try:
                os.kill(p, sig)
            except ProcessLookupError:
                pass
        if not _left(pids, 10):
            return


@pytest.mark.slow  # starts a cluster with `ray start --head`: about 35 s
def test_a_run_on_a_running_cluster_leaves_the_cluster_running(tmp_path: Path) -> None:
    """``ray start --head`` (as docs/workers.md says), then a run with ``workers.ray_address``: its
    actors run on the cluster and are gone after the run; the cluster's own processes stay."""
    import tempfile

    temp_dir = tempfile.mkdtemp(prefix="rt", dir="/tmp")  # short: Ray's socket paths live under it
    port = _free_port()
    env = {k: v for k, v in os.environ.items() if not k.startswith("RAY_")}
    env["PYTHONPATH"] = str(REPO)  # the cluster's workers import this checkout (as if installed on the node)
    ray_cli = str(Path(sys.executable).parent / "ray")
    address = f"{ray.util.get_node_ip_address()}:{port}"
    try:
        subprocess.run([ray_cli, "start", "--head", f"--port={port}", "--num-cpus=2",
                        "--include-dashboard=false", "--object-store-memory=150000000", f"--temp-dir={temp_dir}",
                        "--disable-usage-stats"], env=env, cwd=tmp_path, check=True, timeout=120,
                       stdout=(tmp_path / "ray-start.txt").open("w"), stderr=subprocess.STDOUT)
        cluster = {p: c for p, (_, c) in _procs().items() if temp_dir in c}
        assert {"raylet", "gcs_server"} <= _ray_processes(cluster), cluster
        # Ray enables token authentication where ~/.ray/auth_token exists (a local instance
        # writes it); a driver given an explicit address uses it only when told to
        token = "authentication is enabled" in (tmp_path / "ray-start.txt").read_text()
        res, t = _realize("ce.n_envs=8", "ce.n_elite=2", "ce.iterations=1", "sim.shard_rows=4",
                          "controller.max_time_s=4", "logging.progress=false", "logging.rerun=false", "workers.n=2",
                          "workers.backend=ray", f"workers.ray_address={address}", run_dir=tmp_path / "run",
                          env={"RAY_AUTH_MODE": "token"} if token else {})
        print(f"run on the cluster: {t:.1f} s")
        assert res["workers"] == 2 and res["status"] == "done"
        logs = [f.read_text() for f in Path(temp_dir).glob("session_latest/logs/worker-*.err")]
        assert sum("rollout of 4 rows" in t for t in logs) == 2, "the actors did not run on the cluster"
        assert not _left(cluster, 0).keys() ^ cluster.keys(), "the run stopped the cluster"
        raylet = next(p for p, c in cluster.items() if c.split()[0].endswith("raylet"))
        deadline = time.monotonic() + 15
        while any(c.startswith("ray::ShardActor") for c in _descendants(raylet).values()):
            assert time.monotonic() < deadline, f"actors left on the cluster: {_descendants(raylet)}"
            time.sleep(0.2)
    finally:
        _stop_cluster(temp_dir)
        shutil.rmtree(temp_dir, ignore_errors=True)
