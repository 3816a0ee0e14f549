"""One ManiSkill agent class for every robot: built from a ``RobotSpec``, registered per robot.

What it does: ``agent_uid(spec, lean)`` registers (once) and names the ManiSkill agent of a robot
spec (``realize.robot.spec``): a subclass of ``SpecAgent`` whose
  * URDF is the spec's (``realize.robot.urdf.resolve_urdf``: a bundled file, or a derived copy
    whose visual meshes point at shipped files), parsed once per scene: the N tiled robots of a
    CPU scene are built from one parsed articulation builder (parsing was two thirds of building
    200 robots); the finger links get the spec's friction material;
  * only control mode, ``pd_joint_pos_base_vel``: base x, y, yaw joints velocity-driven in the
    world frame (an omnidirectional base; a fixed base has none: its root link is fixed where
    the task puts it), the upper joints position-driven with absolute targets
    (per drive group), held joints (a head) held by their drive, the gripper's one joint
    position-driven (a one-sided jaw) or its fingers mimic position-driven; no cameras
    (rendering for videos uses a scene camera);
  * collision filtering: the spec's ``no_floor_links`` never touch the floor (``FLOOR_BIT``;
    the task sets it on the ground), ``ignore_pairs`` never touch each other, and
    ``sim.robot_collisions`` (``all`` | ``no_self`` | ``hand``) as ``set_robot_collisions`` says;
  * ``lean``: the robot without the spec's ``lean_drop_links`` (fixed-joint leaves nothing in
    these tasks touches or reads), so PhysX simulates fewer links; joints and their order unchanged.
The robots of ``configs/robot/*.yaml`` are registered under their names when ``envs`` is imported
(``gym.make(id, robot_uids=name)``; a name ManiSkill's own agents hold, ``panda``, is registered as
``realize_panda``); a spec changed by config overrides gets its own uid.
What it doesn't: decide targets. Controllers in ``realize/controllers`` compute them and the
batched scene (``realize.scene``) writes them to the drives.
"""

from __future__ import annotations

import hashlib
import json
from copy import deepcopy
from typing import Any, ClassVar

from mani_skill.agents.base_agent import BaseAgent
from mani_skill.agents.controllers import (
    PDJointPosControllerConfig,
    PDJointPosMimicControllerConfig,
    PDJointVelControllerConfig,
)
from mani_skill.agents.registration import REGISTERED_AGENTS, register_agent
from mani_skill.utils import sapien_utils

from realize.robot.spec import RobotSpec, known_robots, load_robot_spec
from realize.robot.urdf import resolve_urdf

__all__ = ["SpecAgent", "agent_uid", "robot_spec_for_uid", "FLOOR_BIT", "ROBOT_COLLISIONS",
           "ROBOT_COLLISIONS_KEY", "drop_links", "set_robot_collisions"]

FLOOR_BIT = 31  # collision group 2 bit shared by the ground and the links that never touch it
_NO_SELF_BIT = 29  # collision group 2 bit shared by every link: links of one robot never collide
ROBOT_COLLISIONS = ("all", "no_self", "hand")
ROBOT_COLLISIONS_KEY = "_realize_robot_collisions"  # the task passes its choice through the scene
_SPECS: dict[str, RobotSpec] = {}  # uid -> the spec it was built from


class SpecAgent(BaseAgent):
    """A robot built from ``spec`` (see the module docstring); subclassed per spec by ``agent_uid``."""

    spec: ClassVar[RobotSpec]
    dropped_links: ClassVar[tuple[str, ...]] = ()

    @property
    def _sensor_configs(self):
        return []

    def _load_articulation(self, initial_pose=None):
        """Build this agent's robot from the scene's one parsed URDF (parsed by the first agent
        of its kind, less ``dropped_links``). Each build gets its own name and initial pose; the
        builder holds no per-robot state beyond those, so every robot is built as from a fresh parse."""
        mode = self.scene.__dict__.get(ROBOT_COLLISIONS_KEY, "all")
        if self.build_separate:  # one build per sub-scene (GPU): ManiSkill's own way
            if mode != "all" or self.dropped_links or self.spec.collision.ignore_pairs:
                raise NotImplementedError(f"{self.uid}: lean robots, robot_collisions other than 'all' and "
                                          "ignore_pairs need one parsed builder (CPU backend)")
            super()._load_articulation(initial_pose)
            return
        builders = self.scene.__dict__.setdefault("_realize_robot_builders", {})
        builder = builders.get(self.uid)
        if builder is None:
            loader = self.scene.create_urdf_loader()
            loader.name = self.uid
            loader.fix_root_link = self.fix_root_link
            loader.load_multiple_collisions_from_file = self.load_multiple_collisions
            loader.disable_self_collisions = self.disable_self_collisions
            if self.urdf_config is not None:  # the fingers' friction material
                config = sapien_utils.parse_urdf_config(self.urdf_config)
                sapien_utils.check_urdf_config(config)
                sapien_utils.apply_urdf_config(loader, config)
            builder = loader.parse(str(self.urdf_path))["articulation_builders"][0]
            if self.dropped_links:
                drop_links(builder, self.dropped_links)
            ignore_pairs(builder, self.spec.collision.ignore_pairs)
            set_robot_collisions(builder, mode, self.spec.collision.hand_links)
            builders[self.uid] = builder
        builder.initial_pose = initial_pose
        name = self.uid if self._agent_idx is None else f"{self.uid}-agent-{self._agent_idx}"
        self.robot = builder.build(name=name)
        self.robot_link_names = [link.name for link in self.robot.get_links()]

    @property
    def _controller_configs(self):
        s = self.spec
        mode: dict[str, Any] = {}
        for i, d in enumerate(s.upper.drives):
            mode[f"upper{i}"] = PDJointPosControllerConfig(list(d.joints), None, None, d.stiffness, d.damping,
                                                           d.force, normalize_action=False)
        g = s.gripper
        if len(g.joints) == 1:  # one driven joint (a one-sided jaw): a plain position drive
            mode["gripper"] = PDJointPosControllerConfig(list(g.joints), g.closed, g.open, g.stiffness, g.damping,
                                                         g.force, normalize_action=False)
        else:  # joints[0] driven, the others mimic it
            mode["gripper"] = PDJointPosMimicControllerConfig(
                list(g.joints), g.closed, g.open, g.stiffness, g.damping, g.force,
                mimic={j: {"joint": g.joints[0]} for j in g.joints[1:]}, normalize_action=False,
            )
        if s.held:
            h = s.held_drive
            mode["held"] = PDJointPosControllerConfig(list(s.held), None, None, h.stiffness, h.damping, h.force,
                                                      normalize_action=False)
        b = s.base
        if not b.fixed:  # a fixed base has no joints to drive
            mode["base"] = PDJointVelControllerConfig(list(b.joints), -b.speed_limit, b.speed_limit, b.damping,
                                                      b.force, normalize_action=False)
        return deepcopy(dict(pd_joint_pos_base_vel=mode))

    def _after_init(self):
        links = self.robot.links_map
        s = self.spec
        self.tcp = links[s.tcp.link]
        self.finger_links = [links[n] for n in s.gripper.finger_links]
        self.base_link = links[s.base.link]
        for name in s.collision.no_floor_links:
            if name in links:  # a lean robot may have dropped it
                links[name].set_collision_group_bit(group=2, bit_idx=FLOOR_BIT, bit=1)


def _spec_key(spec: RobotSpec) -> str:
    return hashlib.sha256(json.dumps(spec.to_dict(), sort_keys=True, default=str).encode()).hexdigest()[:10]


def agent_uid(spec: RobotSpec, lean: bool = False) -> str:
    """The registered ManiSkill uid of ``spec``'s robot (lean: without ``lean_drop_links``),
    registering it on first use: the spec's name where it equals its config file, else the
    name plus a hash of its content."""
    try:
        same = spec == load_robot_spec(spec.name)
    except ValueError:  # no config file of that name: a robot given as data only
        same = False
    uid = spec.name if same else f"{spec.name}-{_spec_key(spec)}"
    if lean and spec.collision.lean_drop_links:
        uid = f"{uid}_lean"
    if uid in REGISTERED_AGENTS and uid not in _SPECS:  # one of ManiSkill's own agents (its "panda")
        uid = f"realize_{uid}"
    if uid not in REGISTERED_AGENTS:
        attrs = dict(
            uid=uid, spec=spec, urdf_path=resolve_urdf(spec.urdf, spec.visual_mesh_ext),
            urdf_config=_urdf_config(spec),
            dropped_links=tuple(spec.collision.lean_drop_links) if lean else (),
        )
        register_agent()(type(f"SpecAgent_{uid}", (SpecAgent,), attrs))
        _SPECS[uid] = spec
    return uid


def robot_spec_for_uid(uid: str) -> RobotSpec:
    """The spec a registered uid was built from (a config file's robot by its name)."""
    if uid not in _SPECS:
        base = uid[:-len("_lean")] if uid.endswith("_lean") else uid
        base = base[len("realize_"):] if base.startswith("realize_") and base not in known_robots() else base
        if base not in known_robots():
            raise ValueError(f"robot_uids = {uid!r} is unknown: known robots {known_robots()} "
                             "(add one: configs/robot/<name>.yaml)")
        return _SPECS[agent_uid(load_robot_spec(base), lean=uid.endswith("_lean"))]
    return _SPECS[uid]


def _urdf_config(spec: RobotSpec) -> dict | None:
    g = spec.gripper
    if g.static_friction is None:
        return None
    link: dict[str, Any] = {"material": "gripper"}
    if g.patch_radius is not None:
        link["patch_radius"] = g.patch_radius
    if g.min_patch_radius is not None:
        link["min_patch_radius"] = g.min_patch_radius
    return dict(
        _materials=dict(gripper=dict(static_friction=g.static_friction, dynamic_friction=g.dynamic_friction,
                                     restitution=0.0)),
        link={name: dict(link) for name in g.finger_links},
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


def ignore_pairs(builder, pairs) -> None:
    """Link pairs that never collide, as an SRDF's disabled pairs: each pair shares one free
    collision group 2 bit (below the no-self and floor bits)."""
    if not pairs:
        return
    by_name = {b.name: b for b in builder.link_builders}
    used = 0
    for b in builder.link_builders:
        used |= b.collision_groups[2]
    for a, c in pairs:
        if a not in by_name or c not in by_name:
            raise ValueError(f"robot.collision.ignore_pairs: {[a, c]} names a link not in the robot")
        bit = next((i for i in range(_NO_SELF_BIT) if not used >> i & 1), None)
        if bit is None:
            raise ValueError("robot.collision.ignore_pairs: no free collision bit left (at most 29 pairs with an SRDF)")
        used |= 1 << bit
        by_name[a].collision_groups[2] |= 1 << bit
        by_name[c].collision_groups[2] |= 1 << bit


def set_robot_collisions(builder, mode: str, hand_links: tuple[str, ...]) -> None:
    """Edit a parsed articulation builder's collision shapes in place.

    ``all``: as parsed (an SRDF's disabled pairs, parent-child pairs off). ``no_self``: no link
    collides with another link of the robot (tables, cubes and the floor as before). ``hand``:
    only ``hand_links`` keep their collision shapes; every other link keeps its URDF mass and
    inertia but touches nothing."""
    if mode not in ROBOT_COLLISIONS:
        raise ValueError(f"robot collisions {mode!r}: must be one of {ROBOT_COLLISIONS}")
    if mode == "no_self":
        for b in builder.link_builders:
            b.collision_groups[2] |= 1 << _NO_SELF_BIT
    elif mode == "hand":
        names = {b.name for b in builder.link_builders}
        if not hand_links or not set(hand_links) <= names:
            raise ValueError(f"robot.collision.hand_links {list(hand_links)}: links not in the robot: "
                             f"{sorted(set(hand_links) - names)}")
        for b in builder.link_builders:
            if b.name in hand_links or not b.collision_records:
                continue
            if b._auto_inertial:  # its mass would come from the shapes about to go
                raise ValueError(f"link {b.name} has no URDF inertial: its collision shapes cannot go")
            b.collision_records = []


def register_known_robots() -> None:
    """Register every robot of ``configs/robot/`` under its name (and its lean variant)."""
    for name in known_robots():
        spec = load_robot_spec(name)
        agent_uid(spec)
        agent_uid(spec, lean=True)
