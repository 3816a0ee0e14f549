"""Per-plan A* grids that keep a held arm off tall obstacles while ``move_to`` drives the base.

What it does: ``move_to`` holds the torso and arm still and its PID keeps the base's yaw, so
while the base translates, every collision sphere of the body (the robot's sphere file, placed by
``realize.robot.kinematics``) keeps its horizontal offset from the base and its height. A sphere that
stays inside the base's padded disc (the radius the occupancy grid is inflated by) is covered by
the shared grid already. For the others, an arm stretched out with the cube in hand or over a
table, :func:`carry_blocked` marks the grid cells where a base there would put such a sphere
into a static obstacle box (3-D, with the box's yaw and pitch, as the fabric's collision terms
see boxes), the box widened by ``margin`` in its own x and y. An obstacle that every such sphere
passes over (a table top under a lifted arm) blocks nothing: the arm is carried at a fixed height.
``move_to`` plans those plans on the shared grid OR their cells (``planner="field"`` then computes
one field per such plan).

What it doesn't: follow the small yaw drift of the base while it drives (``margin`` covers it:
0.06 rad over a 0.9 m reach is 5 cm), consider the push scene's stick (it moves), or keep the arm
off anything during manipulation actions (the fabric's collision terms do that).
"""

from __future__ import annotations

import torch
from torch import Tensor

from realize.controllers.obstacles import BOX_CENTER, BOX_HALF, BOX_PITCH, BOX_YAW
from realize.controllers.occupancy import GridSpec

__all__ = ["carry_blocked"]

_PAIR_CHUNK = 96  # (sphere, box) pairs evaluated over the whole grid at once (~14 MB at 120 x 100 cells)


def _box_frames(boxes: Tensor, margin: float) -> tuple[Tensor, Tensor, Tensor, Tensor]:
    """(M, 3) centres, (M, 3, 3) box-to-world rotations, (M, 3) half sizes widened by ``margin``
    in x and y, (M, 2) lowest and highest world z of the box."""
    c, h = boxes[:, BOX_CENTER], boxes[:, BOX_HALF].clone()
    h[:, :2] += margin
    yaw, pitch = boxes[:, BOX_YAW], boxes[:, BOX_PITCH]
    cy, sy, cp, sp = torch.cos(yaw), torch.sin(yaw), torch.cos(pitch), torch.sin(pitch)
    z, o = torch.zeros_like(cy), torch.ones_like(cy)
    rz = torch.stack([torch.stack([cy, -sy, z], -1), torch.stack([sy, cy, z], -1), torch.stack([z, z, o], -1)], -2)
    ry = torch.stack([torch.stack([cp, z, sp], -1), torch.stack([z, o, z], -1), torch.stack([-sp, z, cp], -1)], -2)
    rot = rz @ ry
    dz = (rot[:, 2, :].abs() * h).sum(-1)  # half of the box's vertical extent
    return c, rot, h, torch.stack([c[:, 2] - dz, c[:, 2] + dz], -1)


def carry_blocked(grid: GridSpec, boxes: Tensor, offsets: Tensor, heights: Tensor, radii: Tensor,
                  base_reach: float, margin: float) -> Tensor:
    """(R, H, W) bool: cells where a base (yaw as now) would put a sphere into a box.

    grid: the A* grid. boxes: (M, BOX_COLUMNS) static obstacles (``obstacles.boxes_tensor``
    without the floor). offsets: (R, K, 2) each sphere's world (x, y) minus the base's;
    heights: (R, K) sphere centres' z; radii: (K,) or (R, K). base_reach: the padded base disc
    radius of the shared grid (robot radius + A* padding): a sphere inside it is left out.
    margin: how far (m) a sphere must stay from a box sideways.
    """
    r_n, k_n = heights.shape
    dev = offsets.device
    h_n, w_n = grid.shape
    out = torch.zeros(r_n, h_n * w_n, dtype=torch.int32, device=dev)
    if r_n == 0 or boxes.shape[0] == 0:
        return out.reshape(r_n, h_n, w_n).bool()
    f = torch.float32
    boxes = boxes.to(dev, f)
    radii = radii.to(dev, f).expand(r_n, k_n)
    offsets, heights = offsets.to(f), heights.to(f)
    c, rot, half, zr = _box_frames(boxes, margin)
    outside = offsets.norm(dim=-1) + radii + margin > base_reach  # (R, K)
    low, high = heights - radii, heights + radii
    meets = (low[..., None] < zr[:, 1]) & (high[..., None] > zr[:, 0])  # (R, K, M) vertical overlap
    row, sph, box = torch.nonzero(outside[..., None] & meets, as_tuple=True)
    if row.numel() == 0:
        return out.reshape(r_n, h_n, w_n).bool()
    cells = grid.cell_centers(device=dev, dtype=f).reshape(-1, 2)  # (HW, 2)
    for i in range(0, row.numel(), _PAIR_CHUNK):
        rr, kk, mm = row[i:i + _PAIR_CHUNK], sph[i:i + _PAIR_CHUNK], box[i:i + _PAIR_CHUNK]
        xy = cells[None] + offsets[rr, kk][:, None, :] - c[mm, None, :2]  # (P, HW, 2)
        zz = (heights[rr, kk] - c[mm, 2])[:, None].expand(-1, xy.shape[1])
        d = torch.cat([xy, zz[..., None]], -1)  # sphere centre minus box centre, world axes
        local = torch.einsum("pji,pnj->pni", rot[mm], d)  # in the box's axes
        q = local.abs() - half[mm, None, :]
        dist = q.clamp_min(0.0).norm(dim=-1) + q.max(dim=-1).values.clamp_max(0.0)
        hit = dist < radii[rr, kk][:, None]
        out.index_add_(0, rr, hit.to(torch.int32))
    return (out > 0).reshape(r_n, h_n, w_n)
