"""A plan cut in two at an action boundary: the prefix's and the suffix's tasks (stitched segments).

What it does:
  * ``split_task(task, split)``: the prefix task (actions ``0 .. split - 1``, no goal, no final
    cost: its cost counts its own control steps), the suffix task (``realize.tasks.suffix``:
    actions ``split ..``, the goal and the final cost) and the full layout's columns of each; a
    parameter both segments bind (a plan that comes back to a region) is one ``ConfigError``;
  * ``default_split(task)``: the action after the plan's first grasp (the seed's example).
What it doesn't: search or simulate the segments (``realize.search.stitched``, ``realize.app.stitched``).
"""

from __future__ import annotations

import dataclasses

from realize.config import ConfigError
from realize.tasks.goal_spec import GoalSpec
from realize.tasks.spec import TaskSpec, task_for_plan
from realize.tasks.suffix import part_columns, task_suffix

__all__ = ["split_task", "default_split"]


def split_task(task: TaskSpec, split: int) -> tuple[TaskSpec, TaskSpec, list[int], list[int]]:
    """(prefix task, suffix task, prefix columns, suffix columns) of ``task`` cut before ``split``."""
    n = task.n_actions
    if isinstance(split, bool) or not isinstance(split, int) or not 1 <= split < n:
        actions = "; ".join(f"{i}: {a}" for i, a in enumerate(task.plan))
        raise ConfigError(f"stitch.split = {split!r} is invalid: the second segment's first action, 1 .. {n - 1} "
                          f"({actions})")
    prefix = task_for_plan(dataclasses.replace(task, goal=GoalSpec(), final_cost=0.0), task.plan[:split])
    prefix.name = f"{task.name}[:{split}]"
    suffix = task_suffix(task, split, key="stitch.split")
    shared = sorted(set(prefix.layout.names) & set(suffix.layout.names))
    if shared:
        raise ConfigError(f"stitch.split = {split}: parameters {shared} are bound on both sides of the cut; "
                          "cut where no parameter (or goal region) is used on both sides")
    return prefix, suffix, part_columns(task, prefix), part_columns(task, suffix)


def default_split(task: TaskSpec) -> int:
    """The action after the plan's first grasp; a ``ConfigError`` where none is followed by another."""
    for i, a in enumerate(task.plan[:-1]):
        if a.template == "grasp":
            return i + 1
    raise ConfigError(f"stitch.split: the plan of {task.source} has no grasp followed by another action; give "
                      "the second segment's first action (0-based)")
