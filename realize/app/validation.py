"""Validation replicas: a run's best plan re-simulated K times at once under small perturbations.

What it does: ``validate`` builds one batched scene of K copies of the run's world (the run's
task, geometry, physics, controllers) with ``EnvOptions`` that make every reset apply the task's
randomization (each object's xy and yaw, robot start xy; noise amplitudes the task's unless
given), gives each copy's objects their own friction (each its configured value times a factor
drawn from ``friction_range``, object by object in the scene's order; CPU backend), realizes the best plan in all K copies, and reports the share
that reaches the goal, the failure reasons and the cost of the successful ones.
``write_validation`` stores the report in ``result.json`` under ``validation`` (read, add the
key, write back atomically).
What it doesn't: search, replay one copy or record video (``realize.app.replay``), or perturb
anything but the start state and the objects' friction. The K replicas are not bit-identical even
without perturbations: each copy sits at its own tile offset (float32 rounding differs).
"""

from __future__ import annotations

import math
import time
from collections import Counter
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np

from realize.app.replay import ReplayError, best_z_rows, build_replay_spec, saved_plan
from realize.run_dir.directory import RunDir
from realize.scene import EnvOptions

__all__ = ["ValidationReport", "validate", "write_validation"]


@dataclass
class ValidationReport:
    replicas: int
    success_share: float
    failures: dict[str, int]  # failure reason ("<action>:<template>:<reason>") -> count
    seed: int
    friction_range: list[float] | None
    friction: dict[str, list[float]]  # object -> its friction in each replica
    randomize: bool
    object_xy_noise: float | None
    robot_xy_noise: float | None
    cost_mean: float | None  # over the successful replicas
    cost_std: float | None
    saved_cost: float | None
    backend: str
    wall_time_s: float

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)


def validate(run_dir: str | Path, replicas: int = 16, seed: int = 0, *,
             friction_range: tuple[float, float] | None = (0.8, 1.2), randomize: bool = True,
             object_xy_noise: float | None = None, robot_xy_noise: float | None = None,
             backend: str = "cpu", write: bool = True) -> ValidationReport:
    """Re-simulate the best plan ``replicas`` times at once under perturbations; report the share
    that reaches the goal and (``write``) store it in ``result.json`` under ``validation``.

    Perturbations: the task's reset randomization with ``seed`` (noise amplitudes: the task's
    defaults unless given) and, per replica, each object's friction times U(friction_range)
    drawn from ``numpy.random.default_rng(seed)``, object after object (None: unchanged).
    """
    from realize.app.realizers import open_realization

    if isinstance(replicas, bool) or not isinstance(replicas, int) or replicas < 1:
        raise ReplayError(f"replicas = {replicas!r} must be an integer >= 1")
    if friction_range is not None:
        lo, hi = map(float, friction_range)
        if not (0 < lo <= hi and math.isfinite(hi)):
            raise ReplayError(f"friction range {friction_range} must satisfy 0 < low <= high")
    t0 = time.perf_counter()
    run = saved_plan(run_dir)
    spec = build_replay_spec(run, backend)
    options = EnvOptions(object_xy_noise=object_xy_noise, robot_xy_noise=robot_xy_noise, randomize_resets=randomize)
    scene, (realizer,) = open_realization(spec, n_envs=replicas, env=options, seed=seed)
    with scene:
        friction: dict[str, list[float]] = {}
        rng = np.random.default_rng(seed)
        for o in scene.geometry.objects:
            if friction_range is not None:
                friction[o.name] = scene.set_object_friction(o.name, rng.uniform(lo, hi, size=replicas)).tolist()
            else:
                friction[o.name] = [float(o.friction)] * replicas
        res = realizer.rollout(best_z_rows(run, replicas))
        noise = (scene.object_xy_noise, scene.robot_xy_noise)
        used_backend = scene.backend
    ok = res.feasible.numpy()
    costs = res.cost.numpy().astype(np.float64)[ok]
    report = ValidationReport(
        replicas=replicas, success_share=float(ok.mean()),
        failures=dict(sorted(Counter(f for f in res.failure if f).items())), seed=int(seed),
        friction_range=None if friction_range is None else [lo, hi], friction=friction,
        randomize=randomize, object_xy_noise=noise[0] if randomize else None,
        robot_xy_noise=noise[1] if randomize else None,
        cost_mean=float(costs.mean()) if len(costs) else None, cost_std=float(costs.std()) if len(costs) else None,
        saved_cost=run.best_cost if math.isfinite(run.best_cost) else None, backend=used_backend, wall_time_s=time.perf_counter() - t0,
    )
    if write:
        write_validation(run.run_dir, report)
    return report


def write_validation(run_dir: str | Path, report: ValidationReport) -> None:
    """Add ``validation`` to ``RUN_DIR/result.json`` (re-read just before, written atomically)."""
    RunDir(run_dir).add_to_result("validation", report.to_dict())
