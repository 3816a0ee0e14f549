"""Run directory files: result.json, history.npz and checkpoint.json, written atomically.

What it does:
  * ``atomic_write_json`` / ``atomic_write_npz`` write to a temporary file in the target's
    directory and ``os.replace`` it over the target, so a reader (or a run killed mid-write)
    only ever sees the old or the new complete file;
  * ``History`` accumulates the per-iteration arrays of a cross-entropy run (samples, costs,
    feasibility, distribution) and saves them as one ``history.npz`` of plain numeric/string
    arrays (loadable with ``allow_pickle=False``);
  * ``save_checkpoint`` / ``load_checkpoint`` store what a resumed run needs (the CE state, the
    iteration summaries, the resolved config, elapsed wall time) as plain JSON;
  * ``json_safe`` turns tensors/numpy/non-finite floats into JSON values (non-finite -> null).
What it doesn't: decide what to run (``realize.app``), or pickle anything: results and
checkpoints from untrusted run directories are read with ``json`` and ``allow_pickle=False``.
"""

from __future__ import annotations

import importlib.metadata
import json
import math
import os
import tempfile
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

__all__ = [
    "RESULT_FILE",
    "HISTORY_FILE",
    "CHECKPOINT_FILE",
    "ERROR_FILE",
    "CHECKPOINT_FORMAT",
    "CheckpointError",
    "Checkpoint",
    "History",
    "atomic_write_json",
    "atomic_write_npz",
    "atomic_write_text",
    "json_safe",
    "load_checkpoint",
    "load_history",
    "package_versions",
    "read_json",
    "save_checkpoint",
    "series",
]

RESULT_FILE = "result.json"
HISTORY_FILE = "history.npz"
CHECKPOINT_FILE = "checkpoint.json"
ERROR_FILE = "error.txt"
CHECKPOINT_FORMAT = "realize-checkpoint-v1"


class CheckpointError(ValueError):
    """A run directory cannot be resumed; the message names the directory or file."""


# --------------------------------------------------------------------------------------------
# JSON helpers and atomic writes
# --------------------------------------------------------------------------------------------


def json_safe(x: Any) -> Any:
    """Plain JSON value for ``x``: tensors/arrays become lists, non-finite floats ``None``."""
    if x is None or isinstance(x, (bool, str)):
        return x
    if isinstance(x, float):
        return x if math.isfinite(x) else None
    if isinstance(x, int):
        return x
    if isinstance(x, Path):
        return str(x)
    if isinstance(x, Mapping):
        return {str(k): json_safe(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [json_safe(v) for v in x]
    if hasattr(x, "detach"):  # torch tensor, without importing torch here
        x = x.detach().cpu().numpy()
    if isinstance(x, np.ndarray):
        return json_safe(x.tolist())
    if isinstance(x, np.generic):
        return json_safe(x.item())
    return str(x)


def _atomic(path: Path, write: Any, mode: str) -> None:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        os.chmod(tmp, 0o666 & ~_umask())  # mkstemp makes 0600; results are ordinary files
        with os.fdopen(fd, mode) as f:
            write(f)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        try:
            os.unlink(tmp)
        except OSError:
            pass
        raise


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def atomic_write_text(path: Path, text: str) -> None:
    _atomic(path, lambda f: f.write(text), "w")


def atomic_write_json(path: Path, obj: Any, indent: int | None = 2) -> None:
    """Write ``json_safe(obj)`` to ``path`` atomically (strict JSON: no NaN/Infinity)."""
    text = json.dumps(json_safe(obj), indent=indent, allow_nan=False)
    atomic_write_text(path, text + "\n")


def atomic_write_npz(path: Path, arrays: Mapping[str, np.ndarray]) -> None:
    """``np.savez_compressed`` to ``path`` atomically; object arrays are refused."""
    for k, a in arrays.items():
        if np.asarray(a).dtype == object:
            raise TypeError(f"history array {k!r} has dtype object; only numeric/str arrays are stored")
    _atomic(path, lambda f: np.savez_compressed(f, **arrays), "wb")


def package_versions() -> dict[str, str | None]:
    """Versions of the packages that decide a run's numbers."""
    out: dict[str, str | None] = {}
    for name in ("realize", "torch", "mani_skill", "sapien", "numpy", "hydra-core", "rerun-sdk"):
        try:
            out[name] = importlib.metadata.version(name)
        except importlib.metadata.PackageNotFoundError:
            out[name] = None
    return out


# --------------------------------------------------------------------------------------------
# history arrays
# --------------------------------------------------------------------------------------------


@dataclass
class History:
    """Per-iteration arrays of a run; saved as ``history.npz``.

    Per iteration ``i`` (3-digit zero padded): ``Z_i`` (N, D), ``cost_i``, ``feasible_i``,
    ``progress_i``, ``distance_i`` (N,), ``elite_idx_i`` (K,), and where the rollout gave them
    ``action_success_i`` (N, A), ``goal_i``, ``steps_i`` (N,). Stacked over iterations:
    ``iteration``, ``n_samples``, ``success_share``, ``best_cost`` (inf if none), ``mean``/``std``
    (I, D; NaN while the distribution is still uniform). ``column_names`` (D,) names Z's columns.
    A mixture (``ce.n_modes = k > 1``) keeps its heaviest mode in ``mean``/``std`` (so readers of
    (I, D) arrays work unchanged) and all modes in ``mode_mean``/``mode_std`` (I, k, D) and
    ``mode_weight`` (I, k); those three arrays exist only for mixture runs.
    The sample count may change between iterations (linear schedule), hence one array per
    iteration rather than one (I, N, D) block.
    """

    column_names: list[str]
    per_iter: list[dict[str, np.ndarray]] = field(default_factory=list)
    scalars: list[dict[str, float]] = field(default_factory=list)
    mean: list[np.ndarray] = field(default_factory=list)
    std: list[np.ndarray] = field(default_factory=list)
    modes: list[tuple[np.ndarray, np.ndarray, np.ndarray] | None] = field(default_factory=list)

    def __len__(self) -> int:
        return len(self.per_iter)

    def append(
        self,
        arrays: Mapping[str, Any],
        *,
        n_samples: int,
        success_share: float,
        best_cost: float,
        mean: Any | None,
        std: Any | None,
        weights: Any | None = None,
    ) -> None:
        """``mean``/``std`` (D,), or (k, D) with ``weights`` (k,) for a mixture."""
        d = len(self.column_names)
        row = {k: _np(v) for k, v in arrays.items() if v is not None}
        self.per_iter.append(row)
        self.scalars.append(
            {"n_samples": float(n_samples), "success_share": float(success_share), "best_cost": float(best_cost)}
        )
        modes = None
        if mean is not None and std is not None and _np(mean).ndim == 2:
            m, s = _np(mean).astype(np.float64), _np(std).astype(np.float64)
            w = np.full(m.shape[0], 1.0 / m.shape[0]) if weights is None else _np(weights).astype(np.float64)
            modes = (m, s, w)
            top = int(np.argmax(w))
            mean, std = m[top], s[top]
        self.modes.append(modes)
        self.mean.append(np.full(d, np.nan) if mean is None else _np(mean).astype(np.float64))
        self.std.append(np.full(d, np.nan) if std is None else _np(std).astype(np.float64))

    def arrays(self) -> dict[str, np.ndarray]:
        n_it = len(self.per_iter)
        d = len(self.column_names)
        out: dict[str, np.ndarray] = {
            "column_names": np.asarray(self.column_names, dtype=str),
            "iteration": np.arange(n_it, dtype=np.int64),
            "n_samples": np.asarray([s["n_samples"] for s in self.scalars], dtype=np.int64),
            "success_share": np.asarray([s["success_share"] for s in self.scalars], dtype=np.float64),
            "best_cost": np.asarray([s["best_cost"] for s in self.scalars], dtype=np.float64),
            "mean": np.stack(self.mean) if n_it else np.zeros((0, d)),
            "std": np.stack(self.std) if n_it else np.zeros((0, d)),
        }
        known = [m for m in self.modes if m is not None]
        if known:
            k = known[0][0].shape[0]
            nan_modes = (np.full((k, d), np.nan), np.full((k, d), np.nan), np.full(k, np.nan))
            full = [nan_modes if m is None else m for m in self.modes]
            out["mode_mean"] = np.stack([m[0] for m in full])
            out["mode_std"] = np.stack([m[1] for m in full])
            out["mode_weight"] = np.stack([m[2] for m in full])
        for i, row in enumerate(self.per_iter):
            for k, v in row.items():
                out[f"{k}_{i:03d}"] = v
        return out

    def save(self, path: Path) -> None:
        atomic_write_npz(path, self.arrays())

    @classmethod
    def from_arrays(cls, arrays: Mapping[str, np.ndarray], keep: int | None = None) -> History:
        """Rebuild from ``arrays()`` output, keeping the first ``keep`` iterations."""
        names = [str(s) for s in arrays["column_names"].tolist()]
        h = cls(column_names=names)
        n_it = int(arrays["iteration"].shape[0])
        if keep is not None:
            n_it = min(n_it, keep)
        for i in range(n_it):
            suffix = f"_{i:03d}"
            row = {k[: -len(suffix)]: np.asarray(v) for k, v in arrays.items() if k.endswith(suffix)}
            h.per_iter.append(row)
            h.scalars.append(
                {
                    "n_samples": float(arrays["n_samples"][i]),
                    "success_share": float(arrays["success_share"][i]),
                    "best_cost": float(arrays["best_cost"][i]),
                }
            )
            h.mean.append(np.asarray(arrays["mean"][i], dtype=np.float64))
            h.std.append(np.asarray(arrays["std"][i], dtype=np.float64))
            modes = None
            if "mode_weight" in arrays and np.isfinite(arrays["mode_weight"][i]).all():
                modes = tuple(np.asarray(arrays[key][i], dtype=np.float64)
                              for key in ("mode_mean", "mode_std", "mode_weight"))
            h.modes.append(modes)  # type: ignore[arg-type]
        return h


def _np(v: Any) -> np.ndarray:
    if hasattr(v, "detach"):
        v = v.detach().cpu().numpy()
    return np.asarray(v)


def load_history(path: Path, keep: int | None = None) -> History:
    """Read ``history.npz`` without unpickling (``allow_pickle=False``)."""
    with np.load(path, allow_pickle=False) as z:
        return History.from_arrays({k: z[k] for k in z.files}, keep=keep)


# --------------------------------------------------------------------------------------------
# checkpoint
# --------------------------------------------------------------------------------------------


@dataclass
class Checkpoint:
    """What ``resume=<run dir>`` needs: the CE state after ``iteration`` complete iterations.

    ``config`` is the run's resolved config (the resumed run uses it, not the command line);
    ``records`` the ``IterationRecord.summary()`` of every completed iteration; ``wall_time_s``
    the wall time spent so far (all segments); ``segments`` counts how often the run started.
    """

    iteration: int
    ce_state: dict[str, Any]
    config: dict[str, Any]
    records: list[dict[str, Any]]
    wall_time_s: float
    segments: int = 1

    def to_dict(self) -> dict[str, Any]:
        return {
            "format": CHECKPOINT_FORMAT,
            "iteration": self.iteration,
            "ce_state": self.ce_state,
            "config": self.config,
            "records": self.records,
            "wall_time_s": self.wall_time_s,
            "segments": self.segments,
        }


def save_checkpoint(run_dir: Path, ckpt: Checkpoint) -> None:
    # CEState.to_dict encodes inf/nan as strings; keep them verbatim (json_safe keeps strings)
    atomic_write_json(Path(run_dir) / CHECKPOINT_FILE, ckpt.to_dict(), indent=None)


def load_checkpoint(run_dir: Path | str) -> Checkpoint:
    """Read ``<run_dir>/checkpoint.json``; ``CheckpointError`` names the directory or file."""
    run_dir = Path(run_dir)
    path = run_dir / CHECKPOINT_FILE
    if not run_dir.is_dir() or not path.is_file():
        raise CheckpointError(f"resume: {run_dir} is not a realize run directory (no {CHECKPOINT_FILE})")
    try:
        d = json.loads(path.read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as e:
        raise CheckpointError(f"resume: {path} is not valid JSON ({e})") from None
    if not isinstance(d, dict) or d.get("format") != CHECKPOINT_FORMAT:
        raise CheckpointError(f"resume: {path} is not a realize checkpoint (format is not {CHECKPOINT_FORMAT!r})")
    try:
        it = int(d["iteration"])
        ce_state, config, records = d["ce_state"], d["config"], d["records"]
        wall = float(d.get("wall_time_s", 0.0))
        segments = int(d.get("segments", 1))
    except (KeyError, TypeError, ValueError) as e:
        raise CheckpointError(f"resume: {path} is incomplete or malformed ({type(e).__name__}: {e})") from None
    if not isinstance(ce_state, dict) or not isinstance(config, dict) or not isinstance(records, list):
        raise CheckpointError(f"resume: {path} is malformed (ce_state/config/records have the wrong type)")
    if it < 1 or len(records) != it:
        raise CheckpointError(f"resume: {path} is inconsistent (iteration {it}, {len(records)} iteration records)")
    return Checkpoint(it, ce_state, config, records, wall, segments)


def read_json(path: Path) -> dict[str, Any] | None:
    """A JSON object from ``path`` or ``None`` if missing/unreadable (for summaries)."""
    try:
        d = json.loads(Path(path).read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError):
        return None
    return d if isinstance(d, dict) else None


def series(records: Sequence[Mapping[str, Any]], key: str) -> list[Any]:
    """``[r[key] for r in records]`` with the CE's "inf"/"nan" strings mapped to ``None``."""
    out = []
    for r in records:
        v = r.get(key)
        if isinstance(v, str):
            try:
                v = float(v)
            except ValueError:
                pass
        out.append(json_safe(v))
    return out
