"""Validation replicas: a run's best plan re-simulated K times at once under the task's perturbations.

What it does: ``validate`` builds one batched scene of K copies of the run's world (the run's
task, geometry, physics, controllers) whose every reset applies the task's perturbation model
(``TaskSpec.perturbation``, ``realize.tasks.perturbation``: each object's xy and yaw, the robot
start's xy; any field can be overridden), gives each copy's objects their own friction and
mass (the configured values times factors drawn from the model's ranges, object by object in
the scene's order; CPU backend), realizes the best plan in all K copies, and reports the share
that reaches the goal, the failure reasons and the cost of the successful ones.
``write_validation`` stores the report in ``result.json`` under ``validation`` (read, add the
key, write back atomically).
What it doesn't: search, replay one copy or record video (``realize.app.replay``), or perturb
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

from realize.app.replay import ReplayError, best_z_rows, build_replay_spec, saved_plan
from realize.config import ConfigError
from realize.tasks.perturbation import Perturbation
from realize.run_dir.directory import RunDir
from realize.scene import EnvOptions

__all__ = ["ValidationReport", "validate", "write_validation", "replica_spec", "simulate_replicas"]


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

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)


def validate(run_dir: str | Path, replicas: int = 16, seed: int = 0, *,
             perturbation: Perturbation | None = None, backend: str = "cpu", write: bool = True,
             track_objects: bool | None = None, **overrides: Any) -> ValidationReport:
    """Re-simulate the best plan ``replicas`` times at once under perturbations; report the share
    that reaches the goal and (``write``) store it in ``result.json`` under ``validation``.

    Perturbations: ``perturbation`` (None: the run task's model) with ``overrides`` of its fields
    (``object_xy=0.03``, ``friction=(1.0, 1.0)``, ...); the reset randomization is seeded with
    ``seed``, the friction and mass factors are drawn from ``numpy.random.default_rng(seed)``.
    ``track_objects``: override the run's ``controller.track_objects`` (None: the run's).
    """
    if isinstance(replicas, bool) or not isinstance(replicas, int) or replicas < 1:
        raise ReplayError(f"replicas = {replicas!r} must be an integer >= 1")
    t0 = time.perf_counter()
    run = saved_plan(run_dir)
    spec, model = replica_spec(run, backend, perturbation, track_objects, overrides)
    res, friction, mass, used_backend = simulate_replicas(spec, best_z_rows(run, replicas), model, seed)
    ok = res.feasible.numpy()
    costs = res.cost.numpy().astype(np.float64)[ok]
    report = ValidationReport(
        replicas=replicas, success_share=float(ok.mean()),
        failures=dict(sorted(Counter(f for f in res.failure if f).items())), seed=int(seed),
        perturbation=model.to_dict(), track_objects=spec.rollout.track_objects, friction=friction, mass=mass,
        cost_mean=float(costs.mean()) if len(costs) else None, cost_std=float(costs.std()) if len(costs) else None,
        saved_cost=run.best_cost if math.isfinite(run.best_cost) else None, backend=used_backend, wall_time_s=time.perf_counter() - t0,
    )
    if write:
        write_validation(run.run_dir, report)
    return report


def replica_spec(run: Any, backend: str, perturbation: Perturbation | None, track_objects: bool | None,
                 overrides: dict[str, Any]) -> tuple[Any, Perturbation]:
    """The run's replay spec (``track_objects`` overriding its controller's) and the perturbation
    model (``perturbation`` or the run task's, with ``overrides`` of its fields)."""
    spec = build_replay_spec(run, backend)
    if track_objects is not None:
        spec.rollout = dataclasses.replace(spec.rollout, track_objects=bool(track_objects))
    try:
        model = (perturbation or spec.task.perturbation).with_overrides(**overrides)
    except (TypeError, ConfigError) as e:
        raise ReplayError(f"perturbation: {e}") from None
    return spec, model


def simulate_replicas(spec: Any, Z: torch.Tensor, model: Perturbation, seed: int
                      ) -> tuple[Any, dict[str, list[float]], dict[str, list[float]], str]:
    """Realize the rows of ``Z`` (one per copy) in one scene whose every reset draws from
    ``model`` (seeded with ``seed``) and whose objects get friction and mass factors from
    ``numpy.random.default_rng(seed)``: (rollout result, friction and mass per object and copy,
    the backend)."""
    from realize.app.realizers import open_realization

    n = Z.shape[0]
    options = EnvOptions(object_xy_noise=model.object_xy, object_yaw_noise=model.object_yaw,
                         robot_xy_noise=model.robot_xy, randomize_resets=model.moves_start)
    scene, (realizer,) = open_realization(spec, n_envs=n, env=options, seed=seed)
    with scene:
        f_friction, f_mass = model.draw_factors(scene.object_names, n, np.random.default_rng(seed))
        # a [1, 1] range leaves the simulator untouched (the configured values, bit for bit)
        friction = {o.name: (scene.set_object_friction(o.name, f_friction[o.name]).tolist()
                             if model.friction != (1.0, 1.0) else [o.friction] * n)
                    for o in scene.geometry.objects}
        mass = {o.name: (scene.set_object_mass(o.name, f_mass[o.name]).tolist()
                         if model.mass != (1.0, 1.0) else [o.mass] * n) for o in scene.geometry.objects}
        return realizer.rollout(Z), friction, mass, scene.backend


def write_validation(run_dir: str | Path, report: ValidationReport) -> None:
    """Add ``validation`` to ``RUN_DIR/result.json`` (re-read just before, written atomically)."""
    RunDir(run_dir).add_to_result("validation", report.to_dict())
