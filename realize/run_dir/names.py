"""The file names of a run directory, in one place.

What it does: names every file ``realize`` writes into a run directory (``result.json``,
``history.npz`` and per-candidate ``history_c{i}.npz``, ``checkpoint.json``, ``error.txt``,
``scene.json``, ``trajectories_iter{k}.npz``, a sweep job's ``job_status.json``) and derives the
per-candidate and per-iteration names.
What it doesn't: read or write anything (``realize.run_dir.directory.RunDir`` does).
"""

from __future__ import annotations

from pathlib import Path

__all__ = [
    "RESULT_FILE",
    "HISTORY_FILE",
    "CHECKPOINT_FILE",
    "ERROR_FILE",
    "SCENE_FILE",
    "TRAJ_PATTERN",
    "JOB_STATUS_FILE",
    "candidate_file",
    "trajectories_name",
]

RESULT_FILE = "result.json"
HISTORY_FILE = "history.npz"
CHECKPOINT_FILE = "checkpoint.json"
ERROR_FILE = "error.txt"
WORKER_LOG_DIR = "workers"  # worker-K.log of each rollout worker process
SCENE_FILE = "scene.json"
TRAJ_PATTERN = "trajectories_iter{k}.npz"
JOB_STATUS_FILE = "job_status.json"


def candidate_file(name: str, index: int) -> str:
    """``history.npz`` -> ``history_c1.npz``: the per-candidate file of a top-k run."""
    p = Path(name)
    return str(p.with_name(f"{p.stem}_c{index}{p.suffix}"))


def trajectories_name(iteration: int) -> str:
    """``trajectories_iter{k}.npz`` (``k`` not zero padded)."""
    return TRAJ_PATTERN.format(k=int(iteration))
