"""Layout of a mobile manipulator's whole-body state: named slices of the (N, n_dof) joint vectors.

What it does: names the columns of the whole-body configuration ``q`` (and of its velocity
``qd``) that the scene reads (``BatchedScene.whole_body_q``), the kinematics and the fabric
use. Every robot's ``q`` is ``[x, y, yaw, *upper]`` (``RobotSpec.whole_body_joints``): base x, y
(m, local frame), base yaw (rad), then the ``UPPER`` body, the joints driven by position
targets (a lift or torso if any, then the arm; the base is driven by velocity). How many upper
joints there are is the robot's (``RobotSpec.n_upper``, ``RobotKinematics.n_dof``).
What it doesn't: know joint names, limits or kinematics (``realize.robot``, ``realize.robot.kinematics``).
"""

from __future__ import annotations

BASE = slice(0, 3)  # x, y, yaw
BASE_XY = slice(0, 2)  # x, y
YAW = 2
N_BASE = 3
UPPER = slice(3, None)  # lift/torso + arm: position-driven joints
