"""2D occupancy grids for base planning, built from box obstacles.

What it does:
  * ``GridSpec`` describes a regular grid over the floor: world ``origin`` (x, y) of the lower-left
    corner of cell (0, 0), square cell ``resolution`` in metres, and ``shape`` (H, W).
    Cells are indexed ``(row, col)``; ``row`` grows with world y, ``col`` with world x, so a grid
    tensor is read as ``occ[row, col]``.
  * ``occupancy_from_boxes`` marks a cell occupied when its *centre* lies within ``padding`` of any
    (possibly yawed) box, i.e. inside the box's Minkowski sum with a disc of radius ``padding``
    (rounded-rectangle inflation, exact, not a bigger rectangle). ``padding`` is meant to be the
    robot radius plus a safety margin (the paper uses 20 cm). Optionally, cells whose centre is
    closer than ``padding`` to the grid border are occupied as well (the world bounds act as walls).
    Obstacles may carry leading batch dims, giving one grid per plan (..., H, W).
  * ``world_to_cell`` / ``cell_to_world`` / ``cell_in_grid``: batched conversions.

What it does not do: no 3D (a ramp is a box in the plane; whether the base may drive over it is the
caller's decision: leave it out of the obstacle list), no cell-coverage rasterisation (a box that
covers part of a cell but not its centre, after padding, leaves the cell free; use a padding a
little larger than the robot radius, or ``conservative=True`` which adds half a cell diagonal).
Pure torch, device-agnostic, no numpy.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import torch
from torch import Tensor

__all__ = [
    "GridSpec",
    "grid_from_bounds",
    "occupancy_from_boxes",
    "world_to_cell",
    "cell_to_world",
    "cell_in_grid",
]


@dataclass(frozen=True)
class GridSpec:
    """Geometry of a 2D grid.

    origin: world (x, y) of the lower-left corner of cell (0, 0), metres.
    resolution: side of one square cell, metres (> 0).
    shape: (H, W) = (rows along y, cols along x).
    """

    origin: tuple[float, float]
    resolution: float
    shape: tuple[int, int]

    def __post_init__(self) -> None:
        if not (self.resolution > 0 and math.isfinite(self.resolution)):
            raise ValueError(f"resolution must be a positive finite number, got {self.resolution}")
        if len(self.shape) != 2 or self.shape[0] < 1 or self.shape[1] < 1:
            raise ValueError(f"shape must be (H, W) with H, W >= 1, got {self.shape}")
        if len(self.origin) != 2 or not all(math.isfinite(float(o)) for o in self.origin):
            raise ValueError(f"origin must be a finite (x, y) pair, got {self.origin}")

    @property
    def height(self) -> int:
        return int(self.shape[0])

    @property
    def width(self) -> int:
        return int(self.shape[1])

    @property
    def bounds(self) -> tuple[float, float, float, float]:
        """(xmin, ymin, xmax, ymax) covered by the grid."""
        x0, y0 = self.origin
        return (x0, y0, x0 + self.width * self.resolution, y0 + self.height * self.resolution)

    def cell_centers(self, device: torch.device | str | None = None,
                     dtype: torch.dtype = torch.float32) -> Tensor:
        """World (x, y) of every cell centre, shape (H, W, 2)."""
        r = (torch.arange(self.height, device=device, dtype=dtype) + 0.5) * self.resolution
        c = (torch.arange(self.width, device=device, dtype=dtype) + 0.5) * self.resolution
        yy, xx = torch.meshgrid(r + self.origin[1], c + self.origin[0], indexing="ij")
        return torch.stack([xx, yy], dim=-1)


def grid_from_bounds(bounds: tuple[float, float, float, float], resolution: float) -> GridSpec:
    """Smallest grid with lower-left corner at (xmin, ymin) that covers ``bounds``.

    bounds: (xmin, ymin, xmax, ymax) in metres.
    """
    xmin, ymin, xmax, ymax = (float(b) for b in bounds)
    if not (xmax > xmin and ymax > ymin):
        raise ValueError(f"bounds must satisfy xmax > xmin and ymax > ymin, got {bounds}")
    if not (resolution > 0):
        raise ValueError(f"resolution must be positive, got {resolution}")
    # small tolerance so that e.g. 8.0 / 0.1 does not become 81 cells by rounding
    w = max(1, math.ceil((xmax - xmin) / resolution - 1e-9))
    h = max(1, math.ceil((ymax - ymin) / resolution - 1e-9))
    return GridSpec(origin=(xmin, ymin), resolution=float(resolution), shape=(h, w))


def occupancy_from_boxes(
    spec: GridSpec,
    centers: Tensor,
    half_extents: Tensor,
    yaws: Tensor | None = None,
    padding: float = 0.2,
    *,
    valid: Tensor | None = None,
    pad_bounds: bool = True,
    conservative: bool = False,
) -> Tensor:
    """Boolean occupancy grid (True = blocked) from boxes inflated by ``padding``.

    centers: (..., M, 2) box centres (x, y), metres.
    half_extents: (..., M, 2) half sizes along the box's own x / y axes (>= 0).
    yaws: (..., M) box yaw in radians (None: axis aligned).
    padding: inflation radius, metres (>= 0): robot radius + margin.
    valid: optional (..., M) bool mask; False boxes are ignored (lets callers pad obstacle lists).
    pad_bounds: also block cells whose centre is within ``padding`` of the grid border.
    conservative: add half a cell diagonal to ``padding`` so any cell the inflated box touches
        (not only those whose centre it contains) is blocked.

    Returns (..., H, W) bool on the device of ``centers``. Loops over the M boxes (few), never
    over the batch.
    """
    if padding < 0 or not math.isfinite(padding):
        raise ValueError(f"padding must be a finite number >= 0, got {padding}")
    if centers.shape[-1] != 2 or half_extents.shape != centers.shape:
        raise ValueError(
            f"centers and half_extents must both be (..., M, 2); got {tuple(centers.shape)} "
            f"and {tuple(half_extents.shape)}")
    if yaws is not None and yaws.shape != centers.shape[:-1]:
        raise ValueError(f"yaws must be (..., M) = {tuple(centers.shape[:-1])}, got {tuple(yaws.shape)}")
    if valid is not None and valid.shape != centers.shape[:-1]:
        raise ValueError(f"valid must be (..., M) = {tuple(centers.shape[:-1])}, got {tuple(valid.shape)}")
    if not torch.isfinite(centers).all() or not torch.isfinite(half_extents).all():
        raise ValueError("centers and half_extents must be finite")
    if (half_extents < 0).any():
        raise ValueError("half_extents must be >= 0")

    dtype = centers.dtype if centers.dtype.is_floating_point else torch.float32
    device = centers.device
    pad = float(padding) + (spec.resolution * math.sqrt(0.5) if conservative else 0.0)
    batch = centers.shape[:-2]
    n_boxes = centers.shape[-2]
    pts = spec.cell_centers(device=device, dtype=dtype)  # (H, W, 2)
    occ = torch.zeros(*batch, spec.height, spec.width, dtype=torch.bool, device=device)

    for m in range(n_boxes):
        c = centers[..., m, :].to(dtype)  # (..., 2)
        he = half_extents[..., m, :].to(dtype)
        d = pts - c[..., None, None, :]  # (..., H, W, 2)
        if yaws is not None:
            yaw = yaws[..., m].to(dtype)
            cy, sy = torch.cos(yaw)[..., None, None], torch.sin(yaw)[..., None, None]
            lx = cy * d[..., 0] + sy * d[..., 1]
            ly = -sy * d[..., 0] + cy * d[..., 1]
        else:
            lx, ly = d[..., 0], d[..., 1]
        ex = (lx.abs() - he[..., 0, None, None]).clamp_min(0.0)
        ey = (ly.abs() - he[..., 1, None, None]).clamp_min(0.0)
        hit = ex * ex + ey * ey <= pad * pad
        if valid is not None:
            hit = hit & valid[..., m, None, None]
        occ = occ | hit

    if pad_bounds and pad > 0:
        xmin, ymin, xmax, ymax = spec.bounds
        x, y = pts[..., 0], pts[..., 1]
        border = (x - xmin < pad) | (xmax - x < pad) | (y - ymin < pad) | (ymax - y < pad)
        occ = occ | border
    return occ


def world_to_cell(spec: GridSpec, xy: Tensor) -> Tensor:
    """World points (..., 2) -> integer cells (..., 2) as (row, col), int64.

    No clamping: points outside the grid give out-of-range indices (check with ``cell_in_grid``).
    Non-finite inputs give an arbitrary index; callers must mask them (the planner flags them).
    """
    x0, y0 = spec.origin
    fx = torch.nan_to_num((xy[..., 0] - x0) / spec.resolution, nan=-1.0, posinf=-1.0, neginf=-1.0)
    fy = torch.nan_to_num((xy[..., 1] - y0) / spec.resolution, nan=-1.0, posinf=-1.0, neginf=-1.0)
    # clamp to a safe int range before the cast; anything that far is out of the grid anyway
    big = float(2 ** 30)
    col = torch.floor(fx.clamp(-big, big)).to(torch.int64)
    row = torch.floor(fy.clamp(-big, big)).to(torch.int64)
    return torch.stack([row, col], dim=-1)


def cell_to_world(spec: GridSpec, cells: Tensor, dtype: torch.dtype = torch.float32) -> Tensor:
    """Cells (..., 2) as (row, col) -> world (x, y) of the cell centres, (..., 2)."""
    x0, y0 = spec.origin
    c = cells.to(dtype)
    x = x0 + (c[..., 1] + 0.5) * spec.resolution
    y = y0 + (c[..., 0] + 0.5) * spec.resolution
    return torch.stack([x, y], dim=-1)


def cell_in_grid(spec: GridSpec, cells: Tensor) -> Tensor:
    """(..., 2) (row, col) -> (...) bool, True where the cell lies inside the grid."""
    r, c = cells[..., 0], cells[..., 1]
    return (r >= 0) & (r < spec.height) & (c >= 0) & (c < spec.width)
