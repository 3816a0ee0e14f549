"""Cell-level helpers of the A* planner: validating cell inputs, connected components, nearest
free cell.

What it does
------------
* :func:`as_cells`: checks an (N, 2) (row, col) tensor and turns it into int64 cells (float
  inputs floored; non-finite rows become -1 and are reported in a mask).
* :func:`components`: labels the connected components of the free cells of a batch of grids
  (under A*'s corner rule 8-connectivity reduces to 4-connectivity), with a loop over rounds of
  label propagation, not over plans.
* :func:`nearest_free`: per row, the free cell nearest to a given cell (Euclidean distance in
  cells, ties -> lowest row-major index), used to snap starts and goals that lie in obstacles.

What it doesn't: search (``realize.controllers.astar_search``), decide when to snap
(``realize.controllers.astar``), or convert between cells and world coordinates
(``realize.controllers.occupancy``).
"""

from __future__ import annotations

import torch
from torch import Tensor

__all__ = ["as_cells", "components", "nearest_free"]


def as_cells(x: Tensor, name: str, n: int | None) -> tuple[Tensor, Tensor]:
    """Validate a (N, 2) cell tensor; returns (int64 cells with -1 where non-finite, finite mask)."""
    if x.ndim != 2 or x.shape[-1] != 2:
        raise ValueError(f"{name} must have shape (N, 2) as (row, col); got {tuple(x.shape)}")
    if n is not None and x.shape[0] != n:
        raise ValueError(f"{name} has {x.shape[0]} rows, expected {n}")
    if x.dtype.is_floating_point:
        finite = torch.isfinite(x).all(dim=-1)
        big = float(2 ** 30)
        xi = torch.floor(torch.nan_to_num(x, nan=-1.0).clamp(-big, big)).to(torch.int64)
        xi = torch.where(finite[:, None], xi, torch.full_like(xi, -1))
        return xi, finite
    if x.dtype == torch.bool or x.is_complex():
        raise ValueError(f"{name} must be an integer or float tensor, got {x.dtype}")
    return x.to(torch.int64), torch.ones(x.shape[0], dtype=torch.bool, device=x.device)


def components(free: Tensor) -> Tensor:
    """Connected-component labels of free cells, (B, H, W) bool -> (B, H*W) int64.

    Under the corner rule a diagonal move needs both orthogonal side cells free, so 8-connectivity
    reduces to 4-connectivity. Every free cell gets the flat index of one cell of its component
    (the same for the whole component); blocked cells get -1. Hook-and-shortcut label
    propagation (each round: hook every label's root to the smallest neighbouring label, then
    pointer-jump), a loop over rounds (about log of the component diameter), not over plans.
    """
    b, h, w = free.shape
    hw = h * w
    freef = free.reshape(b, hw)
    ar = torch.arange(hw, device=free.device).expand(b, hw)
    # column hw is a blocked sentinel whose label is itself
    lab = torch.cat([torch.where(freef, ar, hw), torch.full((b, 1), hw, device=free.device)], dim=1)
    big = torch.full((b, h, w), hw, dtype=lab.dtype, device=free.device)
    while True:
        grid = lab[:, :hw].reshape(b, h, w)
        m = grid.clone()
        m[:, 1:] = torch.minimum(m[:, 1:], grid[:, :-1])
        m[:, :-1] = torch.minimum(m[:, :-1], grid[:, 1:])
        m[:, :, 1:] = torch.minimum(m[:, :, 1:], grid[:, :, :-1])
        m[:, :, :-1] = torch.minimum(m[:, :, :-1], grid[:, :, 1:])
        m = torch.where(free, m, big).reshape(b, hw)
        m = torch.cat([m, torch.full((b, 1), hw, dtype=m.dtype, device=m.device)], dim=1)
        new = lab.scatter_reduce(1, lab, m, reduce="amin")  # hook roots
        new = torch.minimum(new, m)
        while True:  # shortcut: point every cell at its label's label until flat
            nxt = new.gather(1, new)
            if torch.equal(nxt, new):
                break
            new = nxt
        if torch.equal(new, lab):
            break
        lab = new
    return torch.where(freef, lab[:, :hw], -1)


def nearest_free(free_rows: Tensor, cells: Tensor, w: int) -> tuple[Tensor, Tensor]:
    """free_rows (K, HW) bool, cells (K, 2) -> (flat index of nearest free cell (K,), any free (K,))."""
    hw = free_rows.shape[1]
    idx = torch.arange(hw, device=cells.device)
    rr, cc = idx // w, idx % w
    dr_, dc_ = rr[None] - cells[:, :1], cc[None] - cells[:, 1:]
    d2 = dr_ * dr_ + dc_ * dc_
    d2 = torch.where(free_rows, d2, torch.full_like(d2, torch.iinfo(torch.int64).max))
    best = torch.argmin(d2, dim=1)  # first minimum -> lowest row-major index on ties
    return best, free_rows.any(dim=1)
