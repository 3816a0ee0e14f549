"""The hemisphere (sphere-cap) region of grasp / place positions, with the gripper orientation
it implies.

What it does: :class:`Hemisphere` is a ``realize.tasks.regions.Region`` (sampling area-uniform on the
cap, ``contains``, nearest-point ``project``, bounds) whose points are gripper positions on a
sphere cap around an object, optionally with a yaw column; ``approach`` and ``frames`` derive the
approach direction and the gripper rotation from a sampled row. Like the other regions it is a
``realize.config.Settings`` dataclass whose bad fields raise ``realize.config.ConfigError``.

What it doesn't: decide what a controller does with the orientation, or parse a region's
``type`` from a config mapping (``realize.tasks.param_layout``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, ClassVar

import torch
from torch import Tensor

from realize.config import ConfigError, Settings, setting
from realize.tasks.regions import DEFAULT_TOL, Region, check_batch, uniform_draws, wrap_angle

__all__ = ["Hemisphere"]


@dataclass(eq=False, repr=False)
class Hemisphere(Region, Settings):
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

    With ``azimuth`` (rad) and ``azimuth_half_width`` < pi, the cap is also limited to the
    azimuth band ``|phi - azimuth| <= azimuth_half_width`` (``phi`` of ``p - center``), sampled
    uniformly in it; ``facing: robot`` centres that band on the robot's start when the task is
    placed in its scene (``realize.tasks.spec``): the approach of a 5-joint arm, which tilts only
    in the vertical plane through its base.

    ``project`` gives the nearest point of the cap surface: keep the azimuth of ``p - center``
    (with an azimuth band: clamped into it), clamp its polar angle into the band, put it at ``radius``. (That is exactly the nearest
    point, since within a polar band the great-circle distance is minimised at equal azimuth.)
    ``p == center`` goes to the point of the cap closest to the top (+z) at azimuth 0; a point on
    the z-axis keeps azimuth 0. Yaw is wrapped to ``[-pi, pi)`` when the range is the full circle,
    otherwise clamped to the circularly nearest end of the range.

    Orientation (``frames``): at the top (``a = -z``, a top-down grasp) the gripper frame is
    ``x = world x, y = -world y, z = a``; elsewhere it is that frame turned by the smallest
    rotation taking ``-z`` to ``a`` (smooth on everything but the bottom pole, so on the whole
    upper hemisphere), then rotated by ``yaw`` about ``a``.
    """

    type_name: ClassVar[str] = "hemisphere"
    config_key: ClassVar[str] = "hemisphere"

    center: tuple[float, float, float]
    radius: float = setting(gt=0, help="sphere radius (m)")
    polar_min: float = setting(0.0, ge=0, le=math.pi, help="polar band, angle from +z (rad)")
    polar_max: float = setting(math.pi / 2, ge=0, le=math.pi)
    yaw: bool = False
    yaw_min: float = -math.pi
    yaw_max: float = math.pi
    # an azimuth band: p - center's azimuth within azimuth +- azimuth_half_width (rad, world frame);
    # None: all around. facing: robot sets azimuth toward the robot's start (a fixed-base arm's
    # base) when the task is placed in its scene: the pre-poses between the base and the centre,
    # the approach pointing away from the base (a 5-joint arm tilts only in that vertical plane)
    azimuth: float | None = None
    azimuth_half_width: float = setting(math.pi, gt=0, le=math.pi)
    facing: str | None = setting(None, choices=("robot",))

    def check(self, where: str) -> None:
        if self.polar_min > self.polar_max:
            raise ConfigError(f"{where}.polar_min = {self.polar_min} is invalid: must be <= polar_max ({self.polar_max})")
        if self.yaw_min > self.yaw_max:
            raise ConfigError(f"{where}.yaw_min = {self.yaw_min} is invalid: must be <= yaw_max ({self.yaw_max})")
        if self.yaw_max - self.yaw_min > 2.0 * math.pi + 1e-12:
            raise ConfigError(f"{where}.yaw_max = {self.yaw_max} is invalid: yaw_max - yaw_min must be <= 2*pi, "
                              f"got {self.yaw_max - self.yaw_min}")

    @property
    def banded(self) -> bool:
        """Whether the azimuth is limited to a band (``azimuth`` set, narrower than the circle)."""
        return self.azimuth is not None and self.azimuth_half_width < math.pi

    @property
    def full_yaw(self) -> bool:
        """Whether the yaw range is the full circle (then yaw is wrapped, not clamped)."""
        return self.yaw_max - self.yaw_min >= 2.0 * math.pi - 1e-12

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
        u = uniform_draws(n, 3 if self.yaw else 2, generator, dtype)
        cos_hi, cos_lo = math.cos(self.polar_min), math.cos(self.polar_max)
        cos_t = cos_lo + u[:, 0] * (cos_hi - cos_lo)
        sin_t = torch.sqrt((1.0 - cos_t * cos_t).clamp_min(0.0))
        if self.banded:
            phi = self.azimuth + self.azimuth_half_width * (2.0 * u[:, 1] - 1.0)
        else:
            phi = (2.0 * math.pi) * u[:, 1] - math.pi
        d = torch.stack([sin_t * torch.cos(phi), sin_t * torch.sin(phi), cos_t], dim=-1)
        p = self._c(u) + self.radius * d
        if not self.yaw:
            return p
        yaw = self.yaw_min + u[:, 2] * (self.yaw_max - self.yaw_min)
        if self.full_yaw:
            yaw = wrap_angle(yaw)
        return torch.cat([p, yaw[:, None]], dim=-1)

    def _polar(self, d: Tensor) -> Tensor:
        return torch.atan2(torch.linalg.vector_norm(d[:, :2], dim=-1), d[:, 2])

    def contains(self, z: Tensor, tol: float = DEFAULT_TOL) -> Tensor:
        """On the sphere within ``tol`` (m), polar angle within ``tol / radius`` (rad), yaw in range."""
        check_batch(z, self.dim, "Hemisphere.contains")
        d = z[:, :3] - self._c(z)
        r = torch.linalg.vector_norm(d, dim=-1)
        theta = self._polar(d)
        ang_tol = tol / self.radius
        ok = ((r - self.radius).abs() <= tol) & (theta >= self.polar_min - ang_tol) & (theta <= self.polar_max + ang_tol)
        if self.banded:  # near the pole the azimuth does not matter
            rho = torch.linalg.vector_norm(d[:, :2], dim=-1)
            rel = wrap_angle(torch.atan2(d[:, 1], d[:, 0]) - self.azimuth).abs()
            ok = ok & ((rel <= self.azimuth_half_width + tol / self.radius) | (rho <= tol))
        if self.yaw and not self.full_yaw:
            y = z[:, 3]
            ok = ok & (y >= self.yaw_min - tol) & (y <= self.yaw_max + tol)
        elif self.yaw:
            ok = ok & (z[:, 3] >= -math.pi - tol) & (z[:, 3] <= math.pi + tol)
        return ok

    def project(self, z: Tensor) -> Tensor:
        check_batch(z, self.dim, "Hemisphere.project")
        c = self._c(z)
        d = z[:, :3] - c
        rho = torch.linalg.vector_norm(d[:, :2], dim=-1)
        # p == center: atan2(0, 0) = 0 -> the top of the sphere, clamped into the band below
        theta = torch.atan2(rho, d[:, 2]).clamp(self.polar_min, self.polar_max)
        phi = torch.atan2(d[:, 1], d[:, 0])  # 0 on the z-axis (atan2(0, 0) = 0)
        if self.banded:  # the azimuth clamped into its band
            phi = self.azimuth + wrap_angle(phi - self.azimuth).clamp(-self.azimuth_half_width, self.azimuth_half_width)
        st = torch.sin(theta)
        p = c + self.radius * torch.stack([st * torch.cos(phi), st * torch.sin(phi), torch.cos(theta)], dim=-1)
        if not self.yaw:
            return p
        return torch.cat([p, self._project_yaw(z[:, 3])[:, None]], dim=-1)

    def _project_yaw(self, y: Tensor) -> Tensor:
        if self.full_yaw:
            inside = (y >= -math.pi) & (y < math.pi)
            return torch.where(inside, y, wrap_angle(y))
        mid = 0.5 * (self.yaw_min + self.yaw_max)
        rel = wrap_angle(y - mid)  # circular offset from the middle of the range
        half = 0.5 * (self.yaw_max - self.yaw_min)
        out = mid + rel.clamp(-half, half)
        inside = (y >= self.yaw_min) & (y <= self.yaw_max)
        return torch.where(inside, y, out)

    def approach(self, z: Tensor) -> Tensor:
        """``(n, 3)`` unit approach directions, from each sampled position towards the centre."""
        check_batch(z, self.dim, "Hemisphere.approach")
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
        if self.azimuth is not None:
            d["azimuth"] = self.azimuth
            d["azimuth_half_width"] = self.azimuth_half_width
        if self.facing is not None:
            d["facing"] = self.facing
        return d

    def turn_toward(self, pre: Tensor, centre: Tensor, point: Tensor) -> Tensor:
        """(n, 3) pre-poses ``pre`` (n, 3) of this region centred at ``centre`` (n, 3) (its own
        centre, or the object's where it lies now, the pre-poses moved with it) turned about the
        vertical through ``centre`` so that the middle of the azimuth band points at ``point``
        (n, 2) (a ``facing: robot`` region: the arm's base axis where it stands). An unbanded
        region's are returned as they are."""
        rel = pre - centre
        if self.azimuth is None:
            return pre
        d = point - centre[:, :2]
        turn = torch.atan2(d[:, 1], d[:, 0]) - self.azimuth
        c, s = torch.cos(turn), torch.sin(turn)
        x, y = c * rel[:, 0] - s * rel[:, 1], s * rel[:, 0] + c * rel[:, 1]
        return centre + torch.stack([x, y, rel[:, 2]], dim=1)

    def facing_from(self, x: float, y: float) -> "Hemisphere":
        """This region with ``azimuth`` toward the point (x, y) (``facing: robot``: the robot's start)."""
        from dataclasses import replace

        return replace(self, azimuth=math.atan2(y - self.center[1], x - self.center[0]))
