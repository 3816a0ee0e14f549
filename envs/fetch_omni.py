"""Fetch with an omnidirectional planar base and joint-level drives, for plan realization.

What it does: registers the ManiSkill agent ``fetch_omni``: ManiSkill's Fetch (same URDF,
links, gripper materials and collision filtering) with
  * no cameras (sensors cost memory and time; rendering for videos uses a scene camera),
  * one control mode, ``pd_joint_pos_base_vel``: base x, y, yaw joints velocity-driven in the
    world frame (so the base can move sideways like the paper's Dingo-O), torso + arm joints
    position-driven with absolute targets, head held, gripper fingers mimic position-driven,
  * the URDF parsed once per scene: the N tiled robots of a CPU scene are built from one parsed
    articulation builder (parsing was two thirds of building 200 robots).
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
from mani_skill.utils import sapien_utils
from mani_skill import format_path

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

    def _load_articulation(self, initial_pose=None):
        """Build this agent's robot from the scene's one parsed URDF (parsed by the first agent).

        Each build gets its own name and initial pose; the builder holds no per-robot state
        beyond those, so every robot is built exactly as from a fresh parse."""
        if self.build_separate:  # one build per sub-scene (GPU): ManiSkill's own way
            return super()._load_articulation(initial_pose)
        builder = getattr(self.scene, "_fetch_omni_builder", None)
        if builder is None:
            loader = self.scene.create_urdf_loader()
            loader.name = self.uid
            loader.fix_root_link = self.fix_root_link
            loader.load_multiple_collisions_from_file = self.load_multiple_collisions
            loader.disable_self_collisions = self.disable_self_collisions
            if self.urdf_config is not None:
                config = sapien_utils.parse_urdf_config(self.urdf_config)
                sapien_utils.check_urdf_config(config)
                sapien_utils.apply_urdf_config(loader, config)
            builder = loader.parse(format_path(str(self.urdf_path)))["articulation_builders"][0]
            self.scene._fetch_omni_builder = builder
        builder.initial_pose = initial_pose
        name = self.uid if self._agent_idx is None else f"{self.uid}-agent-{self._agent_idx}"
        self.robot = builder.build(name=name)
        self.robot_link_names = [link.name for link in self.robot.get_links()]

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
