"""Per-copy properties of the scene's movable objects, and the what-ifs tests and validation use.

What it does: ``ObjectProperties``, a part of ``realize.scene.BatchedScene``: each copy's
friction and mass of an object by name (scaled from its configured value by per-copy factors,
once per scene: validation's perturbations), the perturbed worlds of every copy
(``set_worlds``: reset offsets, friction and mass; robust search and validation), a push (one copy's object given a velocity: copies
are independent) and a teleport of every copy's object (where does an object dropped here end
up?). Each goes through the backend's ``PhysicsBackend`` contract.
What it doesn't: read or step the simulation (``BatchedScene``), or draw the factors
(``realize.tasks.perturbation``).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

import numpy as np
import torch

from realize.config import ConfigError
from realize.world.geometry import SceneGeometry

if TYPE_CHECKING:
    from realize.tasks.worlds import Worlds

__all__ = ["ObjectProperties"]


class ObjectProperties:
    """Object friction, mass, pushes and teleports of a ``BatchedScene`` (module docstring);
    uses its ``_impl`` (the backend), ``n_envs``, ``geometry``, ``object_index`` and
    ``state_changed``."""

    _impl: Any
    n_envs: int
    geometry: SceneGeometry

    _reset_offsets: dict[str, Any] | None = None  # BatchedScene.reset passes it to the task's reset

    def set_worlds(self, worlds: Worlds | None) -> None:
        """Give copy ``k`` the world ``worlds[k]`` (``realize.tasks.worlds``; one entry per copy,
        objects by name): from the next ``reset`` on, its start offsets (robot xy, each object's xy
        and yaw) replace the task's reset noise, and its friction and mass factors are set now
        (the simulator is left untouched where every factor is 1). ``None``: back to the task's
        own resets (friction and mass stay as set)."""
        if worlds is None:
            self._reset_offsets = None
            return
        if len(worlds) != self.n_envs:
            raise ConfigError(f"{len(worlds)} worlds for {self.n_envs} copies")
        if set(worlds.names) != set(self.geometry.object_names):
            raise ConfigError(f"worlds for objects {list(worlds.names)}, the scene has {list(self.geometry.object_names)}")
        k = {n: i for i, n in enumerate(worlds.names)}
        t = lambda a: torch.as_tensor(np.asarray(a), dtype=torch.float32)  # noqa: E731
        self._reset_offsets = {"robot_xy": t(worlds.robot_xy),
                               "object_xy": {n: t(worlds.object_xy[:, i]) for n, i in k.items()},
                               "object_yaw": {n: t(worlds.object_yaw[:, i]) for n, i in k.items()}}
        if worlds.changes_friction:
            for n, i in k.items():
                self.set_object_friction(n, worlds.friction[:, i])
        if worlds.changes_mass:
            for n, i in k.items():
                self.set_object_mass(n, worlds.mass[:, i])

    def object_index(self, name: str) -> int:  # pragma: no cover - BatchedScene's
        raise NotImplementedError

    def state_changed(self) -> None:  # pragma: no cover - BatchedScene's
        raise NotImplementedError

    def _factors(self, factors: torch.Tensor | np.ndarray | Sequence[float], what: str) -> torch.Tensor:
        f = torch.as_tensor(np.asarray(factors, dtype=np.float64)).reshape(-1)
        if len(f) != self.n_envs:
            raise ConfigError(f"{len(f)} {what} factors for {self.n_envs} copies")
        if not bool(torch.isfinite(f).all()) or bool((f <= 0).any()):
            raise ConfigError(f"{what} factors must be finite and > 0, got {f.tolist()}")
        return f

    def object_friction(self, name: str) -> torch.Tensor:
        """(N, 2) static and dynamic friction of object ``name`` in each copy (float64; CPU backend)."""
        return self._impl.object_friction(self.object_index(name))

    def set_object_friction(self, name: str, factors: torch.Tensor | np.ndarray | Sequence[float]) -> torch.Tensor:
        """Scale each copy's friction of object ``name`` (static and dynamic) by ``factors`` (N,)
        from its configured value; returns the (N,) friction now set (float64).

        PhysX combines the friction of two touching shapes by averaging (its default), so the
        friction of an object-finger or object-table contact moves by half the object's change.
        Set once per scene (a loop over the copies on CPU), not per step."""
        k = self.object_index(name)
        values = float(self.geometry.objects[k].friction) * self._factors(factors, "friction")
        self._impl.set_object_friction(k, values)
        return values

    def object_mass(self, name: str) -> torch.Tensor:
        """(N,) mass (kg) of object ``name`` in each copy (float64; CPU backend)."""
        return self._impl.object_mass(self.object_index(name))

    def set_object_mass(self, name: str, factors: torch.Tensor | np.ndarray | Sequence[float]) -> torch.Tensor:
        """Scale each copy's mass (and inertia) of object ``name`` by ``factors`` (N,) from its
        configured value; returns the (N,) masses now set (float64). Once per scene, not per step."""
        k = self.object_index(name)
        values = float(self.geometry.objects[k].mass) * self._factors(factors, "mass")
        self._impl.set_object_mass(k, values)
        return values

    def push_object(self, name: str, copy: int, velocity: tuple[float, float, float]) -> None:
        """Give one copy's object ``name`` a linear velocity (used to check that copies are independent)."""
        self._impl.push_object(self.object_index(name), copy, velocity)
        self.state_changed()

    def place_object(self, name: str, positions: torch.Tensor) -> None:
        """Teleport every copy's object ``name`` to ``positions`` (N, 3) in its copy's local frame,
        axis-aligned and at rest (tests and what-if checks: where does an object dropped here end up?)."""
        k = self.object_index(name)
        self._impl.place_object(k, torch.as_tensor(positions, dtype=torch.float32).reshape(self.n_envs, 3).cpu())
        self.state_changed()
