"""Fetch with an omnidirectional planar base and joint-level drives, for plan realization.

What it does: registers the ManiSkill agent ``fetch_omni``: ManiSkill's Fetch (same URDF,
links, gripper materials and collision filtering) with
  * no cameras (sensors cost memory and time; rendering for videos uses a scene camera),
  * one control mode, ``pd_joint_pos_base_vel``: base x, y, yaw joints velocity-driven in the
    world frame (so the base can move sideways like the paper's Dingo-O), torso + arm joints
    position-driven with absolute targets, head held, gripper fingers mimic position-driven.
What it doesn't: decide targets. Controllers in ``realize/controllers`` compute them and the
batched scene view (``realize.scene``) writes them to the drives.
"""

from __future__ import annotations

from copy import deepcopy

import numpy as np
import sapien

from mani_skill.agents.base_agent import Keyframe
from mani_skill.agents.controllers import (
    PDJointPosControllerConfig,
    PDJointPosMimicControllerConfig,
    PDJointVelControllerConfig,
)
from mani_skill.agents.registration import register_agent
from mani_skill.agents.robots.fetch import Fetch

# Drive gains. Arm values are ManiSkill's Fetch defaults; the base is a stiff velocity drive so
# commanded base velocities are tracked closely (the real base has its own velocity loop).
ARM_STIFFNESS, ARM_DAMPING, ARM_FORCE = 1e3, 1e2, 100.0
TORSO_STIFFNESS, TORSO_DAMPING, TORSO_FORCE = 1e5, 1e4, 1e4
GRIPPER_STIFFNESS, GRIPPER_DAMPING, GRIPPER_FORCE = 1e3, 1e2, 100.0
BASE_DAMPING, BASE_FORCE = 1e4, 2e3

# ManiSkill's Fetch "rest" keyframe (arm folded in front) with the torso off its upper limit
# (0.25 of 0.386 m: the fabric's joint-limit leaves are singular at the limit) and fingers open;
# free of self-contact. Order: ManiSkill Fetch active joints (base x, y, yaw, torso, head pan,
# shoulder pan, head tilt, shoulder lift, upperarm roll, elbow, forearm roll, wrist flex, wrist
# roll, r finger, l finger).
REST_QPOS = np.array(
    [0, 0, 0, 0.25, 0, -0.370, 0.562, -1.032, 0.695, 0.955, -0.1, 2.077, 0, 0.045, 0.045], dtype=np.float32
)


@register_agent()
class FetchOmni(Fetch):
    uid = "fetch_omni"
    keyframes = dict(rest=Keyframe(pose=sapien.Pose(), qpos=REST_QPOS))

    @property
    def _sensor_configs(self):
        return []

    @property
    def _controller_configs(self):
        arm = PDJointPosControllerConfig(
            self.arm_joint_names, None, None, ARM_STIFFNESS, ARM_DAMPING, ARM_FORCE, normalize_action=False
        )
        body = PDJointPosControllerConfig(
            self.body_joint_names, None, None, TORSO_STIFFNESS, TORSO_DAMPING, TORSO_FORCE,
            normalize_action=False,
        )
        gripper = PDJointPosMimicControllerConfig(
            self.gripper_joint_names, -0.01, 0.05, GRIPPER_STIFFNESS, GRIPPER_DAMPING, GRIPPER_FORCE,
            mimic={"r_gripper_finger_joint": {"joint": "l_gripper_finger_joint"}},
            normalize_action=False,
        )
        base = PDJointVelControllerConfig(
            self.base_joint_names, -1.5, 1.5, BASE_DAMPING, BASE_FORCE, normalize_action=False
        )
        return deepcopy(
            dict(pd_joint_pos_base_vel=dict(arm=arm, gripper=gripper, body=body, base=base))
        )
