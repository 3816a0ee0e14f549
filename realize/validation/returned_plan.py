"""Validation replicas: the plan a run returns re-simulated K times at once under the task's perturbations.

What it does: ``validate`` builds one batched scene of K copies of the run's world (the run's
task, geometry, physics, controllers), copy ``k`` in the ``k``-th world drawn from the task's
perturbation model (``TaskSpec.perturbation``; any field can be overridden) by
``realize.tasks.worlds.draw_worlds`` (by default the run's seed and replica count: the worlds
its candidates met, ``run_validation``): each object's xy and yaw, the robot start's xy, each
object's friction and mass (CPU backend), realizes the plan the run returns in all K copies
(``nominal``: ``best_z``), and reports the share that reaches the goal, the failure reasons,
where in the plan the replicas failed (``per_action``, ``per_segment``:
``realize.validation.action_outcomes``) and the cost of the successful ones. ``simulate_worlds`` (one world per copy, the copies in the run's shards on its workers) is
shared with the candidates' validation.
``write_validation`` stores the report in ``result.json`` under ``plan_validation`` (read, add
the key, write back atomically; the run's own candidates block, ``validation``, stays).
What it doesn't: search, replay one copy or record video (``realize.validation.replay``), or perturb
anything the model does not name. The K replicas are not bit-identical even without
perturbations: each copy sits at its own tile offset (float32 rounding differs).
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections import Counter
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch

from realize.validation.action_outcomes import plan_outcomes
from realize.validation.replay import ReplayError, build_replay_spec, replay_spec, returned_z, saved_plan
from realize.spec.run_spec import ValidationSettings
from realize.config import ConfigError
from realize.tasks.perturbation import Perturbation
from realize.run_dir.directory import BestPlan, RunDir
from realize.run_dir.names import WORKER_LOG_DIR
from realize.tasks.worlds import Worlds, draw_worlds

__all__ = ["ValidationReport", "validate", "write_validation", "replica_spec", "simulate_worlds", "PLAN_VALIDATION",
           "validation_log_dir", "validation_worlds", "run_validation"]


@dataclass
class ValidationReport:
    replicas: int
    success_share: float
    failures: dict[str, int]  # failure reason ("<action>:<template>:<reason>") -> count
    seed: int
    perturbation: dict[str, Any]  # the model the replicas were drawn from (realize.tasks.perturbation)
    track_objects: bool  # controller.track_objects of the replicas' rollouts
    friction: dict[str, list[float]]  # object -> its friction in each replica
    mass: dict[str, list[float]]  # object -> its mass (kg) in each replica
    cost_mean: float | None  # over the successful replicas
    cost_std: float | None
    saved_cost: float | None
    backend: str
    wall_time_s: float
    plan: str = "best_z"  # which plan: "best_z" or "validation.returned" (realize.validation.replay.returned_z)
    candidate: int | None = None  # its index in the run's validation candidates
    # per action (then the goal) and per stitched segment: replicas that started, completed, failed and why
    # (realize.validation.action_outcomes; None in a report written before they were counted)
    per_action: list[dict[str, Any]] | None = None
    per_segment: list[dict[str, Any]] | None = None

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)


def validate(run_dir: str | Path, replicas: int | None = None, seed: int | None = None, *,
             perturbation: Perturbation | None = None, backend: str | None = None, write: bool = True,
             track_objects: bool | None = None, nominal: bool = False, **overrides: Any) -> ValidationReport:
    """Re-simulate the plan the run returns (``realize.validation.replay.returned_z``: its candidate
    validation's returned plan, else ``best_z``; ``nominal``: ``best_z``) ``replicas`` times at
    once under perturbations; report the share that reaches the goal and (``write``) store it in
    ``result.json`` under ``plan_validation`` (``validation`` is the run's candidates block).

    Perturbations: ``perturbation`` (None: the run task's model) with ``overrides`` of its fields
    (``object_xy=0.03``, ``friction=(1.0, 1.0)``, ...); the worlds are worlds 1..R of
    ``validation_worlds(model, objects, replicas, seed)``, those the run's candidates were
    validated in for the same seed.
    ``replicas``, ``seed``: None takes the run's (``run_validation``: its ``validation.replicas``,
    its seed), so the check meets the worlds the run chose its plan in; another seed gives
    held-out worlds.
    ``track_objects``: override the run's ``controller.track_objects`` (None: the run's).
    """
    t0 = time.perf_counter()
    run = saved_plan(run_dir)
    settings, run_seed = run_validation(run)
    replicas = settings.replicas if replicas is None else replicas
    seed = run_seed if seed is None else seed
    if isinstance(replicas, bool) or not isinstance(replicas, int) or replicas < 1:
        raise ReplayError(f"replicas = {replicas!r} must be an integer >= 1")
    spec, model = replica_spec(run, backend, perturbation, track_objects, overrides)
    # the perturbed worlds 1..R the run's candidates met for the same seed (world 0 is the unperturbed one)
    worlds = validation_worlds(model, spec.geometry.objects, replicas, seed).select(np.arange(1, replicas + 1))
    plan = returned_z(run, nominal)
    res, used_backend = simulate_worlds(spec, torch.tensor([plan.z] * replicas, dtype=torch.float64), worlds,
                                        validation_log_dir(run.run_dir))
    ok = res.feasible.numpy()
    costs = res.cost.numpy().astype(np.float64)[ok]
    objects = spec.geometry.objects
    report = ValidationReport(
        replicas=replicas, success_share=float(ok.mean()),
        failures=dict(sorted(Counter(f for f in res.failure if f).items())), seed=int(seed),
        perturbation=model.to_dict(), track_objects=spec.rollout.track_objects,
        friction={o.name: (o.friction * worlds.friction[:, k]).tolist() for k, o in enumerate(objects)},
        mass={o.name: (o.mass * worlds.mass[:, k]).tolist() for k, o in enumerate(objects)},
        cost_mean=float(costs.mean()) if len(costs) else None, cost_std=float(costs.std()) if len(costs) else None,
        saved_cost=plan.cost if math.isfinite(plan.cost) else None, backend=used_backend,
        wall_time_s=time.perf_counter() - t0, plan=plan.source, candidate=plan.candidate,
        **plan_outcomes(res.action_success, res.goal, res.failure, [str(a) for a in spec.task.plan],
                        spec.stitch.cuts if spec.stitch is not None else ()).to_dict(),
    )
    if write:
        write_validation(run.run_dir, report)
    return report


def run_validation(run: BestPlan) -> tuple[ValidationSettings, int]:
    """The ``validation`` settings the run validated its candidates with, and its seed: the
    defaults that put a later check in the worlds the run's candidates met. A run with
    validation off (or recorded before it existed) gets the group's default settings
    (``ValidationSettings``')."""
    v = ValidationSettings.from_mapping(run.config.get("validation"))
    if v.replicas == 0:
        v = ValidationSettings()  # the group's defaults
    return v, int(run.config.get("seed", 0))


def validation_worlds(model: Perturbation, objects: Any, replicas: int, seed: int) -> Worlds:
    """The R + 1 worlds a validation draws: world 0 the unperturbed one, worlds 1..R from
    ``model`` (validation's stream of ``realize.tasks.worlds.draw_worlds``); one plan's check and
    the candidates' validation use the same ones for the same seed."""
    return draw_worlds(model, objects, replicas + 1, seed, nominal_first=True)


def replica_spec(run: Any, backend: str | None, perturbation: Perturbation | None, track_objects: bool | None,
                 overrides: dict[str, Any], spec: Any = None) -> tuple[Any, Perturbation]:
    """The run's replay spec (``track_objects`` overriding its controller's) and the perturbation
    model (``perturbation`` or the run task's, with ``overrides`` of its fields). ``spec``: the
    run's spec in memory (a run validating itself), taken as it is where no ``backend`` is forced;
    else the spec is rebuilt from the run's saved config. The goal is judged without the search's
    ``goal.margin``."""
    spec = (build_replay_spec(run, backend, judged=True) if spec is None or backend is not None
            else replay_spec(spec, run, judged=True))  # the goal itself, not the search's margin
    if track_objects is not None:
        spec = dataclasses.replace(spec, rollout=dataclasses.replace(spec.rollout, track_objects=bool(track_objects)))
    try:
        model = (perturbation or spec.task.perturbation).with_overrides(**overrides)
    except (TypeError, ConfigError) as e:
        raise ReplayError(f"perturbation: {e}") from None
    return spec, model


def simulate_worlds(spec: Any, Z: torch.Tensor, worlds: Worlds, log_dir: Path | None = None) -> tuple[Any, str]:
    """Realize the rows of ``Z`` (one per copy) in a scene whose copy ``k`` is the world
    ``worlds[k]``, cut into the run's shards (``sim.shard_rows``) on the run's workers (every
    core: ``workers``; the numbers depend on the shards only; worker processes log into
    ``log_dir``): (rollout result, the backend)."""
    from realize.workers.pool import open_pool

    n = Z.shape[0]
    if len(worlds) != n:
        raise ReplayError(f"{len(worlds)} worlds for {n} plans")
    ce = dataclasses.replace(spec.ce, n_envs=n, n_envs_end=None, schedule="constant", n_elite=1, replicas=1,
                             knn_robust=0, n_modes=1)
    vspec = dataclasses.replace(spec, ce=ce, worlds=worlds)
    pool = open_pool(vspec, [spec.task], log_dir=log_dir)
    try:
        return pool.rollout(None, Z), pool.backend
    finally:
        pool.close()


PLAN_VALIDATION = "plan_validation"  # result.json's key of a one-plan validation


def validation_log_dir(run_dir: str | Path) -> Path:
    """Where a validation's worker processes log: ``RUN_DIR/workers/validation``."""
    return Path(run_dir) / WORKER_LOG_DIR / "validation"


def write_validation(run_dir: str | Path, report: ValidationReport) -> None:
    """Add ``plan_validation`` to ``RUN_DIR/result.json`` (re-read just before, written atomically)."""
    RunDir(run_dir).add_to_result(PLAN_VALIDATION, report.to_dict())
