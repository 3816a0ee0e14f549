"""Per-action and per-segment validation counts (``realize.validation.action_outcomes``) add up.

On hand-made replica outcomes of a 4-action plan cut into segments [0, 1] and [2, 3] (+ goal):
each action's ``completed`` never exceeds the one before it, the goal's is the replicas that
succeeded, every failure is counted at the action it names, and the failures of all entries sum
to the replicas that did not succeed; the weak-action lines name each failing action with its
reasons. A real validation's numbers are checked the same way in ``tests/test_replay.py``
(``test_validation_writes_result_json``).
"""

from __future__ import annotations

from typing import Any

import pytest
import torch

from realize.validation.action_outcomes import GOAL, plan_outcomes, weak_lines

PLAN = ["grasp(a, Ga)", "place(a, Pa)", "grasp(b, Gb)", "place(b, Pb)"]

# (actions completed, goal, failure) per replica: 8 replicas of the plan above
REPLICAS = [
    (4, True, ""), (4, True, ""), (4, True, ""),
    (4, False, "4:goal:goal_not_reached"),
    (3, False, "3:place:object_dropped"), (3, False, "3:place:object_dropped"),
    (1, False, "1:place:timeout"),
    (0, False, "0:grasp:timeout"),
]


def _rollout() -> tuple[torch.Tensor, torch.Tensor, list[str]]:
    done = torch.tensor([n for n, _, _ in REPLICAS])
    action_success = torch.arange(len(PLAN)).unsqueeze(0) < done.unsqueeze(1)  # (R, A): the first n actions
    goal = torch.tensor([g for _, g, _ in REPLICAS])
    return action_success, goal, [f for _, _, f in REPLICAS]


def assert_adds_up(per_action: list[dict[str, Any]], replicas: int, successes: int) -> None:
    """The invariants of a stored ``per_action`` list (also used on a real validation's)."""
    completed = [a["completed"] for a in per_action]
    assert all(x >= y for x, y in zip(completed, completed[1:]))
    assert per_action[-1]["action"] == GOAL and completed[-1] == successes
    assert per_action[0]["started"] == replicas
    for a, b in zip(per_action, per_action[1:]):
        assert b["started"] == a["completed"]
    for a in per_action:
        assert sum(a["failures"].values()) == a["started"] - a["completed"]
    assert sum(sum(a["failures"].values()) for a in per_action) == replicas - successes


def test_per_action_counts_add_up() -> None:
    action_success, goal, failures = _rollout()
    out = plan_outcomes(action_success, goal, failures, PLAN, cuts=(2,))
    d = out.to_dict()
    assert out.replicas == 8 and out.successes == 3
    assert_adds_up(d["per_action"], 8, 3)
    got = [(a["index"], a["action"], a["segment"], a["started"], a["completed"], a["failures"]) for a in d["per_action"]]
    assert got == [
        (0, PLAN[0], 0, 8, 7, {"timeout": 1}),
        (1, PLAN[1], 0, 7, 6, {"timeout": 1}),
        (2, PLAN[2], 1, 6, 6, {}),
        (3, PLAN[3], 1, 6, 4, {"object_dropped": 2}),
        (4, GOAL, 1, 4, 3, {"goal_not_reached": 1}),
    ]


def test_per_segment_counts_add_up() -> None:
    action_success, goal, failures = _rollout()
    segs = plan_outcomes(action_success, goal, failures, PLAN, cuts=(2,)).to_dict()["per_segment"]
    assert [(s["index"], s["first"], s["last"], s["started"], s["completed"]) for s in segs] == \
        [(0, 0, 1, 8, 6), (1, 2, 3, 6, 3)]
    assert segs[0]["failures"] == {"0:grasp:timeout": 1, "1:place:timeout": 1}
    assert segs[1]["failures"] == {"3:place:object_dropped": 2, "4:goal:goal_not_reached": 1}
    assert sum(sum(s["failures"].values()) for s in segs) == 8 - 3
    whole = plan_outcomes(action_success, goal, failures, PLAN).to_dict()["per_segment"]  # searched whole
    assert [(s["first"], s["last"], s["started"], s["completed"]) for s in whole] == [(0, 3, 8, 3)]


def test_weak_lines_name_each_failing_action_and_its_reasons() -> None:
    action_success, goal, failures = _rollout()
    lines = weak_lines(plan_outcomes(action_success, goal, failures, PLAN).to_dict()["per_action"])
    assert lines == ["action 0 grasp(a, Ga): 7/8 completed; failed: timeout 1",
                     "action 1 place(a, Pa): 6/7 completed; failed: timeout 1",
                     "action 3 place(b, Pb): 4/6 completed; failed: object_dropped 2",
                     "goal: 3/4 completed; failed: goal_not_reached 1"]


def test_bad_input_is_one_line() -> None:
    action_success, goal, failures = _rollout()
    with pytest.raises(ValueError, match="3 descriptions"):
        plan_outcomes(action_success, goal, failures, PLAN[:3])
    with pytest.raises(ValueError, match="not increasing"):
        plan_outcomes(action_success, goal, failures, PLAN, cuts=(2, 2))
    with pytest.raises(ValueError, match="names action 7"):
        plan_outcomes(action_success, goal, ["7:place:timeout", *failures[1:]], PLAN)
