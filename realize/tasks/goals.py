"""Goal predicates psi_g, in one place: used by the rollout and by the ManiSkill tasks' ``evaluate()``.

What it does: batched predicates over N copies, each with the distance to it that the CE
fallback ranks infeasible plans by (m, 0 where it holds geometrically):
  * ``cube_on_table``: the cube's centre above the table top's footprint, within
    ``HEIGHT_TOL`` of its resting height, and nearly still;
  * ``cube_in_container``: the cube's centre inside an open box's inner footprint, below its
    wall tops, and nearly still;
  * ``base_in_rectangle``: the base's (x, y) inside an axis-aligned rectangle;
  * ``goal_reached``: a task's ``GoalSpec`` (every given condition) and the summed distance.
Positions are in one copy's local frame: (N, 3) cube centres, (N,) cube speeds, (N, 2) bases.
What it doesn't: read the simulator (callers pass tensors), or decide when a goal is read
(the rollout reads it ``goal_settle_s`` after a plan's last action). It imports only torch and
light realize modules (geometry, regions, task), so the tasks in ``envs`` can import it.
"""

from __future__ import annotations

from typing import Mapping, Sequence

import torch
from torch import Tensor

from realize.world.geometry import SceneGeometry
from realize.tasks.regions import DEFAULT_TOL, Box, Region
from realize.tasks.spec import GoalSpec

REST_SPEED = 0.05  # m/s, the cube counts as resting at or below this (``controller.rest_speed``)
HEIGHT_TOL = 0.02  # m, a cube on a table rests within this of its resting height


def _outside_xy(p: Tensor, center: Sequence[float], half: Sequence[float]) -> Tensor:
    """(N,) horizontal distance of points p (N, 3) from the rectangle centre +- half."""
    c = torch.tensor(center[:2], dtype=p.dtype, device=p.device)
    h = torch.tensor(half[:2], dtype=p.dtype, device=p.device)
    return ((p[:, :2] - c).abs() - h).clamp(min=0.0).norm(dim=1)


def cube_on_table(p: Tensor, speed: Tensor, geometry: SceneGeometry, table: str,
                  rest_speed: float = REST_SPEED) -> Tensor:
    """(N,) bool: cube centres ``p`` (N, 3) rest on table ``table`` (speeds ``speed`` (N,))."""
    t = geometry.table(table)
    top = 2 * t.half_size[2] + geometry.cube_half_size
    ok = ((p[:, 0] - t.center[0]).abs() <= t.half_size[0]) & ((p[:, 1] - t.center[1]).abs() <= t.half_size[1])
    ok &= (p[:, 2] - top).abs() <= HEIGHT_TOL
    ok &= speed <= rest_speed
    return ok


def cube_on_table_distance(p: Tensor, geometry: SceneGeometry, table: str) -> Tensor:
    """(N,) how far (m) cube centres ``p`` are from resting on table ``table``'s top."""
    t = geometry.table(table)
    top = 2 * t.half_size[2] + geometry.cube_half_size
    dz = ((p[:, 2] - top).abs() - HEIGHT_TOL).clamp(min=0.0)
    return torch.sqrt(_outside_xy(p, t.center, t.half_size) ** 2 + dz ** 2)


def cube_in_container(p: Tensor, speed: Tensor, geometry: SceneGeometry, name: str,
                      rest_speed: float = REST_SPEED) -> Tensor:
    """(N,) bool: cube centres ``p`` (N, 3) inside container ``name``'s inner footprint, below its
    wall tops, with speeds ``speed`` (N,) at most ``rest_speed``."""
    box = geometry.container(name)
    w = geometry.container_wall
    hx, hy, hz = box.half_size
    inside = ((p[:, 0] - box.center[0]).abs() <= hx - w) & ((p[:, 1] - box.center[1]).abs() <= hy - w)
    return inside & (p[:, 2] <= 2 * hz) & (speed <= rest_speed)


def cube_in_container_distance(p: Tensor, geometry: SceneGeometry, name: str) -> Tensor:
    """(N,) how far (m) cube centres ``p`` are from container ``name``'s inside."""
    box, w = geometry.container(name), geometry.container_wall
    dz = (p[:, 2] - 2 * box.half_size[2]).clamp(min=0.0)
    return torch.sqrt(_outside_xy(p, box.center, (box.half_size[0] - w, box.half_size[1] - w)) ** 2 + dz ** 2)


def base_in_rectangle(xy: Tensor, low: Sequence[float], high: Sequence[float], tol: float = DEFAULT_TOL) -> Tensor:
    """(N,) bool: base positions ``xy`` (N, 2) inside ``low <= xy <= high`` (+- ``tol``)."""
    lo = torch.tensor(low, dtype=xy.dtype, device=xy.device)
    hi = torch.tensor(high, dtype=xy.dtype, device=xy.device)
    return ((xy >= lo - tol) & (xy <= hi + tol)).all(dim=-1)


def base_rectangle_distance(xy: Tensor, low: Sequence[float], high: Sequence[float]) -> Tensor:
    """(N,) distance (m) of base positions ``xy`` (N, 2) from the rectangle ``low``..``high``."""
    lo = torch.tensor(low, dtype=xy.dtype, device=xy.device)
    hi = torch.tensor(high, dtype=xy.dtype, device=xy.device)
    return (torch.maximum(torch.minimum(xy, hi), lo) - xy).norm(dim=1)


def goal_reached(goal: GoalSpec, geometry: SceneGeometry, regions: Mapping[str, Region], cube: Tensor,
                 cube_speed: Tensor, base_xy: Tensor, rest_speed: float = REST_SPEED) -> tuple[Tensor, Tensor]:
    """psi_g per copy (N,) bool, and how far (m) each copy is from it: the cube's distance to the
    goal table's top (or the container's inside) plus the base's distance to its goal
    rectangle (a 2-D box region of ``regions``). The distance is the CE fallback's
    distance-to-success for plans whose actions all succeeded but whose goal did not hold.

    ``cube`` (N, 3) positions and ``cube_speed`` (N,) (float32 on the scene's device),
    ``base_xy`` (N, 2)."""
    n, device = cube.shape[0], cube.device
    ok = torch.ones(n, dtype=torch.bool, device=device)
    dist = torch.zeros(n, device=device)
    if goal.cube_on is not None:
        ok &= cube_on_table(cube, cube_speed, geometry, goal.cube_on, rest_speed)
        dist += cube_on_table_distance(cube, geometry, goal.cube_on)
    if goal.cube_in_box is not None:
        ok &= cube_in_container(cube, cube_speed, geometry, goal.cube_in_box, rest_speed)
        dist += cube_in_container_distance(cube, geometry, goal.cube_in_box)
    if goal.base_in is not None:
        region = regions[goal.base_in]
        assert isinstance(region, Box)
        base = base_xy.double()
        ok &= base_in_rectangle(base, region.low, region.high).to(device)
        dist += base_rectangle_distance(base, region.low, region.high).to(dist)
    return ok, dist
