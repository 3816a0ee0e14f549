"""What the planner assumes of an object in the hand: square in the grip, as a grasp leaves it.

What it does: ``square_in_hand(state, hand, obj)`` returns ``state`` with its held object turned,
about its own centre, to the nearest orientation that sits square with the hand: a box's axes
along the hand's axes (the nearest of the 24 such turns, ``SQUARE``), a cylinder's axis along
the nearest hand axis (its turn about that axis kept). Given the hand's ``approach`` axis, the
centre also moves onto the approach line through the TCP link (its depth along it kept, or
``depth``): centred between the pads, as a grasp aims it. ``firm_grip(state, hand, obj, approach,
holds)`` squares and centres it at the first depth whose restore ``holds``, from its own
toward the hand (the link's origin) in ``DEPTH_STEP_M`` steps.

Why: a state captured from a world holds the object as it slipped into the grip, a few degrees
tilted between the finger pads. Restored at rest into the planner's scenes, such a grip can let
go in the first steps (measured: the seed task's worlds 6 and 11 at seed 0, the cube tilted about
5 degrees in the hand, fell out within 3 control steps of every restore, so every replan and
check failed with ``place:not_holding`` although the world's hand held it; squared, it held in
both, and in the worlds that held before). A cube held 2.7 cm to one side of the pads' middle
(``table_moved`` world 6 with realistic noise) held at rest but left the hand on every replan's
drive, squared too; centred as well, it holds (tests/test_execution_world.py). A robot does not see the in-hand tilt either: its
planner assumes the grasp it commanded. The world itself is never changed: only what is planned
from.
What it doesn't: read a simulator (the hand's pose comes with the observation; ``firm_grip``'s
``holds`` does), move an object farther out along the approach than it is, or touch an object
not in hand.
"""

from __future__ import annotations

import dataclasses
import itertools
from collections.abc import Callable, Sequence

import numpy as np
from scipy.spatial.transform import Rotation

from realize.world.objects import SceneObject
from realize.world.state import ObjectPose, SceneState

__all__ = ["SQUARE", "square_in_hand", "firm_grip", "DEPTH_STEP_M"]


def _xyzw(q: Sequence[float]) -> list[float]:
    return [q[1], q[2], q[3], q[0]]


def _square_turns() -> list[np.ndarray]:
    """The 24 rotations that map the axes onto the axes (signed permutations, determinant 1)."""
    out = []
    for perm in itertools.permutations(range(3)):
        for signs in itertools.product((1.0, -1.0), repeat=3):
            m = np.zeros((3, 3))
            for i, (j, s) in enumerate(zip(perm, signs)):
                m[i, j] = s
            if np.linalg.det(m) > 0:
                out.append(m)
    return out


SQUARE = _square_turns()
DEPTH_STEP_M = 0.004  # a squared grip that slips is tried this much nearer the hand, again and again


def square_in_hand(state: SceneState, hand: Sequence[float], obj: SceneObject,
                   approach: Sequence[float] | None = None, depth: float | None = None) -> SceneState:
    """``state`` with its held object ``obj`` squared in the hand (module docstring); ``hand``:
    the TCP link's pose (x, y, z, qw, qx, qy, qz) in the same frame (``BatchedScene.ee_pose``);
    ``approach``: the approach axis in that link's frame (given: the object also centred on the
    approach line through the link's origin, where the TCP offsets of the robots here lie), at
    ``depth`` m along it from the link's origin where given (else at its own). A state that holds
    nothing, or another object, is returned as it is."""
    if state.held != obj.name:
        return state
    pose = state.objects[obj.name]
    r_hand = Rotation.from_quat(_xyzw(hand[3:]))
    rel = (r_hand.inv() * Rotation.from_quat(_xyzw(pose.quaternion))).as_matrix()
    if obj.shape == "box":  # the hand-aligned orientation nearest to rel, among the object's own
        best = max(SQUARE, key=lambda m: float(np.trace(m.T @ rel)))
    else:  # a cylinder: its axis to the nearest hand axis, its turn about it kept
        axis = rel[:, 2]
        k = int(np.argmax(np.abs(axis)))
        target = np.zeros(3)
        target[k] = np.sign(axis[k])
        turn, _ = Rotation.align_vectors([target], [axis])
        best = (turn * Rotation.from_matrix(rel)).as_matrix()
    q = (r_hand * Rotation.from_matrix(best)).as_quat()
    centre = np.asarray(pose.position, dtype=np.float64)
    if approach is not None:  # onto the approach line through the TCP link, at the same depth
        a = r_hand.apply(np.asarray(approach, dtype=np.float64) / np.linalg.norm(approach))
        tcp = np.asarray(hand[:3], dtype=np.float64)
        centre = tcp + a * (float(np.dot(centre - tcp, a)) if depth is None else float(depth))
    squared = ObjectPose(tuple(float(v) for v in centre), (float(q[3]), float(q[0]), float(q[1]), float(q[2])),
                         where=f"objects.{obj.name}")
    return dataclasses.replace(state, objects={**state.objects, obj.name: squared})


def firm_grip(state: SceneState, hand: Sequence[float], obj: SceneObject, approach: Sequence[float],
              holds: Callable[[SceneState], bool]) -> SceneState:
    """``state`` with its held object squared and centred (``square_in_hand``) at the first
    depth along the approach whose restore ``holds`` (e.g. ``Precheck.grip_holds``), from its own
    toward the link's origin in ``DEPTH_STEP_M`` steps; at the origin (or its own depth, if that
    is nearer) where none does. An object that slid down the fingers
    (grasp_slip world 15, seed 0, ``55d5866``: cube C centred 2.3 cm deep, where a grasp leaves it
    1.5 cm) falls out of a restore even squared: every row of the replans failed at step 3."""
    squared = square_in_hand(state, hand, obj, approach)
    r_hand = Rotation.from_quat(_xyzw(hand[3:]))
    a = r_hand.apply(np.asarray(approach, dtype=np.float64) / np.linalg.norm(approach))
    own = float(np.dot(np.asarray(squared.objects[obj.name].position) - np.asarray(hand[:3]), a))
    steps = max(0, int(np.ceil(own / DEPTH_STEP_M - 1e-9)))
    for k in range(steps + 1):
        if k:
            squared = square_in_hand(state, hand, obj, approach, max(0.0, own - k * DEPTH_STEP_M))
        if holds(squared):
            break
    return squared
