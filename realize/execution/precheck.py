"""Check before you repair: the plan's remaining actions simulated from the believed state in a
few copies, to tell a deviation that breaks the plan from one it survives.

What it does: ``Precheck(spec, settings, seed)`` keeps, per believed world layout (the run's
scene config with the tables where they are believed to stand and the boxes seen), one batched
scene of ``settings.copies`` (at least one) copies, built on first use. ``__call__(task, z, action, state,
geometry_cfg)`` simulates actions ``action, ...`` of ``task``'s plan with the parameters of
``z`` (the plan being carried out: nothing re-searched) from ``state`` (the believed state) in
every copy: copy 0 from the state itself, the others with each object not in hand moved by a
draw of ``N(0, scatter_m)`` in x and y (what the belief may be off by), every copy's objects
with friction and mass factors drawn from the task's perturbation model (``draw_worlds`` on its
own stream, ``PRECHECK_STREAM``; the same draws for every check of a study's world). The
controllers plan in the believed layout. It returns a ``PrecheckResult``: how many copies
reached the goal, the failures, the wall time and whether the scene was built for it.
``grip_holds(state, geometry_cfg)`` tells whether the object in the hand of ``state``, restored
at rest, stays in the fingers for ``GRIP_STEPS`` control steps and, on a mobile base, through a
short drive back and forth (the executor squares a grip that does not: ``realize.execution.in_hand``).
What it doesn't: decide (the executor compares the share with ``min_success``), observe the
world, or search.
"""

from __future__ import annotations

import json
import time
from collections import Counter
from dataclasses import asdict, dataclass, field, replace
from typing import Any

import numpy as np
import torch

from realize.execution.settings import PrecheckSettings
from realize.tasks.suffix import suffix_columns, task_suffix
from realize.tasks.worlds import SEARCH_STREAM, VALIDATION_STREAM, draw_worlds
from realize.world.geometry import GeometryCfg, build_geometry
from realize.world.state import ObjectPose, SceneState

__all__ = ["PRECHECK_STREAM", "PrecheckResult", "Precheck"]

GRIP_STEPS = 5  # control steps a restored grip must hold (the slipping ones let go within 3)
SHAKE_S = 0.5  # s of each leg of the drive a restored grip is shaken with (a mobile base)
PRECHECK_STREAM = 4  # draw_worlds stream of the checks' copies (search 1, validation 2, execution 3)
assert PRECHECK_STREAM not in (SEARCH_STREAM, VALIDATION_STREAM, 3)


@dataclass
class PrecheckResult:
    """One check: ``successes`` of ``copies`` reached the goal from action ``action``."""

    action: int
    copies: int
    successes: int
    go_on: bool
    wall_s: float
    scene: str  # built | kept
    failures: dict[str, int] = field(default_factory=dict)

    @property
    def share(self) -> float:
        return self.successes / self.copies if self.copies else 0.0

    def to_dict(self) -> dict[str, Any]:
        return {**asdict(self), "share": self.share}


def _scatter(state: SceneState, copies: int, sigma: float, rng: np.random.Generator) -> list[SceneState]:
    out = [state]
    for _ in range(copies - 1):
        objects = {}
        for name, p in state.objects.items():
            dx, dy = (0.0, 0.0) if name == state.held else (float(v) for v in sigma * rng.standard_normal(2))
            objects[name] = ObjectPose((p.position[0] + dx, p.position[1] + dy, p.position[2]), p.quaternion,
                                       where=f"objects.{name}")
        out.append(replace(state, objects=objects))
    return out


class Precheck:
    """The check (module docstring). ``spec``: the run's spec (its robot, physics, controllers,
    perturbation model); ``seed``: the world's seed (its copies' friction and mass draws)."""

    def __init__(self, spec: Any, settings: PrecheckSettings, seed: int) -> None:
        self.spec, self.settings, self.seed = spec, settings, int(seed)
        self._scenes: dict[str, Any] = {}
        self.checks = 0

    def _scene(self, geometry_cfg: GeometryCfg) -> tuple[Any, str]:
        from realize.scene import BatchedScene

        key = json.dumps(asdict(geometry_cfg), sort_keys=True, default=str)
        if key in self._scenes:
            return self._scenes[key], "kept"
        for old in self._scenes.values():  # one layout at a time: a moved table makes the last one stale
            old.close()
        self._scenes.clear()
        k = max(1, self.settings.copies)
        scene = BatchedScene(k, geometry_cfg, self.spec.sim, robot=self.spec.robot)
        scene.set_worlds(draw_worlds(self.spec.task.perturbation, scene.geometry.objects, k, self.seed,
                                     stream=PRECHECK_STREAM))
        self._scenes[key] = scene
        return scene, "built"

    def __call__(self, task: Any, z: Any, action: int, state: SceneState, geometry_cfg: GeometryCfg) -> PrecheckResult:
        from realize.realization.rollout import PlanRealizer

        t0 = time.perf_counter()
        s = self.settings
        scene, how = self._scene(geometry_cfg)
        suffix = task_suffix(task, action)
        cols = suffix_columns(task, action)
        zs = torch.tensor([[float(z[c]) for c in cols]] * s.copies, dtype=torch.float64)
        rng = np.random.default_rng([self.seed, PRECHECK_STREAM, self.checks])
        self.checks += 1
        starts = _scatter(state, s.copies, s.scatter_m, rng)
        realizer = PlanRealizer(suffix, scene, self.spec.rollout, seed=self.spec.seed,
                                geometry=build_geometry(geometry_cfg))
        res = realizer.rollout(zs, starts=starts)
        ok = int(res.feasible.sum())
        fails = Counter(f.split(":", 1)[1] if ":" in f else (f or "goal not reached")
                        for f, good in zip(res.failure, res.feasible.tolist()) if not good)
        return PrecheckResult(action, s.copies, ok, ok >= s.min_success * s.copies, time.perf_counter() - t0, how,
                              dict(fails))

    def grip_holds(self, state: SceneState, geometry_cfg: GeometryCfg, steps: int = GRIP_STEPS) -> bool:
        """Whether ``state``'s held object, restored at rest in this check's scene (every copy),
        is still in the hand after ``steps`` control steps with every target holding, and, on a
        mobile base, after a shake as a drive gives it: ``SHAKE_S`` backwards then as long
        forwards at the PID's top speed, from rest and back to rest (copy 0). A restore makes
        the grip's contacts anew: one a few degrees askew may hold at rest and let go on the way."""
        scene, _ = self._scene(geometry_cfg)
        n = scene.n_envs
        speed = float(self.spec.rollout.pid.max_lin_speed)
        shake = round(SHAKE_S / scene.control_dt) if scene.robot.base.joints else 0
        legs = [(0.0, steps)] + ([(-speed, shake), (speed, shake), (0.0, steps)] if shake else [])
        with torch.inference_mode():
            scene.reset(seed=self.spec.seed, state=state)
            scene.hold_still()
            for v, n_steps in legs:  # at rest, then back, forward and at rest again
                scene.set_base_velocity_robot_frame(torch.tensor([[v, 0.0, 0.0]] * n))
                for _ in range(n_steps):
                    scene.step()
            k = int(scene.held_object()[0])
        return k >= 0 and scene.object_names[k] == state.held

    def close(self) -> None:
        for scene in self._scenes.values():
            scene.close()
        self._scenes.clear()
