"""Layout of Fetch's whole-body state: named slices of the (N, 11) joint vectors.

What it does: names the columns of the whole-body configuration ``q`` (and of its velocity
``qd``) that the scene reads (``BatchedScene.whole_body_q``), the kinematics and the fabric
use: base x, y (m, local frame), base yaw (rad), torso lift (m), then the 7 arm joints. The
torso and the arm together are the ``UPPER`` body: the joints driven by position targets
(the base is driven by velocity).
What it doesn't: know joint names, limits or kinematics (``realize.kinematics``).
"""

from __future__ import annotations

DOF = 11  # columns of a whole-body state
BASE = slice(0, 3)  # x, y, yaw
BASE_XY = slice(0, 2)  # x, y
YAW = 2
TORSO = 3
ARM = slice(4, 11)  # the 7 arm joints
UPPER = slice(3, 11)  # torso + arm: position-driven joints
N_BASE = 3
N_UPPER = 8
