"""Parameter regions h(z) <= 0 of symbolic plan parameters (Section II of the paper).

A region is the set of values one symbolic parameter may take: an annulus of base positions
around a table, a hemisphere (cap) of grasp/place positions around an object, an axis-aligned
box (the exit rectangle) or a fixed value. Every region works batch-first on torch tensors:

* ``sample_uniform(n, generator)`` draws ``(n, dim)`` samples uniformly over the region
  (area-uniform for the annulus and the sphere cap), as iteration 0 of the cross-entropy search;
* ``contains(z, tol)`` tests ``(n, dim)`` rows, returning ``(n,)`` bool;
* ``project(z)`` maps arbitrary rows (e.g. Gaussian samples) to the nearest point of the region
  (Euclidean nearest point; the few ties/degenerate points are resolved by documented rules).

``ParamLayout`` lays named regions side by side as column slices of one sample matrix
``Z (N, D)``; ``region_from_dict`` / ``ParamLayout.from_dict`` build them from config mappings and
report errors as ``"<where>: ..."``.

This module knows nothing about plans, controllers or simulation. Hemisphere *orientations*
are derived from the sampled position (``Hemisphere.approach`` / ``Hemisphere.frames``), but what
a controller does with them is up to the controller.

Random draws happen on the generator's device in the requested dtype, so the same seed gives the
same numbers regardless of where the caller later moves them.
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from collections.abc import Mapping, Sequence
from typing import Any, ClassVar

import torch
from torch import Tensor

__all__ = [
    "Region",
    "Annulus",
    "Hemisphere",
    "Box",
    "Fixed",
    "ParamLayout",
    "region_from_dict",
    "REGION_TYPES",
]

DEFAULT_TOL = 1e-6


# --------------------------------------------------------------------------------------------
# validation helpers
# --------------------------------------------------------------------------------------------


def _as_floats(value: Any, field: str, length: int | None = None) -> tuple[float, ...]:
    """Turn a sequence (list, tuple, tensor, array) into a tuple of finite floats, or raise."""
    if isinstance(value, Tensor):
        value = value.detach().cpu().reshape(-1).tolist()
    elif hasattr(value, "tolist") and not isinstance(value, (str, bytes)):
        value = value.tolist()
    if isinstance(value, (int, float)) and not isinstance(value, bool):
        value = [value]
    if isinstance(value, (str, bytes)) or not isinstance(value, Sequence):
        raise ValueError(f"{field} must be a list of numbers, got {value!r}")
    try:
        out = tuple(float(v) for v in value)
    except (TypeError, ValueError):
        raise ValueError(f"{field} must be a list of numbers, got {value!r}") from None
    if length is not None and len(out) != length:
        raise ValueError(f"{field} must have {length} entries, got {len(out)}: {list(out)}")
    if len(out) == 0:
        raise ValueError(f"{field} must not be empty")
    if not all(math.isfinite(v) for v in out):
        raise ValueError(f"{field} must be finite (no NaN/inf), got {list(out)}")
    return out


def _as_float(value: Any, field: str) -> float:
    if isinstance(value, bool):
        raise ValueError(f"{field} must be a number, got {value!r}")
    if isinstance(value, Tensor):
        if value.numel() != 1:
            raise ValueError(f"{field} must be a single number, got shape {tuple(value.shape)}")
        value = value.item()
    try:
        out = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{field} must be a number, got {value!r}") from None
    if not math.isfinite(out):
        raise ValueError(f"{field} must be finite (no NaN/inf), got {out}")
    return out


def _check_batch(z: Tensor, dim: int, who: str) -> None:
    if not isinstance(z, Tensor):
        raise TypeError(f"{who}: expected a torch.Tensor of shape (n, {dim}), got {type(z).__name__}")
    if z.ndim != 2 or z.shape[1] != dim:
        raise ValueError(f"{who}: expected shape (n, {dim}), got {tuple(z.shape)}")


def _rand(n: int, k: int, generator: torch.Generator | None, dtype: torch.dtype | None) -> Tensor:
    """Uniform [0, 1) draws on the generator's device."""
    device = generator.device if generator is not None else torch.device("cpu")
    return torch.rand(n, k, generator=generator, device=device, dtype=dtype or torch.get_default_dtype())


def _wrap_angle(a: Tensor) -> Tensor:
    """Wrap angles to [-pi, pi)."""
    return torch.remainder(a + math.pi, 2.0 * math.pi) - math.pi


# --------------------------------------------------------------------------------------------
# regions
# --------------------------------------------------------------------------------------------


class Region(ABC):
    """One parameter region h(z) <= 0 in R^dim; all methods are batched over rows."""

    type_name: ClassVar[str] = ""

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


class Annulus(Region):
    """Planar annulus ``r_min <= ||p - center|| <= r_max`` of points p in R^2.

    ``r_min = 0`` gives a disc. Uniform sampling is area-uniform (radius ``sqrt`` of a uniform
    draw between ``r_min^2`` and ``r_max^2``). ``project`` clamps the radius, keeping the
    direction from the centre; the centre itself (direction undefined) goes to angle 0 (+x).
    """

    type_name = "annulus"

    def __init__(self, center: Sequence[float], r_min: float, r_max: float) -> None:
        self.center = _as_floats(center, "center", 2)
        self.r_min = _as_float(r_min, "r_min")
        self.r_max = _as_float(r_max, "r_max")
        if self.r_min < 0:
            raise ValueError(f"r_min must be >= 0, got {self.r_min}")
        if self.r_max <= 0:
            raise ValueError(f"r_max must be > 0, got {self.r_max}")
        if self.r_min > self.r_max:
            raise ValueError(f"r_min ({self.r_min}) must be <= r_max ({self.r_max})")

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
        u = _rand(n, 2, generator, dtype)
        r2 = self.r_min**2 + u[:, 0] * (self.r_max**2 - self.r_min**2)
        r = torch.sqrt(r2)
        phi = (2.0 * math.pi) * u[:, 1] - math.pi
        return self._c(u) + torch.stack([r * torch.cos(phi), r * torch.sin(phi)], dim=-1)

    def contains(self, z: Tensor, tol: float = DEFAULT_TOL) -> Tensor:
        _check_batch(z, 2, "Annulus.contains")
        r = torch.linalg.vector_norm(z - self._c(z), dim=-1)
        return (r >= self.r_min - tol) & (r <= self.r_max + tol)

    def project(self, z: Tensor) -> Tensor:
        _check_batch(z, 2, "Annulus.project")
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


class Hemisphere(Region):
    """Sphere-cap surface of approach positions around ``center``, optionally with a yaw.

    Parameterisation (``dim`` 3, or 4 with ``yaw``): columns ``(x, y, z)`` are the world position
    of the gripper on the sphere ``||p - center|| = radius``; the gripper points at the centre, so
    the approach direction ``a = (center - p) / radius`` is derived, not sampled. With
    ``yaw=True`` a 4th column is a rotation (rad) of the gripper about its approach axis.

    The cap is the polar band ``polar_min <= theta <= polar_max`` with ``theta`` the angle of
    ``p - center`` from world +z; the default ``[0, pi/2]`` is the upper hemisphere (approaches
    from above or from the side, never from below the support surface). Sampling is
    area-uniform on the cap (Archimedes: the height ``z - center_z`` is uniform on the cap's
    height range, the azimuth uniform). Yaw is uniform on ``[yaw_min, yaw_max]`` (default
    ``[-pi, pi)``, wrapped).

    ``project`` gives the nearest point of the cap surface: keep the azimuth of ``p - center``,
    clamp its polar angle into the band, put it at ``radius``. (That is exactly the nearest
    point, since within a polar band the great-circle distance is minimised at equal azimuth.)
    ``p == center`` goes to the point of the cap closest to the top (+z) at azimuth 0; a point on
    the z-axis keeps azimuth 0. Yaw is wrapped to ``[-pi, pi)`` when the range is the full circle,
    otherwise clamped to the circularly nearest end of the range.

    Orientation (``frames``): at the top (``a = -z``, a top-down grasp) the gripper frame is
    ``x = world x, y = -world y, z = a``; elsewhere it is that frame turned by the smallest
    rotation taking ``-z`` to ``a`` (smooth on everything but the bottom pole, so on the whole
    upper hemisphere), then rotated by ``yaw`` about ``a``.
    """

    type_name = "hemisphere"

    def __init__(
        self,
        center: Sequence[float],
        radius: float,
        polar_min: float = 0.0,
        polar_max: float = math.pi / 2,
        yaw: bool = False,
        yaw_min: float = -math.pi,
        yaw_max: float = math.pi,
    ) -> None:
        self.center = _as_floats(center, "center", 3)
        self.radius = _as_float(radius, "radius")
        if self.radius <= 0:
            raise ValueError(f"radius must be > 0, got {self.radius}")
        self.polar_min = _as_float(polar_min, "polar_min")
        self.polar_max = _as_float(polar_max, "polar_max")
        if not 0.0 <= self.polar_min <= math.pi:
            raise ValueError(f"polar_min must be in [0, pi], got {self.polar_min}")
        if not 0.0 <= self.polar_max <= math.pi:
            raise ValueError(f"polar_max must be in [0, pi], got {self.polar_max}")
        if self.polar_min > self.polar_max:
            raise ValueError(f"polar_min ({self.polar_min}) must be <= polar_max ({self.polar_max})")
        if not isinstance(yaw, bool):
            raise ValueError(f"yaw must be true or false, got {yaw!r}")
        self.yaw = yaw
        self.yaw_min = _as_float(yaw_min, "yaw_min")
        self.yaw_max = _as_float(yaw_max, "yaw_max")
        if self.yaw_min > self.yaw_max:
            raise ValueError(f"yaw_min ({self.yaw_min}) must be <= yaw_max ({self.yaw_max})")
        if self.yaw_max - self.yaw_min > 2.0 * math.pi + 1e-12:
            raise ValueError(f"yaw_max - yaw_min must be <= 2*pi, got {self.yaw_max - self.yaw_min}")
        self.full_yaw = self.yaw_max - self.yaw_min >= 2.0 * math.pi - 1e-12

    @property
    def dim(self) -> int:
        return 4 if self.yaw else 3

    @property
    def coord_names(self) -> tuple[str, ...]:
        return ("x", "y", "z", "yaw") if self.yaw else ("x", "y", "z")

    def _c(self, like: Tensor) -> Tensor:
        return torch.tensor(self.center, dtype=like.dtype, device=like.device)

    def sample_uniform(
        self, n: int, generator: torch.Generator | None = None, dtype: torch.dtype | None = None
    ) -> Tensor:
        u = _rand(n, 3 if self.yaw else 2, generator, dtype)
        cos_hi, cos_lo = math.cos(self.polar_min), math.cos(self.polar_max)
        cos_t = cos_lo + u[:, 0] * (cos_hi - cos_lo)
        sin_t = torch.sqrt((1.0 - cos_t * cos_t).clamp_min(0.0))
        phi = (2.0 * math.pi) * u[:, 1] - math.pi
        d = torch.stack([sin_t * torch.cos(phi), sin_t * torch.sin(phi), cos_t], dim=-1)
        p = self._c(u) + self.radius * d
        if not self.yaw:
            return p
        yaw = self.yaw_min + u[:, 2] * (self.yaw_max - self.yaw_min)
        if self.full_yaw:
            yaw = _wrap_angle(yaw)
        return torch.cat([p, yaw[:, None]], dim=-1)

    def _polar(self, d: Tensor) -> Tensor:
        return torch.atan2(torch.linalg.vector_norm(d[:, :2], dim=-1), d[:, 2])

    def contains(self, z: Tensor, tol: float = DEFAULT_TOL) -> Tensor:
        """On the sphere within ``tol`` (m), polar angle within ``tol / radius`` (rad), yaw in range."""
        _check_batch(z, self.dim, "Hemisphere.contains")
        d = z[:, :3] - self._c(z)
        r = torch.linalg.vector_norm(d, dim=-1)
        theta = self._polar(d)
        ang_tol = tol / self.radius
        ok = ((r - self.radius).abs() <= tol) & (theta >= self.polar_min - ang_tol) & (theta <= self.polar_max + ang_tol)
        if self.yaw and not self.full_yaw:
            y = z[:, 3]
            ok = ok & (y >= self.yaw_min - tol) & (y <= self.yaw_max + tol)
        elif self.yaw:
            ok = ok & (z[:, 3] >= -math.pi - tol) & (z[:, 3] <= math.pi + tol)
        return ok

    def project(self, z: Tensor) -> Tensor:
        _check_batch(z, self.dim, "Hemisphere.project")
        c = self._c(z)
        d = z[:, :3] - c
        rho = torch.linalg.vector_norm(d[:, :2], dim=-1)
        # p == center: atan2(0, 0) = 0 -> the top of the sphere, clamped into the band below
        theta = torch.atan2(rho, d[:, 2]).clamp(self.polar_min, self.polar_max)
        phi = torch.atan2(d[:, 1], d[:, 0])  # 0 on the z-axis (atan2(0, 0) = 0)
        st = torch.sin(theta)
        p = c + self.radius * torch.stack([st * torch.cos(phi), st * torch.sin(phi), torch.cos(theta)], dim=-1)
        if not self.yaw:
            return p
        return torch.cat([p, self._project_yaw(z[:, 3])[:, None]], dim=-1)

    def _project_yaw(self, y: Tensor) -> Tensor:
        if self.full_yaw:
            inside = (y >= -math.pi) & (y < math.pi)
            return torch.where(inside, y, _wrap_angle(y))
        mid = 0.5 * (self.yaw_min + self.yaw_max)
        rel = _wrap_angle(y - mid)  # circular offset from the middle of the range
        half = 0.5 * (self.yaw_max - self.yaw_min)
        out = mid + rel.clamp(-half, half)
        inside = (y >= self.yaw_min) & (y <= self.yaw_max)
        return torch.where(inside, y, out)

    def approach(self, z: Tensor) -> Tensor:
        """``(n, 3)`` unit approach directions, from each sampled position towards the centre."""
        _check_batch(z, self.dim, "Hemisphere.approach")
        d = self._c(z) - z[:, :3]
        return d / torch.linalg.vector_norm(d, dim=-1, keepdim=True).clamp_min(1e-12)

    def frames(self, z: Tensor) -> Tensor:
        """``(n, 3, 3)`` gripper rotation matrices (columns = gripper x, y, z axes in world).

        The z column is the approach direction; see the class docstring for x and y.
        """
        a = self.approach(z)
        down = torch.tensor([0.0, 0.0, -1.0], dtype=z.dtype, device=z.device).expand_as(a)
        v = torch.linalg.cross(down, a)
        cth = (down * a).sum(-1)
        zero = torch.zeros_like(cth)
        vx = torch.stack(
            [
                torch.stack([zero, -v[:, 2], v[:, 1]], -1),
                torch.stack([v[:, 2], zero, -v[:, 0]], -1),
                torch.stack([-v[:, 1], v[:, 0], zero], -1),
            ],
            dim=-2,
        )
        eye = torch.eye(3, dtype=z.dtype, device=z.device).expand(a.shape[0], 3, 3)
        r_min = eye + vx + (vx @ vx) / (1.0 + cth).clamp_min(1e-12)[:, None, None]
        r0 = torch.diag(torch.tensor([1.0, -1.0, -1.0], dtype=z.dtype, device=z.device))
        r = r_min @ r0
        if self.yaw:
            cy, sy = torch.cos(z[:, 3]), torch.sin(z[:, 3])
            one = torch.ones_like(cy)
            zero = torch.zeros_like(cy)
            rz = torch.stack(
                [torch.stack([cy, -sy, zero], -1), torch.stack([sy, cy, zero], -1), torch.stack([zero, zero, one], -1)],
                dim=-2,
            )
            r = r @ rz
        return r

    def bounds(self) -> tuple[Tensor, Tensor]:
        c = torch.tensor(self.center, dtype=torch.float64)
        r = self.radius
        # horizontal extent: max sin(theta) over the band; vertical: cos range
        s_max = 1.0 if self.polar_min <= math.pi / 2 <= self.polar_max else max(
            math.sin(self.polar_min), math.sin(self.polar_max)
        )
        low = torch.tensor([c[0] - r * s_max, c[1] - r * s_max, c[2] + r * math.cos(self.polar_max)], dtype=torch.float64)
        high = torch.tensor([c[0] + r * s_max, c[1] + r * s_max, c[2] + r * math.cos(self.polar_min)], dtype=torch.float64)
        if self.yaw:
            ylo, yhi = (-math.pi, math.pi) if self.full_yaw else (self.yaw_min, self.yaw_max)
            low = torch.cat([low, torch.tensor([ylo], dtype=torch.float64)])
            high = torch.cat([high, torch.tensor([yhi], dtype=torch.float64)])
        return low, high

    def to_dict(self) -> dict[str, Any]:
        d: dict[str, Any] = {
            "type": self.type_name,
            "center": list(self.center),
            "radius": self.radius,
            "polar_min": self.polar_min,
            "polar_max": self.polar_max,
            "yaw": self.yaw,
        }
        if self.yaw:
            d["yaw_min"] = self.yaw_min
            d["yaw_max"] = self.yaw_max
        return d


class Box(Region):
    """Axis-aligned box ``low <= z <= high`` in R^d (e.g. the exit rectangle).

    Uniform sampling per coordinate; ``project`` clamps each coordinate (the Euclidean nearest
    point of a box).
    """

    type_name = "box"

    def __init__(self, low: Sequence[float], high: Sequence[float]) -> None:
        self.low = _as_floats(low, "low")
        self.high = _as_floats(high, "high", len(self.low))
        bad = [i for i, (lo, hi) in enumerate(zip(self.low, self.high)) if not lo < hi]
        if bad:
            raise ValueError(
                f"low must be < high in every coordinate (empty box); violated at index {bad}: "
                f"low={list(self.low)}, high={list(self.high)}"
            )

    @property
    def dim(self) -> int:
        return len(self.low)

    @property
    def coord_names(self) -> tuple[str, ...]:
        return ("x", "y", "z")[: self.dim] if self.dim <= 3 else tuple(f"z{i}" for i in range(self.dim))

    def _lh(self, like: Tensor) -> tuple[Tensor, Tensor]:
        return (
            torch.tensor(self.low, dtype=like.dtype, device=like.device),
            torch.tensor(self.high, dtype=like.dtype, device=like.device),
        )

    def sample_uniform(
        self, n: int, generator: torch.Generator | None = None, dtype: torch.dtype | None = None
    ) -> Tensor:
        u = _rand(n, self.dim, generator, dtype)
        lo, hi = self._lh(u)
        return lo + u * (hi - lo)

    def contains(self, z: Tensor, tol: float = DEFAULT_TOL) -> Tensor:
        _check_batch(z, self.dim, "Box.contains")
        lo, hi = self._lh(z)
        return ((z >= lo - tol) & (z <= hi + tol)).all(dim=-1)

    def project(self, z: Tensor) -> Tensor:
        _check_batch(z, self.dim, "Box.project")
        lo, hi = self._lh(z)
        return torch.maximum(torch.minimum(z, hi), lo)

    def bounds(self) -> tuple[Tensor, Tensor]:
        return torch.tensor(self.low, dtype=torch.float64), torch.tensor(self.high, dtype=torch.float64)

    def to_dict(self) -> dict[str, Any]:
        return {"type": self.type_name, "low": list(self.low), "high": list(self.high)}


class Fixed(Region):
    """A single point: the parameter is not optimised (its CE std stays at the floor, and
    ``project`` puts it back on the value)."""

    type_name = "fixed"

    def __init__(self, value: Sequence[float] | float) -> None:
        self.value = _as_floats(value, "value")

    @property
    def dim(self) -> int:
        return len(self.value)

    @property
    def coord_names(self) -> tuple[str, ...]:
        return ("x", "y", "z")[: self.dim] if self.dim <= 3 else tuple(f"z{i}" for i in range(self.dim))

    def _v(self, like: Tensor) -> Tensor:
        return torch.tensor(self.value, dtype=like.dtype, device=like.device)

    def sample_uniform(
        self, n: int, generator: torch.Generator | None = None, dtype: torch.dtype | None = None
    ) -> Tensor:
        device = generator.device if generator is not None else torch.device("cpu")
        v = torch.tensor(self.value, dtype=dtype or torch.get_default_dtype(), device=device)
        return v.expand(n, self.dim).clone()

    def contains(self, z: Tensor, tol: float = DEFAULT_TOL) -> Tensor:
        _check_batch(z, self.dim, "Fixed.contains")
        return ((z - self._v(z)).abs() <= tol).all(dim=-1)

    def project(self, z: Tensor) -> Tensor:
        _check_batch(z, self.dim, "Fixed.project")
        return self._v(z).expand_as(z).clone()

    def bounds(self) -> tuple[Tensor, Tensor]:
        v = torch.tensor(self.value, dtype=torch.float64)
        return v, v.clone()

    def to_dict(self) -> dict[str, Any]:
        return {"type": self.type_name, "value": list(self.value)}


REGION_TYPES: dict[str, type[Region]] = {cls.type_name: cls for cls in (Annulus, Hemisphere, Box, Fixed)}

_REQUIRED: dict[str, tuple[str, ...]] = {
    "annulus": ("center", "r_min", "r_max"),
    "hemisphere": ("center", "radius"),
    "box": ("low", "high"),
    "fixed": ("value",),
}
_OPTIONAL: dict[str, tuple[str, ...]] = {
    "annulus": (),
    "hemisphere": ("polar_min", "polar_max", "yaw", "yaw_min", "yaw_max"),
    "box": (),
    "fixed": (),
}


def region_from_dict(d: Mapping[str, Any], where: str = "region") -> Region:
    """Build a region from a config mapping such as
    ``{type: annulus, center: [x, y], r_min: 0.6, r_max: 1.0}``.

    Every error is a ``ValueError`` starting with ``"<where>: "`` and naming the offending key
    (unknown type, missing or unknown key, bad value).
    """
    if not isinstance(d, Mapping):
        raise ValueError(f"{where}: a region must be a mapping with a 'type' key, got {d!r}")
    allowed = ", ".join(sorted(REGION_TYPES))
    if "type" not in d:
        raise ValueError(f"{where}: missing key 'type' (one of: {allowed})")
    kind = str(d["type"]).lower()
    if kind not in REGION_TYPES:
        raise ValueError(f"{where}: unknown region type {d['type']!r} in key 'type' (allowed: {allowed})")
    keys = {str(k) for k in d if k != "type"}
    required, optional = _REQUIRED[kind], _OPTIONAL[kind]
    missing = [k for k in required if k not in keys]
    if missing:
        raise ValueError(f"{where}: {kind} region is missing key(s) {missing} (needs {list(required)})")
    unknown = sorted(keys - set(required) - set(optional))
    if unknown:
        raise ValueError(
            f"{where}: unknown key(s) {unknown} for a {kind} region (allowed: {list(required) + list(optional)})"
        )
    kwargs = {k: d[k] for k in keys}
    try:
        return REGION_TYPES[kind](**kwargs)
    except ValueError as e:
        raise ValueError(f"{where}: {e}") from None


# --------------------------------------------------------------------------------------------
# layout
# --------------------------------------------------------------------------------------------


class ParamLayout:
    """Named parameters (ordered name -> region) laid out as column slices of ``Z (N, D)``.

    Column order follows the insertion order of the mapping; each parameter owns the
    contiguous slice ``slices[name]``.
    """

    def __init__(self, regions: Mapping[str, Region]) -> None:
        if not isinstance(regions, Mapping) or len(regions) == 0:
            raise ValueError("ParamLayout needs at least one named region")
        self.regions: dict[str, Region] = {}
        self.slices: dict[str, slice] = {}
        start = 0
        for name, reg in regions.items():
            if not isinstance(name, str) or not name:
                raise ValueError(f"parameter names must be non-empty strings, got {name!r}")
            if not isinstance(reg, Region):
                raise ValueError(f"{name}: expected a Region, got {type(reg).__name__}")
            self.regions[name] = reg
            self.slices[name] = slice(start, start + reg.dim)
            start += reg.dim
        self._dim = start

    @classmethod
    def from_dict(cls, d: Mapping[str, Mapping[str, Any]], where: str = "params") -> ParamLayout:
        """Build from ``{name: {type: ..., ...}, ...}``; errors read ``"<where>.<name>: ..."``."""
        if not isinstance(d, Mapping) or len(d) == 0:
            raise ValueError(f"{where}: expected a non-empty mapping of parameter name -> region")
        return cls({str(k): region_from_dict(v, f"{where}.{k}") for k, v in d.items()})

    def to_dict(self) -> dict[str, dict[str, Any]]:
        return {k: r.to_dict() for k, r in self.regions.items()}

    @property
    def names(self) -> list[str]:
        return list(self.regions)

    @property
    def dim(self) -> int:
        return self._dim

    @property
    def column_names(self) -> list[str]:
        """``"<param>.<coord>"`` per column of Z, e.g. ``["Table1.x", "Table1.y", ...]``."""
        return [f"{n}.{c}" for n, r in self.regions.items() for c in r.coord_names]

    def _check(self, Z: Tensor, who: str) -> None:
        _check_batch(Z, self._dim, f"ParamLayout.{who}")

    def sample_uniform(
        self, n: int, generator: torch.Generator | None = None, dtype: torch.dtype | None = None
    ) -> Tensor:
        """``(n, D)``: each parameter uniform over its region, independently, in name order."""
        return torch.cat([r.sample_uniform(n, generator, dtype) for r in self.regions.values()], dim=-1)

    def project(self, Z: Tensor) -> Tensor:
        self._check(Z, "project")
        return torch.cat([r.project(Z[:, self.slices[n]]) for n, r in self.regions.items()], dim=-1)

    def contains(self, Z: Tensor, tol: float = DEFAULT_TOL) -> Tensor:
        """``(N,)`` bool: every parameter of the row lies in its region."""
        self._check(Z, "contains")
        ok = torch.ones(Z.shape[0], dtype=torch.bool, device=Z.device)
        for n, r in self.regions.items():
            ok = ok & r.contains(Z[:, self.slices[n]], tol)
        return ok

    def split(self, Z: Tensor) -> dict[str, Tensor]:
        """``{name: Z[:, slice] (N, dim)}`` (views, not copies)."""
        self._check(Z, "split")
        return {n: Z[:, s] for n, s in self.slices.items()}

    def join(self, parts: Mapping[str, Tensor]) -> Tensor:
        """Inverse of ``split``: concatenate ``{name: (N, dim)}`` in layout order."""
        missing = [n for n in self.regions if n not in parts]
        if missing:
            raise ValueError(f"ParamLayout.join: missing parameter(s) {missing}")
        return torch.cat([parts[n] for n in self.regions], dim=-1)

    def bounds(self) -> tuple[Tensor, Tensor]:
        """``(low (D,), high (D,))`` float64 bounding box of all regions."""
        lows, highs = zip(*(r.bounds() for r in self.regions.values()))
        return torch.cat(lows), torch.cat(highs)

    def __len__(self) -> int:
        return len(self.regions)

    def __repr__(self) -> str:
        return f"ParamLayout({', '.join(f'{n}={r!r}' for n, r in self.regions.items())})"
