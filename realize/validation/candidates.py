"""Validate a run's K best distinct plans under the task's perturbations and pick the one to return.

What it does: ``validate_candidates`` takes, from the run's history (the lead candidate's in a
top-k run), the K cheapest distinct feasible samples of its last ``iterations`` iterations and
the run's best sample where it came earlier (a robust search's: by success share over its worlds
first, then cost), re-simulates each in the
same R worlds (``realize.tasks.worlds.draw_worlds`` of the task's perturbation model, on the
validation stream: other worlds than the search's) and once in the unperturbed world, K x (R + 1)
copies in the run's shards on its workers (``realize.validation.returned_plan.simulate_worlds``), and reports for every
candidate its search cost, nominal cost (re-simulated), success share, 95 % Wilson interval
(``wilson_interval``), failure reasons, where in the plan its replicas failed (``per_action``,
``per_segment``: ``realize.validation.action_outcomes``) and the mean cost of its successful replicas. The plan
to return is the cheapest candidate whose interval's lower bound is at least ``min_success``,
else the most robust one (highest success share, then cheapest). ``write`` stores it in
``result.json`` under ``validation``. ``realize.spec.run_spec.ValidationSettings`` (the Hydra
``validation`` group) runs it after a run's search (``realize.run.assembly``; ``validation.replicas=0``
turns it off).
What it doesn't: run inside the search, or change ``best_z`` (the nominal best stays the
search's; ``validation.returned`` names the plan to execute: replay runs it).
"""

from __future__ import annotations

import math
import time
from collections import Counter
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch

from realize.validation.action_outcomes import plan_outcomes
from realize.validation.replay import ReplayError, saved_plan
from realize.validation.returned_plan import (replica_spec, run_validation, simulate_worlds, validation_log_dir,
                                    validation_worlds)
from realize.run_dir.directory import RunDir
from realize.tasks.perturbation import Perturbation

__all__ = ["CandidateResult", "CandidatesReport", "wilson_interval", "pick_candidates",
           "validate_candidates"]

Z95 = 1.959963984540054  # two-sided 95 % normal quantile


def wilson_interval(successes: int, n: int, z: float = Z95) -> tuple[float, float]:
    """The Wilson score interval of a success share ``successes / n`` (n >= 1)."""
    p = successes / n
    denom = 1.0 + z * z / n
    centre = (p + z * z / (2 * n)) / denom
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / denom
    return max(0.0, centre - half), min(1.0, centre + half)


@dataclass
class CandidateResult:
    z: list[float]
    cost: float  # nominal (the search's) cost
    iteration: int  # where the search found it
    success_share: float
    ci95: tuple[float, float]
    failures: dict[str, int]
    cost_mean: float | None  # over its successful replicas
    nominal_cost: float | None = None  # re-simulated in the unperturbed world (None: it failed there)
    search_share: float | None = None  # a robust search's success share over its worlds (ce.replicas > 1)
    # per action (then the goal) and per stitched segment: replicas that started, completed, failed and why
    # (realize.validation.action_outcomes; None in a block written before they were counted)
    per_action: list[dict[str, Any]] | None = None
    per_segment: list[dict[str, Any]] | None = None


@dataclass
class CandidatesReport:
    replicas: int
    min_success: float
    seed: int
    perturbation: dict[str, Any]
    candidates: list[CandidateResult]
    returned: int  # index into candidates
    reason: str  # "cheapest above min_success" or "most robust"
    success_share: float  # the returned plan's
    ci95: tuple[float, float]
    backend: str
    wall_time_s: float
    leader: int | None = None  # a top-k run: the candidate plan whose history the candidates came from

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)


def pick_candidates(history: Any, k: int, iterations: int) -> list[tuple[np.ndarray, float, int, float | None]]:
    """The ``k`` best distinct feasible samples of the last ``iterations`` iterations of a
    ``History``, and the best feasible sample of the whole run wherever it lies (the search's
    ``best_z``: an earlier iteration's cheapest plan is a candidate too): (z, cost, iteration,
    share), cheapest first (ties: the later iteration first). A robust search's history
    (``share``: each sample's success share over its worlds) ranks by share first, then cost, as
    the search did; ``share`` is None otherwise."""
    n = len(history)

    def rows_of(i: int) -> list[tuple[float, float, int, np.ndarray]]:
        it = history.per_iter[i]
        ok = np.asarray(it["feasible"], dtype=bool)
        share = np.asarray(it["share"], dtype=np.float64) if "share" in it else np.full(len(ok), np.nan)
        return [(-float(sh) if np.isfinite(sh) else 0.0, float(c), -i, z)
                for z, c, sh in zip(np.asarray(it["Z"])[ok], np.asarray(it["cost"])[ok], share[ok])]

    def key(r: tuple[float, float, int, np.ndarray]) -> tuple[float, float, int]:
        return r[0], r[1], r[2]

    first = max(0, n - iterations)
    rows = [r for i in range(first, n) for r in rows_of(i)]
    earlier = [r for i in range(first) for r in rows_of(i)]
    if earlier:
        rows.append(min(earlier, key=key))
    rows.sort(key=key)
    out: list[tuple[np.ndarray, float, int, float | None]] = []
    for neg_share, c, neg_i, z in rows:
        if any(np.array_equal(z, o[0]) for o in out):
            continue
        out.append((z, c, -neg_i, -neg_share if "share" in history.per_iter[-neg_i] else None))
        if len(out) == k:
            break
    return out


def validate_candidates(run_dir: str | Path, candidates: int | None = None, replicas: int | None = None, *,
                        min_success: float | None = None, iterations: int | None = None, seed: int | None = None,
                        perturbation: Perturbation | None = None, backend: str | None = None,
                        track_objects: bool | None = None, write: bool = True, spec: Any = None,
                        **overrides: Any) -> CandidatesReport:
    """Validate the run's ``candidates`` cheapest distinct feasible plans, ``replicas`` each
    (module docstring); perturbations as ``realize.validation.returned_plan.validate``'s. A setting left
    None is the run's (``realize.validation.returned_plan.run_validation``: its ``validation`` group, its
    seed), so the call redoes the run's own validation. ``spec``: the run's ``RunSpec`` in memory (a
    run validating itself at its end; else rebuilt from ``result.json``)."""
    t0 = time.perf_counter()
    run = saved_plan(run_dir)
    settings, run_seed = run_validation(run)
    candidates = settings.candidates if candidates is None else candidates
    replicas = settings.replicas if replicas is None else replicas
    min_success = settings.min_success if min_success is None else min_success
    iterations = settings.iterations if iterations is None else iterations
    seed = run_seed if seed is None else seed
    for name, v in (("candidates", candidates), ("replicas", replicas), ("iterations", iterations)):
        if isinstance(v, bool) or not isinstance(v, int) or v < 1:
            raise ReplayError(f"{name} = {v!r} must be an integer >= 1")
    if not 0.0 <= float(min_success) <= 1.0:
        raise ReplayError(f"min_success = {min_success!r} must be in [0, 1]")
    rd = RunDir(run.run_dir)
    lead = run.leader.index if run.leader is not None else None
    try:
        history = rd.load_history(candidate=lead)
    except (OSError, KeyError, ValueError) as e:
        raise ReplayError(f"{rd.history_path(lead)}: the run's history cannot be read ({e})") from None
    picked = pick_candidates(history, candidates, iterations)
    if not picked:
        raise ReplayError(f"{run.run_dir}: no feasible sample in its last {iterations} iteration(s) to validate")
    spec, model = replica_spec(run, backend, perturbation, track_objects, overrides, spec)
    k, u = len(picked), replicas + 1
    # candidate j fills copies j*u .. j*u + R: world 0, the unperturbed one (its nominal cost), then
    # the perturbed worlds 1..R, the same for every candidate
    worlds = validation_worlds(model, spec.geometry.objects, replicas, seed)
    zs = np.stack([z for z, _, _, _ in picked])
    Z = torch.tensor(np.repeat(zs, u, axis=0), dtype=torch.float64)
    res, used_backend = simulate_worlds(spec, Z, worlds.tile(k * u), validation_log_dir(run.run_dir))
    ok_all = res.feasible.numpy().reshape(k, u)
    cost_all = res.cost.numpy().astype(np.float64).reshape(k, u)
    ok, cost = ok_all[:, 1:], cost_all[:, 1:]
    nominal_ok, nominal_cost = ok_all[:, 0], cost_all[:, 0]
    out = []
    plan, cuts = [str(a) for a in spec.task.plan], spec.stitch.cuts if spec.stitch is not None else ()
    for j, (z, c, it, share) in enumerate(picked):
        rows = slice(j * u + 1, (j + 1) * u)
        fails = Counter(f for f in res.failure[rows] if f)
        where = plan_outcomes(res.action_success[rows], res.goal[rows], res.failure[rows], plan, cuts).to_dict()
        good = cost[j][ok[j]]
        out.append(CandidateResult(z=[float(v) for v in z], cost=c, iteration=it, success_share=float(ok[j].mean()),
                                   ci95=wilson_interval(int(ok[j].sum()), replicas), failures=dict(sorted(fails.items())),
                                   cost_mean=float(good.mean()) if len(good) else None,
                                   nominal_cost=float(nominal_cost[j]) if nominal_ok[j] else None,
                                   search_share=share, **where))
    above = [j for j, r in enumerate(out) if r.ci95[0] >= min_success]
    if above:
        ret, reason = min(above, key=lambda j: (out[j].cost, j)), "cheapest above min_success"
    else:
        ret, reason = min(range(len(out)), key=lambda j: (-out[j].success_share, out[j].cost, j)), "most robust"
    report = CandidatesReport(replicas=replicas, min_success=float(min_success), seed=int(seed),
                              perturbation=model.to_dict(), candidates=out, returned=ret, reason=reason,
                              success_share=out[ret].success_share, ci95=out[ret].ci95, backend=used_backend,
                              wall_time_s=time.perf_counter() - t0, leader=lead)
    if write:
        rd.add_to_result("validation", report.to_dict())
    return report
