"""Movable objects as obstacles of the whole-body fabric (``controller.avoid_movable``).

What it does:
  * ``object_boxes``: the scene's movable objects at their current poses, per copy, as obstacle
    box rows (N, m, ``BOX_COLUMNS``) of ``realize.controllers.obstacles``: the box's yaw and pitch
    from its rotation (z-y-x angles), its half sizes those of the smallest box in that yawed and
    pitched frame that holds the object (exact for an object turned about z and its own y only, as
    blocks standing or lying on a face are; larger, never smaller, for one rolled about x);
  * ``bounding_radius``: the radius of the sphere about an object's centre that holds it (a box:
    its half diagonal; an upright cylinder: ``hypot(radius, half height)``): the held object's
    collision sphere;
  * ``MovableObstacles``: what one fabric step needs of them, per row: the boxes, which of them
    each row leaves out, and the held object's centre and radius (radius 0: nothing held).
What it doesn't: decide which objects a row leaves out or whether it carries one (the action
templates do: ``realize.realization.actions``), read the simulator, or compute a leaf
(``realize.controllers.whole_body`` adds these boxes and the held sphere to its collision leaves).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import torch
from torch import Tensor

from realize.controllers.obstacles import BOX_CENTER, BOX_COLUMNS, BOX_HALF, BOX_PITCH, BOX_YAW

__all__ = ["MovableObstacles", "bounding_radius", "object_boxes"]


def bounding_radius(shape: str, half_size: tuple[float, float, float]) -> float:
    """m: radius of the smallest sphere about the centre that holds an object of ``shape``
    (``box``: half sizes hx, hy, hz; ``cylinder``: radius, radius, half height)."""
    hx, hy, hz = half_size
    return math.hypot(hx, hz) if shape == "cylinder" else math.sqrt(hx * hx + hy * hy + hz * hz)


def object_boxes(centres: Tensor, rot: Tensor, half: Tensor) -> Tensor:
    """(N, m, BOX_COLUMNS) obstacle boxes of m objects with centres (N, m, 3), rotations
    (N, m, 3, 3) (columns: the object's axes in the world) and half sizes (m, 3) or (N, m, 3).

    The box's yaw and pitch are the rotation's z-y-x angles (``R = Rz(yaw) Ry(pitch) Rx(roll)``,
    the frame ``BoxDistance`` turns a box by); its half sizes are ``|Rb^T R| h`` with
    ``Rb = Rz(yaw) Ry(pitch)``: the object's extents along the box's axes, so the box holds the
    object whatever the roll (and whatever the angles at gimbal lock)."""
    yaw = torch.atan2(rot[..., 1, 0], rot[..., 0, 0])
    pitch = torch.asin((-rot[..., 2, 0]).clamp(-1.0, 1.0))
    cy, sy, cp, sp = torch.cos(yaw), torch.sin(yaw), torch.cos(pitch), torch.sin(pitch)
    zero = torch.zeros_like(cy)
    # Rb = Rz(yaw) Ry(pitch), columns: the box's axes in the world
    rb = torch.stack([torch.stack([cy * cp, -sy, cy * sp], -1),
                      torch.stack([sy * cp, cy, sy * sp], -1),
                      torch.stack([-sp, zero, cp], -1)], -2)
    rel = rb.transpose(-1, -2) @ rot  # the object's axes in the box's frame
    h = half.to(rot).expand(rot.shape[:-2] + (3,))
    ext = (rel.abs() * h[..., None, :]).sum(-1)
    out = torch.zeros(rot.shape[:-2] + (BOX_COLUMNS,), dtype=rot.dtype, device=rot.device)
    out[..., BOX_CENTER] = centres.to(rot)
    out[..., BOX_HALF] = ext
    out[..., BOX_YAW] = yaw
    out[..., BOX_PITCH] = pitch
    return out


@dataclass
class MovableObstacles:
    """The movable objects one fabric step avoids, for the R rows it steps.

    boxes: (R, m, BOX_COLUMNS) where each object stands now (``object_boxes``).
    ignore: (R, m) bool, objects a row leaves out (it handles them: the object grasped or held,
        the support it sets the held one down on).
    held_centre: (R, 3) the centre of the object a row carries (any finite point where none).
    held_radius: (R,) its ``bounding_radius`` (m); 0 where the row carries nothing.
    range: leaf units (gap over a sphere's radius, less 1): pairs with a movable object or the
        held sphere farther apart than this get no leaf (``controller.avoid_range``).
    """

    boxes: Tensor
    ignore: Tensor
    held_centre: Tensor
    held_radius: Tensor
    range: float = math.inf

    def to(self, device: torch.device, dtype: torch.dtype) -> MovableObstacles:
        return MovableObstacles(self.boxes.to(device, dtype), self.ignore.to(device),
                                self.held_centre.to(device, dtype), self.held_radius.to(device, dtype), self.range)
