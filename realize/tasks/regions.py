"""Parameter regions h(z) <= 0 of symbolic plan parameters (Section II of the paper): the base
class and the flat regions.

A region is the set of values one symbolic parameter may take. This module holds the
:class:`Region` interface and the regions without orientation: an annulus of base positions
around a table (:class:`Annulus`), an axis-aligned box such as the exit rectangle (:class:`Box`)
and a fixed value (:class:`Fixed`); the hemisphere of grasp positions is ``realize.tasks.hemisphere``.
Every region works batch-first on torch tensors:

* ``sample_uniform(n, generator)`` draws ``(n, dim)`` samples uniformly over the region
  (area-uniform for the annulus and the sphere cap), as iteration 0 of the cross-entropy search;
* ``contains(z, tol)`` tests ``(n, dim)`` rows, returning ``(n,)`` bool;
* ``project(z)`` maps arbitrary rows (e.g. Gaussian samples) to the nearest point of the region
  (Euclidean nearest point; the few ties/degenerate points are resolved by documented rules).

Each region is also a ``realize.config.Settings`` dataclass: its fields are its config keys,
checked when it is built (directly or with ``from_mapping``); a bad value raises
``realize.config.ConfigError`` naming the field (``<where>.r_min = -0.1 is invalid: ...``).

What it doesn't: lay regions out as columns of a sample matrix or pick a region type from a
config mapping (``realize.tasks.param_layout``), or know about plans, controllers or simulation.

Random draws happen on the generator's device in the requested dtype, so the same seed gives the
same numbers regardless of where the caller later moves them.
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from collections.abc import Mapping
from dataclasses import dataclass, fields
from typing import Any, ClassVar

import torch
from torch import Tensor

from realize.config import ConfigError, Settings, setting

__all__ = ["Region", "Annulus", "Box", "Fixed", "DEFAULT_TOL", "check_batch", "uniform_draws", "wrap_angle"]

DEFAULT_TOL = 1e-6


def check_batch(z: Tensor, dim: int, who: str) -> None:
    """Refuse anything but an ``(n, dim)`` tensor (``who`` names the caller in the message)."""
    if not isinstance(z, Tensor):
        raise TypeError(f"{who}: expected a torch.Tensor of shape (n, {dim}), got {type(z).__name__}")
    if z.ndim != 2 or z.shape[1] != dim:
        raise ValueError(f"{who}: expected shape (n, {dim}), got {tuple(z.shape)}")


def uniform_draws(n: int, k: int, generator: torch.Generator | None, dtype: torch.dtype | None) -> Tensor:
    """Uniform [0, 1) draws on the generator's device."""
    device = generator.device if generator is not None else torch.device("cpu")
    return torch.rand(n, k, generator=generator, device=device, dtype=dtype or torch.get_default_dtype())


def wrap_angle(a: Tensor) -> Tensor:
    """Wrap angles to [-pi, pi)."""
    return torch.remainder(a + math.pi, 2.0 * math.pi) - math.pi


def _point_coord_names(dim: int) -> tuple[str, ...]:
    """x, y, z for points of up to 3 columns, else z0, z1, ..."""
    return ("x", "y", "z")[:dim] if dim <= 3 else tuple(f"z{i}" for i in range(dim))


class Region(ABC):
    """One parameter region h(z) <= 0 in R^dim; all methods are batched over rows."""

    type_name: ClassVar[str] = ""

    def __post_init__(self) -> None:
        """Validate (``Settings``), then store numbers as floats and lists as float tuples, as
        ``from_mapping`` does, so that equal regions compare, hash and compute alike."""
        super().__post_init__()  # type: ignore[misc]
        for f in fields(self):  # type: ignore[arg-type]
            v = getattr(self, f.name)
            if isinstance(v, (list, tuple)):
                setattr(self, f.name, tuple(float(x) for x in v))
            elif isinstance(v, int) and not isinstance(v, bool):
                setattr(self, f.name, float(v))

    @property
    @abstractmethod
    def dim(self) -> int:
        """Number of columns this parameter takes in Z."""

    @property
    @abstractmethod
    def coord_names(self) -> tuple[str, ...]:
        """A short name per column (e.g. ``("x", "y")``), for logs and plots."""

    @abstractmethod
    def sample_uniform(
        self, n: int, generator: torch.Generator | None = None, dtype: torch.dtype | None = None
    ) -> Tensor:
        """``(n, dim)`` samples drawn uniformly over the region (on the generator's device)."""

    @abstractmethod
    def contains(self, z: Tensor, tol: float = DEFAULT_TOL) -> Tensor:
        """``(n,)`` bool: whether each row lies in the region, up to ``tol`` (in its units)."""

    @abstractmethod
    def project(self, z: Tensor) -> Tensor:
        """``(n, dim)``: each row mapped to the nearest point of the region (rows inside stay)."""

    @abstractmethod
    def bounds(self) -> tuple[Tensor, Tensor]:
        """An axis-aligned bounding box ``(low (dim,), high (dim,))`` of the region (float64)."""

    @abstractmethod
    def to_dict(self) -> dict[str, Any]:
        """Config mapping that ``region_from_dict`` turns back into an equal region."""

    def __repr__(self) -> str:
        args = ", ".join(f"{k}={v}" for k, v in self.to_dict().items() if k != "type")
        return f"{type(self).__name__}({args})"

    def __eq__(self, other: object) -> bool:
        return isinstance(other, Region) and self.to_dict() == other.to_dict()

    def __hash__(self) -> int:
        return hash(repr(self))


@dataclass(eq=False, repr=False)
class Annulus(Region, Settings):
    """Planar annulus ``r_min <= ||p - center|| <= r_max`` of points p in R^2.

    ``r_min = 0`` gives a disc. Uniform sampling is area-uniform (radius ``sqrt`` of a uniform
    draw between ``r_min^2`` and ``r_max^2``). ``project`` clamps the radius, keeping the
    direction from the centre; the centre itself (direction undefined) goes to angle 0 (+x).
    """

    type_name: ClassVar[str] = "annulus"
    config_key: ClassVar[str] = "annulus"

    center: tuple[float, float]
    r_min: float = setting(ge=0, help="inner radius (m)")
    r_max: float = setting(gt=0, help="outer radius (m)")

    def check(self, where: str) -> None:
        if self.r_min > self.r_max:
            raise ConfigError(f"{where}.r_min = {self.r_min} is invalid: must be <= r_max ({self.r_max})")

    @property
    def dim(self) -> int:
        return 2

    @property
    def coord_names(self) -> tuple[str, ...]:
        return ("x", "y")

    def _c(self, like: Tensor) -> Tensor:
        return torch.tensor(self.center, dtype=like.dtype, device=like.device)

    def sample_uniform(
        self, n: int, generator: torch.Generator | None = None, dtype: torch.dtype | None = None
    ) -> Tensor:
        u = uniform_draws(n, 2, generator, dtype)
        r2 = self.r_min**2 + u[:, 0] * (self.r_max**2 - self.r_min**2)
        r = torch.sqrt(r2)
        phi = (2.0 * math.pi) * u[:, 1] - math.pi
        return self._c(u) + torch.stack([r * torch.cos(phi), r * torch.sin(phi)], dim=-1)

    def contains(self, z: Tensor, tol: float = DEFAULT_TOL) -> Tensor:
        check_batch(z, 2, "Annulus.contains")
        r = torch.linalg.vector_norm(z - self._c(z), dim=-1)
        return (r >= self.r_min - tol) & (r <= self.r_max + tol)

    def project(self, z: Tensor) -> Tensor:
        check_batch(z, 2, "Annulus.project")
        c = self._c(z)
        d = z - c
        r = torch.linalg.vector_norm(d, dim=-1, keepdim=True)
        at_center = r <= 0
        unit = torch.where(at_center, torch.tensor([1.0, 0.0], dtype=z.dtype, device=z.device), d / r.clamp_min(1e-300))
        r_new = r.clamp(self.r_min, self.r_max)
        inside = (r >= self.r_min) & (r <= self.r_max)
        return torch.where(inside, z, c + unit * r_new)

    def bounds(self) -> tuple[Tensor, Tensor]:
        c = torch.tensor(self.center, dtype=torch.float64)
        return c - self.r_max, c + self.r_max

    def to_dict(self) -> dict[str, Any]:
        return {"type": self.type_name, "center": list(self.center), "r_min": self.r_min, "r_max": self.r_max}


@dataclass(eq=False, repr=False)
class Box(Region, Settings):
    """Axis-aligned box ``low <= z <= high`` in R^d (e.g. the exit rectangle).

    Uniform sampling per coordinate; ``project`` clamps each coordinate (the Euclidean nearest
    point of a box).
    """

    type_name: ClassVar[str] = "box"
    config_key: ClassVar[str] = "box"

    low: tuple[float, ...]
    high: tuple[float, ...]

    def check(self, where: str) -> None:
        if not self.low:
            raise ConfigError(f"{where}.low = [] is invalid: must not be empty")
        if len(self.high) != len(self.low):
            raise ConfigError(f"{where}.high = {list(self.high)} is invalid: must have {len(self.low)} entries, "
                              f"as low = {list(self.low)}")
        bad = [i for i, (lo, hi) in enumerate(zip(self.low, self.high)) if not lo < hi]
        if bad:
            raise ConfigError(
                f"{where}: low must be < high in every coordinate (empty box); violated at index {bad}: "
                f"low={list(self.low)}, high={list(self.high)}"
            )

    @property
    def dim(self) -> int:
        return len(self.low)

    @property
    def coord_names(self) -> tuple[str, ...]:
        return _point_coord_names(self.dim)

    def _lh(self, like: Tensor) -> tuple[Tensor, Tensor]:
        return (
            torch.tensor(self.low, dtype=like.dtype, device=like.device),
            torch.tensor(self.high, dtype=like.dtype, device=like.device),
        )

    def sample_uniform(
        self, n: int, generator: torch.Generator | None = None, dtype: torch.dtype | None = None
    ) -> Tensor:
        u = uniform_draws(n, self.dim, generator, dtype)
        lo, hi = self._lh(u)
        return lo + u * (hi - lo)

    def contains(self, z: Tensor, tol: float = DEFAULT_TOL) -> Tensor:
        check_batch(z, self.dim, "Box.contains")
        lo, hi = self._lh(z)
        return ((z >= lo - tol) & (z <= hi + tol)).all(dim=-1)

    def project(self, z: Tensor) -> Tensor:
        check_batch(z, self.dim, "Box.project")
        lo, hi = self._lh(z)
        return torch.maximum(torch.minimum(z, hi), lo)

    def bounds(self) -> tuple[Tensor, Tensor]:
        return torch.tensor(self.low, dtype=torch.float64), torch.tensor(self.high, dtype=torch.float64)

    def to_dict(self) -> dict[str, Any]:
        return {"type": self.type_name, "low": list(self.low), "high": list(self.high)}


@dataclass(eq=False, repr=False)
class Fixed(Region, Settings):
    """A single point: the parameter is not optimised (its CE std stays at the floor, and
    ``project`` puts it back on the value)."""

    type_name: ClassVar[str] = "fixed"
    config_key: ClassVar[str] = "fixed"

    value: tuple[float, ...]

    def __post_init__(self) -> None:
        if isinstance(self.value, (int, float)) and not isinstance(self.value, bool):
            self.value = (self.value,)  # a scalar is a 1-D point
        super().__post_init__()

    def check(self, where: str) -> None:
        if not self.value:
            raise ConfigError(f"{where}.value = [] is invalid: must not be empty")

    @classmethod
    def from_mapping(cls, d: Any, where: str | None = None) -> Fixed:
        """As ``Settings.from_mapping``; a scalar ``value`` is a 1-D point."""
        if isinstance(d, Mapping) and isinstance(d.get("value"), (int, float)) and not isinstance(d["value"], bool):
            d = {**d, "value": [d["value"]]}
        return super().from_mapping(d, where)

    @property
    def dim(self) -> int:
        return len(self.value)

    @property
    def coord_names(self) -> tuple[str, ...]:
        return _point_coord_names(self.dim)

    def _v(self, like: Tensor) -> Tensor:
        return torch.tensor(self.value, dtype=like.dtype, device=like.device)

    def sample_uniform(
        self, n: int, generator: torch.Generator | None = None, dtype: torch.dtype | None = None
    ) -> Tensor:
        device = generator.device if generator is not None else torch.device("cpu")
        v = torch.tensor(self.value, dtype=dtype or torch.get_default_dtype(), device=device)
        return v.expand(n, self.dim).clone()

    def contains(self, z: Tensor, tol: float = DEFAULT_TOL) -> Tensor:
        check_batch(z, self.dim, "Fixed.contains")
        return ((z - self._v(z)).abs() <= tol).all(dim=-1)

    def project(self, z: Tensor) -> Tensor:
        check_batch(z, self.dim, "Fixed.project")
        return self._v(z).expand_as(z).clone()

    def bounds(self) -> tuple[Tensor, Tensor]:
        v = torch.tensor(self.value, dtype=torch.float64)
        return v, v.clone()

    def to_dict(self) -> dict[str, Any]:
        return {"type": self.type_name, "value": list(self.value)}
