"""The planner's square grip (realize/execution/in_hand.py): a tilted object in the hand is turned
to the nearest orientation square with the hand, about its own centre, and nothing else moves."""

from __future__ import annotations

import math

import numpy as np
from scipy.spatial.transform import Rotation

from realize.execution.in_hand import SQUARE, square_in_hand
from realize.world.objects import SceneObject
from realize.world.state import ObjectPose, SceneState

REST = (0.1, 1.0, (0.8, 0.1, 0.1, 1.0), "table1")  # mass, friction, colour, support
CUBE = SceneObject("cube", "box", (0.0225, 0.0225, 0.0225), (0.0, 0.0, 0.7425), 0.0, *REST)
BAR = SceneObject("bar", "box", (0.06, 0.02, 0.02), (0.0, 0.0, 0.74), 0.0, *REST)
CAN = SceneObject("can", "cylinder", (0.03, 0.03, 0.06), (0.0, 0.0, 0.78), 0.0, *REST)
HAND = Rotation.from_euler("xyz", [0.3, -1.2, 0.7])  # an arbitrary hand orientation
HAND_POSE = (0.1, 0.2, 0.9, *np.roll(HAND.as_quat(), 1))


def held(obj: SceneObject, rel: Rotation, held_name: str | None = None) -> SceneState:
    q = np.roll((HAND * rel).as_quat(), 1)
    return SceneState(base=(0.0, 0.0, 0.0), gripper_closed=True, held=held_name or obj.name,
                      objects={obj.name: ObjectPose((0.11, 0.21, 0.85), tuple(q)), "other": ObjectPose((1, 1, 0.7))})


def rel_of(state: SceneState, name: str) -> Rotation:
    return HAND.inv() * Rotation.from_quat(np.roll(state.objects[name].quaternion, -1))


def test_the_square_turns_are_the_24_rotations_of_a_cube() -> None:
    assert len(SQUARE) == 24
    assert len({tuple(m.flatten()) for m in SQUARE}) == 24
    assert all(math.isclose(np.linalg.det(m), 1.0) and np.allclose(m @ m.T, np.eye(3)) for m in SQUARE)


def test_a_tilted_cube_is_squared_with_the_hand_about_its_centre() -> None:
    tilt = Rotation.from_euler("xyz", [0.09, -0.05, 0.03])  # about 6 degrees off square
    s = square_in_hand(held(CUBE, tilt), HAND_POSE, CUBE)
    assert np.allclose(rel_of(s, "cube").as_matrix(), np.eye(3), atol=1e-9)
    assert s.objects["cube"].position == (0.11, 0.21, 0.85) and s.objects["other"] == held(CUBE, tilt).objects["other"]


def test_a_cube_turned_past_45_degrees_goes_to_the_next_square_face() -> None:
    s = square_in_hand(held(CUBE, Rotation.from_euler("z", 1.2)), HAND_POSE, CUBE)  # 69 degrees: nearer 90
    assert np.allclose(rel_of(s, "cube").as_matrix(), Rotation.from_euler("z", math.pi / 2).as_matrix(), atol=1e-9)


def test_a_bar_keeps_its_long_axis_where_it_lies() -> None:
    """A 12 cm bar lying across the hand 10 degrees off: its long axis stays across (a box is
    squared among all 24 turns, so its long side ends along the nearest hand axis)."""
    rel = Rotation.from_euler("z", math.pi / 2 + 0.17)
    s = square_in_hand(held(BAR, rel), HAND_POSE, BAR)
    long_axis = rel_of(s, "bar").as_matrix()[:, 0]
    assert np.allclose(np.abs(long_axis), [0.0, 1.0, 0.0], atol=1e-9)


def test_a_cylinder_keeps_its_turn_about_its_axis() -> None:
    rel = Rotation.from_euler("zx", [0.8, 0.1])  # turned 46 degrees about its axis, the axis tilted 6
    s = square_in_hand(held(CAN, rel), HAND_POSE, CAN)
    m = rel_of(s, "can").as_matrix()
    assert np.allclose(m[:, 2], [0.0, 0.0, 1.0], atol=1e-9)
    assert math.isclose(math.atan2(m[1, 0], m[0, 0]), 0.8, abs_tol=0.02)


def test_nothing_changes_where_the_object_is_not_in_hand() -> None:
    tilt = Rotation.from_euler("x", 0.1)
    s = held(CUBE, tilt, held_name="other")
    assert square_in_hand(s, HAND_POSE, CUBE) is s


def test_given_the_approach_the_centre_moves_onto_its_line_at_the_same_depth() -> None:
    approach = (0.0, 0.0, 1.0)  # in the hand's frame
    a = HAND.apply(approach)
    side = HAND.apply((0.0, 1.0, 0.0))
    centre = np.array(HAND_POSE[:3]) + 0.03 * a + 0.02 * side  # 3 cm deep, 2 cm off the line
    state = SceneState(base=(0.0, 0.0, 0.0), objects={"cube": ObjectPose(tuple(centre), HAND_POSE[3:])}, held="cube",
                       gripper_closed=True)
    out = square_in_hand(state, HAND_POSE, CUBE, approach).objects["cube"].position
    assert np.allclose(out, np.array(HAND_POSE[:3]) + 0.03 * a, atol=1e-9)
    assert square_in_hand(state, HAND_POSE, CUBE).objects["cube"].position == tuple(centre)  # without: kept


def test_a_grip_that_slips_squared_is_tried_shallower_until_one_holds() -> None:
    """firm_grip: squared and centred at its own depth (3 cm), then DEPTH_STEP_M shallower each
    time, until the restore holds (here: the centre within 1.8 cm of the hand, measured along the
    approach independently of firm_grip); never shallower than the hand's origin."""
    from realize.execution.in_hand import DEPTH_STEP_M, firm_grip

    approach = (0.0, 0.0, 1.0)
    a, side = HAND.apply(approach), HAND.apply((0.0, 1.0, 0.0))
    centre = np.array(HAND_POSE[:3]) + 0.03 * a + 0.02 * side
    state = SceneState(base=(0.0, 0.0, 0.0), objects={"cube": ObjectPose(tuple(centre), HAND_POSE[3:])}, held="cube",
                       gripper_closed=True)

    def depth_of(s: SceneState) -> float:
        return float(np.dot(np.array(s.objects["cube"].position) - np.array(HAND_POSE[:3]), a))

    tried: list[float] = []

    def holds(s: SceneState) -> bool:
        tried.append(depth_of(s))
        return depth_of(s) <= 0.018 + 1e-9

    out = firm_grip(state, HAND_POSE, CUBE, approach, holds)
    assert np.allclose(tried, [0.03 - k * DEPTH_STEP_M for k in range(len(tried))], atol=1e-9)
    assert depth_of(out) <= 0.018 + 1e-9 and depth_of(out) > 0.018 - DEPTH_STEP_M
    centred = np.array(out.objects["cube"].position) - np.array(HAND_POSE[:3])
    assert np.allclose(centred, depth_of(out) * a, atol=1e-9)  # on the approach line
    never = firm_grip(state, HAND_POSE, CUBE, approach, lambda s: False)
    assert abs(depth_of(never)) < 1e-9  # none holds: at the hand's origin, no nearer
    assert firm_grip(state, HAND_POSE, CUBE, approach, lambda s: True).objects["cube"].position == \
        square_in_hand(state, HAND_POSE, CUBE, approach).objects["cube"].position  # the first holds: its own depth
