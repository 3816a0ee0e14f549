"""A plan's remaining actions as a task of their own, and whether they can start from a state.

What it does:
  * ``task_suffix(task, k)``: the task of actions ``k, k+1, ...`` of ``task``'s plan (0-based),
    with only the parameters those actions bind (plus the goal's ``base_in``), the same goal
    and final cost; its eq. (2) cost then counts the remaining actions only;
  * ``suffix_columns(task, k)``: which columns of the full task's sample matrix the suffix's
    columns are (to pick a plan's remaining parameters out of a full one, e.g. a run's best);
    ``part_columns(task, part)`` the same for any task over some of its parameters;
  * ``tail_index(whole, part)``: where a task mapping's plan is the tail of another's (same
    parameters, goal and final cost), so a new action sequence can be searched as a replan of
    those actions;
  * ``check_suffix_start(task, state)``: what the action templates assume about the actions
    before them in the same rollout, checked against the state the suffix starts from: the
    hand's contents through the remaining plan (``realize.tasks.spec.check_hand``) starting
    from the state's ``held`` object. ``place(o, ...)`` begins only while the fingers hold o
    (``Place.begin``: a grasp happened before); ``grasp`` approaches with an open gripper, so it
    needs an empty hand (it would drop what it holds); ``push`` drives a closed gripper and
    needs none in hand. ``move_to`` assumes nothing: it plans from where the base is and holds
    the arm and the gripper as they are (the rollout starts the gripper command from the state).
What it doesn't: simulate (``realize.realization``), load state files (``realize.world.state``)
or read run directories (``realize.spec.replan_from``).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from realize.config import ConfigError
from realize.world.state import SceneState
from realize.tasks.spec import TaskSpec, check_hand, task_for_plan

__all__ = ["task_suffix", "suffix_columns", "part_columns", "check_suffix_start", "tail_index"]


def task_suffix(task: TaskSpec, k: int, key: str = "replan.action") -> TaskSpec:
    """The task of ``task``'s actions ``k..`` (``key`` names the setting in errors)."""
    n = task.n_actions
    if isinstance(k, bool) or not isinstance(k, int) or not 0 <= k < n:
        actions = "; ".join(f"{i}: {a}" for i, a in enumerate(task.plan))
        raise ConfigError(f"{key} = {k!r} is invalid: the plan has {n} actions, numbered from 0 ({actions})")
    out = task_for_plan(task, task.plan[k:])
    out.name = task.name if k == 0 else f"{task.name}[{k}:]"
    return out


def part_columns(task: TaskSpec, part: TaskSpec) -> list[int]:
    """Column indices, in ``task``'s sample matrix, of ``part``'s columns (a task over some of
    ``task``'s parameters: a suffix, or a stitched search's prefix)."""
    full = task.layout
    return [i for name in part.layout.names for i in range(full.slices[name].start, full.slices[name].stop)]


def suffix_columns(task: TaskSpec, k: int) -> list[int]:
    """Column indices, in ``task``'s sample matrix, of ``task_suffix(task, k)``'s columns."""
    return part_columns(task, task_suffix(task, k))


def check_suffix_start(task: TaskSpec, state: SceneState, where: str = "replan") -> None:
    """Refuse a start state the suffix cannot begin from (module docstring)."""
    try:
        check_hand(task.plan, "the remaining plan", state.held)
    except ConfigError as e:
        raise ConfigError(f"{where}: {e} (the state, {state.source or 'given'}, holds "
                          f"{state.held or 'nothing'})") from None


def _action_text(a: object) -> str:
    return "".join(str(a).split())


def tail_index(whole: Mapping[str, Any], part: Mapping[str, Any]) -> int | None:
    """``k`` where task mapping ``part``'s plan is ``whole``'s plan from action ``k`` on and both
    have the same params, goal and final cost; None otherwise (plain task mappings, as configs
    hold them)."""
    a = [_action_text(x) for x in whole.get("plan") or []]
    b = [_action_text(x) for x in part.get("plan") or []]
    if not b or len(b) > len(a) or a[len(a) - len(b):] != b:
        return None
    for key in ("params", "goal", "final_cost"):
        if whole.get(key) != part.get(key):
            return None
    return len(a) - len(b)
