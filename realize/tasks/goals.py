"""Goal predicates psi_g, in one place: used by the rollout and by the ManiSkill tasks' ``evaluate()``.

What it does: batched predicates over N copies, each with the distance to it that the CE
fallback ranks infeasible plans by (m, 0 where it holds geometrically):
  * ``object_on_table``: a named object's centre above the table top's footprint, within
    ``HEIGHT_TOL`` of its resting height (table top + the object's half height), nearly still;
  * ``object_on_object``: the same on another object's top, where that object stands now;
  * ``object_in_container``: the centre inside an open box's inner footprint, below its wall
    tops, and nearly still;
  * ``object_at``: the centre within a tolerance of a point (or inside a grown box), nearly still;
  * ``base_in_rectangle``: the base's (x, y) inside an axis-aligned rectangle;
  * ``goal_reached``: a task's ``GoalSpec`` (every given condition, ``realize.tasks.goal_spec``)
    and the summed distance.
Positions are in one copy's local frame: (N, 3) object centres, (N,) speeds, (N, 2) bases;
``goal_reached`` takes every object at once, (N, m, 3) and (N, m), in the scene's object order.
What it doesn't: read the simulator (callers pass tensors), or decide when a goal is read
(the rollout reads it ``goal_settle_s`` after a plan's last action). It imports only torch and
light realize modules (geometry, regions, task), so the tasks in ``envs`` can import it.
"""

from __future__ import annotations

from typing import Mapping, Sequence

import torch
from torch import Tensor

from realize.world.geometry import SceneGeometry
from realize.tasks.goal_spec import GoalSpec
from realize.tasks.regions import DEFAULT_TOL, Box, Fixed, Region

REST_SPEED = 0.05  # m/s, an object counts as resting at or below this (``controller.rest_speed``)
HEIGHT_TOL = 0.02  # m, an object on a table rests within this of its resting height


def _outside_xy(p: Tensor, center: Sequence[float], half: Sequence[float]) -> Tensor:
    """(N,) horizontal distance of points p (N, 3) from the rectangle centre +- half."""
    c = torch.tensor(center[:2], dtype=p.dtype, device=p.device)
    h = torch.tensor(half[:2], dtype=p.dtype, device=p.device)
    return ((p[:, :2] - c).abs() - h).clamp(min=0.0).norm(dim=1)


def object_on_table(p: Tensor, speed: Tensor, geometry: SceneGeometry, obj: str, table: str,
                    rest_speed: float = REST_SPEED) -> Tensor:
    """(N,) bool: centres ``p`` (N, 3) of object ``obj`` rest on table ``table`` (speeds (N,))."""
    t = geometry.table(table)
    top = 2 * t.half_size[2] + geometry.object(obj).half_height
    ok = ((p[:, 0] - t.center[0]).abs() <= t.half_size[0]) & ((p[:, 1] - t.center[1]).abs() <= t.half_size[1])
    ok &= (p[:, 2] - top).abs() <= HEIGHT_TOL
    ok &= speed <= rest_speed
    return ok


def object_on_object(p: Tensor, speed: Tensor, below: Tensor, below_speed: Tensor, geometry: SceneGeometry,
                     obj: str, support: str, rest_speed: float = REST_SPEED, margin: float = 0.0) -> Tensor:
    """(N,) bool: centres ``p`` (N, 3) of object ``obj`` rest on object ``support``'s top, where
    that object stands now (its centres ``below``, (N, 3)): the centre over the support's
    inscribed circle shrunk by ``margin`` (whatever either's yaw), at resting height within
    ``HEIGHT_TOL``, both nearly still (speeds (N,) each)."""
    ok = object_on_object_distance(p, below, geometry, obj, support, margin) <= 0.0
    return ok & (speed <= rest_speed) & (below_speed <= rest_speed)


def object_on_object_distance(p: Tensor, below: Tensor, geometry: SceneGeometry, obj: str, support: str,
                              margin: float = 0.0) -> Tensor:
    """(N,) how far (m) centres ``p`` of object ``obj`` are from resting on object ``support``
    whose centres are ``below`` (its top's inscribed circle shrunk by ``margin``)."""
    s = geometry.object(support)
    r = min(s.half_size[0], s.half_size[1]) - margin
    top = below[:, 2] + s.half_height + geometry.object(obj).half_height
    dxy = ((p[:, :2] - below[:, :2]).norm(dim=1) - r).clamp(min=0.0)
    dz = ((p[:, 2] - top).abs() - HEIGHT_TOL).clamp(min=0.0)
    return torch.sqrt(dxy ** 2 + dz ** 2)


def object_on_table_distance(p: Tensor, geometry: SceneGeometry, obj: str, table: str) -> Tensor:
    """(N,) how far (m) centres ``p`` of object ``obj`` are from resting on table ``table``'s top."""
    t = geometry.table(table)
    top = 2 * t.half_size[2] + geometry.object(obj).half_height
    dz = ((p[:, 2] - top).abs() - HEIGHT_TOL).clamp(min=0.0)
    return torch.sqrt(_outside_xy(p, t.center, t.half_size) ** 2 + dz ** 2)


def object_in_container(p: Tensor, speed: Tensor, geometry: SceneGeometry, name: str,
                        rest_speed: float = REST_SPEED) -> Tensor:
    """(N,) bool: centres ``p`` (N, 3) inside container ``name``'s inner footprint, below its
    wall tops, with speeds ``speed`` (N,) at most ``rest_speed``."""
    box = geometry.container(name)
    w = geometry.container_wall(name)
    hx, hy, hz = box.half_size
    inside = ((p[:, 0] - box.center[0]).abs() <= hx - w) & ((p[:, 1] - box.center[1]).abs() <= hy - w)
    return inside & (p[:, 2] <= 2 * hz) & (speed <= rest_speed)


def object_in_container_distance(p: Tensor, geometry: SceneGeometry, name: str) -> Tensor:
    """(N,) how far (m) centres ``p`` are from container ``name``'s inside."""
    box, w = geometry.container(name), geometry.container_wall(name)
    dz = (p[:, 2] - 2 * box.half_size[2]).clamp(min=0.0)
    return torch.sqrt(_outside_xy(p, box.center, (box.half_size[0] - w, box.half_size[1] - w)) ** 2 + dz ** 2)


def object_at_distance(p: Tensor, region: Region, tol: float) -> Tensor:
    """(N,) how far (m) centres ``p`` (N, 3) are from within ``tol`` of a fixed point or a box
    region (its first 2 or 3 coordinates; a 2-D region leaves the height free)."""
    k = region.dim
    q = p[:, :k].double()
    if isinstance(region, Fixed):
        c = torch.tensor(region.value[:k], dtype=q.dtype, device=q.device)
        return ((q - c).norm(dim=1) - tol).clamp(min=0.0).to(p)
    assert isinstance(region, Box)
    return base_rectangle_distance(q, [v - tol for v in region.low[:k]], [v + tol for v in region.high[:k]]).to(p)


def object_at(p: Tensor, speed: Tensor, region: Region, tol: float, rest_speed: float = REST_SPEED) -> Tensor:
    """(N,) bool: centres ``p`` rest (speed at most ``rest_speed``) within ``tol`` of ``region``."""
    return (object_at_distance(p, region, tol) <= 0.0) & (speed <= rest_speed)


def base_in_rectangle(xy: Tensor, low: Sequence[float], high: Sequence[float], tol: float = DEFAULT_TOL) -> Tensor:
    """(N,) bool: base positions ``xy`` (N, 2) inside ``low <= xy <= high`` (+- ``tol``)."""
    lo = torch.tensor(low, dtype=xy.dtype, device=xy.device)
    hi = torch.tensor(high, dtype=xy.dtype, device=xy.device)
    return ((xy >= lo - tol) & (xy <= hi + tol)).all(dim=-1)


def base_rectangle_distance(xy: Tensor, low: Sequence[float], high: Sequence[float]) -> Tensor:
    """(N,) distance (m) of points ``xy`` (N, k) from the axis-aligned box ``low``..``high`` (k values
    each; the base's (x, y) and a 2-D rectangle, or an object's centre and a 3-D box)."""
    lo = torch.tensor(low, dtype=xy.dtype, device=xy.device)
    hi = torch.tensor(high, dtype=xy.dtype, device=xy.device)
    return (torch.maximum(torch.minimum(xy, hi), lo) - xy).norm(dim=1)


def _frame_shift(region: str, frames: Mapping[str, str] | None, geometry: SceneGeometry, objects: Tensor) -> Tensor:
    """(N, 3) how far the movable object that frames parameter ``region`` stands from its
    configured place (zeros: a world, table or container frame, or no frames given)."""
    frame = (frames or {}).get(region)
    if frame is None or frame not in geometry.object_names:
        return torch.zeros(3, dtype=objects.dtype, device=objects.device)
    configured = torch.tensor(geometry.object(frame).position, dtype=objects.dtype, device=objects.device)
    return objects[:, geometry.object_index(frame)] - configured


def goal_reached(goal: GoalSpec, geometry: SceneGeometry, regions: Mapping[str, Region], objects: Tensor,
                 speeds: Tensor, base_xy: Tensor, rest_speed: float = REST_SPEED,
                 frames: Mapping[str, str] | None = None) -> tuple[Tensor, Tensor]:
    """psi_g per copy (N,) bool, and how far (m) each copy is from it: the sum over the goal's
    conditions of each object's distance to its table top, container inside or spot, plus the
    base's distance to its goal rectangle (a 2-D box region of ``regions``). The distance is
    the CE fallback's distance-to-success for plans whose actions all succeeded but whose goal
    did not hold.

    ``objects`` (N, m, 3) centres and ``speeds`` (N, m) of every object of ``geometry`` in its
    order (float32 on the scene's device), ``base_xy`` (N, 2). ``frames`` (a task's parameter ->
    frame, ``TaskSpec.frames``): a ``rests_at`` spot framed by a movable object is where that
    object stands now, not where the scene config put it (the spot moves with the object's
    centre; its turn is not followed). Without ``frames`` every spot stays where it was built."""
    n, device = objects.shape[0], objects.device
    ok = torch.ones(n, dtype=torch.bool, device=device)
    dist = torch.zeros(n, device=device)
    for name, support in goal.on.items():
        k = geometry.object_index(name)
        if support in geometry.object_names:  # a stack: on that object, where it stands
            j = geometry.object_index(support)
            ok &= object_on_object(objects[:, k], speeds[:, k], objects[:, j], speeds[:, j], geometry, name, support,
                                   rest_speed, goal.margin)
            dist += object_on_object_distance(objects[:, k], objects[:, j], geometry, name, support, goal.margin)
            continue
        ok &= object_on_table(objects[:, k], speeds[:, k], geometry, name, support, rest_speed)
        dist += object_on_table_distance(objects[:, k], geometry, name, support)
    for name, box in goal.inside.items():
        k = geometry.object_index(name)
        ok &= object_in_container(objects[:, k], speeds[:, k], geometry, box, rest_speed)
        dist += object_in_container_distance(objects[:, k], geometry, box)
    for name, spot in goal.at.items():
        k = geometry.object_index(name)
        p = objects[:, k] - _frame_shift(spot.region, frames, geometry, objects)
        ok &= object_at(p, speeds[:, k], regions[spot.region], spot.tol, rest_speed)
        dist += object_at_distance(p, regions[spot.region], spot.tol)
    if goal.base_in is not None:
        region = regions[goal.base_in]
        assert isinstance(region, Box)
        base = base_xy.double()
        ok &= base_in_rectangle(base, region.low, region.high).to(device)
        dist += base_rectangle_distance(base, region.low, region.high).to(dist)
    return ok, dist
