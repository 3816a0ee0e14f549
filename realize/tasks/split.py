"""A plan cut in two at an action boundary: the prefix's and the suffix's tasks (stitched segments).

What it does:
  * ``split_task(task, split)``: the prefix task (actions ``0 .. split - 1``, no final cost: its
    cost counts its own control steps; its goal the part of the task's that it settles for good,
    ``settled_goal``: none for a cut after a grasp), the suffix task (``realize.tasks.suffix``:
    actions ``split ..``, the goal and the final cost) and the full layout's columns of each; a
    parameter both segments bind (a plan that comes back to a region) is one ``ConfigError``;
  * ``default_split(task)``: the action after the plan's first grasp (the seed's example);
  * ``chain_tasks(task, cuts)``: the plan cut before each action of ``cuts`` (a chain of
    stitched segments): each segment's task (only the last has the whole goal and the final cost;
    an earlier one the part of the goal its places settle for good, ``settled_goal``) and the full
    layout's columns of each; ``place_cuts(task)``: after every place that another
    action follows (the hand is empty, the object at rest: a stable symbolic state).
What it doesn't: search or simulate the segments (``realize.search.chain``, ``realize.run.stitched_run``).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping

from realize.config import ConfigError
from realize.tasks.goal_spec import GoalSpec
from realize.tasks.spec import TaskSpec, task_for_plan
from realize.tasks.suffix import part_columns, task_suffix

__all__ = ["split_task", "default_split", "chain_tasks", "place_cuts", "settled_goal", "CUT_RULES"]

CUT_RULES = ("after_grasp", "after_each_place")  # stitch.cut


def split_task(task: TaskSpec, split: int) -> tuple[TaskSpec, TaskSpec, list[int], list[int]]:
    """(prefix task, suffix task, prefix columns, suffix columns) of ``task`` cut before ``split``."""
    n = task.n_actions
    if isinstance(split, bool) or not isinstance(split, int) or not 1 <= split < n:
        actions = "; ".join(f"{i}: {a}" for i, a in enumerate(task.plan))
        raise ConfigError(f"stitch.split = {split!r} is invalid: the second segment's first action, 1 .. {n - 1} "
                          f"({actions})")
    prefix = task_for_plan(dataclasses.replace(task, goal=settled_goal(task, split), final_cost=0.0),
                           task.plan[:split])
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


def settled_goal(task: TaskSpec, upto: int) -> GoalSpec:
    """The part of ``task``'s goal that the actions before ``upto`` settle for good: the ``rests_on``
    and ``rests_in`` conditions of each object placed there that no later action grasps again, on a
    support no later action grasps. A chain's segment that ends before the plan does must leave
    them holding (a cube dropped beside the tower is not a start the next segment can finish
    from). ``rests_at`` and ``base_in`` read regions of their own and stay with the last segment."""
    placed = {a.obj for a in task.plan[:upto] if a.template == "place" and a.obj is not None}
    moved_later = {a.obj for a in task.plan[upto:] if a.template == "grasp" and a.obj is not None}
    done = placed - moved_later

    def keep(m: Mapping[str, str]) -> dict[str, str]:
        return {o: s for o, s in m.items() if o in done and s not in moved_later}

    return GoalSpec(on=keep(task.goal.on), inside=keep(task.goal.inside), margin=task.goal.margin)


def place_cuts(task: TaskSpec) -> list[int]:
    """The action after each place that another action follows; a ``ConfigError`` where none is."""
    cuts = [i + 1 for i, a in enumerate(task.plan[:-1]) if a.template == "place"]
    if not cuts:
        raise ConfigError(f"stitch.cut = after_each_place: the plan of {task.source} has no place followed by "
                          "another action; give the cuts as stitch.splits")
    return cuts


def chain_tasks(task: TaskSpec, cuts: list[int], key: str = "stitch.splits") -> tuple[list[TaskSpec], list[list[int]]]:
    """The segments' tasks of ``task`` cut before each action of ``cuts`` (increasing, 1 ..
    n_actions - 1) and the full layout's columns of each; one ``ConfigError`` naming ``key``
    for a bad cut or a parameter bound in two segments."""
    n = task.n_actions
    if not cuts or any(isinstance(c, bool) or not isinstance(c, int) for c in cuts) or \
            list(cuts) != sorted(set(cuts)) or not 1 <= cuts[0] <= cuts[-1] < n:
        actions = "; ".join(f"{i}: {a}" for i, a in enumerate(task.plan))
        raise ConfigError(f"{key} = {list(cuts)!r} is invalid: increasing first actions of the segments after the "
                          f"first, each 1 .. {n - 1} ({actions})")
    bounds = [0, *cuts, n]
    tasks = []
    for a, b in zip(bounds[:-1], bounds[1:]):
        if b == n:
            t = task_suffix(task, a, key=key)
        else:
            t = task_for_plan(dataclasses.replace(task, goal=settled_goal(task, b), final_cost=0.0), task.plan[a:b])
            t.name = f"{task.name}[{a or ''}:{b}]"
        tasks.append(t)
    seen: dict[str, int] = {}
    for j, t in enumerate(tasks):
        for name in t.layout.names:
            if name in seen:
                raise ConfigError(f"{key} = {list(cuts)}: parameter {name} is bound in segments {seen[name]} and {j}; "
                                  "cut where no parameter (or goal region) is used in two segments")
            seen[name] = j
    return tasks, [part_columns(task, t) for t in tasks]
