"""Rollout workers as Ray actors: one actor per group of shards, on any node of a Ray cluster.

What it does: ``ray_cores(address)`` connects this process to Ray (``workers.ray_address``:
``None`` starts a local instance, ``"auto"`` or ``"host:port"`` joins a running cluster) and
returns the cluster's CPUs; ``RayPool`` starts one actor per group of shards, each building its
``ShardWorker`` once (all at once) and keeping it for the run, hands each actor its shards'
parts of every batch (``worker_parts``) and joins the results in row order (``join_results``).
Each actor asks for ``num_cpus`` CPUs (its PhysX threads, fitted to the nodes by
``actor_cpus``), so Ray never puts more simulating threads on a node than it has cores.
Faults: an actor that dies (its process killed, out of memory, its node lost) is replaced by a
fresh one that re-runs its rows; a second death on the same rows raises ``WorkerFailed``
naming the worker (index, rows, node, pid), Ray's cause of death and the last lines of the
actor's log (read on its node). An exception inside an actor is raised at once as
``WorkerFailed`` with the remote traceback.
``close`` kills our actors, and shuts down Ray only where this module started or joined it
(a local instance ends with all its processes; a cluster keeps running). Waiting, the run polls
Ray and sleeps in Python: a signal handler's exception inside a blocking ``ray.wait`` would come
back as a plain ``KeyboardInterrupt`` (SIGTERM read as Ctrl-C); so Ctrl-C and SIGTERM reach the
loop as they are, and the loop calls ``close``.
What it doesn't: choose the number of workers or shards (``realize.spec.workers_settings``,
``realize.workers.blocks``), install this project on the cluster's nodes (every node needs the
same environment), or use Ray's own actor restarts (``max_restarts=0``: one re-run, ours).
"""

from __future__ import annotations

import logging
import math
import os
import pickle
import re
import signal
import socket
import sys
import threading
import time
from collections.abc import Sequence
from types import ModuleType
from typing import TYPE_CHECKING, Any

from torch import Tensor

from realize.config import ConfigError
from realize.realization.result import RolloutResult
from realize.scene.shards import RowBlock
from realize.workers.blocks import check_batch, join_results, worker_parts, worker_starts
from realize.workers.errors import WorkerFailed

if TYPE_CHECKING:
    from realize.spec.run_spec import RunSpec
    from realize.tasks.spec import TaskSpec
    from realize.world.state import SceneState
    from realize.spec.workers_settings import WorkersSettings

__all__ = ["RayPool", "ray_cores", "ray_release", "actor_cpus"]

log = logging.getLogger("realize")

LOCAL_OBJECT_STORE_BYTES = 256 * 2**20  # a local instance's shared memory: plans and results are small
_RAY_MARKER = re.compile(r"^:(job_id|actor_name|task_name):")
_POLL_S = 0.05  # the run's sleep between looks at its actors (see the module docstring)
_owner = {"joined": False, "users": 0}  # ray_cores started or joined Ray here; pools (and callers) using it


def _ray() -> ModuleType:
    try:
        import ray
    except ImportError as e:
        raise ConfigError("workers.backend=ray needs Ray, an optional extra: pip install -e '.[ray]'") from e
    return ray


def ray_cores(address: str | None) -> int:
    """Connect to Ray (``None``: start a local instance on this machine's cores; ``"auto"`` or
    ``"host:port"``: a running cluster) unless connected already; the cluster's CPUs."""
    ray, address = _ray(), address or None  # "" (workers.ray_address=) is a local instance too
    if not ray.is_initialized():
        from realize.scene.cpu_tiled import available_cores

        kwargs: dict[str, Any] = dict(log_to_driver=False, logging_level=logging.WARNING)
        if address is None:
            kwargs.update(address="local", num_cpus=available_cores(), include_dashboard=False,
                          object_store_memory=LOCAL_OBJECT_STORE_BYTES)
        else:
            _check_reachable(os.environ.get("RAY_ADDRESS") or address if address == "auto" else address)
            kwargs["address"] = address
        main = threading.current_thread() is threading.main_thread()
        sigterm = signal.getsignal(signal.SIGTERM) if main else None
        try:
            ray.init(**kwargs)
        except (ConnectionError, RuntimeError, ValueError) as e:
            where = "a local Ray instance" if address is None else f"the Ray cluster at workers.ray_address={address}"
            hint = "" if address is None else (
                " (is it running: `ray status`? A cluster with token authentication needs RAY_AUTH_MODE=token here "
                "when the address is given, and its token in ~/.ray/auth_token or RAY_AUTH_TOKEN)")
            raise ConfigError(f"could not start or join {where}: {e}{hint}") from e
        finally:
            if main:  # ray.init sets its own SIGTERM handler (sys.exit); the run's handler decides
                signal.signal(signal.SIGTERM, sigterm)
        _owner["joined"] = True
        log.info("Ray: %s, %d CPU(s) on %d node(s)", "local instance" if address is None else f"cluster at {address}",
                 int(ray.cluster_resources().get("CPU", 0)), len(_alive_nodes(ray)))
    _owner["users"] += 1
    cpus = int(ray.cluster_resources().get("CPU", 0))
    if cpus < 1:
        ray_release()
        raise ConfigError(f"the Ray cluster at {address} has no CPUs")
    return cpus


def _check_reachable(address: str, timeout_s: float = 10.0) -> None:
    """Refuse a ``host:port`` where nothing listens (``ray.init`` would wait for it for ever)."""
    host, _, port = address.rpartition(":")
    if "://" in address or not host or not port.isdigit():
        return  # "auto" (Ray finds the cluster it started last on this node) or a form Ray checks itself
    try:
        socket.create_connection((host.strip("[]"), int(port)), timeout=timeout_s).close()
    except OSError as e:
        raise ConfigError(f"nothing answers at workers.ray_address={address} ({e.strerror or e}): start the "
                          f"cluster first (`ray start --head` on its head node) or correct the address") from None


def ray_release() -> None:
    """Undo one ``ray_cores``: the last one disconnects from Ray if ``ray_cores`` connected (a
    local instance stops, processes and all; a cluster keeps running)."""
    _owner["users"] = max(0, _owner["users"] - 1)
    if _owner["joined"] and _owner["users"] == 0:
        _owner["joined"] = False
        _ray().shutdown()


def _alive_nodes(ray: ModuleType) -> list[dict[str, Any]]:
    return [n for n in ray.nodes() if n.get("Alive")]


def actor_cpus(node_cpus: Sequence[float], n: int, want: float) -> float:
    """CPUs per actor so that ``n`` actors fit on nodes of ``node_cpus`` CPUs: the most up to
    ``want`` (at least one), or a fraction of one where the cluster has fewer CPUs than actors."""
    fits = lambda c: sum(math.floor(x / c + 1e-9) for x in node_cpus) >= n  # noqa: E731
    c = max(1, int(want))
    while c > 1 and not fits(c):
        c -= 1
    if fits(c):
        return float(c)
    k = 2
    while not fits(1 / k) and k < 10_000:
        k += 1
    return 1 / k


def _tail(path: str, n: int = 20) -> list[str]:
    with open(path, "rb") as f:
        f.seek(0, os.SEEK_END)
        f.seek(max(0, f.tell() - 64 * 1024))
        return f.read().decode(errors="replace").splitlines()[-n:]


# ---------------------------------------------------------------------- inside an actor
class ShardActor:
    """A Ray actor holding one ``ShardWorker`` (its log: the Ray worker's stderr on its node)."""

    def __init__(self, k: int) -> None:
        self.k, self.worker = k, None
        if threading.current_thread() is threading.main_thread():
            signal.signal(signal.SIGINT, signal.SIG_IGN)  # the run decides what Ctrl-C means
        logging.basicConfig(level=logging.INFO, stream=sys.stderr, force=True,
                            format=f"%(asctime)s worker {k} [pid {os.getpid()}] %(message)s")

    def build(self, payload: bytes) -> dict[str, Any]:
        """Build the shards' scenes; where this actor runs (node, pid, log files)."""
        import ray

        from realize.workers.worker import ShardWorker

        spec, tasks, shards, threads = pickle.loads(payload)
        self.worker = ShardWorker(spec, tasks, shards, threads)
        log.info("%s: scenes built in %.1f s (PhysX threads: %s)", self.worker.describe(),
                 self.worker.setup_time_s, threads)
        logs = []
        for fd in (2, 1):
            try:
                logs.append(os.readlink(f"/proc/self/fd/{fd}"))
            except OSError:
                pass
        return dict(pid=os.getpid(), node_id=ray.get_runtime_context().get_node_id(),
                    node_ip=ray.util.get_node_ip_address(), logs=[p for p in logs if p.startswith("/")],
                    setup_time_s=self.worker.setup_time_s)

    def rollout(self, candidate: int | None, parts: list[Tensor], record: bool, starts: Any = None,
                capture_end: bool = False) -> RolloutResult:
        """Realize ``parts[k]`` in shard ``k`` (``ShardWorker.rollout``)."""
        assert self.worker is not None
        log.info("rollout of %d rows (candidate %s)", sum(p.shape[0] for p in parts), candidate)
        res = self.worker.rollout(candidate, parts, record, starts, capture_end)
        log.info("done in %.1f s, %d control steps", res.wall_time_s, res.sim_steps)
        return res


def _read_tails(paths: Sequence[str], n: int) -> str:
    """The last ``n`` lines of each file (Ray's own ``:job_id:``-style marker lines left out)."""
    out = []
    for p in paths:
        try:
            lines = [ln for ln in _tail(p, n + 4) if not _RAY_MARKER.match(ln)][-n:]
        except OSError as e:
            out.append(f"    ({p}: {e.strerror})")
            continue
        if lines:
            out.append(f"    [{p}]")
            out.extend("    " + ln for ln in lines)
    return "\n".join(out) or "    (empty log)"


# ---------------------------------------------------------------------- the run's side
class _Slot:
    """One actor as the pool sees it."""

    def __init__(self, k: int, shards: list[RowBlock], actor: Any, ready: Any) -> None:
        self.k, self.shards, self.actor, self.ready = k, shards, actor, ready
        self.first, self.stop = shards[0].first, shards[-1].stop
        self.info: dict[str, Any] = {}

    def name(self) -> str:
        where = f", node {self.info['node_ip']}, pid {self.info['pid']}" if self.info else ""
        return f"worker {self.k} (rows {self.first}-{self.stop - 1}{where})"


class RayPool:
    """Rollout workers as Ray actors (see the module docstring). Call ``ray_cores`` first."""

    backend = "cpu"
    kind = "ray"

    def __init__(self, spec: RunSpec, tasks: Sequence[TaskSpec], groups: Sequence[Sequence[RowBlock]],
                 settings: WorkersSettings, physx_threads: int | None) -> None:
        self._ray = ray = _ray()
        self.groups = [list(g) for g in groups]
        self.n_envs = self.groups[-1][-1].stop
        self.unit = spec.ce.replicas  # a robust search's sample: its copies stay in one shard
        self.n_workers = len(self.groups)
        self.log_location = "each actor's worker-*.err in its node's Ray session logs (/tmp/ray/session_latest/logs)"
        self._timeout = settings.start_timeout_s
        self.slots: list[_Slot] = []
        self._payloads: dict[int, Any] = {}
        self._holds_ray = True  # the ray_cores call that opened this pool, undone by close
        t0 = time.perf_counter()
        try:
            nodes = [float(nd["Resources"].get("CPU", 0)) for nd in _alive_nodes(ray)]
            self.cpus = actor_cpus(nodes, self.n_workers, max(1, physx_threads or 0))
            threads = physx_threads if spec.sim.cpu_workers is not None else (int(self.cpus) if self.cpus >= 2 else 0)
            if self.cpus < 1:
                log.warning("%d Ray actors on %d CPU(s): %.2f CPU each (oversubscribed)", self.n_workers,
                            int(sum(nodes)), self.cpus)
            self._actor_class = ray.remote(ShardActor).options(num_cpus=self.cpus, max_restarts=0,
                                                                 max_task_retries=0)
            self._payloads = {k: ray.put(pickle.dumps((spec, list(tasks), g, threads)))
                              for k, g in enumerate(self.groups)}
            self.slots = [self._start(k) for k in range(self.n_workers)]
            self._await_ready(self.slots)
        except BaseException:
            self.close()
            raise
        self.setup_time_s = time.perf_counter() - t0

    # -------------------------------------------------------------- lifecycle
    def _start(self, k: int) -> _Slot:
        actor = self._actor_class.remote(k)
        return _Slot(k, self.groups[k], actor, actor.build.remote(self._payloads[k]))

    def _await_ready(self, slots: Sequence[_Slot]) -> None:
        ray, deadline = self._ray, time.monotonic() + self._timeout
        pending = {s.ready: s for s in slots}
        while pending:
            left = deadline - time.monotonic()
            if left <= 0:
                s = next(iter(pending.values()))
                raise WorkerFailed(
                    f"{s.name()} did not build its scenes within workers.start_timeout_s = {self._timeout:.0f} s "
                    f"(each actor needs {self.cpus:g} CPU(s); Ray cluster: {ray.cluster_resources().get('CPU', 0):g} "
                    f"CPU(s), {ray.available_resources().get('CPU', 0):g} free)")
            for ref in _finished(ray, list(pending)):
                s = pending.pop(ref)
                try:
                    s.info = ray.get(ref)
                except ray.exceptions.RayTaskError as e:
                    raise WorkerFailed(f"{s.name()} could not build its scenes:\n{e}") from None
                except _deaths(ray) as e:
                    raise self._failure(s, e, "died while building its scenes") from None
                log.info("%s ready (setup %.1f s; its log: %s on that node)", s.name(), s.info["setup_time_s"],
                         s.info["logs"][0] if s.info["logs"] else "Ray's worker log")

    def _failure(self, s: _Slot, e: BaseException, what: str) -> WorkerFailed:
        cause = "\n".join("    " + ln for ln in str(e).strip().splitlines())
        if "ModuleNotFoundError" in cause:
            what += " (is this project installed, in the same environment, on every node of the cluster?)"
        return WorkerFailed(f"{s.name()} {what}. Ray says:\n{cause}\nits last log lines:\n{self._last_lines(s)}")

    def _last_lines(self, s: _Slot, n: int = 20) -> str:
        """The tail of a dead actor's log: read here if it is on this node, else by a task on its node."""
        ray, paths = self._ray, s.info.get("logs", [])
        if not paths:
            return "    (the actor never reported its log files)"
        try:
            here = ray.get_runtime_context().get_node_id() == s.info["node_id"]
            if here and all(os.path.exists(p) for p in paths):
                return _read_tails(paths, n)
            from ray.util.scheduling_strategies import NodeAffinitySchedulingStrategy

            task = ray.remote(_read_tails).options(
                num_cpus=0, max_retries=0,
                scheduling_strategy=NodeAffinitySchedulingStrategy(s.info["node_id"], soft=False))
            return ray.get(task.remote(paths, n), timeout=30)
        except Exception as e:  # the node itself may be gone
            return f"    (could not read {', '.join(paths)} on node {s.info.get('node_ip')}: {type(e).__name__})"

    def _restart(self, s: _Slot) -> _Slot:
        self._kill(s)
        fresh = self._start(s.k)
        self.slots[s.k] = fresh
        self._await_ready([fresh])
        return fresh

    def _kill(self, s: _Slot) -> None:
        try:
            self._ray.kill(s.actor, no_restart=True)
        except Exception:  # already gone
            pass

    def close(self) -> None:
        """Kill our actors; stop (local instance) or leave (cluster) Ray if ``ray_cores`` joined it."""
        for s in self.slots:
            self._kill(s)
        self.slots = []
        self._payloads = {}
        if self._holds_ray:
            self._holds_ray = False
            try:
                ray_release()
            except Exception:  # pragma: no cover
                log.warning("Ray did not shut down cleanly", exc_info=True)

    def __enter__(self) -> RayPool:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # -------------------------------------------------------------- work
    def rollout(self, candidate: int | None, Z: Tensor, record: bool = False,
                starts: Sequence[SceneState] | None = None, capture_end: bool = False) -> RolloutResult:
        """Realize the ``M <= n_envs`` rows of ``Z``: each actor its shards' parts, joined in order."""
        ray = self._ray
        check_batch(Z, self.n_envs)
        t0 = time.perf_counter()
        per_worker = worker_parts(Z.detach().cpu(), self.groups, self.unit)
        start_parts = worker_starts(starts, Z.shape[0], self.groups, self.unit)
        # each part copied out of Z: a view would send Z's whole storage to every actor
        jobs = {k: [p.clone() for p in parts] for k, parts in enumerate(per_worker) if sum(p.shape[0] for p in parts)}
        pending = {self.slots[k].actor.rollout.remote(candidate, parts, record, start_parts[k], capture_end): k
                   for k, parts in jobs.items()}
        results: dict[int, RolloutResult] = {}
        retried: set[int] = set()
        while pending:
            for ref in _finished(ray, list(pending)):
                k = pending.pop(ref)
                s = self.slots[k]
                try:
                    results[k] = ray.get(ref)
                except ray.exceptions.RayTaskError as e:
                    raise WorkerFailed(f"{s.name()} raised during a rollout:\n{e}") from None
                except _deaths(ray) as e:
                    if k in retried:
                        raise self._failure(s, e, "died again on the same rows") from None
                    log.warning("%s died (%s); re-running its rows on a fresh worker", s.name(),
                                str(e).strip().splitlines()[0] if str(e).strip() else type(e).__name__)
                    retried.add(k)
                    fresh = self._restart(s)
                    pending[fresh.actor.rollout.remote(candidate, jobs[k], record, start_parts[k], capture_end)] = k
        res = join_results([results[k] for k in sorted(results)])
        res.wall_time_s = time.perf_counter() - t0
        return res

    def pids(self) -> list[int]:
        """The actors' process ids (for tests and tools)."""
        return [s.info["pid"] for s in self.slots]


def _finished(ray: ModuleType, refs: list[Any]) -> list[Any]:
    """Those of ``refs`` that are done, after a short sleep in Python if none is."""
    done, _ = ray.wait(refs, num_returns=len(refs), timeout=0)
    if not done:
        time.sleep(_POLL_S)
    return done


def _deaths(ray: ModuleType) -> tuple[type[BaseException], ...]:
    """Ray's errors for an actor that is gone (rather than one that raised)."""
    ex = ray.exceptions
    return (ex.RayActorError, ex.WorkerCrashedError, ex.OutOfMemoryError, ex.NodeDiedError, ex.ObjectLostError,
            ex.LocalRayletDiedError)
