"""A task's perturbation model: how the world a plan meets may differ from the one it was found in.

What it does: ``Perturbation`` (the task config's ``perturbation`` key; every field has a
default, so a task without the key gets the seed world's model) says, per replica of a world:
  * ``object_xy`` (m) and ``object_yaw`` (rad): every object that does not stand on the floor
    starts ``U(-a, a)`` off its configured xy and turned by ``U(-a, a)`` (an object on another
    object stays above its top; objects on the floor, such as the push scene's stick, keep
    their pose);
  * ``robot_xy`` (m): the robot starts ``U(-a, a)`` off its configured xy;
  * ``friction`` and ``mass`` ``[low, high]``: every object's friction and mass times a factor
    ``U(low, high)``, drawn object by object (``[1, 1]``: unchanged; CPU backend only, PhysX GPU
    fixes materials and masses when the scene is built).
``realize.tasks.worlds.draw_worlds`` draws worlds from it (one seeded generator, so a set of
worlds repeats); the robust search (``ce.replicas``), the validation of a run's candidates and
``scripts/validate.py`` all read it from the run's task.
What it doesn't: apply anything to a simulator (``realize.scene.BatchedScene`` does), or decide
how many replicas run (callers do).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Any, ClassVar


from realize.config import Settings, setting

__all__ = ["Perturbation", "NONE"]


def _factor_range(v: tuple[float, float]) -> str | None:
    lo, hi = v
    return None if 0 < lo <= hi else "must be [low, high] with 0 < low <= high"


@dataclass
class Perturbation(Settings):
    """The task's perturbation model (module docstring)."""

    config_key: ClassVar[str] = "task.perturbation"

    object_xy: float = setting(0.02, ge=0, le=0.5)
    object_yaw: float = setting(math.pi / 4, ge=0, le=math.pi)
    robot_xy: float = setting(0.05, ge=0, le=1.0)
    friction: tuple[float, float] = setting((0.8, 1.2), check=_factor_range)
    mass: tuple[float, float] = setting((1.0, 1.0), check=_factor_range)

    def with_overrides(self, **changes: Any) -> Perturbation:
        """A copy with the given fields replaced (``None`` values keep this model's)."""
        return replace(self, **{k: v for k, v in changes.items() if v is not None})



NONE = Perturbation(object_xy=0.0, object_yaw=0.0, robot_xy=0.0, friction=(1.0, 1.0), mass=(1.0, 1.0))

