"""Per-iteration and per-candidate summaries, and a sweep job's status: dataclasses + JSON form.

What it does: ``IterationSummary`` is one CE iteration in plain numbers (what the checkpoint
stores as ``records`` and what the result document's per-iteration series are built from);
``CandidateSummary`` is one candidate plan of a top-k run (``result.json["candidates"]``);
``JobStatusDoc`` is a sweep job's ``job_status.json``. Float fields hold real floats in memory,
``inf``/``nan`` included; ``to_json``/``from_json`` convert at the JSON boundary only, with the
one encoding of ``realize.run_dir.jsonio`` (non-finite -> ``null``; each field says what
``null`` reads back as).
What it doesn't: compute anything from a search (``IterationRecord.summary()`` and
``Candidate.summary()`` make these), or read/write files (``realize.run_dir.directory``).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

from realize.run_dir.jsonio import decode_float, decode_floats, encode_float, encode_floats, json_safe

__all__ = ["IterationSummary", "CandidateSummary", "JobStatusDoc", "BestParams", "best_params"]

BestParams = dict[str, dict[str, float]]  # {parameter: {coordinate: value}}

INF = math.inf
NAN = math.nan


def _opt_int(v: Any) -> int | None:
    return None if v is None else int(v)


def best_params(layout: Any, z: Any) -> BestParams | None:
    """``z`` (D,) split by parameter, ``{name: {coord: value}}``; ``layout`` is a
    ``realize.tasks.regions.ParamLayout`` (its ``slices`` and regions' ``coord_names``). ``None`` for
    ``z is None``."""
    if z is None:
        return None
    values = [float(v) for v in (z.reshape(-1).tolist() if hasattr(z, "reshape") else z)]
    return {name: dict(zip(layout.regions[name].coord_names, values[s])) for name, s in layout.slices.items()}


def _best_params(v: Any) -> BestParams | None:
    if v is None:
        return None
    return {str(k): {str(c): float(x) for c, x in p.items()} for k, p in v.items()}


@dataclass
class IterationSummary:
    """One CE iteration in plain numbers.

    ``n_envs`` plans were sampled (``sampled_from`` ``"uniform"`` or ``"gaussian"``), of which
    ``n_feasible`` succeeded (``success_share``); ``refit`` says how the distribution was
    updated (``"elite"``, ``"fallback_progress"``, ``"feasible_only"``, ``"kept"``) from
    ``n_elite`` elites. ``best_cost``: best feasible cost of all iterations so far and
    ``iteration_best_cost`` of this batch (``inf``: none feasible); ``elite_cost_*`` over the
    feasible elites (``nan``: none). ``mean``/``std``: the distribution after the update
    (``(D,)``, or ``(k, D)`` with ``weights`` ``(k,)`` for a mixture; ``None`` while uniform).
    Times in seconds (``eval_time`` ``nan`` when unknown). ``candidate``: the candidate plan of
    a top-k run (``None`` in a single-plan run; then it is left out of the JSON). ``n_stopped``
    (``ce.prune``): of the infeasible rows, those stopped because they could no longer be an
    elite ("stopped: could not be an elite"; they might have succeeded, so ``success_share`` is
    a lower bound then); ``None`` (left out) without pruning.
    """

    iteration: int
    n_envs: int
    sampled_from: str
    refit: str
    n_feasible: int
    success_share: float
    best_cost: float = INF
    iteration_best_cost: float = INF
    elite_cost_min: float = NAN
    elite_cost_mean: float = NAN
    elite_cost_max: float = NAN
    n_elite: int = 0
    mean: list[Any] | None = None
    std: list[Any] | None = None
    eval_time: float = NAN
    wall_time: float = NAN
    converged: bool = False
    weights: list[float] | None = None
    candidate: int | None = None
    n_stopped: int | None = None  # ce.prune: rows stopped because they could not be an elite (None: off)
    n_screened: int | None = None  # ce.screen: draws rejected before simulation (None: off)

    def to_json(self) -> dict[str, Any]:
        out: dict[str, Any] = {
            "iteration": self.iteration,
            "n_envs": self.n_envs,
            "sampled_from": self.sampled_from,
            "refit": self.refit,
            "n_feasible": self.n_feasible,
            "success_share": encode_float(self.success_share),
            "best_cost": encode_float(self.best_cost),
            "iteration_best_cost": encode_float(self.iteration_best_cost),
            "elite_cost_min": encode_float(self.elite_cost_min),
            "elite_cost_mean": encode_float(self.elite_cost_mean),
            "elite_cost_max": encode_float(self.elite_cost_max),
            "n_elite": self.n_elite,
            "mean": encode_floats(self.mean),
            "std": encode_floats(self.std),
            "eval_time": encode_float(self.eval_time),
            "wall_time": encode_float(self.wall_time),
            "converged": self.converged,
        }
        if self.weights is not None:
            out["weights"] = encode_floats(self.weights)
        if self.candidate is not None:
            out["candidate"] = self.candidate
        if self.n_stopped is not None:
            out["n_stopped"] = self.n_stopped
        if self.n_screened is not None:
            out["n_screened"] = self.n_screened
        return out

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> IterationSummary:
        """Inverse of ``to_json`` (also reads the ``n_samples`` key and ``"inf"`` strings of
        checkpoints written before this module). ``KeyError``/``ValueError`` if malformed."""
        n = d["n_envs"] if "n_envs" in d else d["n_samples"]
        return cls(
            iteration=int(d["iteration"]),
            n_envs=int(n),
            sampled_from=str(d.get("sampled_from", "")),
            refit=str(d.get("refit", "")),
            n_feasible=int(d.get("n_feasible", 0)),
            success_share=decode_float(d.get("success_share")),
            best_cost=decode_float(d.get("best_cost"), INF),
            iteration_best_cost=decode_float(d.get("iteration_best_cost"), INF),
            elite_cost_min=decode_float(d.get("elite_cost_min")),
            elite_cost_mean=decode_float(d.get("elite_cost_mean")),
            elite_cost_max=decode_float(d.get("elite_cost_max")),
            n_elite=int(d.get("n_elite", 0)),
            mean=decode_floats(d.get("mean")),
            std=decode_floats(d.get("std")),
            eval_time=decode_float(d.get("eval_time")),
            wall_time=decode_float(d.get("wall_time")),
            converged=bool(d.get("converged", False)),
            weights=decode_floats(d.get("weights")),
            candidate=_opt_int(d.get("candidate")),
            n_stopped=_opt_int(d.get("n_stopped")),
            n_screened=_opt_int(d.get("n_screened")),
        )


@dataclass
class CandidateSummary:
    """One candidate plan of a top-k run: its plan and parameters, its best sample (``best_cost``
    ``inf`` unless ``feasible``; ``best_z``/``best_params``/``best_iteration`` ``None`` before
    its first iteration), the CE iterations and samples it spent, and the halving round that
    dropped it (``None``: still running, or the winner)."""

    index: int
    plan: str
    n_actions: int
    columns: list[str]
    feasible: bool = False
    best_cost: float = INF
    best_iteration: int | None = None
    best_params: BestParams | None = None
    best_z: list[float] | None = None
    iterations: int = 0
    samples: int = 0
    dropped_round: int | None = None
    converged: bool = False

    def to_json(self) -> dict[str, Any]:
        return {
            "index": self.index,
            "plan": self.plan,
            "n_actions": self.n_actions,
            "columns": list(self.columns),
            "feasible": self.feasible,
            "best_cost": encode_float(self.best_cost) if self.feasible else None,
            "best_iteration": self.best_iteration,
            "best_params": json_safe(self.best_params),
            "best_z": encode_floats(self.best_z),
            "iterations": self.iterations,
            "samples": self.samples,
            "dropped_round": self.dropped_round,
            "converged": self.converged,
        }

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> CandidateSummary:
        return cls(
            index=int(d["index"]),
            plan=str(d.get("plan", "")),
            n_actions=int(d.get("n_actions", 0)),
            columns=[str(c) for c in d.get("columns") or []],
            feasible=bool(d.get("feasible", False)),
            best_cost=decode_float(d.get("best_cost"), INF),
            best_iteration=_opt_int(d.get("best_iteration")),
            best_params=_best_params(d.get("best_params")),
            best_z=decode_floats(d.get("best_z")),
            iterations=int(d.get("iterations", 0)),
            samples=int(d.get("samples", 0)),
            dropped_round=_opt_int(d.get("dropped_round")),
            converged=bool(d.get("converged", False)),
        )


@dataclass
class JobStatusDoc:
    """A sweep job's ``job_status.json``: Hydra's job number, its overrides, ``status``
    (``done`` or ``failed``: how Hydra saw the job) and the error if it raised."""

    job_num: int | None
    overrides: list[str] = field(default_factory=list)
    status: str = "failed"
    error: str = ""

    def to_json(self) -> dict[str, Any]:
        return {"job_num": self.job_num, "overrides": list(self.overrides), "status": self.status,
                "error": self.error}

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> JobStatusDoc:
        return cls(job_num=_opt_int(d.get("job_num")), overrides=[str(o) for o in d.get("overrides") or []],
                   status=str(d.get("status", "failed")), error=str(d.get("error") or ""))
