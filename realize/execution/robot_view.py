"""What the robot knows of its world: the execution world itself, or a sensor feeding a belief.

What it does: ``RobotView(world, noise, seed)`` stands between an ``ExecutionWorld`` and the
executor. With the noise off it hands out the world's own observation. With an observation model
it keeps a ``Sensor`` (noisy, late, sometimes dropped readings) and the filtered ``Belief`` they
feed (``realize.execution.perception``): ``sense(step)`` takes the step's reading and folds in
the ones that arrive; ``observe(step)`` is the believed observation; ``seen_objects(step)`` and
``base_error()`` are what the controllers act on (where the belief has each object, how far off
the localizer has the base: ``PlanRealizer.seen_objects`` / ``base_error``).
What it doesn't: decide anything, drive the robot, or model the noise (``perception`` does).
"""

from __future__ import annotations

import dataclasses

import torch

from realize.execution.perception import Belief, Noise, Sensor
from realize.execution.world import ExecutionWorld, Observation

__all__ = ["RobotView"]


class RobotView:
    """The robot's view of ``world`` (module docstring); ``noise`` off: the world itself."""

    def __init__(self, world: ExecutionWorld, noise: Noise, seed: int) -> None:
        self.world, self.noise = world, noise
        self.sensor = None if noise.off else Sensor(noise, world.scene.control_dt, seed)
        self.belief = None if noise.off else Belief(noise)

    def observe(self, step: int) -> Observation:
        """What the robot decides from at ``step``: the world itself (no noise) or its belief."""
        truth = self.world.observe()
        if self.belief is None:
            return truth
        return self.belief.observation(dataclasses.replace(truth, step=step))

    def sense(self, step: int, first: bool = False) -> None:
        """The reading of ``step`` (every ``noise.every`` steps) and those arriving now; ``first``:
        the look before the robot moves, which needs no wait (taken again where it is dropped)."""
        if self.sensor is None or self.belief is None:
            return
        if first:
            if self.belief.readings == 0:
                r = self.sensor.read(dataclasses.replace(self.world.observe(), step=step))
                while r is None:
                    r = self.sensor.read(dataclasses.replace(self.world.observe(), step=step))
                self.sensor.deliver(step + self.sensor.latency_steps)
                self.belief.update(r)
            return
        if step % self.noise.every == 0:
            self.sensor.read(dataclasses.replace(self.world.observe(), step=step))
        for r in self.sensor.deliver(step):
            self.belief.update(r)

    def seen_objects(self, step: int) -> torch.Tensor:
        """(1, n_objects, 3) where the robot believes each object's centre is (the scene's order)."""
        seen = self.observe(step).state.objects
        return torch.tensor([[seen[n].position for n in self.world.scene.object_names]], dtype=torch.float32)

    def base_error(self) -> torch.Tensor:
        """(1, 3) how far off the localizer has the base (x, y, yaw); zeros without a belief."""
        err = self.belief.base_error if self.belief is not None else (0.0, 0.0, 0.0)
        return torch.tensor([err], dtype=torch.float32)
