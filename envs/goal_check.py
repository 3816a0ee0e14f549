"""The success check of the realize tasks: a task goal evaluated on every copy, predicate by predicate.

What it does: ``goal_info(goal, geometry, regions, pos, speed, base)`` is what the tasks'
``evaluate`` returns: ``success`` (``realize.tasks.goals.goal_reached``) and one entry per
predicate (``cube_on_table2``, ``cube_in_box``, ``base_in_Exit``). ``default_goal_regions()``
is the region a goal may name when a task is made without ``goal_regions``: the default task's
``Exit`` (``configs/task/pick_place.yaml``), the one place the exit is given.
What it doesn't: read the simulator (the tasks hand it positions and speeds) or build goals
(``realize.tasks.goal_spec``).
"""

from __future__ import annotations

from collections.abc import Mapping

import torch
import yaml

from realize.paths import CONFIG_DIR
from realize.tasks.goal_spec import GoalSpec
from realize.tasks.goals import base_in_rectangle, goal_reached, object_in_container, object_on_object, object_on_table
from realize.tasks.param_layout import region_from_dict
from realize.tasks.regions import Box, Region
from realize.world.geometry import SceneGeometry

__all__ = ["DEFAULT_TASK", "EXIT", "default_goal_regions", "goal_info"]

DEFAULT_TASK = CONFIG_DIR / "task" / "pick_place.yaml"  # its goal and its exit: a task's default success check
EXIT = "Exit"  # the default goal's base_in: the default task's exit region


def default_goal_regions() -> dict[str, Region]:
    """``{"Exit": the default task's exit box}``."""
    d = yaml.safe_load(DEFAULT_TASK.read_text())["params"][EXIT]
    return {EXIT: region_from_dict(d, f"{DEFAULT_TASK.name}:params.{EXIT}")}


def goal_info(goal: GoalSpec, geometry: SceneGeometry, regions: Mapping[str, Region], pos: torch.Tensor,
              speed: torch.Tensor, base: torch.Tensor, frames: Mapping[str, str] | None = None
              ) -> dict[str, torch.Tensor]:
    """(N,) bools: ``success`` and each predicate of ``goal``, from the objects' centres ``pos``
    (N, m, 3), speeds (N, m) and the base's xy (N, 2), every copy in its local frame; ``frames``:
    the regions' frames (a spot framed by a movable object follows it, ``goal_reached``)."""
    g = geometry
    ok, _ = goal_reached(goal, g, regions, pos, speed, base, frames=frames)
    info = dict(success=ok)
    for name, support in goal.on.items():
        k = g.object_index(name)
        if support in g.object_names:
            j = g.object_index(support)
            info[f"{name}_on_{support}"] = object_on_object(pos[:, k], speed[:, k], pos[:, j], speed[:, j], g, name,
                                                            support)
        else:
            info[f"{name}_on_{support}"] = object_on_table(pos[:, k], speed[:, k], g, name, support)
    for name, box in goal.inside.items():
        k = g.object_index(name)
        info[f"{name}_in_{box}"] = object_in_container(pos[:, k], speed[:, k], g, box)
    if goal.base_in is not None:
        area = regions[goal.base_in]
        assert isinstance(area, Box)  # goal_from_dict checked it
        info[f"base_in_{goal.base_in}"] = base_in_rectangle(base, tuple(area.low), tuple(area.high))
    return info
