"""Executed trajectories as a LeRobot dataset (the v3.0 layout, written with pyarrow).

What it does: ``episode_from_trajectory(trajectory)`` turns one world's executed trajectory into
an ``Episode`` (one frame per control step): ``action`` = what was commanded (the upper-joint
position targets, the base velocity vx, vy, wz in the world frame, the gripper 1 closed / 0
open); ``observation.state`` = the robot's joint positions, base pose (x, y, yaw) and gripper
per step where the caller hands them in (``measured``) or the trajectory file has them (its
``joint_positions`` and ``base_pose``, read at the end of the previous step: the state each
command began from; the gripper the previous command); without them, the COMMANDED state (each
step's state is the previous step's targets; the base pose integrated from the velocity
commands, relative to the start pose; the gripper the previous command), said so in
``meta/info.json`` (``realize.state_source``). Each frame's task is its action's text.
``write_lerobot_dataset(root, episodes, fps, robot_type)`` writes (rewriting what was there):
``meta/info.json``, ``meta/stats.json``, ``meta/tasks.parquet``,
``meta/episodes/chunk-000/file-000.parquet`` (per episode: its tasks, length, where its frames
are, and its statistics), ``data/chunk-000/file-000.parquet`` (every frame). The layout follows
LeRobot's dataset format ``codebase_version`` v3.0 as lerobot 0.4.4 writes it; the lerobot
library itself is not used (its install needs another torch, torchvision and CUDA libraries
beside this project's torch; docs/execution_format.md).
What it doesn't: images or videos (the execution has no cameras), more than one data file
(episodes of executions are small: 100 MB of frames is far off), or upload anything.
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from realize.execution.trajectory import Trajectory

__all__ = ["CODEBASE_VERSION", "Episode", "episode_from_trajectory", "write_lerobot_dataset"]

CODEBASE_VERSION = "v3.0"  # LeRobot's dataset format version followed (as lerobot 0.4.4 writes it)
CHUNKS_SIZE = 1000  # files per chunk folder (lerobot's default)
DATA_FILES_SIZE_IN_MB = 100
VIDEO_FILES_SIZE_IN_MB = 200
DATA_PATH = "data/chunk-{chunk_index:03d}/file-{file_index:03d}.parquet"
EPISODES_PATH = "meta/episodes/chunk-{chunk_index:03d}/file-{file_index:03d}.parquet"
_INDEX_FEATURES = ("timestamp", "frame_index", "episode_index", "index", "task_index")


@dataclass(frozen=True)
class Episode:
    """One episode's frames: ``state`` (T, S) and ``action`` (T, A) with their column names, the
    time of each frame from the episode's start and each frame's task text."""

    state: np.ndarray
    action: np.ndarray
    state_names: tuple[str, ...]
    action_names: tuple[str, ...]
    timestamp: np.ndarray  # (T,) s
    tasks: tuple[str, ...]  # (T,)
    state_source: str  # measured | commanded

    def __len__(self) -> int:
        return len(self.timestamp)


def _base_pose(velocity: np.ndarray, dt: float) -> np.ndarray:
    """Pose (x, y, yaw) before each step, integrated from world-frame velocity commands from 0."""
    pose = np.zeros((len(velocity), 3))
    pose[1:] = np.cumsum(velocity[:-1] * dt, axis=0)
    return pose


def episode_from_trajectory(trajectory: Trajectory, measured: np.ndarray | None = None) -> Episode:
    """One world's trajectory as an ``Episode`` (module docstring); ``measured`` (T, J + 4): the
    joint positions, base x, y, yaw and gripper (1 closed) measured at each step, if known."""
    t = trajectory
    joints = list(t.joint_names)
    grip = t.gripper.astype(np.float64)[:, None]
    action = np.concatenate([t.joint_targets, t.base_velocity, grip], axis=1)
    action_names = (*joints, "base_vx", "base_vy", "base_wz", "gripper_closed")
    state_names = (*joints, "base_x", "base_y", "base_yaw", "gripper_closed")
    if measured is not None:
        state = np.asarray(measured, dtype=np.float64)
        if state.shape != (len(t), len(state_names)):
            raise ValueError(f"measured has shape {state.shape}, expected {(len(t), len(state_names))}")
        source = "measured"
    elif t.joint_positions is not None and t.base_pose is not None:  # the file has what the robot read
        prev = np.r_[0, np.arange(len(t) - 1)] if len(t) else np.zeros(0, dtype=int)
        state = np.concatenate([t.joint_positions[prev], t.base_pose[prev], grip[prev]], axis=1)  # as it began
        source = "measured"
    else:
        prev = np.r_[0, np.arange(len(t) - 1)] if len(t) else np.zeros(0, dtype=int)
        state = np.concatenate([t.joint_targets[prev], _base_pose(t.base_velocity, 1.0 / t.control_freq),
                                grip[prev]], axis=1)
        source = "commanded"
    ts = t.t_s - (t.t_s[0] if len(t) else 0.0)
    tasks = tuple(t.action_text[a] for a in t.action)
    return Episode(state, action, state_names, action_names, ts, tasks, source)


def _stats(x: np.ndarray) -> dict[str, np.ndarray]:
    x = np.asarray(x, dtype=np.float64).reshape(len(x), -1)
    return {"min": x.min(axis=0), "max": x.max(axis=0), "mean": x.mean(axis=0), "std": x.std(axis=0),
            "count": np.array([len(x)])}


def _pandas_index_metadata(index_type: str, columns: Sequence[tuple[str, str]]) -> bytes:
    """The schema metadata by which pandas reads ``__index_level_0__`` back as the frame's index
    (LeRobot reads ``meta/tasks.parquet`` with pandas, the task text as the index)."""
    cols = [{"name": n, "field_name": n, "pandas_type": t, "numpy_type": t, "metadata": None} for n, t in columns]
    cols.append({"name": None, "field_name": "__index_level_0__", "pandas_type": index_type, "numpy_type": "object",
                 "metadata": None})
    meta = {"index_columns": ["__index_level_0__"], "column_indexes": [], "columns": cols,
            "creator": {"library": "pyarrow", "version": __import__("pyarrow").__version__}, "pandas_version": "2.2.0"}
    return json.dumps(meta).encode()


def write_lerobot_dataset(root: str | Path, episodes: Sequence[Episode], fps: float,
                          robot_type: str | None = None) -> Path:
    """Write ``episodes`` (episode k = ``episodes[k]``) as one LeRobot dataset at ``root``."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    if not episodes:
        raise ValueError("no episodes to write")
    root = Path(root)
    e0 = episodes[0]
    for e in episodes:
        if e.state_names != e0.state_names or e.action_names != e0.action_names:
            raise ValueError("episodes differ in their state or action columns")
    task_list: list[str] = []
    for e in episodes:
        task_list += [s for s in dict.fromkeys(e.tasks) if s not in task_list]
    task_index = {s: i for i, s in enumerate(task_list)}
    s_dim, a_dim = len(e0.state_names), len(e0.action_names)
    features: dict[str, Any] = {
        "observation.state": {"dtype": "float32", "shape": [s_dim], "names": list(e0.state_names)},
        "action": {"dtype": "float32", "shape": [a_dim], "names": list(e0.action_names)},
        "timestamp": {"dtype": "float32", "shape": [1], "names": None},
        "frame_index": {"dtype": "int64", "shape": [1], "names": None},
        "episode_index": {"dtype": "int64", "shape": [1], "names": None},
        "index": {"dtype": "int64", "shape": [1], "names": None},
        "task_index": {"dtype": "int64", "shape": [1], "names": None},
    }
    frames: dict[str, list[np.ndarray]] = {k: [] for k in features}
    ep_rows: list[dict[str, Any]] = []
    start = 0
    for k, e in enumerate(episodes):
        n = len(e)
        cols = {"observation.state": e.state.astype(np.float32), "action": e.action.astype(np.float32),
                "timestamp": e.timestamp.astype(np.float32), "frame_index": np.arange(n, dtype=np.int64),
                "episode_index": np.full(n, k, dtype=np.int64), "index": np.arange(start, start + n, dtype=np.int64),
                "task_index": np.array([task_index[s] for s in e.tasks], dtype=np.int64)}
        row: dict[str, Any] = {"episode_index": k, "tasks": list(dict.fromkeys(e.tasks)), "length": n,
                               "data/chunk_index": 0, "data/file_index": 0, "dataset_from_index": start,
                               "dataset_to_index": start + n, "meta/episodes/chunk_index": 0,
                               "meta/episodes/file_index": 0}
        for name, x in cols.items():
            frames[name].append(x)
            for stat, v in _stats(x).items():
                row[f"stats/{name}/{stat}"] = v.tolist()
        ep_rows.append(row)
        start += n
    data = {k: np.concatenate(v) for k, v in frames.items()}
    arrays = [pa.FixedSizeListArray.from_arrays(pa.array(data[k].reshape(-1)), d)
              for k, d in (("observation.state", s_dim), ("action", a_dim))]
    arrays += [pa.array(data[k]) for k in _INDEX_FEATURES]
    table = pa.table(arrays, names=["observation.state", "action", *_INDEX_FEATURES])
    for rel, tab in ((DATA_PATH, table), (EPISODES_PATH, pa.Table.from_pylist(ep_rows))):
        out = root / rel.format(chunk_index=0, file_index=0)
        out.parent.mkdir(parents=True, exist_ok=True)
        pq.write_table(tab, out, compression="snappy")
    tasks = pa.table({"task_index": pa.array(range(len(task_list)), pa.int64()),
                      "__index_level_0__": pa.array(task_list, pa.string())})
    tasks = tasks.replace_schema_metadata({b"pandas": _pandas_index_metadata("unicode", [("task_index", "int64")])})
    pq.write_table(tasks, root / "meta" / "tasks.parquet")
    stats = {name: {s: v.tolist() for s, v in _stats(x).items()} for name, x in data.items()}
    (root / "meta" / "stats.json").write_text(json.dumps(stats, indent=2) + "\n")
    info = {"codebase_version": CODEBASE_VERSION, "robot_type": robot_type, "total_episodes": len(episodes),
            "total_frames": start, "total_tasks": len(task_list), "chunks_size": CHUNKS_SIZE,
            "data_files_size_in_mb": DATA_FILES_SIZE_IN_MB, "video_files_size_in_mb": VIDEO_FILES_SIZE_IN_MB,
            "fps": int(fps) if float(fps).is_integer() else float(fps), "splits": {"train": f"0:{len(episodes)}"}, "data_path": DATA_PATH, "video_path": None,
            "features": features, "realize.state_source": sorted({e.state_source for e in episodes})}
    (root / "meta" / "info.json").write_text(json.dumps(info, indent=4) + "\n")
    return root
