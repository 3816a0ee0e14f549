"""Warm start: begin a search from an earlier run's final distribution, carried into today's world.

What it does: ``load_warm_start(run_dir, task, geometry, ce)`` reads the earlier run's
``result.json`` (its plan, parameter columns, final distribution and resolved config), refuses a
run that cannot seed this one (another plan, other parameters, no fitted distribution yet, a
top-k run) with a ``ConfigError`` that names both sides, and returns a ``WarmStart``. This
run's plan may be the tail of the earlier one (a replan of the remaining actions): the
distribution is then the marginal over the columns this run has.
  * every parameter whose region follows an object (``frame: cube``, ``frame: table2``;
    ``realize.tasks.frames``) has its mean moved by how far that object moved between the earlier
    run's scene config and this one's, so a grasp distribution learnt around the cube stays
    around the cube;
  * the std is widened by ``ce.warm_widen`` (floored at ``ce.min_std``), and iteration 0 draws
    ``ce.warm_uniform_share`` of its batch uniformly over the regions, so a change that
    invalidates the old solution is still explored;
  * a mixture is kept as it is when both runs have the same ``ce.n_modes``; otherwise it is
    merged into one normal (moment matching) and, for a mixture run, copied into every mode.
``WarmStart.distribution`` is the ``realize.search.ce.state.WarmDistribution`` the optimizer takes;
``WarmStart.to_dict`` is what ``result.json`` records under ``warm_start``.
What it doesn't: search (``realize.search.ce``) or change the regions themselves (the task config and
``realize.tasks.frames`` do).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import torch
from torch import Tensor

from realize.search.ce.config import CEConfig
from realize.search.ce.state import WarmDistribution
from realize.config import ConfigError
from realize.tasks.frames import WORLD, move_points, object_frames
from realize.world.geometry import GeometryCfg, SceneGeometry, build_geometry
from realize.run_dir.directory import RunDir
from realize.tasks.spec import TaskSpec
from realize.run_dir.upgrade import upgrade_config

__all__ = ["WarmStart", "load_warm_start", "merge_modes"]


@dataclass
class WarmStart:
    """An earlier run's final distribution, moved into this run's world and widened."""

    run_dir: str
    distribution: WarmDistribution
    widen: float
    moved: dict[str, list[float]] = field(default_factory=dict)  # param -> how far its frame moved (m)
    source_modes: int = 1

    def to_dict(self) -> dict[str, Any]:
        return {"run_dir": self.run_dir, "widen": self.widen, "uniform_share": self.distribution.uniform_share,
                "source_modes": self.source_modes, "moved": self.moved}


def merge_modes(mean: Tensor, std: Tensor, weights: Tensor) -> tuple[Tensor, Tensor]:
    """One normal with the mixture's mean and per-column variance (``(k, D)`` -> ``(D,)``)."""
    w = (weights / weights.sum())[:, None]
    mu = (w * mean).sum(0)
    var = (w * (std**2 + (mean - mu) ** 2)).sum(0)
    return mu, var.sqrt()


def _err(run_dir: str, what: str) -> ConfigError:
    return ConfigError(f"warm_start = {run_dir!r}: {what}")


def _read(run_dir: str) -> tuple[dict[str, Any], RunDir]:
    try:
        rd = RunDir.existing(run_dir)
    except FileNotFoundError as e:
        raise _err(run_dir, str(e)) from None
    d = rd.result_json()
    if d is None:
        raise _err(run_dir, f"{rd.result_path} is missing or unreadable")
    if d.get("status") == "failed" or d.get("simulated") is False:
        raise _err(run_dir, "that run failed before it searched; warm-start from a run that finished iterations")
    if d.get("top_k") is not None or d.get("candidates") is not None:
        raise _err(run_dir, "a top-k run (several candidate plans) cannot seed one plan's search; "
                            "warm-start from a run of the plan itself")
    return d, rd


def _source_distribution(d: dict[str, Any], run_dir: str, dtype: torch.dtype) -> tuple[Tensor, Tensor, Tensor | None]:
    mean, std = d.get("final_mean"), d.get("final_std")
    if mean is None or std is None:
        raise _err(run_dir, "result.json has no final distribution (final_mean/final_std): the run has not "
                            "refitted its distribution yet")
    m, s = torch.tensor(mean, dtype=dtype), torch.tensor(std, dtype=dtype)
    w = d.get("final_weights")
    return m, s, (None if w is None else torch.tensor(w, dtype=dtype))


def _columns_of(d: dict[str, Any], run_dir: str, task: TaskSpec) -> list[int]:
    """Which of the earlier run's columns this run's are (its plan equal to, or the tail of, the
    earlier plan; its columns among the earlier ones)."""
    plan, mine = d.get("plan"), task.describe()
    if plan is not None and not (str(plan) == mine or str(plan).endswith(", " + mine)):
        raise _err(run_dir, f"that run realized the plan {plan}; this run realizes {mine}")
    cols = [str(c) for c in d.get("columns") or []]
    want = task.layout.column_names
    missing = [c for c in want if c not in cols]
    if missing or (str(plan) == mine and cols != want):
        raise _err(run_dir, f"that run's parameters are {cols}; this run's are {want}")
    return [cols.index(c) for c in want]


def _old_frames(d: dict[str, Any], run_dir: str) -> dict[str, Any]:
    scene = upgrade_config(d.get("config") or {}).get("scene")
    if not isinstance(scene, dict):
        raise _err(run_dir, "result.json has no resolved scene config to tell where its objects stood")
    try:
        return object_frames(build_geometry(GeometryCfg.from_mapping(scene, "scene")))
    except (ConfigError, ValueError, TypeError) as e:
        raise _err(run_dir, f"its scene config cannot be read ({e})") from None


def load_warm_start(run_dir: str | Path, task: TaskSpec, geometry: SceneGeometry, ce: CEConfig) -> WarmStart:
    """The earlier run at ``run_dir`` as the start of this run's search (``ConfigError`` if it
    cannot be; see the module docstring)."""
    where = str(run_dir)
    d, _ = _read(where)
    keep = _columns_of(d, where, task)
    dtype = ce.torch_dtype
    mean, std, weights = _source_distribution(d, where, dtype)
    D, k_old = task.layout.dim, (1 if weights is None else weights.numel())
    n_cols = len(d.get("columns") or [])
    if mean.shape[-1] != n_cols or std.shape != mean.shape:
        raise _err(where, f"its final distribution has shape {tuple(mean.shape)} for {n_cols} parameter columns")
    mean, std = mean[..., keep], std[..., keep]
    old_frames, new_frames = _old_frames(d, where), object_frames(geometry)
    moved: dict[str, list[float]] = {}
    rows = mean.reshape(-1, D).clone()
    for name in task.layout.names:
        frame = task.frame_of(name)
        if frame == WORLD:
            continue
        if frame not in old_frames:
            raise _err(where, f"parameter {name} follows {frame!r}, which that run's scene does not have "
                              f"(its frames: {sorted(old_frames)})")
        old, new = old_frames[frame], new_frames[frame]
        cols = task.layout.slices[name]
        rows[:, cols] = move_points(rows[:, cols], task.layout.regions[name], old, new)
        moved[name] = [round(n - o, 12) for n, o in zip(new.origin, old.origin)]
    mean = rows.reshape(mean.shape)
    k = ce.n_modes
    if k_old != k:
        if weights is not None:
            mean, std = merge_modes(mean, std, weights)
        if k > 1:
            mean, std, weights = mean.expand(k, D).clone(), std.expand(k, D).clone(), torch.full((k,), 1.0 / k, dtype=dtype)
        else:
            weights = None
    std = (std * ce.warm_widen).clamp_min(ce.min_std)
    dist = WarmDistribution(mean=mean, std=std, weights=weights, uniform_share=ce.warm_uniform_share)
    return WarmStart(run_dir=where, distribution=dist, widen=ce.warm_widen, moved=moved, source_modes=k_old)
