"""Where a validated plan fails: per action and per segment, how many replicas completed it and why the others did not.

What it does: ``plan_outcomes`` reads one plan's R replica rollouts (``RolloutResult``'s
``action_success`` (R, A), ``goal`` (R,) and failure strings ``"<action>:<template>:<reason>"``)
and counts, for each action of the plan and then the goal, the replicas that started it (completed
every action before it), that completed it, and those that failed there by reason; for each
segment of the run's stitched search (``stitch`` cuts; a plan searched whole is one segment) the
same, its failures named by action. The counts add up: ``completed`` never grows along the plan,
the goal's ``completed`` is the replicas that succeeded, and the failures of all actions and the
goal sum to the replicas that did not. ``weak_lines`` gives one line per action some replica
failed in (what a run prints after its validation).
What it doesn't: simulate (``realize.validation.returned_plan``, ``realize.validation.candidates`` call
it on their rollouts) or decide which plan a run returns.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Sequence
from dataclasses import asdict, dataclass
from typing import Any

import torch
from torch import Tensor

__all__ = ["ActionOutcome", "SegmentOutcome", "PlanOutcomes", "plan_outcomes", "weak_lines", "GOAL"]

GOAL = "goal"  # the name of the entry after the last action (the goal's check)


@dataclass
class ActionOutcome:
    """One action of the plan (or the goal, ``index`` = the number of actions) over the replicas."""

    index: int
    action: str  # "place(cubeB, CubeB_p)", or "goal"
    segment: int  # the stitched segment it belongs to (0 in a plan searched whole)
    started: int  # replicas that completed every action before it
    completed: int
    failures: dict[str, int]  # reason ("object_dropped", "timeout", ...) -> replicas that failed here

    @property
    def failed(self) -> int:
        return self.started - self.completed


@dataclass
class SegmentOutcome:
    """One stitched segment (actions ``first .. last``; the last segment also holds the goal)."""

    index: int
    first: int
    last: int
    started: int  # replicas that completed every segment before it
    completed: int  # replicas that completed its last action (the last segment: and the goal)
    failures: dict[str, int]  # "<action>:<template>:<reason>" -> replicas that failed in it


@dataclass
class PlanOutcomes:
    replicas: int
    successes: int
    actions: list[ActionOutcome]  # one per action, then the goal
    segments: list[SegmentOutcome]

    def to_dict(self) -> dict[str, Any]:
        """``per_action`` and ``per_segment``: the two lists as a validation block stores them."""
        return {"per_action": [asdict(a) for a in self.actions], "per_segment": [asdict(s) for s in self.segments]}


def _failure_index(failure: str, n_actions: int) -> tuple[int, str]:
    """(action index, reason) of a rollout's failure string; the goal's index is ``n_actions``."""
    head, _, rest = failure.partition(":")
    _, _, reason = rest.partition(":")
    try:
        a = int(head)
    except ValueError:
        raise ValueError(f"failure {failure!r} does not start with an action index") from None
    if not 0 <= a <= n_actions:
        raise ValueError(f"failure {failure!r} names action {a}: the plan has {n_actions}")
    return a, reason or rest


def plan_outcomes(action_success: Tensor, goal: Tensor, failures: Sequence[str], plan: Sequence[str],
                  cuts: Sequence[int] = ()) -> PlanOutcomes:
    """The per-action and per-segment counts of one plan's replicas (module docstring).

    ``action_success`` (R, A) and ``goal`` (R,) bool, ``failures`` R strings ("" where the replica
    succeeded), ``plan`` the A actions' descriptions, ``cuts`` the first action of each segment
    after the first (increasing, 1 .. A - 1)."""
    R, A = action_success.shape
    if len(plan) != A or goal.shape != (R,) or len(failures) != R:
        raise ValueError(f"plan_outcomes: {A} actions and {R} replicas, but {len(plan)} descriptions, goal "
                         f"{tuple(goal.shape)} and {len(failures)} failure strings")
    bounds = [0, *cuts, A]
    if any(b >= c for b, c in zip(bounds[:-1], bounds[1:])):
        raise ValueError(f"plan_outcomes: cuts {list(cuts)} are not increasing action indices in 1 .. {A - 1}")
    # a replica completed action a when it completed every action up to a (a plan stops at its first failure)
    done = action_success.to(torch.int64).cumprod(dim=1).bool()
    reached = torch.cat([done, (done[:, -1] & goal.bool()).unsqueeze(1)], dim=1) if A else goal.bool().unsqueeze(1)
    completed = reached.sum(dim=0).tolist()  # A + 1: each action's, then the goal's
    started = [R, *completed[:-1]]
    where = [_failure_index(f, A) for f in failures if f]
    by_action = [Counter(reason for a, reason in where if a == i) for i in range(A + 1)]
    seg_of = [j for j in range(len(bounds) - 1) for _ in range(bounds[j], bounds[j + 1])] + [len(bounds) - 2]
    actions = [ActionOutcome(i, plan[i] if i < A else GOAL, seg_of[i], int(started[i]), int(completed[i]),
                             dict(sorted(by_action[i].items()))) for i in range(A + 1)]
    segments = []
    for j, (b, c) in enumerate(zip(bounds[:-1], bounds[1:])):
        last = c if c == A else c - 1  # the last segment ends with the goal
        fails = Counter(f for f, (a, _) in zip((f for f in failures if f), where) if b <= a <= last)
        segments.append(SegmentOutcome(j, b, min(last, A - 1), int(started[b]), int(completed[last]),
                                       dict(sorted(fails.items()))))
    return PlanOutcomes(R, int(completed[-1]), actions, segments)


def weak_lines(per_action: Sequence[dict[str, Any]]) -> list[str]:
    """One line per action (or the goal) some replica failed in, from a stored ``per_action`` list:
    ``"action 3 place(cubeC, C_p): 54/64 completed; failed: object_dropped 6, timeout 4"``."""
    out = []
    for a in per_action:
        if a["started"] > a["completed"]:
            what = "goal" if a["action"] == GOAL else f"action {a['index']} {a['action']}"
            reasons = ", ".join(f"{r} {n}" for r, n in sorted(a["failures"].items(), key=lambda kv: (-kv[1], kv[0])))
            out.append(f"{what}: {a['completed']}/{a['started']} completed; failed: {reasons or 'no reason recorded'}")
    return out
