"""Rollout workers as local processes: one scene per process, kept for the whole run.

What it does: ``ProcessPool`` starts one spawned process per group of shards (each builds its
``ShardWorker`` at once, all in parallel), hands each its rows of every batch, waits for all
and joins their results in row order. Faults: a worker that dies (killed, out of memory)
is replaced by a fresh one that re-runs its rows; if that one dies too, ``WorkerFailed`` names
the worker, its rows, how it ended and its last log lines (its log: ``<log_dir>/worker-K.log``).
An exception inside a worker is raised here with the worker's traceback (re-running a bug does
not help). Workers ignore SIGINT (the run decides what Ctrl-C means), die with their parent
(Linux ``PR_SET_PDEATHSIG``, and a watch on the parent everywhere else), and ``close`` ends
them: asked first, then SIGTERM, then SIGKILL, so no process outlives the run.
What it doesn't: choose the number of workers (``realize.spec.workers_settings``) or run on other
machines (``realize.workers.ray_pool``).
"""

from __future__ import annotations

import ctypes
import logging
import multiprocessing as mp
import os
import pickle
import signal
import sys
import threading
import time
import traceback
from collections.abc import Sequence
from multiprocessing.connection import Connection, wait
from pathlib import Path
from typing import TYPE_CHECKING, Any

from torch import Tensor

from realize.realization.result import RolloutResult
from realize.scene.shards import RowBlock
from realize.workers.blocks import check_batch, join_results, worker_parts, worker_starts
from realize.workers.errors import WorkerFailed

if TYPE_CHECKING:
    from realize.spec.run_spec import RunSpec
    from realize.tasks.spec import TaskSpec
    from realize.world.state import SceneState

__all__ = ["ProcessPool", "WorkerFailed", "last_lines"]

log = logging.getLogger("realize")


def last_lines(path: Path | None, n: int = 15) -> str:
    """The last ``n`` lines of a worker's log, indented (or a note that there is none)."""
    if path is None or not path.is_file():
        return "    (no log)"
    lines = path.read_text(errors="replace").splitlines()[-n:]
    return "\n".join("    " + ln for ln in lines) or "    (empty log)"


def _exit_text(code: int | None) -> str:
    if code is None:
        return "still running"
    if code < 0:
        try:
            return f"killed by {signal.Signals(-code).name}"
        except ValueError:
            return f"killed by signal {-code}"
    return f"exited with code {code}"


# ---------------------------------------------------------------------- inside a worker
def _die_with_parent(parent_pid: int) -> None:
    """End this process when the run's process ends, however it ends."""
    if sys.platform.startswith("linux"):
        try:
            ctypes.CDLL(None, use_errno=True).prctl(1, signal.SIGKILL)  # PR_SET_PDEATHSIG
        except (OSError, AttributeError):  # pragma: no cover
            pass

    def watch() -> None:
        while True:
            if os.getppid() != parent_pid:
                os._exit(1)
            time.sleep(1.0)

    if os.getppid() != parent_pid:  # the parent ended before the line above took effect
        os._exit(1)
    threading.Thread(target=watch, name="parent-watch", daemon=True).start()


def _send(conn: Connection, msg: tuple[Any, ...]) -> None:
    conn.send_bytes(pickle.dumps(msg, protocol=pickle.HIGHEST_PROTOCOL))


def worker_main(conn: Connection, payload: bytes, k: int, log_path: str | None, parent_pid: int) -> None:
    """A worker process: build its shards' scenes, then realize batches until told to close."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    _die_with_parent(parent_pid)
    if log_path is not None:
        fd = os.open(log_path, os.O_WRONLY | os.O_CREAT | os.O_APPEND, 0o644)
        os.dup2(fd, 1)
        os.dup2(fd, 2)
        os.close(fd)
        sys.stdout = os.fdopen(1, "w", buffering=1, closefd=False)
        sys.stderr = os.fdopen(2, "w", buffering=1, closefd=False)
    logging.basicConfig(level=logging.INFO, stream=sys.stderr, force=True,
                        format=f"%(asctime)s worker {k} [pid {os.getpid()}] %(message)s")
    from realize.workers.worker import ShardWorker

    spec, tasks, shards, threads = pickle.loads(payload)
    try:
        worker = ShardWorker(spec, tasks, shards, threads)
    except BaseException:
        _send(conn, ("error", traceback.format_exc()))
        return
    log.info("%s: scenes built in %.1f s (PhysX threads: %s)", worker.describe(), worker.setup_time_s, threads)
    _send(conn, ("ready", os.getpid(), worker.setup_time_s))
    while True:
        try:
            msg = pickle.loads(conn.recv_bytes())
        except (EOFError, OSError):
            break
        if msg[0] == "close":
            break
        if msg[0] in ("retask", "rebuild"):  # a replan: new realizers (retask) or new scenes (rebuild)
            try:
                t0 = time.perf_counter()
                (worker.retask if msg[0] == "retask" else worker.rebuild)(msg[1], msg[2])
            except Exception:
                _send(conn, ("error", traceback.format_exc()))
                continue
            log.info("%s done in %.1f s", msg[0], time.perf_counter() - t0)
            _send(conn, ("retasked",))
            continue
        _, candidate, parts, record, starts, capture_end = msg
        log.info("rollout of %d rows (candidate %s)", sum(p.shape[0] for p in parts), candidate)
        t0 = time.perf_counter()
        try:
            res = worker.rollout(candidate, parts, record, starts, capture_end)
        except Exception:
            _send(conn, ("error", traceback.format_exc()))
            continue
        log.info("done in %.1f s, %d control steps", time.perf_counter() - t0, res.sim_steps)
        _send(conn, ("result", res))
    worker.close()


# ---------------------------------------------------------------------- the run's side
class _Slot:
    """One worker process as the pool sees it."""

    def __init__(self, k: int, shards: list[RowBlock], proc: Any, conn: Connection, log_path: Path | None) -> None:
        self.k, self.shards, self.proc, self.conn, self.log_path = k, shards, proc, conn, log_path
        self.first, self.stop = shards[0].first, shards[-1].stop
        self.pid: int | None = None

    def name(self) -> str:
        return f"worker {self.k} (rows {self.first}-{self.stop - 1}, pid {self.pid or self.proc.pid})"


class ProcessPool:
    """Rollout workers in local processes (see the module docstring)."""

    backend = "cpu"
    kind = "process"

    def __init__(self, spec: RunSpec, tasks: Sequence[TaskSpec], groups: Sequence[Sequence[RowBlock]], *,
                 physx_threads: int | None, log_dir: Path | None = None, start_timeout_s: float = 600.0) -> None:
        self.groups = [list(g) for g in groups]
        self.n_envs = self.groups[-1][-1].stop
        self.unit = spec.ce.replicas  # a robust search's sample: its copies stay in one shard
        self.n_workers = len(self.groups)
        self._spec, self._tasks, self._threads = spec, list(tasks), physx_threads
        self._log_dir, self._timeout = log_dir, start_timeout_s
        if log_dir is not None:
            log_dir.mkdir(parents=True, exist_ok=True)
        self._ctx = mp.get_context("spawn")
        self.slots: list[_Slot] = []
        t0 = time.perf_counter()
        try:
            self.slots = [self._spawn(k, g) for k, g in enumerate(self.groups)]
            for s in self.slots:
                self._await_ready(s)
        except BaseException:
            self.close()
            raise
        self.setup_time_s = time.perf_counter() - t0

    # -------------------------------------------------------------- lifecycle
    def _spawn(self, k: int, shards: list[RowBlock]) -> _Slot:
        log_path = None if self._log_dir is None else self._log_dir / f"worker-{k}.log"
        parent, child = self._ctx.Pipe()
        payload = pickle.dumps((self._spec, self._tasks, shards, self._threads))
        proc = self._ctx.Process(target=worker_main, name=f"realize-worker-{k}", daemon=True,
                                 args=(child, payload, k, None if log_path is None else str(log_path), os.getpid()))
        proc.start()
        child.close()
        return _Slot(k, shards, proc, parent, log_path)

    def _failure(self, s: _Slot, what: str) -> WorkerFailed:
        s.proc.join(timeout=1.0)
        where = f" (log: {s.log_path})" if s.log_path is not None else ""
        return WorkerFailed(f"{s.name()} {what}: {_exit_text(s.proc.exitcode)}{where}; its last log lines:\n"
                            f"{last_lines(s.log_path)}")

    def _receive(self, s: _Slot, timeout: float | None) -> tuple[Any, ...] | None:
        """The worker's next message, or None if it died first. Raises on a timeout."""
        ready = wait([s.conn, s.proc.sentinel], timeout)
        if not ready:
            raise self._failure(s, f"sent nothing for {timeout:.0f} s")
        if s.conn.poll():
            try:
                return pickle.loads(s.conn.recv_bytes())
            except (EOFError, OSError):
                return None
        return None

    def _await_ready(self, s: _Slot) -> None:
        msg = self._receive(s, self._timeout)
        if msg is None:
            raise self._failure(s, "died while building its scene")
        if msg[0] == "error":
            raise WorkerFailed(f"{s.name()} could not build its scene:\n{msg[1]}")
        s.pid = msg[1]
        log.info("%s ready (setup %.1f s)", s.name(), msg[2])

    def _restart(self, s: _Slot) -> _Slot:
        self._end(s, ask=False)
        fresh = self._spawn(s.k, s.shards)
        self.slots[s.k] = fresh
        self._await_ready(fresh)
        return fresh

    def _end(self, s: _Slot, ask: bool = True) -> None:
        if ask and s.proc.is_alive():
            try:
                _send(s.conn, ("close",))
            except (OSError, ValueError):
                pass
            s.proc.join(timeout=2.0)
        if s.proc.is_alive():
            s.proc.terminate()
            s.proc.join(timeout=5.0)
        if s.proc.is_alive():  # pragma: no cover - ignores SIGTERM
            s.proc.kill()
            s.proc.join(timeout=5.0)
        s.conn.close()

    def close(self) -> None:
        """End every worker (asked, then SIGTERM, then SIGKILL)."""
        for s in self.slots:
            try:
                self._end(s)
            except Exception:  # pragma: no cover
                pass
        self.slots = []

    def __enter__(self) -> ProcessPool:
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()

    def retask(self, spec: RunSpec, tasks: Sequence[TaskSpec], what: str = "retask") -> None:
        """Every worker realizes ``tasks`` from now on, on the scenes it has (``ShardWorker.retask``;
        ``what="rebuild"``: on new scenes of ``spec``, ``ShardWorker.rebuild``); a worker started
        later (a restart) is built for them too."""
        self._spec, self._tasks = spec, list(tasks)
        for s in self.slots:
            _send(s.conn, (what, spec, self._tasks))
        for s in self.slots:
            msg = self._receive(s, self._timeout)
            if msg is None:
                raise self._failure(s, "died while taking a new task")
            if msg[0] == "error":
                raise WorkerFailed(f"{s.name()} could not take a new task:\n{msg[1]}")

    def rebuild(self, spec: RunSpec, tasks: Sequence[TaskSpec]) -> None:
        """New scenes for ``spec`` in the running workers (their processes kept)."""
        t0 = time.perf_counter()
        self.retask(spec, tasks, "rebuild")
        self.setup_time_s = time.perf_counter() - t0

    def pids(self) -> list[int]:
        """The worker processes' pids (for tests and tools)."""
        return [s.proc.pid for s in self.slots]

    # -------------------------------------------------------------- work
    def rollout(self, candidate: int | None, Z: Tensor, record: bool = False,
                starts: Sequence[SceneState] | None = None, capture_end: bool = False) -> RolloutResult:
        """Realize the ``M <= n_envs`` rows of ``Z``: each worker its shards' rows, joined in order
        (row i from ``starts[i]`` where given; ``capture_end``: ``PlanRealizer.rollout``)."""
        check_batch(Z, self.n_envs)
        t0 = time.perf_counter()
        per_worker = worker_parts(Z.detach().cpu(), self.groups, self.unit)
        start_parts = worker_starts(starts, Z.shape[0], self.groups, self.unit)
        jobs = {k: ("rollout", candidate, parts, record, start_parts[k], capture_end)
                for k, parts in enumerate(per_worker) if sum(p.shape[0] for p in parts)}
        for k, job in jobs.items():
            _send(self.slots[k].conn, job)
        results: dict[int, RolloutResult] = {}
        retried: set[int] = set()
        while len(results) < len(jobs):
            waiting = [self.slots[k] for k in jobs if k not in results]
            by_handle = {}
            for s in waiting:
                by_handle[s.conn] = s
                by_handle[s.proc.sentinel] = s
            for h in wait(list(by_handle)):
                s = by_handle[h]
                if s.k in results or self.slots[s.k] is not s:
                    continue
                msg = self._receive(s, 0)
                if msg is not None and msg[0] == "result":
                    results[s.k] = msg[1]
                elif msg is not None and msg[0] == "error":
                    raise WorkerFailed(f"{s.name()} raised during a rollout:\n{msg[1]}")
                elif s.k in retried:
                    raise self._failure(s, "died again on the same rows")
                else:
                    log.warning("%s died (%s); re-running its rows on a fresh worker", s.name(),
                                _exit_text(s.proc.exitcode))
                    retried.add(s.k)
                    fresh = self._restart(s)
                    _send(fresh.conn, jobs[s.k])
        res = join_results([results[k] for k in sorted(results)])
        res.wall_time_s = time.perf_counter() - t0
        return res
