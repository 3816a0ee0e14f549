"""A* cell paths -> world waypoints for the base controller.

What it does: :func:`path_to_waypoints` turns the batched cell paths of an ``AStarResult`` into
world (x, y) waypoints (cell centres), dropping cells where the path keeps its direction,
optionally shortcutting along sampled line-of-sight segments through free cells, dropping the
start cell where the robot already is and ending at the exact requested goal. Batched over
plans; the only Python loop is over waypoint positions. The result is a :class:`Waypoints`.

What it doesn't: search (``realize.controllers.astar``), smooth or time-parametrise the path, or
track it (``realize.controllers.pid``).
"""

from __future__ import annotations

from dataclasses import dataclass

import torch
from torch import Tensor

from realize.controllers.astar import AStarResult
from realize.controllers.occupancy import GridSpec, cell_to_world

__all__ = ["Waypoints", "path_to_waypoints"]


@dataclass
class Waypoints:
    """World waypoints per plan: points (N, L, 2) (x, y), padded by repeating the last valid point
    (zeros for an empty plan); lengths (N,) int64 (0 when no path was found)."""

    points: Tensor
    lengths: Tensor


def _compact(points: Tensor, keep: Tensor) -> tuple[Tensor, Tensor]:
    """Keep points[i, j] where keep[i, j], packed to the front; pad by repeating the last kept point."""
    n, l = keep.shape
    pos = torch.cumsum(keep.to(torch.int64), dim=1) - 1
    lengths = keep.sum(dim=1)
    tgt = torch.where(keep, pos, torch.full_like(pos, l))  # column l = trash
    out = torch.zeros(n, l + 1, points.shape[-1], dtype=points.dtype, device=points.device)
    out = out.scatter(1, tgt[..., None].expand(-1, -1, points.shape[-1]), points)[:, :l]
    j = torch.arange(l, device=points.device)[None]
    last = (lengths - 1).clamp(min=0)
    fill = out.gather(1, last[:, None, None].expand(-1, 1, points.shape[-1]))
    out = torch.where((j < lengths[:, None])[..., None], out, fill)
    return out, lengths


def _samples(spec: GridSpec, seg: Tensor) -> int:
    """Samples per segment of one shortcut round: every quarter cell of the round's longest segment
    over the whole batch (so a plan's samples do not depend on which rows are checked)."""
    return int(torch.ceil(seg.max() / (0.25 * spec.resolution)).item()) + 2 if seg.numel() else 2


def _line_free(free_pad: Tensor, shared: bool, spec: GridSpec, a: Tensor, b: Tensor, rows: Tensor,
               n_s: int) -> Tensor:
    """Line of sight between finite world points a, b (K, 2): ``n_s`` evenly spaced samples all lie
    in free cells. free_pad: (B, (H + 2) * (W + 2)) free grid with a blocked one-cell border."""
    t = torch.linspace(0.0, 1.0, n_s, device=a.device, dtype=a.dtype)
    pts = a[:, None] + t[None, :, None] * (b - a)[:, None]
    # world_to_cell for finite points (its NaN / range guards are identities here); cells off the
    # grid land on the blocked border of free_pad
    x0, y0 = spec.origin
    col = torch.floor((pts[..., 0] - x0) / spec.resolution).to(torch.int64).clamp_(-1, spec.width)
    row = torch.floor((pts[..., 1] - y0) / spec.resolution).to(torch.int64).clamp_(-1, spec.height)
    flat = (row + 1) * (spec.width + 2) + (col + 1)
    fr = free_pad[0][flat] if shared else free_pad[rows[:, None], flat]
    return fr.all(dim=1)


def path_to_waypoints(
    result: AStarResult,
    spec: GridSpec,
    *,
    thin: bool = True,
    occupied: Tensor | None = None,
    start_xy: Tensor | None = None,
    goal_xy: Tensor | None = None,
    dtype: torch.dtype = torch.float32,
) -> Waypoints:
    """Cell paths -> world waypoints (cell centres).

    thin: drop cells where the path keeps its direction (only corners remain, plus both ends).
    occupied: if given ((H, W) or (N, H, W)), also shortcut greedily: from each anchor, skip to the
        farthest later waypoint reachable in a straight line whose samples (every quarter cell) all
        lie in free cells. A sampled check, not an exact supercover; the grid's padding absorbs the
        difference.
    start_xy: (N, 2) current base positions; where the start was not snapped, the first waypoint
        (the start cell's centre, where the robot already is) is dropped if more remain.
    goal_xy: (N, 2) requested goals; where the goal was not snapped, the last waypoint becomes the
        exact goal point instead of its cell centre.
    Plans without a path get length 0.
    """
    n, l = result.path.shape[:2]
    dev = result.path.device
    j = torch.arange(l, device=dev)[None]
    ln = result.lengths
    valid = j < ln[:, None]
    pts = cell_to_world(spec, result.path.clamp(min=0), dtype=dtype)
    keep = valid.clone()
    if thin and l > 2:
        d = result.path[:, 1:] - result.path[:, :-1]  # (N, L-1, 2)
        same = (d[:, 1:] == d[:, :-1]).all(dim=-1)  # point j+1 is interior and straight
        interior = (j[:, 1:-1] < (ln[:, None] - 1))
        drop = torch.zeros_like(keep)
        drop[:, 1:-1] = same & interior
        keep = keep & ~drop
    pts, ln2 = _compact(pts, keep)
    l2 = pts.shape[1]

    if occupied is not None and l2 > 2:
        free = ~occupied.bool().reshape(-1, spec.height, spec.width)
        shared = free.shape[0] == 1
        free_pad = torch.nn.functional.pad(free, (1, 1, 1, 1), value=False).reshape(free.shape[0], -1)
        rows = torch.arange(n, device=dev)
        keep = torch.zeros(n, l2, dtype=torch.bool, device=dev)
        keep[:, 0] = ln2 > 0
        anchor = pts[:, 0]
        # positions past every plan's last thinned waypoint change nothing: stop there
        for jj in range(2, min(l2, int(ln2.max()))):
            inpath = jj < ln2
            n_s = _samples(spec, (pts[:, jj] - anchor).norm(dim=-1))
            # only plans whose path reaches jj are checked (the others' answer is not used)
            act = inpath.nonzero().squeeze(1)
            brk = torch.zeros_like(inpath)
            brk[act] = ~_line_free(free_pad, shared, spec, anchor[act], pts[act, jj], rows[act], n_s)
            keep[:, jj - 1] = keep[:, jj - 1] | brk
            anchor = torch.where(brk[:, None], pts[:, jj - 1], anchor)
        last = (ln2 - 1).clamp(min=0)
        keep = keep | ((torch.arange(l2, device=dev)[None] == last[:, None]) & (ln2[:, None] > 0))
        pts, ln2 = _compact(pts, keep)
        l2 = pts.shape[1]

    if goal_xy is not None:
        rep = result.found & ~result.goal_snapped
        last = (ln2 - 1).clamp(min=0)
        is_last = torch.arange(l2, device=dev)[None] >= last[:, None]
        pts = torch.where((rep[:, None] & is_last)[..., None], goal_xy.to(dev, dtype)[:, None], pts)
    if start_xy is not None:
        drop_first = result.found & ~result.start_snapped & (ln2 > 1)
        idx = (torch.arange(l2, device=dev)[None] + drop_first[:, None].to(torch.int64)).clamp(max=l2 - 1)
        pts = pts.gather(1, idx[..., None].expand(-1, -1, 2))
        ln2 = ln2 - drop_first.to(torch.int64)
        # re-pad by repeating the last valid point
        last = (ln2 - 1).clamp(min=0)
        fill = pts.gather(1, last[:, None, None].expand(-1, 1, 2))
        pts = torch.where((torch.arange(l2, device=dev)[None] < ln2[:, None])[..., None], pts, fill)
    empty = ln2 == 0
    pts = torch.where(empty[:, None, None], torch.zeros_like(pts), pts)
    return Waypoints(points=pts, lengths=ln2)
