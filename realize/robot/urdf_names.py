"""A robot config's joint and link names against its URDF, before anything is built.

What it does: ``check_urdf_names(spec, where)`` reads the spec's URDF (``robot.urdf``; the
XML only, no meshes; a file that is not a readable URDF is one line naming the key and the
file) and refuses, in one ``ConfigError`` line naming the key, a joint the spec
drives or holds that the URDF does not have as a movable joint (``base.joints``,
``upper.joints``, ``gripper.joints``, ``held``, ``rest``) and a link it names that the URDF does
not have (``base.link``, ``tcp.link``, ``gripper.finger_links``, ``collision.*``). Without it, a
misspelt finger link surfaced as a bare ``KeyError`` from inside ManiSkill's agent build. Then
the gripper itself (``realize.robot.grip_geometry.check_gripper``: joint types, units, limits,
what the fingers reach).
What it doesn't: check geometry, limits or whether the simulated robot behaves (the agent build
and the scene's own check of the driven joints do), or read the sphere file.
"""

from __future__ import annotations

from collections.abc import Iterable

from realize.config import ConfigError, did_you_mean
from realize.robot.spec import RobotSpec
from realize.robot.urdf import parse_urdf_joints, source_urdf

__all__ = ["urdf_names", "check_urdf_names"]


def urdf_names(path: str) -> tuple[set[str], set[str]]:
    """The movable joints and the links (every joint's parent and child) of a URDF file."""
    joints = parse_urdf_joints(path).values()
    return {j.name for j in joints if j.type != "fixed"}, {n for j in joints for n in (j.parent, j.child)}


def _refuse(key: str, kind: str, names: Iterable[str], known: set[str], urdf: str) -> None:
    for name in names:
        if name not in known:
            has = f"its {kind}s: {', '.join(sorted(known))}" if known else f"it has no {kind}s"
            raise ConfigError(f"{key}: {kind} {name!r} is not in {urdf}{did_you_mean(name, sorted(known))}; {has}")


def check_urdf_names(spec: RobotSpec, where: str = "robot") -> None:
    """Refuse a joint or link name of ``spec`` that its URDF lacks (module docstring)."""
    path = source_urdf(spec.urdf)
    try:
        joints, links = urdf_names(str(path))
    except ConfigError as e:  # not readable XML, a joint without its links: the key, then the file's line
        raise ConfigError(f"{where}.urdf = {spec.urdf!r}: {e}") from None
    name = path.name
    for key, names in ((f"{where}.base.joints", spec.base.joints), (f"{where}.upper.joints", spec.upper.joints),
                       (f"{where}.gripper.joints", spec.gripper.joints), (f"{where}.held", spec.held),
                       (f"{where}.rest", spec.rest)):
        _refuse(key, "movable joint", names, joints, name)
    c = spec.collision
    for key, names in ((f"{where}.base.link", [spec.base.link]), (f"{where}.tcp.link", [spec.tcp.link]),
                       (f"{where}.gripper.finger_links", spec.gripper.finger_links),
                       (f"{where}.collision.no_floor_links", c.no_floor_links),
                       (f"{where}.collision.hand_links", c.hand_links),
                       (f"{where}.collision.lean_drop_links", c.lean_drop_links),
                       (f"{where}.collision.ignore_pairs", [n for pair in c.ignore_pairs for n in pair])):
        _refuse(key, "link", names, links, name)
    from realize.robot.grip_geometry import check_gripper  # (it reads the finger meshes too)

    check_gripper(spec, where)
