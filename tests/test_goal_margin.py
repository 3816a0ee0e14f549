"""``goal.margin``: while a run searches, a stacked object must stand that much further inside its
support's top; validation and execution judge the goal itself. Checked against the geometry (a
block 1.5 cm off its support's centre, on a 4.5 cm block whose top admits 2.25 cm) and the specs
each stage builds."""

from __future__ import annotations

import dataclasses

import pytest
import torch

from helpers import compose_config
from realize.config import ConfigError
from realize.spec.run_spec import build_run_spec
from realize.tasks.goal_spec import GoalSpec, goal_from_dict
from realize.tasks.goals import goal_reached
from realize.tasks.split import settled_goal


@pytest.fixture(scope="module")
def stack_two():
    return build_run_spec(compose_config("experiment=stack_two", "device=cpu", "+task.goal.margin=0.01"))


def test_the_margin_shrinks_the_support_top_by_itself(stack_two) -> None:
    spec = stack_two
    g = spec.geometry
    names = list(g.object_names)
    on = dict(spec.task.goal.on)
    (top, support), = [(k, v) for k, v in on.items() if v in names]
    s = g.object(support)
    r = min(s.half_size[0], s.half_size[1])
    assert spec.task.goal.margin == 0.01 and r == pytest.approx(0.0225)
    objects = torch.zeros(2, len(names), 3)
    for k, name in enumerate(names):  # every object where the goal has it: the others on their tables
        objects[:, k] = torch.tensor(g.object(name).position, dtype=torch.float32)
    i, j = names.index(top), names.index(support)
    objects[:, j] = objects[0, j]
    z = objects[0, j, 2] + s.half_height + g.object(top).half_height
    objects[0, i] = objects[0, j] + torch.tensor([0.015, 0.0, 0.0]); objects[0, i, 2] = z  # 1.5 cm off centre
    objects[1, i] = objects[0, j] + torch.tensor([0.010, 0.0, 0.0]); objects[1, i, 2] = z  # 1.0 cm off centre
    speeds = torch.zeros(2, len(names))
    judged = GoalSpec(on={top: support})  # the stack alone
    searched = dataclasses.replace(judged, margin=0.01)
    base = torch.zeros(2, 2)
    ok_j, d_j = goal_reached(judged, g, spec.task.layout.regions, objects, speeds, base)
    ok_s, d_s = goal_reached(searched, g, spec.task.layout.regions, objects, speeds, base)
    assert ok_j.tolist() == [True, True] and d_j.tolist() == [0.0, 0.0]
    assert ok_s.tolist() == [False, True]  # 1.5 cm > 2.25 - 1 cm; 1.0 cm is inside 1.25 cm
    assert d_s[0].item() == pytest.approx(0.015 - (0.0225 - 0.01), abs=1e-6)


def test_validation_and_execution_judge_the_goal_itself(stack_two) -> None:
    from realize.validation.replay import replay_spec

    class Run:  # the fields replay_spec reads of a saved run
        leader = None
        best_z = [0.0] * stack_two.task.layout.dim
        run_dir = "run"

    assert replay_spec(stack_two, Run()).task.goal.margin == 0.01  # a replay: the run's own outcome
    judged = replay_spec(stack_two, Run(), judged=True)
    assert judged.task.goal.margin == 0.0 and judged.task.goal.on == stack_two.task.goal.on
    assert stack_two.task.goal.margin == 0.01  # a new spec, the run's unchanged
    assert settled_goal(stack_two.task, len(stack_two.task.plan)).margin == 0.01  # a chain's segments search with it


def test_the_margin_is_read_and_checked(stack_two) -> None:
    d = stack_two.task.goal.to_dict()
    assert d["margin"] == 0.01
    again = goal_from_dict(d, stack_two.geometry, stack_two.task.layout.regions)
    assert again == stack_two.task.goal
    for bad, needle in ((-0.01, "must be a distance >= 0"), (0.03, "the margin must be smaller"),
                        (True, "must be a distance")):
        with pytest.raises(ConfigError, match=needle):
            goal_from_dict({**d, "margin": bad}, stack_two.geometry, stack_two.task.layout.regions)
