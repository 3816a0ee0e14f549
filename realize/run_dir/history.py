"""``history.npz``: every iteration's samples, evaluations and distribution, as plain arrays.

What it does: ``History`` accumulates the per-iteration arrays of a cross-entropy run and saves
them as one ``.npz`` of numeric/string arrays (loadable with ``allow_pickle=False``);
``History.from_arrays`` / ``load_history`` read one back (a resumed run keeps the first
``keep`` iterations).

File layout. Per iteration ``i`` (3-digit zero padded): ``Z_i`` (N, D), ``cost_i``,
``feasible_i``, ``progress_i``, ``distance_i`` (N,), ``elite_idx_i`` (K,), and where the rollout
gave them ``action_success_i`` (N, A), ``goal_i``, ``steps_i`` (N,); a robust search
(``ce.replicas`` = R > 1) adds ``share_i`` (N,), each sample's success share over its worlds,
and ``world_cost_i`` / ``world_feasible_i`` (N, R). A search with ``ce.screen`` adds ``screened_Z_i``
(k, D), the draws its kinematic screen rejected and drew again (not simulated). Stacked over iterations:
``iteration``, ``n_samples`` (the plans of each iteration, ``n_envs``; the file keeps its
original key), ``success_share``, ``best_cost`` (inf if none), ``mean``/``std`` (I, D; NaN while
the distribution is still uniform). ``column_names`` (D,) names Z's columns. A mixture
(``ce.n_modes = k > 1``) keeps its heaviest mode in ``mean``/``std`` (so readers of (I, D)
arrays work unchanged) and all modes in ``mode_mean``/``mode_std`` (I, k, D) and
``mode_weight`` (I, k); those three arrays exist only for mixture runs. The sample count may
change between iterations (linear schedule), hence one array per iteration.
``batch_digests(run_dir)`` reads every history file of a run down to one digest per batch (the
same-seed checks compare runs, hosts and fixtures by it).
What it doesn't: decide where the file goes (``realize.run_dir.directory.RunDir``).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from realize.run_dir.jsonio import atomic_write_npz

__all__ = ["History", "load_history", "batch_digests"]

Modes = tuple[np.ndarray, np.ndarray, np.ndarray]  # mean (k, D), std (k, D), weight (k,)


def _np(v: Any) -> np.ndarray:
    if hasattr(v, "detach"):
        v = v.detach().cpu().numpy()
    return np.asarray(v)


@dataclass
class History:
    """Per-iteration arrays of a run (file layout in the module docstring)."""

    column_names: list[str]
    per_iter: list[dict[str, np.ndarray]] = field(default_factory=list)
    n_envs: list[int] = field(default_factory=list)
    success_share: list[float] = field(default_factory=list)
    best_cost: list[float] = field(default_factory=list)
    mean: list[np.ndarray] = field(default_factory=list)
    std: list[np.ndarray] = field(default_factory=list)
    modes: list[Modes | None] = field(default_factory=list)

    def __len__(self) -> int:
        return len(self.per_iter)

    def append(
        self,
        arrays: Mapping[str, Any],
        *,
        n_envs: int,
        success_share: float,
        best_cost: float,
        mean: Any | None,
        std: Any | None,
        weights: Any | None = None,
    ) -> None:
        """One iteration: its per-sample ``arrays`` (None values skipped), its scalars and the
        distribution after it, ``mean``/``std`` (D,), or (k, D) with ``weights`` (k,) for a
        mixture."""
        d = len(self.column_names)
        self.per_iter.append({k: _np(v) for k, v in arrays.items() if v is not None})
        self.n_envs.append(int(n_envs))
        self.success_share.append(float(success_share))
        self.best_cost.append(float(best_cost))
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
        """The file's arrays (layout in the module docstring)."""
        n_it = len(self.per_iter)
        d = len(self.column_names)
        out: dict[str, np.ndarray] = {
            "column_names": np.asarray(self.column_names, dtype=str),
            "iteration": np.arange(n_it, dtype=np.int64),
            "n_samples": np.asarray(self.n_envs, dtype=np.int64),
            "success_share": np.asarray(self.success_share, dtype=np.float64),
            "best_cost": np.asarray(self.best_cost, dtype=np.float64),
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
        """Write the file atomically."""
        atomic_write_npz(path, self.arrays())

    @classmethod
    def from_arrays(cls, arrays: Mapping[str, np.ndarray], keep: int | None = None) -> History:
        """Rebuild from ``arrays()`` output, keeping the first ``keep`` iterations."""
        h = cls(column_names=[str(s) for s in arrays["column_names"].tolist()])
        n_it = int(arrays["iteration"].shape[0])
        if keep is not None:
            n_it = min(n_it, keep)
        for i in range(n_it):
            suffix = f"_{i:03d}"
            h.per_iter.append({k[: -len(suffix)]: np.asarray(v) for k, v in arrays.items() if k.endswith(suffix)})
            h.n_envs.append(int(arrays["n_samples"][i]))
            h.success_share.append(float(arrays["success_share"][i]))
            h.best_cost.append(float(arrays["best_cost"][i]))
            h.mean.append(np.asarray(arrays["mean"][i], dtype=np.float64))
            h.std.append(np.asarray(arrays["std"][i], dtype=np.float64))
            modes: Modes | None = None
            if "mode_weight" in arrays and np.isfinite(arrays["mode_weight"][i]).all():
                modes = (np.asarray(arrays["mode_mean"][i], dtype=np.float64),
                         np.asarray(arrays["mode_std"][i], dtype=np.float64),
                         np.asarray(arrays["mode_weight"][i], dtype=np.float64))
            h.modes.append(modes)
        return h


def load_history(path: Path, keep: int | None = None) -> History:
    """Read a history file without unpickling (``allow_pickle=False``)."""
    with np.load(path, allow_pickle=False) as z:
        return History.from_arrays({k: z[k] for k in z.files}, keep=keep)


def batch_digests(run_dir: Path) -> dict[str, list[str]]:
    """A digest of every batch's per-row costs, feasibility and final distances, per history file
    of ``run_dir`` (``history.npz``; a segment search's ``history_cK.npz``), in batch order. Finer
    than the best cost per batch: two runs whose last bits differ part first in the distances of
    rows that are not the best, and only later in a cost."""
    import hashlib

    out: dict[str, list[str]] = {}
    for path in sorted(Path(run_dir).glob("history*.npz")):
        with np.load(path, allow_pickle=False) as h:
            rows = []
            for i in range(sum(1 for k in h.files if k.startswith("cost_"))):
                d = hashlib.sha256()
                for key in (f"cost_{i:03d}", f"feasible_{i:03d}", f"distance_{i:03d}"):
                    if key in h.files:
                        d.update(np.ascontiguousarray(h[key]).tobytes())
                rows.append(d.hexdigest()[:16])
        out[path.name] = rows
    return out
