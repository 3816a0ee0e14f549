"""ManiSkill's Koch v1.1 arm as a user adds it, for the URDF reader tests (no config file of the
project: the arm is not one of its robots).

``koch_mapping()`` is ``configs/robot/so100.yaml`` with the Koch's URDF, joints and links put in,
as issue 71's user did: a fixed base, ``joint_1``-``joint_5`` the arm, ``joint_6`` the one revolute
jaw (``gripper`` turning against ``link_6``), the TCP at the URDF's ``gripper_tcp`` point of
``link_6``. Its URDF names every mesh ``package://koch/meshes/...`` (the files lie in the URDF's
own ``meshes/`` folder) and gives no ``effort`` or ``velocity`` on any ``<limit>``.
``koch_spec()`` reads the mapping as ``realize`` reads a robot config.
"""

from __future__ import annotations

from typing import Any

import yaml

from realize.robot.spec import ROBOT_CONFIG_DIR, RobotSpec

KOCH_URDF = "mani_skill:robots/koch/follower_arm_v1.1.urdf"
ARM = ("joint_1", "joint_2", "joint_3", "joint_4", "joint_5")
FINGERS = ("link_6", "gripper")


def koch_mapping(urdf: str = KOCH_URDF) -> dict[str, Any]:
    """The Koch's robot config (module docstring) as the mapping a YAML file gives."""
    with open(ROBOT_CONFIG_DIR / "so100.yaml") as f:
        d = yaml.safe_load(f)
    d.update(name="koch", urdf=urdf, rest={}, fabric_exclude=[])
    d["base"]["link"] = "base_link"
    d["upper"] = {"joints": list(ARM), "drives": [{"joints": list(ARM)}]}
    # the jaw: joint_6 in [0, 1.6] rad, 0 closed; 1 rad opens the pads about 48 mm
    d["gripper"].update(joints=["joint_6"], finger_links=list(FINGERS), open=1.0, closed=-0.1, fingertip_reach=0.01)
    d["tcp"] = {"link": "link_6", "offset": [-0.008, 0.0, -0.065], "approach_axis": [0.0, 0.0, -1.0],
                "closing_axis": [1.0, 0.0, 0.0]}
    d["collision"] = {"no_floor_links": [], "hand_links": list(FINGERS), "lean_drop_links": [], "ignore_pairs": []}
    return d


def koch_spec(urdf: str = KOCH_URDF, **gripper: Any) -> RobotSpec:
    """The Koch's ``RobotSpec`` (``gripper``: keys of ``robot.gripper`` changed)."""
    d = koch_mapping(urdf)
    d["gripper"].update(gripper)
    return RobotSpec.from_mapping(d, "robot")
