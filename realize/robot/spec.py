"""A robot as data: the typed ``RobotSpec`` read from ``configs/robot/<name>.yaml`` (Hydra group ``robot``).

What it does
------------
* ``RobotSpec`` names everything realize needs to know about one mobile manipulator: its URDF
  (a file bundled with ManiSkill, ``mani_skill:robots/...``, or a file of this project), the
  planar base (x, y, yaw joints, velocity-driven; or a fixed base), the position-driven upper joints in ``q``
  order (a lift or torso first if any, then the arm), the joints held still (a head), the
  gripper (finger joints, open and closed targets, the finger links whose contact forces mean
  "holding", pad sizes, friction material), the tool centre point (link, offset, approach and
  closing axes), the rest pose, drive gains, collision filtering and the sphere file.
* ``load_robot_spec(name)`` reads a robot's config file; ``RobotSpec.from_mapping(d, "robot")``
  reads the Hydra group's mapping (every key can be overridden: ``robot.gripper.closed=-0.02``).
  Bad values are refused in one line naming the key (``realize.config.ConfigError``).
* ``RobotSpec.spheres()`` reads the sphere file (``realize.robot.spheres``).

What it doesn't: open the URDF (``realize.robot.urdf``), compute kinematics
(``realize.robot.kinematics``) or build the simulated robot (``envs.robot_agent``).
The whole-body vector ``q`` of every robot is ``[x, y, yaw, *upper.joints]``
(the slices of ``realize.robot.layout``: ``BASE``, ``UPPER``, ...).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import ClassVar, Sequence

import yaml

from realize.config import ConfigError, Settings, setting
from realize.paths import CONFIG_DIR

__all__ = ["Drive", "BaseSpec", "UpperSpec", "GripperSpec", "TcpSpec", "CollisionSpec", "RobotSpec",
           "ROBOT_CONFIG_DIR", "known_robots", "load_robot_spec", "DEFAULT_ROBOT", "FIXED_BASE_JOINTS"]

ROBOT_CONFIG_DIR = CONFIG_DIR / "robot"
DEFAULT_ROBOT = "fetch_omni"
FIXED_BASE_JOINTS = ("fixed_base_x", "fixed_base_y", "fixed_base_yaw")  # q's base columns of a fixed base


def _unit(v: tuple[float, ...]) -> str | None:
    n = math.sqrt(sum(x * x for x in v))
    return None if abs(n - 1.0) < 1e-9 else f"must be a unit vector (norm {n:.6g})"


@dataclass
class Drive(Settings):
    """PD drive gains of a group of position-driven joints (PhysX joint drives, force mode)."""

    joints: tuple[str, ...] = ()
    stiffness: float = setting(1e3, ge=0)
    damping: float = setting(1e2, ge=0)
    force: float = setting(100.0, gt=0)


@dataclass
class BaseSpec(Settings):
    """The base: three joints (x, y prismatic, yaw revolute) driven by velocity in the world
    frame, so the base moves like an omnidirectional one; or none (``joints: []``), a fixed
    base: the URDF's root ``link`` bolted at the scene's ``robot_start`` (x, y, yaw), ``height``
    above the floor. A fixed base still fills the three base columns of ``q`` (its pose, which
    never changes); its plans have no ``move_to``."""

    joints: tuple[str, ...] = ("root_x_axis_joint", "root_y_axis_joint", "root_z_rotation_joint")
    link: str = "base_link"  # the link the base joints carry (a fixed base: the URDF's root link)
    height: float = setting(0.0, ge=0)  # m: a fixed base's root above the floor (a mobile base: 0)
    damping: float = setting(1e4, gt=0)  # velocity drive
    force: float = setting(2e3, gt=0)
    speed_limit: float = setting(1.5, gt=0)  # |joint velocity target| bound of ManiSkill's controller
    # the base's footprint as a disc (m): A* pads obstacles by it (plus controller.astar.padding),
    # and the robot's start must keep it clear of every obstacle and inside the world's bounds
    footprint_radius: float = setting(0.32, gt=0)

    def check(self, where: str) -> None:
        if len(self.joints) not in (0, 3):
            raise ConfigError(f"{where}.joints = {list(self.joints)} is invalid: name three joints (x, y prismatic, "
                              "yaw revolute) for a mobile base, or none ([]) for a fixed base")
        if self.joints and self.height != 0.0:
            raise ConfigError(f"{where}.height = {self.height} is invalid: only a fixed base (joints: []) "
                              "stands above the floor")

    @property
    def fixed(self) -> bool:
        """No base joints: the robot's root stays where the scene put it."""
        return not self.joints


@dataclass
class UpperSpec(Settings):
    """The position-driven joints after the base, in ``q`` order: a lift or torso first (if
    any), then the arm; ``drives`` give their gains (every joint in exactly one group)."""

    joints: tuple[str, ...] = ()
    drives: tuple[Drive, ...] = ()

    def check(self, where: str) -> None:
        if not self.joints:
            raise ConfigError(f"{where}.joints = []: a robot needs at least one upper-body joint")
        named = [j for d in self.drives for j in d.joints]
        missing = [j for j in self.joints if j not in named]
        extra = [j for j in named if j not in self.joints]
        if missing or extra or len(named) != len(set(named)):
            raise ConfigError(f"{where}.drives: every joint of {where}.joints must be in exactly one drive group "
                              f"(missing {missing}, unknown {extra})")


@dataclass
class GripperSpec(Settings):
    """A gripper's driven joints: one (driven alone: a one-sided jaw against a fixed one) or
    several (``joints[0]`` driven, the others mimic it: a parallel gripper), prismatic or revolute.
    ``open`` and ``closed`` are in the joint's unit (m or rad, from the URDF); the gap between the
    pads they leave, the pads' centre and the joint for a gap come from the fingers' kinematics
    (``realize.robot.grip_geometry``), which also refuses a gripper the agent cannot build."""

    joints: tuple[str, ...] = ()
    finger_links: tuple[str, str] = ("", "")  # whose contact forces on an object mean "holding"
    open: float = setting(0.05)  # finger joint target in the joint's unit: m (prismatic) or rad (revolute)
    closed: float = setting(-0.01)  # the same unit, past the closed limit: the fingers squeeze
    stiffness: float = setting(1e3, ge=0)
    damping: float = setting(1e2, ge=0)
    force: float = setting(100.0, gt=0)
    fingertip_reach: float = setting(0.031, ge=0)  # m the fingertips reach beyond the TCP on the approach axis
    pad_half_width: float = setting(0.013, ge=0)  # m, half width of a finger pad across the closing axis
    # the settle rule of grasp / place (the fingers close, or open, once the TCP has settled this close
    # to its goal for this long): this robot's values; None: the controller's (controller.reach_tolerance,
    # 15 mm; controller.settle_s, 0.5 s). reach_share scales a grasp's tolerance with the gripper and
    # the object: at most this share of the clearance the open pads leave on each side of the object,
    # (width_open - width) / 2 (None: not scaled, the fixed tolerance alone)
    reach_tolerance: float | None = setting(None, gt=0)  # m
    reach_share: float | None = setting(None, gt=0, le=1)
    settle_s: float | None = setting(None, gt=0)  # s
    static_friction: float | None = setting(None, ge=0)  # finger material (None: the URDF loader's default)
    dynamic_friction: float | None = setting(None, ge=0)
    patch_radius: float | None = setting(None, ge=0)
    min_patch_radius: float | None = setting(None, ge=0)

    def check(self, where: str) -> None:
        if len(self.joints) < 1:
            raise ConfigError(f"{where}.joints = []: name the finger joint(s)")
        if self.closed >= self.open:
            raise ConfigError(f"{where}.closed = {self.closed} is invalid: must be < {where}.open = {self.open}")
        if (self.static_friction is None) != (self.dynamic_friction is None):
            raise ConfigError(f"{where}: give both static_friction and dynamic_friction, or neither")


@dataclass
class TcpSpec(Settings):
    """The tool centre point: a point fixed in ``link`` (the centre of the finger pads), with
    the approach axis (the fingers point along it) and the closing axis (the line joining the
    fingers) as unit vectors in ``link``'s frame."""

    link: str = "gripper_link"
    offset: tuple[float, float, float] = (0.0, 0.0, 0.0)
    approach_axis: tuple[float, float, float] = setting((1.0, 0.0, 0.0), check=_unit)
    closing_axis: tuple[float, float, float] = setting((0.0, 1.0, 0.0), check=_unit)

    def check(self, where: str) -> None:
        dot = sum(a * b for a, b in zip(self.approach_axis, self.closing_axis))
        if abs(dot) > 1e-9:
            raise ConfigError(f"{where}: approach_axis and closing_axis must be orthogonal (dot {dot:.3g})")


@dataclass
class CollisionSpec(Settings):
    """Which links touch what in the simulated robot."""

    no_floor_links: tuple[str, ...] = ()  # never touch the floor (the base is driven through its joints)
    hand_links: tuple[str, ...] = ()  # ``sim.robot_collisions=hand`` keeps only these links' shapes
    lean_drop_links: tuple[str, ...] = ()  # ``sim.lean_robot`` leaves out these fixed-joint leaves
    ignore_pairs: tuple[tuple[str, str], ...] = ()  # link pairs that never collide (as an SRDF's disabled pairs)


@dataclass
class RobotSpec(Settings):
    """One robot (see the module docstring). Every field is a config key of the ``robot`` group."""

    config_key: ClassVar[str] = "robot"

    name: str = DEFAULT_ROBOT
    urdf: str = "mani_skill:robots/fetch/fetch.urdf"  # "mani_skill:<path in its assets>" or a path relative to the repo
    visual_mesh_ext: dict[str, str] | None = None  # e.g. {".dae": ".glb"}: a derived URDF reads shipped files
    base: BaseSpec = field(default_factory=BaseSpec)
    upper: UpperSpec = field(default_factory=lambda: UpperSpec(("torso_lift_joint",), (Drive(("torso_lift_joint",)),)))
    held: dict[str, float] = field(default_factory=dict)  # joint -> value: not in q, its drive's target (rest may start it elsewhere)
    held_drive: Drive = field(default_factory=Drive)
    gripper: GripperSpec = field(default_factory=lambda: GripperSpec(("finger",)))
    tcp: TcpSpec = field(default_factory=TcpSpec)
    rest: dict[str, float] = field(default_factory=dict)  # joint -> value at the start of every fresh scene
    spheres_file: str = "fetch_omni"  # a file of realize/robot/spheres/ (name without .yaml) or a repo path
    fabric_exclude: tuple[str, ...] = ()  # spheres that may touch a table top while grasping (no box leaves)
    collision: CollisionSpec = field(default_factory=CollisionSpec)

    def check(self, where: str) -> None:
        for key, d in (("held", self.held), ("rest", self.rest)):
            if not isinstance(d, dict) or not all(isinstance(k, str) for k in d):
                raise ConfigError(f"{where}.{key} = {d!r} is invalid: must be a mapping joint -> value")
            for k, v in d.items():
                if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
                    raise ConfigError(f"{where}.{key}.{k} = {v!r} is invalid: must be a finite number")
        if self.visual_mesh_ext is not None and not all(
                isinstance(k, str) and isinstance(v, str) and k.startswith(".") and v.startswith(".")
                for k, v in self.visual_mesh_ext.items()):
            raise ConfigError(f"{where}.visual_mesh_ext = {self.visual_mesh_ext!r} is invalid: "
                              "must map extensions to extensions, e.g. {'.dae': '.glb'}")
        names = [*self.base.joints, *self.upper.joints, *self.held, *self.gripper.joints]
        dup = sorted({n for n in names if names.count(n) > 1})
        if dup:
            raise ConfigError(f"{where}: joints {dup} appear in more than one of base.joints, upper.joints, "
                              "held, gripper.joints")
        unknown = sorted(set(self.rest) - set(names))
        if unknown:
            raise ConfigError(f"{where}.rest: unknown joints {unknown}; known: {names}")

    # ------------------------------------------------------------------ derived names
    @property
    def whole_body_joints(self) -> tuple[str, ...]:
        """The joints of ``q``, in order: base x, y, yaw, then the upper joints. A fixed base's
        three are ``FIXED_BASE_JOINTS``, joints of the kinematic model only (``realize.robot.kinematics``
        puts them ahead of the URDF's root), not of the simulated robot."""
        return (*(FIXED_BASE_JOINTS if self.base.fixed else self.base.joints), *self.upper.joints)

    @property
    def n_dof(self) -> int:
        return len(self.whole_body_joints)

    @property
    def n_upper(self) -> int:
        return len(self.upper.joints)

    def rest_value(self, joint: str) -> float:
        """A joint's rest position: ``rest``, else its held value, else the open gripper, else 0."""
        if joint in self.rest:
            return float(self.rest[joint])
        if joint in self.held:
            return float(self.held[joint])
        if joint in self.gripper.joints:
            return float(self.gripper.open)
        return 0.0

    @property
    def state_joints(self) -> tuple[str, ...]:
        """Every joint a scene state names (all but the base's): upper, held, gripper."""
        return (*self.upper.joints, *self.held, *self.gripper.joints)

    def check_state_joints(self, joints, where: str) -> None:
        """Refuse joint names of a scene state that this robot does not have (one line)."""
        unknown = sorted(set(joints) - set(self.state_joints))
        if unknown:
            raise ConfigError(f"{where}: joints has unknown joint(s) {unknown} of robot {self.name!r}; known: "
                              f"{list(self.state_joints)} (the base is the 'base' key)")

    def fabric_exclusions(self, override: tuple[str, ...] | None, known: Sequence[str]) -> tuple[str, ...]:
        """The spheres the fabric gives no box leaves: ``override`` (``controller.fabric.collision_exclude``)
        or this robot's ``fabric_exclude``; a name not in ``known`` (the robot's sphere names) is a
        one-line ``ConfigError`` naming the key it came from."""
        key, names = ("robot.fabric_exclude", self.fabric_exclude) if override is None else \
            ("controller.fabric.collision_exclude", override)
        unknown = [n for n in names if n not in known]
        if unknown:
            raise ConfigError(f"{key} = {list(names)!r} is invalid: unknown spheres {unknown} of robot "
                              f"{self.name!r} (its sphere file {self.spheres_file!r} has {list(known)})")
        return tuple(names)

    def rest_q(self) -> tuple[float, ...]:
        """The rest pose as a whole-body ``q`` (base at 0)."""
        return tuple(self.rest_value(j) for j in self.whole_body_joints)

    def spheres(self):  # -> tuple[SphereSpec, ...]
        """The collision spheres of this robot's sphere file."""
        from realize.robot.sphere_file import load_spheres

        return load_spheres(self.spheres_file)


def known_robots() -> list[str]:
    """Names of the robots with a config file in ``configs/robot/``."""
    return sorted(p.stem for p in ROBOT_CONFIG_DIR.glob("*.yaml"))


def load_robot_spec(name: str = DEFAULT_ROBOT) -> RobotSpec:
    """The robot of ``configs/robot/<name>.yaml``; an unknown name is a one-line ``ConfigError``."""
    path = ROBOT_CONFIG_DIR / f"{name}.yaml"
    if not path.is_file():
        raise ConfigError(f"robot = {name!r} is unknown: no {path.relative_to(CONFIG_DIR.parent)}; "
                          f"known robots: {known_robots()}")
    with open(path) as f:
        data = yaml.safe_load(f)
    return RobotSpec.from_mapping(data, f"robot ({Path(path).name})")
