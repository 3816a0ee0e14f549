"""The result document of a run (``result.json``) and the failure document: dataclasses + JSON.

What it does: ``ResultDoc`` is everything ``result.json`` says about a run (status, best plan,
per-iteration series, final distribution, config, versions, how the run was set up and, for a
top-k run, its ``HalvingDoc``: candidates, winner, budget). ``FailureDoc`` is what a run that
failed before simulating anything leaves (``simulated: false``). ``read_result_doc`` tells the
two apart. Float fields hold real floats in memory (``inf``: no feasible cost; ``nan``: no
value); ``to_json``/``from_json`` convert at the JSON boundary with the one encoding of
``realize.run_dir.jsonio``. ``from_json`` is lenient: any key may be missing (partial or older
documents, stand-in apps in tests); keys it does not know are kept in ``extra`` and written
back (e.g. ``validation``, added by ``realize.validation.candidates``, and ``plan_validation``,
added by ``realize.validation.returned_plan``).

JSON keys (the ones readers rely on): ``status`` (running | done | interrupted | failed),
``interrupted``, ``error``, ``feasible``, ``best_cost`` (null: none feasible),
``best_iteration``, ``best_params`` ({param: {coord: value}}), ``best_z``, ``columns``,
``iterations_done``, ``iterations``, ``converged``, ``success_per_iter``, ``best_cost_per_iter``,
``iteration_best_cost_per_iter``, ``n_envs_per_iter``, ``n_feasible_per_iter``,
``elite_per_iter`` ([{n_elite, refit, cost_min, cost_mean, cost_max}]), ``iteration_time_s``,
``final_mean``/``final_std``/``final_weights``, ``wall_time_s``, ``seed``, ``task`` ({name,
source}), ``plan``, ``config``, ``versions``, ``run_dir``, ``files``, ``segments``,
``resumed_from_iteration``, ``backend``, ``n_envs`` (the scene's copies), ``setup_time_s``, ``workers``,
``warm_start`` (null, or the earlier run it started from: ``realize.search.warm_start``),
``n_stopped_per_iter`` (only with ``ce.prune``: rows stopped as they could not be an elite, which
``success_per_iter`` counts as not succeeded), ``finished_success_per_iter`` (only with
``ce.prune``: the share of the rows that ran to their end that ended feasible, derived from the
counts and never read back), ``n_screened_per_iter`` (only with ``ce.screen``: draws
rejected before simulation and drawn again, spent but not simulated); top-k runs add ``top_k``, ``n_candidates``,
``leader``, ``winner``, ``budget``, ``spent_iterations``, ``spent_samples``, ``halving_round``, ``candidates`` (with ``history``).
What it doesn't: build a document from a search (``realize.run_dir.build``) or touch files
(``realize.run_dir.directory``).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

from realize.run_dir.jsonio import decode_float, decode_floats, encode_float, encode_floats, json_safe
from realize.run_dir.names import CHECKPOINT_FILE, HISTORY_FILE, candidate_file
from realize.run_dir.summaries import BestParams, CandidateSummary

__all__ = ["EliteStats", "PlanRef", "HalvingDoc", "ResultDoc", "FailureDoc", "read_result_doc"]

INF = math.inf
NAN = math.nan
# keys of documents written before the n_envs naming rule
_OLD_KEYS = {"n_samples_per_iter": "n_envs_per_iter", "n_envs_scene": "n_envs"}


def _opt_int(v: Any) -> int | None:
    return None if v is None else int(v)


def _floats(v: Any, missing: float = NAN) -> list[float]:
    return [decode_float(x, missing) for x in v or []]


@dataclass
class EliteStats:
    """One iteration's elite set: its size, how it was used, its feasible members' costs."""

    n_elite: int | None
    refit: str | None
    cost_min: float = NAN
    cost_mean: float = NAN
    cost_max: float = NAN

    def to_json(self) -> dict[str, Any]:
        return {"n_elite": self.n_elite, "refit": self.refit, "cost_min": encode_float(self.cost_min),
                "cost_mean": encode_float(self.cost_mean), "cost_max": encode_float(self.cost_max)}

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> EliteStats:
        return cls(_opt_int(d.get("n_elite")), d.get("refit"), decode_float(d.get("cost_min")),
                   decode_float(d.get("cost_mean")), decode_float(d.get("cost_max")))


@dataclass
class PlanRef:
    """A candidate plan by index and description (``leader``/``winner`` of a top-k run)."""

    index: int
    plan: str

    def to_json(self) -> dict[str, Any]:
        return {"index": self.index, "plan": self.plan}

    @classmethod
    def from_json(cls, d: Any) -> PlanRef | None:
        return None if not isinstance(d, Mapping) else cls(int(d["index"]), str(d.get("plan", "")))


@dataclass
class HalvingDoc:
    """The top-k part of a result: the candidates, who leads/won, the budget and its use.
    ``budget`` is ``realize.search.budget.HalvingBudget.to_dict()``."""

    top_k: int
    leader: PlanRef
    winner: PlanRef | None
    budget: dict[str, Any]
    spent_iterations: int
    spent_samples: int
    halving_round: int
    candidates: list[CandidateSummary]

    @property
    def n_candidates(self) -> int:
        return len(self.candidates)

    def history_files(self) -> list[str]:
        return [candidate_file(HISTORY_FILE, c.index) for c in self.candidates]

    def to_json(self) -> dict[str, Any]:
        return {
            "top_k": self.top_k,
            "n_candidates": self.n_candidates,
            "leader": self.leader.to_json(),
            "winner": None if self.winner is None else self.winner.to_json(),
            "budget": json_safe(self.budget),
            "spent_iterations": self.spent_iterations,
            "spent_samples": self.spent_samples,
            "halving_round": self.halving_round,
            "candidates": [dict(c.to_json(), history=candidate_file(HISTORY_FILE, c.index))
                           for c in self.candidates],
        }

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> HalvingDoc:
        leader = PlanRef.from_json(d.get("leader"))
        return cls(
            top_k=int(d.get("top_k") or len(d["candidates"])),
            leader=leader if leader is not None else PlanRef(0, ""),
            winner=PlanRef.from_json(d.get("winner")),
            budget=dict(d.get("budget") or {}),
            spent_iterations=int(d.get("spent_iterations", 0)),
            spent_samples=int(d.get("spent_samples", 0)),
            halving_round=int(d.get("halving_round", 0)),
            candidates=[CandidateSummary.from_json(c) for c in d["candidates"]],
        )


_HALVING_KEYS = ("top_k", "n_candidates", "leader", "winner", "budget", "spent_iterations", "spent_samples",
                 "halving_round", "candidates")


@dataclass
class ResultDoc:
    """A run's ``result.json`` (keys and meaning in the module docstring).

    ``best_cost`` is ``inf`` unless ``feasible``; ``best_cost_per_iter`` /
    ``iteration_best_cost_per_iter`` hold ``inf`` before the first feasible sample; ``elite_per_iter``
    costs ``nan`` where no elite was feasible. ``status`` is ``None`` only for documents that do
    not say (stand-ins); readers decide what that means."""

    status: str | None = None
    error: str | None = None
    feasible: bool = False
    best_cost: float = INF
    best_iteration: int | None = None
    best_params: BestParams | None = None
    best_z: list[float] | None = None
    columns: list[str] = field(default_factory=list)
    iterations_done: int = 0
    iterations: int | None = None
    converged: bool = False
    success_per_iter: list[float] = field(default_factory=list)
    best_cost_per_iter: list[float] = field(default_factory=list)
    iteration_best_cost_per_iter: list[float] = field(default_factory=list)
    n_envs_per_iter: list[int] = field(default_factory=list)
    n_feasible_per_iter: list[int] = field(default_factory=list)
    # ce.prune: rows per iteration stopped as they could not be an elite (None: pruning off)
    n_stopped_per_iter: list[int] | None = None
    n_screened_per_iter: list[int] | None = None
    elite_per_iter: list[EliteStats] = field(default_factory=list)
    iteration_time_s: list[float] = field(default_factory=list)
    final_mean: list[Any] | None = None
    final_std: list[Any] | None = None
    final_weights: list[float] | None = None
    wall_time_s: float = NAN
    seed: int | None = None
    task_name: str | None = None
    task_source: str | None = None
    plan: str | None = None
    config: dict[str, Any] | None = None
    versions: dict[str, str | None] = field(default_factory=dict)
    run_dir: str | None = None
    segments: int = 1
    resumed_from_iteration: int | None = None
    backend: str | None = None
    n_envs: int | None = None
    setup_time_s: float = NAN
    workers: int = 1
    warm_start: dict[str, Any] | None = None  # realize.search.warm_start.WarmStart.to_dict(): where the search began
    halving: HalvingDoc | None = None
    extra: dict[str, Any] = field(default_factory=dict)

    simulated = True  # a ResultDoc is the document of a run that got to simulate (FailureDoc: False)

    @property
    def interrupted(self) -> bool:
        return self.status == "interrupted"

    def to_json(self) -> dict[str, Any]:
        h = self.halving
        doc: dict[str, Any] = {
            "status": self.status,
            "interrupted": self.interrupted,
            "error": self.error,
            "feasible": self.feasible,
            "best_cost": encode_float(self.best_cost) if self.feasible else None,
            "best_iteration": self.best_iteration,
            "best_params": json_safe(self.best_params),
            "best_z": encode_floats(self.best_z),
            "columns": list(self.columns),
            "iterations_done": self.iterations_done,
            "iterations": self.iterations,
            "converged": self.converged,
            "success_per_iter": encode_floats(self.success_per_iter),
            "best_cost_per_iter": encode_floats(self.best_cost_per_iter),
            "iteration_best_cost_per_iter": encode_floats(self.iteration_best_cost_per_iter),
            "n_envs_per_iter": list(self.n_envs_per_iter),
            "n_feasible_per_iter": list(self.n_feasible_per_iter),
            **({} if self.n_stopped_per_iter is None else {"n_stopped_per_iter": list(self.n_stopped_per_iter),
                                                           "finished_success_per_iter": self.finished_success_per_iter()}),
            **({} if self.n_screened_per_iter is None else {"n_screened_per_iter": list(self.n_screened_per_iter)}),
            "elite_per_iter": [e.to_json() for e in self.elite_per_iter],
            "iteration_time_s": encode_floats(self.iteration_time_s),
            "final_mean": encode_floats(self.final_mean),
            "final_std": encode_floats(self.final_std),
            "final_weights": encode_floats(self.final_weights),
            "wall_time_s": encode_float(self.wall_time_s),
            "seed": self.seed,
            "task": {"name": self.task_name, "source": self.task_source},
            "plan": self.plan,
            "config": json_safe(self.config),
            "versions": dict(self.versions),
            "run_dir": self.run_dir,
            "files": {"history": HISTORY_FILE if h is None else h.history_files(), "checkpoint": CHECKPOINT_FILE},
            "segments": self.segments,
            "resumed_from_iteration": self.resumed_from_iteration,
            "backend": self.backend,
            "n_envs": self.n_envs,
            "setup_time_s": encode_float(self.setup_time_s),
            "workers": self.workers,
            "warm_start": json_safe(self.warm_start),
        }
        if h is not None:
            doc.update(h.to_json())
        doc.update(json_safe(self.extra))
        return doc

    def finished_success_per_iter(self) -> list[float | None]:
        """``ce.prune``: per iteration, the share of the rows that were not stopped that ended
        feasible (None where every row was stopped). ``success_per_iter`` counts a stopped row as
        failed, so with pruning it stays low while the search improves; this one does not."""
        stopped = self.n_stopped_per_iter or [0] * len(self.n_envs_per_iter)
        out: list[float | None] = []
        for n, k, s in zip(self.n_envs_per_iter, self.n_feasible_per_iter, stopped):
            out.append(k / (n - s) if n > s else None)
        return out

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> ResultDoc:
        """A ``ResultDoc`` from ``result.json``'s object; ``ValueError``/``KeyError``/``TypeError``
        if a key holds a value of the wrong kind."""
        d = {_OLD_KEYS.get(k, k): v for k, v in d.items()}
        task = d.get("task") if isinstance(d.get("task"), Mapping) else {}
        cfg = d.get("config")
        known = ({f for f in cls.__dataclass_fields__} | {"interrupted", "task", "files", "finished_success_per_iter"}
                 | set(_HALVING_KEYS))
        best_params = d.get("best_params")
        return cls(
            status=None if d.get("status") is None else str(d["status"]),
            error=d.get("error"),
            feasible=bool(d.get("feasible", False)),
            best_cost=decode_float(d.get("best_cost"), INF),
            best_iteration=_opt_int(d.get("best_iteration")),
            best_params=None if best_params is None else {
                str(k): {str(c): float(x) for c, x in p.items()} for k, p in best_params.items()},
            best_z=decode_floats(d.get("best_z")),
            columns=[str(c) for c in d.get("columns") or []],
            iterations_done=int(d.get("iterations_done", len(d.get("success_per_iter") or []))),
            iterations=_opt_int(d.get("iterations")),
            converged=bool(d.get("converged", False)),
            success_per_iter=_floats(d.get("success_per_iter")),
            best_cost_per_iter=_floats(d.get("best_cost_per_iter"), INF),
            iteration_best_cost_per_iter=_floats(d.get("iteration_best_cost_per_iter"), INF),
            n_envs_per_iter=[int(v) for v in d.get("n_envs_per_iter") or []],
            n_feasible_per_iter=[int(v) for v in d.get("n_feasible_per_iter") or []],
            n_stopped_per_iter=None if d.get("n_stopped_per_iter") is None else [int(v) for v in d["n_stopped_per_iter"]],
            n_screened_per_iter=(None if d.get("n_screened_per_iter") is None
                                 else [int(v) for v in d["n_screened_per_iter"]]),
            elite_per_iter=[EliteStats.from_json(e) for e in d.get("elite_per_iter") or []],
            iteration_time_s=_floats(d.get("iteration_time_s")),
            final_mean=decode_floats(d.get("final_mean")),
            final_std=decode_floats(d.get("final_std")),
            final_weights=decode_floats(d.get("final_weights")),
            wall_time_s=decode_float(d.get("wall_time_s")),
            seed=_opt_int(d.get("seed")),
            task_name=task.get("name"),
            task_source=task.get("source"),
            plan=None if d.get("plan") is None else _plan_text(d["plan"]),
            config=dict(cfg) if isinstance(cfg, Mapping) else None,
            versions=dict(d.get("versions") or {}),
            run_dir=d.get("run_dir"),
            segments=int(d.get("segments") or 1),
            resumed_from_iteration=_opt_int(d.get("resumed_from_iteration")),
            backend=d.get("backend"),
            n_envs=_opt_int(d.get("n_envs")),
            setup_time_s=decode_float(d.get("setup_time_s")),
            workers=int(d.get("workers") or 1),
            warm_start=d.get("warm_start") if isinstance(d.get("warm_start"), dict) else None,
            halving=HalvingDoc.from_json(d) if d.get("candidates") is not None else None,
            extra={k: v for k, v in d.items() if k not in known},
        )


def _plan_text(plan: Any) -> str:
    return ", ".join(map(str, plan)) if isinstance(plan, list) else str(plan)


@dataclass
class FailureDoc:
    """``result.json`` of a run that failed before it simulated anything (a bad config): the
    error, the config as far as it was read, the package versions. The ``ResultDoc`` summary
    attributes are there too (nothing feasible, no iterations)."""

    error: str
    config: Any = None
    versions: dict[str, str | None] = field(default_factory=dict)

    status = "failed"
    interrupted = False
    simulated = False
    feasible = False
    best_cost = INF
    iterations_done = 0
    wall_time_s = NAN

    def to_json(self) -> dict[str, Any]:
        return {
            "status": self.status,
            "interrupted": False,
            "error": self.error,
            "feasible": False,
            "best_cost": None,
            "iterations_done": 0,
            "simulated": False,
            "wall_time_s": None,
            "config": json_safe(self.config),
            "versions": dict(self.versions),
        }

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> FailureDoc:
        return cls(error=str(d.get("error") or ""), config=d.get("config"), versions=dict(d.get("versions") or {}))


def read_result_doc(d: Mapping[str, Any]) -> ResultDoc | FailureDoc:
    """The document ``d`` (``result.json``'s object) holds: a ``FailureDoc`` when it says
    ``simulated: false``, else a ``ResultDoc``."""
    if d.get("simulated") is False:
        return FailureDoc.from_json(d)
    return ResultDoc.from_json(d)
