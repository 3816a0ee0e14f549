"""Regions framed by a movable object, resolved where the robot sees that object now.

What it does: ``track_region`` moves a parameter's points by how far the object its region is
framed by lies from its config pose (``controller.track_objects``), as a robot with perception
aims at an object where it lies.
What it doesn't: decide which regions are framed by what (``TaskSpec.frame_of``), move the
hemisphere's centre (``Manipulate`` adds the returned shift to it), or turn a region with the
object's yaw: tried (a hemisphere's points turned about the box's vertical by its yaw offset
modulo 90 degrees), it removed the two-cubes and tower grasp drops but lost more plans than it
saved in validation (docs/objects.md, "Grasps that survive a turned object").
"""

from __future__ import annotations

import torch
from torch import Tensor

from realize.tasks.frames import position_columns
from realize.tasks.regions import Region
from realize.world.objects import SceneObject


def track_region(region: Region, params: Tensor, obj: SceneObject, seen: Tensor,
                 min_shift: float) -> tuple[Tensor, Tensor]:
    """(params, shift) of a region framed by ``obj``, seen with its centre at ``seen`` (n, 3):
    ``params``' position columns moved by the shift (n, 3) of the object's centre from its
    config place; a shift within ``min_shift`` counts as none (the nominal world reads the
    same numbers bit for bit)."""
    shift = seen - torch.tensor(obj.position, dtype=seen.dtype, device=seen.device)
    shift = torch.where((shift.norm(dim=1) > min_shift)[:, None], shift, torch.zeros_like(shift))
    k = position_columns(region)
    params = params.clone()
    params[:, :k] += shift[:, :k].to(params.dtype)
    return params, shift
