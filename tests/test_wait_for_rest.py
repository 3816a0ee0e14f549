"""Which deviations the executor waits on, for every object to come to rest, before it reads the
state to repair from (``realize.repair.executor.waits_for_rest``): the reasons as the world logs of
the grasp_slip and tower_knocked studies write them."""

from __future__ import annotations

import pytest

from realize.repair.executor import waits_for_rest


@pytest.mark.parametrize("reasons, waits", [
    (["action_failed: 1:place:object_dropped"], True),  # a place that knocked the block out of the hand
    (["action_failed: 0:grasp:object_dropped"], True),
    (["support_moved: cube_b, which a remaining place stacks on, is 0.039 m lower than the plan assumed "
      "(tolerance 0.02 m)"], True),
    (["grasp_lost: the plan holds cube_c; the hand holds nothing"], True),
    (["action_failed: 4:goal:goal_not_reached"], False),  # nothing fell: read at once
    (["action_failed: 2:grasp:timeout"], False),
    (["object_moved: cube_c is 0.06 m from where the plan assumed"], False),
    ([], False),
])
def test_a_deviation_that_drops_an_object_is_waited_on(reasons: list[str], waits: bool) -> None:
    assert waits_for_rest(reasons) is waits
