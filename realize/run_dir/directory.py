"""``RunDir``: the one reader and writer of a run directory's files.

What it does: ``RunDir(path)`` names the files of a run directory (``realize.run_dir.names``)
and reads and writes each in its typed form:

=========================  ==========================================  =========================
file                       read                                        write
=========================  ==========================================  =========================
``result.json``            ``result()`` -> ``ResultDoc | FailureDoc``  ``write_result(doc)``,
                           (``result_json()``: the raw object),        ``write_failure(...)``,
                           ``status()``, ``best_plan()``               ``add_to_result(key, v)``
``history.npz``            ``history_arrays()``, ``load_history()``    ``write_history(h)``
``history_c{i}.npz``       the same with ``candidate=i``               the same
``checkpoint.json``        ``checkpoint()``                            ``write_checkpoint(c)``
``error.txt``              -                                           ``write_error(text)``
``scene.json``             ``scene()`` (else from the config)          ``write_scene(...)``
``trajectories_iter{k}``   ``trajectories(k)``, ``trajectory_iterations()``  ``write_trajectories(...)``
``job_status.json``        ``job_status()``                            ``write_job_status(s)``
=========================  ==========================================  =========================

Every write is atomic (a reader never sees half a file). Readers never unpickle.
``RunDir.existing(path)`` is the constructor for readers: it refuses a path that is not a run
directory. ``best_plan()`` is what replay and validation need (config, best_z, columns, saved
cost, the scene's copies and backend, the leading candidate of a top-k run).
What it doesn't: decide what a run does or when files are written (the search loop and its
sinks), or draw (``realize.figures``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from realize.tasks.param_layout import ParamLayout
from realize.run_dir.checkpoint import Checkpoint, load_checkpoint, save_checkpoint
from realize.run_dir.history import History, load_history
from realize.run_dir.jsonio import atomic_write_json, atomic_write_text, decode_float, read_json
from realize.run_dir.names import (
    CHECKPOINT_FILE,
    ERROR_FILE,
    HISTORY_FILE,
    JOB_STATUS_FILE,
    RESULT_FILE,
    candidate_file,
)
from realize.run_dir.result_doc import FailureDoc, PlanRef, ResultDoc, read_result_doc
from realize.run_dir.scene_files import (
    SceneInfo,
    load_trajectories,
    read_scene,
    save_scene,
    save_trajectories,
    trajectory_iterations,
)
from realize.run_dir.summaries import JobStatusDoc
from realize.run_dir.upgrade import upgrade_config

__all__ = ["RunDir", "RunDirError", "BestPlan"]


class RunDirError(ValueError):
    """A run directory lacks what a reader needs; the message names the file."""


@dataclass
class BestPlan:
    """What replay and validation need of a run: its resolved ``config``, the best sample
    ``best_z`` over ``columns``, its saved ``best_cost`` (``inf`` if none was feasible),
    ``feasible``, the scene's copy count ``n_envs`` and ``backend`` of the run, its ``status``,
    and for a top-k run the ``leader`` (the winner once decided) whose plan ``best_z`` belongs to."""

    run_dir: Path
    config: dict[str, Any]
    best_z: list[float]
    columns: list[str]
    best_cost: float
    feasible: bool
    n_envs: int | None
    backend: str | None
    status: str | None
    leader: PlanRef | None


class RunDir:
    """The files of one run directory (table in the module docstring)."""

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)

    @classmethod
    def existing(cls, path: str | Path) -> RunDir:
        """A run directory to read: ``FileNotFoundError`` unless ``path`` is a directory holding a
        ``result.json`` or a ``history.npz``."""
        rd = cls(path)
        if not rd.path.is_dir():
            raise FileNotFoundError(f"{rd.path} is not a directory")
        if not (rd.path / RESULT_FILE).is_file() and not (rd.path / HISTORY_FILE).is_file():
            raise FileNotFoundError(f"{rd.path} holds neither {RESULT_FILE} nor {HISTORY_FILE}: "
                                    "not a realize run directory")
        return rd

    def __repr__(self) -> str:
        return f"RunDir({str(self.path)!r})"

    # ---- paths ---------------------------------------------------------------------------

    @property
    def result_path(self) -> Path:
        return self.path / RESULT_FILE

    @property
    def checkpoint_path(self) -> Path:
        return self.path / CHECKPOINT_FILE

    def history_path(self, candidate: int | None = None) -> Path:
        """``history.npz``, or ``history_c{candidate}.npz`` of a top-k run."""
        return self.path / (HISTORY_FILE if candidate is None else candidate_file(HISTORY_FILE, candidate))

    # ---- result.json ---------------------------------------------------------------------

    def result_json(self) -> dict[str, Any] | None:
        """The raw object of ``result.json``; ``None`` if missing or unreadable."""
        return read_json(self.result_path)

    def result(self) -> ResultDoc | FailureDoc | None:
        """``result.json`` as a document (``None`` if missing or unreadable)."""
        d = self.result_json()
        return None if d is None else read_result_doc(d)

    def status(self) -> str | None:
        """``status`` of ``result.json`` (``running``, ``done``, ``interrupted``, ``failed``;
        ``"unknown"`` if it does not say), ``None`` without a readable ``result.json``."""
        d = self.result_json()
        return None if d is None else str(d.get("status", "unknown"))

    def config(self) -> dict[str, Any] | None:
        """The run's resolved config: ``result.json``'s, else the checkpoint's, else ``None``."""
        d = self.result_json() or {}
        cfg = d.get("config")
        if not isinstance(cfg, dict):
            cfg = (read_json(self.checkpoint_path) or {}).get("config")
        return upgrade_config(cfg) if isinstance(cfg, dict) else None

    def best_plan(self) -> BestPlan:
        """The run's best plan (``RunDirError`` if ``result.json`` is missing, unreadable, or
        holds no config or no best plan)."""
        path = self.result_path
        if not path.is_file():
            raise RunDirError(f"{path}: not found (is {self.path} a run directory written by `realize`?)")
        d = self.result_json()
        if d is None:
            raise RunDirError(f"{path}: cannot read it as a JSON object")
        if not isinstance(d.get("config"), dict):
            raise RunDirError(f"{path}: no resolved `config` mapping")
        z = d.get("best_z")
        if not isinstance(z, list) or not z or not all(isinstance(v, (int, float)) for v in z):
            raise RunDirError(f"{path}: no `best_z` (the run found no plan to replay)")
        try:
            doc = ResultDoc.from_json(d)
        except (KeyError, TypeError, ValueError, AttributeError) as e:
            raise RunDirError(f"{path}: malformed ({type(e).__name__}: {e})") from None
        n_envs = doc.n_envs if doc.n_envs is not None else (d["config"].get("ce") or {}).get("n_envs")
        return BestPlan(
            run_dir=self.path, config=upgrade_config(d["config"]), best_z=[float(v) for v in z], columns=doc.columns,
            best_cost=doc.best_cost,
            feasible=doc.feasible, n_envs=int(n_envs) if isinstance(n_envs, (int, float)) else None,
            backend=doc.backend, status=doc.status, leader=None if doc.halving is None else doc.halving.leader,
        )

    def write_result(self, doc: ResultDoc | FailureDoc) -> None:
        atomic_write_json(self.result_path, doc.to_json())

    def add_to_result(self, key: str, value: Any) -> None:
        """Add (or replace) one top-level key of ``result.json`` (re-read just before)."""
        d = self.result_json()
        if d is None:
            raise RunDirError(f"{self.result_path}: not found or unreadable")
        d[key] = value
        atomic_write_json(self.result_path, d)

    def write_error(self, text: str) -> None:
        """``error.txt``: a failure's message or traceback."""
        atomic_write_text(self.path / ERROR_FILE, text.rstrip() + "\n")

    def write_failure(self, doc: FailureDoc, detail: str | None = None) -> bool:
        """Record a run that failed before it simulated: ``error.txt`` and ``result.json``. Never
        in a directory that holds a run (a checkpoint): ``resume=DIR`` with a bad override must
        not overwrite DIR's result. Returns whether it wrote; an unwritable directory is ignored."""
        if self.checkpoint_path.exists():
            return False
        try:
            self.write_error(detail or doc.error)
            self.write_result(doc)
        except OSError:  # pragma: no cover - the run dir itself is unwritable
            return False
        return True

    # ---- history, checkpoint -------------------------------------------------------------

    def history_arrays(self, candidate: int | None = None) -> dict[str, np.ndarray]:
        """The arrays of the history file (empty if there is none)."""
        p = self.history_path(candidate)
        if not p.is_file():
            return {}
        with np.load(p, allow_pickle=False) as z:
            return {k: z[k] for k in z.files}

    def load_history(self, keep: int | None = None, candidate: int | None = None) -> History:
        """The history file as a ``History`` (its first ``keep`` iterations)."""
        return load_history(self.history_path(candidate), keep=keep)

    def write_history(self, history: History, candidate: int | None = None) -> None:
        history.save(self.history_path(candidate))

    def checkpoint(self) -> Checkpoint:
        """``checkpoint.json`` (``CheckpointError`` naming the directory or file)."""
        return load_checkpoint(self.path)

    def write_checkpoint(self, ckpt: Checkpoint) -> None:
        save_checkpoint(self.path, ckpt)

    # ---- per-iteration series ------------------------------------------------------------

    def success_per_iter(self) -> np.ndarray:
        """Share of successful samples per iteration (``result.json``, else the history)."""
        d = self.result_json() or {}
        if "success_per_iter" in d:
            return np.asarray([decode_float(v) for v in d["success_per_iter"]], dtype=np.float64)
        h = self.history_arrays()
        return np.asarray(h["success_share"], dtype=np.float64) if "success_share" in h else np.zeros(0)

    def finished_success_per_iter(self) -> np.ndarray:
        """Per iteration, the share of the rows that ran to their end that ended feasible (NaN
        where every row was stopped). With ``ce.prune``, ``success_per_iter`` counts the rows
        stopped as "could not be an elite" as failed and reads flat while the search learns; this
        share leaves them out. ``result.json``'s ``finished_success_per_iter``, else derived from
        its counts (pruned runs written before that key), else ``success_per_iter`` (a run without
        pruning, where both are the same share)."""
        d = self.result_json() or {}
        if "finished_success_per_iter" in d:
            return np.asarray([decode_float(v) for v in d["finished_success_per_iter"]], dtype=np.float64)
        stopped = d.get("n_stopped_per_iter")
        n, k = d.get("n_envs_per_iter"), d.get("n_feasible_per_iter")
        if stopped is not None and n is not None and k is not None and len(n) == len(k) == len(stopped):
            return np.asarray([ki / (ni - si) if ni > si else math.nan for ni, ki, si in zip(n, k, stopped)],
                              dtype=np.float64)
        return self.success_per_iter()

    def n_stopped_per_iter(self) -> np.ndarray | None:
        """Rows stopped by ``ce.prune`` per iteration (``result.json``'s ``n_stopped_per_iter``);
        ``None`` where the run does not say (no pruning, or a run from before the key)."""
        d = self.result_json() or {}
        stopped = d.get("n_stopped_per_iter")
        return None if stopped is None else np.asarray([int(v) for v in stopped], dtype=np.int64)

    def best_cost_per_iter(self) -> np.ndarray:
        """Best feasible cost so far per iteration (``inf`` before the first success)."""
        d = self.result_json() or {}
        if "best_cost_per_iter" in d:
            return np.asarray([decode_float(v, math.inf) for v in d["best_cost_per_iter"]], dtype=np.float64)
        h = self.history_arrays()
        return np.asarray(h["best_cost"], dtype=np.float64) if "best_cost" in h else np.zeros(0)

    # ---- figure inputs -------------------------------------------------------------------

    def scene(self) -> SceneInfo | None:
        """``scene.json``, else the scene described by the run's config, else ``None``."""
        return read_scene(self.path, self.config())

    def write_scene(self, layout: ParamLayout, geometry: Any, padding: float = 0.2) -> Path:
        return save_scene(self.path, layout, geometry, padding)

    def trajectories(self, iteration: int) -> dict[str, np.ndarray]:
        """``trajectories_iter{iteration}.npz`` (``FileNotFoundError`` says which exist)."""
        return load_trajectories(self.path, iteration)

    def trajectory_iterations(self) -> list[int]:
        return trajectory_iterations(self.path)

    def write_trajectories(self, iteration: int, traj_base: Any, traj_ee: Any, feasible: Any, best: int,
                           **optional: Any) -> Path:
        """See ``realize.run_dir.scene_files.save_trajectories`` (``Z``, ``cost``, ``progress``,
        ``traj_t`` optional)."""
        return save_trajectories(self.path, iteration, traj_base, traj_ee, feasible, best, **optional)

    # ---- sweeps --------------------------------------------------------------------------

    def job_status(self) -> JobStatusDoc | None:
        d = read_json(self.path / JOB_STATUS_FILE)
        return None if d is None else JobStatusDoc.from_json(d)

    def write_job_status(self, status: JobStatusDoc) -> None:
        atomic_write_json(self.path / JOB_STATUS_FILE, status.to_json())
