"""Why a plan failed: the failure codes of a rollout.

What it does: ``Failure`` is an ``IntEnum`` whose values are the codes kept per plan in
(N,) int64 tensors (0 = no failure); ``Failure.label`` is the reason written into
``RolloutResult.failure`` (``"<action index>:<action>:<label>"``).
What it doesn't: decide when a plan fails (the templates and the rollout do).
"""

from __future__ import annotations

from enum import IntEnum


class Failure(IntEnum):
    """Failure code of a plan (its value is what the rollout's (N,) code tensor holds)."""

    NONE = 0
    TIMEOUT = 1
    NO_PATH = 2
    GRASP_NOT_HELD = 3
    OBJECT_DROPPED = 4
    NOT_HOLDING = 5
    CONTROLLER_INVALID = 6
    DIVERGED = 7
    PLACE_NOT_RELEASED = 8
    GOAL_NOT_REACHED = 9
    PUSH_BLOCKED = 10
    STOPPED = 11  # ce.prune: stopped once it could no longer be an elite (it might have succeeded)

    @property
    def label(self) -> str:
        """The reason as written in a result: ``""`` for NONE, else the lower-case name."""
        return "" if self is Failure.NONE else self.name.lower()
