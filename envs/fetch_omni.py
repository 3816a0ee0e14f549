"""Fetch with an omnidirectional planar base and joint-level drives, for plan realization.

What it does: registers the ManiSkill agent ``fetch_omni``: ManiSkill's Fetch (same URDF,
links, gripper materials and collision filtering) with
  * no cameras (sensors cost memory and time; rendering for videos uses a scene camera),
  * one control mode, ``pd_joint_pos_base_vel``: base x, y, yaw joints velocity-driven in the
    world frame (so the base can move sideways like the paper's Dingo-O), torso + arm joints
    position-driven with absolute targets, head held, gripper fingers mimic position-driven,
  * the URDF parsed once per scene: the N tiled robots of a CPU scene are built from one parsed
    articulation builder (parsing was two thirds of building 200 robots).
  * ``fetch_omni_lean``: the same robot without the 11 links nothing in these tasks touches or
    reads (wheels, laser, e-stop, bellows, head camera and its frames: fixed-joint leaves of the
    tree, 4 of them convex collision meshes), so PhysX simulates 18 links instead of 29. The
    joints, their order and every other link are unchanged; the dropped links' masses are gone
    (gravity is off on the robot and the base is velocity-driven, so only inertia changes).
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
from mani_skill.agents.robots.fetch import FETCH_BASE_COLLISION_BIT, Fetch
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

    dropped_links: tuple[str, ...] = ()  # links left out of the parsed robot (see the lean robot)

    def _load_articulation(self, initial_pose=None):
        """Build this agent's robot from the scene's one parsed URDF (parsed by the first agent
        of its kind, less ``dropped_links``).

        Each build gets its own name and initial pose; the builder holds no per-robot state
        beyond those, so every robot is built exactly as from a fresh parse."""
        if self.build_separate:  # one build per sub-scene (GPU): ManiSkill's own way
            if self.scene.__dict__.get(ROBOT_COLLISIONS_KEY, "all") != "all":
                raise NotImplementedError(f"{self.uid}: robot collisions other than 'all' need one parsed builder")
            if self.dropped_links:
                raise NotImplementedError(f"{self.uid} builds one articulation builder for all sub-scenes")
            return super()._load_articulation(initial_pose)
        builders = self.scene.__dict__.setdefault("_realize_robot_builders", {})
        builder = builders.get(self.uid)
        if builder is None:
            loader = self.scene.create_urdf_loader()
            loader.name = self.uid
            loader.fix_root_link = self.fix_root_link
            loader.load_multiple_collisions_from_file = self.load_multiple_collisions
            loader.disable_self_collisions = self.disable_self_collisions
            if self.urdf_config is not None:  # the gripper's friction materials
                config = sapien_utils.parse_urdf_config(self.urdf_config)
                sapien_utils.check_urdf_config(config)
                sapien_utils.apply_urdf_config(loader, config)
            builder = loader.parse(format_path(str(self.urdf_path)))["articulation_builders"][0]
            if self.dropped_links:
                drop_links(builder, self.dropped_links)
            set_robot_collisions(builder, self.scene.__dict__.get(ROBOT_COLLISIONS_KEY, "all"))
            builders[self.uid] = builder
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


# Links the lean robot leaves out: fixed-joint leaves (with their fixed-joint children) that no
# rollout of the seed task touches (contact log by link name over a rollout of 200 plans of a
# late CE iteration: only the two fingers and gripper_link ever touched the cube or a table;
# over 200 uniform plans the lean robot's feasible share and mean cost matched the full one's).
LEAN_DROPPED_LINKS = (
    "r_wheel_link", "l_wheel_link", "estop_link", "laser_link", "bellows_link", "bellows_link2",
    "head_camera_link", "head_camera_rgb_frame", "head_camera_depth_frame",
    "head_camera_rgb_optical_frame", "head_camera_depth_optical_frame",
)


def drop_links(builder, names: tuple[str, ...]) -> None:
    """Remove the link builders ``names`` from a parsed SAPIEN articulation builder, in place.
    Only leaves of the tree may go (every child of a dropped link is dropped too) and only links
    on fixed joints, so the active joints and their order stay as they are."""
    drop = set(names)
    found = {b.name for b in builder.link_builders} & drop
    if found != drop:
        raise ValueError(f"links not in the robot: {sorted(drop - found)}")
    keep = []
    for b in builder.link_builders:
        if b.name in drop:
            if b.joint_record.joint_type != "fixed":
                raise ValueError(f"link {b.name} hangs on a {b.joint_record.joint_type} joint: only fixed links go")
            continue
        if b.parent is not None and b.parent.name in drop:
            raise ValueError(f"link {b.name} is a child of the dropped {b.parent.name}")
        keep.append(b)
    for i, b in enumerate(keep):
        b.index = i
    builder.link_builders = keep


# Which of the robot's links collide with what (``set_robot_collisions``; the task passes its
# choice through the scene, where the parsed builder is kept, under this key).
ROBOT_COLLISIONS_KEY = "_realize_robot_collisions"
ROBOT_COLLISIONS = ("all", "no_self", "hand")
HAND_LINKS = ("gripper_link", "l_gripper_finger_link", "r_gripper_finger_link")
_NO_SELF_BIT = 29  # collision group 2 bit shared by every link: links of one robot never collide (ManiSkill's)


def set_robot_collisions(builder, mode: str) -> None:
    """Edit a parsed Fetch articulation builder's collision shapes in place.

    ``all``: as parsed (the SRDF's disabled pairs, parent-child pairs off). ``no_self``: no link
    collides with another link of the robot (tables, cubes and the floor as before). ``hand``:
    only ``HAND_LINKS`` keep their collision shapes; every other link keeps its URDF mass and
    inertia but touches nothing (contact logs: only the hand touches the cube or a table)."""
    if mode not in ROBOT_COLLISIONS:
        raise ValueError(f"robot collisions {mode!r}: must be one of {ROBOT_COLLISIONS}")
    if mode == "no_self":
        for b in builder.link_builders:
            b.collision_groups[2] |= 1 << _NO_SELF_BIT
    elif mode == "hand":
        names = {b.name for b in builder.link_builders}
        if not set(HAND_LINKS) <= names:
            raise ValueError(f"links not in the robot: {sorted(set(HAND_LINKS) - names)}")
        for b in builder.link_builders:
            if b.name in HAND_LINKS or not b.collision_records:
                continue
            if b._auto_inertial:  # its mass would come from the shapes about to go
                raise ValueError(f"link {b.name} has no URDF inertial: its collision shapes cannot go")
            b.collision_records = []


@register_agent()
class FetchOmniLean(FetchOmni):
    """``fetch_omni`` without ``LEAN_DROPPED_LINKS`` (see the module docstring)."""

    uid = "fetch_omni_lean"
    dropped_links = LEAN_DROPPED_LINKS

    def _after_init(self):
        links = self.robot.links_map
        self.finger1_link = links["l_gripper_finger_link"]
        self.finger2_link = links["r_gripper_finger_link"]
        self.tcp = links[self.ee_link_name]
        self.base_link = links["base_link"]
        self.base_link.set_collision_group_bit(group=2, bit_idx=FETCH_BASE_COLLISION_BIT, bit=1)
        self.torso_lift_link = links["torso_lift_link"]
        self.head_camera_link = None
        self.queries = dict()
