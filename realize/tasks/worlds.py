"""Perturbed worlds as data: R draws of a task's perturbation model, and which copy meets which.

What it does: ``Worlds`` holds, per world, the robot's start offset, every object's xy offset
and yaw turn, and every object's friction and mass factor, object by object in the scene's
order (``names``). ``draw_worlds(model, objects, R, seed)`` draws R of them from a task's
``realize.tasks.perturbation.Perturbation`` with one seeded ``numpy`` generator (objects on the
floor keep their pose; a ``[1, 1]`` factor range draws nothing), so the same seed gives the same
worlds in every process; ``nominal_first`` makes world 0 the unperturbed one.
``Worlds.tile(n)`` lays R worlds over n copies (copy ``k`` meets world ``k % R``: a batch whose
sample ``i`` fills copies ``i*R .. i*R + R - 1`` meets every world once per sample, the same
worlds for every sample); ``Worlds.select(idx)`` picks copies. ``BatchedScene.set_worlds`` puts
them into a scene (reset offsets, friction, mass).
Used alike by the robust search (``ce.replicas``), the validation of a run's candidates and
``scripts/validate.py``: every plan they compare meets the same worlds (common random numbers).
What it doesn't: touch a simulator, or decide how many worlds a caller needs.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:
    from realize.tasks.perturbation import Perturbation
    from realize.world.objects import SceneObject

__all__ = ["Worlds", "draw_worlds", "SEARCH_STREAM", "VALIDATION_STREAM"]

# the generator streams of the two users of a seed (numpy SeedSequence entropy [seed, stream]):
# the robust search's worlds differ from the worlds its plans are validated in
SEARCH_STREAM = 1
VALIDATION_STREAM = 2


@dataclass(frozen=True)
class Worlds:
    """R worlds (or one per copy after ``tile``/``select``); arrays indexed [world, object]."""

    names: tuple[str, ...]
    robot_xy: np.ndarray  # (R, 2) m, added to the robot's start xy
    object_xy: np.ndarray  # (R, m, 2) m, added to each object's start xy
    object_yaw: np.ndarray  # (R, m) rad, added to each object's start yaw
    friction: np.ndarray  # (R, m) factor on each object's configured friction
    mass: np.ndarray  # (R, m) factor on each object's configured mass

    def __len__(self) -> int:
        return int(self.robot_xy.shape[0])

    def select(self, idx: Sequence[int] | np.ndarray) -> Worlds:
        """The worlds ``idx`` (one entry per copy)."""
        i = np.asarray(idx, dtype=np.int64)
        return Worlds(self.names, self.robot_xy[i], self.object_xy[i], self.object_yaw[i], self.friction[i],
                      self.mass[i])

    def tile(self, n: int, first: int = 0) -> Worlds:
        """Copies ``first .. first + n - 1`` of the layout in which copy ``k`` meets world ``k % R``."""
        return self.select((first + np.arange(n)) % len(self))

    @property
    def moves_start(self) -> bool:
        return bool(np.any(self.robot_xy) or np.any(self.object_xy) or np.any(self.object_yaw))

    @property
    def changes_friction(self) -> bool:
        return bool(np.any(self.friction != 1.0))

    @property
    def changes_mass(self) -> bool:
        return bool(np.any(self.mass != 1.0))

    def to_dict(self) -> dict[str, Any]:
        """Plain data (result files): per object name its offsets and factors per world."""
        return {"robot_xy": self.robot_xy.tolist(),
                "objects": {n: {"xy": self.object_xy[:, k].tolist(), "yaw": self.object_yaw[:, k].tolist(),
                                "friction": self.friction[:, k].tolist(), "mass": self.mass[:, k].tolist()}
                            for k, n in enumerate(self.names)}}


def draw_worlds(model: Perturbation, objects: Sequence[SceneObject], replicas: int, seed: int, *,
                stream: int = VALIDATION_STREAM, nominal_first: bool = False) -> Worlds:
    """``replicas`` worlds drawn from ``model`` for the scene objects ``objects`` (their order is
    the worlds' object axis), from ``numpy.random.default_rng([seed, stream])``: per world the
    robot offset, then per object its xy offset and yaw (objects on the floor: none), then the
    friction factors of every object, then the mass factors (a ``[1, 1]`` range draws nothing).
    ``nominal_first``: world 0 is the unperturbed world (the others are drawn as without it)."""
    from realize.world.objects import FLOOR

    if isinstance(replicas, bool) or not isinstance(replicas, int) or replicas < 1:
        raise ValueError(f"replicas = {replicas!r} must be an integer >= 1")
    rng = np.random.default_rng([int(seed), int(stream)])
    m = len(objects)
    moves = np.array([o.rests_on != FLOOR for o in objects], dtype=bool)
    robot = rng.uniform(-model.robot_xy, model.robot_xy, size=(replicas, 2)) if model.robot_xy > 0 \
        else np.zeros((replicas, 2))
    xy = rng.uniform(-model.object_xy, model.object_xy, size=(replicas, m, 2)) if model.object_xy > 0 \
        else np.zeros((replicas, m, 2))
    yaw = rng.uniform(-model.object_yaw, model.object_yaw, size=(replicas, m)) if model.object_yaw > 0 \
        else np.zeros((replicas, m))
    xy[:, ~moves] = 0.0
    yaw[:, ~moves] = 0.0
    factors = []
    for lo, hi in (model.friction, model.mass):
        factors.append(np.ones((replicas, m)) if lo == hi == 1.0 else rng.uniform(lo, hi, size=(replicas, m)))
    worlds = Worlds(tuple(o.name for o in objects), robot, xy, yaw, factors[0], factors[1])
    if nominal_first:
        for a in (worlds.robot_xy, worlds.object_xy, worlds.object_yaw):
            a[0] = 0.0
        worlds.friction[0] = 1.0
        worlds.mass[0] = 1.0
    return worlds
