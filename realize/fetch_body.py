"""Fetch's body model for planning: the tool centre point and the collision spheres.

What it does
------------
* :data:`TCP_OFFSET`, :data:`FINGERTIP_REACH`: where the tool centre point (TCP) sits in
  ``gripper_link`` and how far the fingertips reach beyond it (measured from the finger
  collision meshes of ManiSkill's ``fetch.urdf``, see below).
* :class:`SphereSpec` and :data:`FETCH_SPHERES`: 23 spheres rigidly attached to Fetch's links
  that cover its collision meshes, for keeping the robot off tables (boxes) and the floor.

What it doesn't: compute where the spheres are (``realize.kinematics`` does, batched), model
self-collision (neighbouring spheres overlap on purpose), or treat the fingers as degrees of
freedom (the finger spheres follow the opening given to ``FetchKinematics``).

TCP definition
--------------
The finger pads' inner faces are planes ``y = +-finger_opening`` of ``gripper_link`` and span
``x in [-0.029, 0.031]``, ``z in [-0.013, 0.013]`` of ``gripper_link``; the pad centre is
therefore ``(0.001, 0, 0)`` in ``gripper_link``. The TCP is that point (:data:`TCP_OFFSET`),
with ``gripper_link``'s orientation: ``+x`` is the approach axis (the fingers point along it,
their tips reach :data:`FINGERTIP_REACH` = 0.031 m beyond ``gripper_link``'s origin) and ``+y``
is the closing axis (the line joining the fingers). ManiSkill's own ``agent.tcp_pos``
(the midpoint of the two finger-link origins) is ``gripper_link``'s origin, 1 mm behind ours.
"""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["TCP_OFFSET", "FINGERTIP_REACH", "SphereSpec", "FETCH_SPHERES"]

TCP_OFFSET: tuple[float, float, float] = (0.001, 0.0, 0.0)
"""TCP in ``gripper_link``: the centre of the finger pads (see the module docstring)."""

FINGERTIP_REACH: float = 0.031
"""How far the fingertips reach beyond ``gripper_link``'s origin along the approach axis."""


@dataclass(frozen=True)
class SphereSpec:
    """A collision sphere rigidly attached to a link.

    ``check_floor`` is False for spheres that touch the floor by design (the base sphere);
    callers should leave those out of floor avoidance.
    """

    name: str
    link: str
    offset: tuple[float, float, float]
    radius: float
    check_floor: bool = True


# How these were chosen: for each link, the vertices plus 20k surface samples of its
# collision mesh in the URDF (``fetch_description/meshes/*collision*.STL``; for the torso
# column, gripper and fingers the only STL given) were split among 1-3 centres placed along
# the link's long axis (centres moved to the bounding-box centre of their cluster, a few
# k-means rounds); each radius is the largest distance of its cluster to the centre, rounded
# up to 5 mm. Arm links are ~0.052 m radius cylinders with joint housings sticking out, hence
# ~0.085 m spheres. The base is a ~0.29 m radius, 0.36 m tall drum: one 0.335 m sphere (5 cm
# conservative sideways) also swallows the wheels, laser and e-stop. The two torso_fixed
# spheres sit 3 cm forward of their column's centre so they also cover the bellows (the skirt
# under the lifted torso). The head sphere covers head_pan and head_tilt (head at 0). Finger
# spheres sit on the finger links at the pad centre, so they follow the opening given to
# :class:`FetchKinematics`. ``tests/test_kinematics.py`` checks that every collision-mesh
# vertex and surface sample of every link lies inside the union of the spheres at random
# configurations (torso down and up, head at 0).
FETCH_SPHERES: tuple[SphereSpec, ...] = (
    SphereSpec("base", "base_link", (0.0, 0.0, 0.179), 0.335, check_floor=False),
    SphereSpec("torso_fixed_low", "torso_fixed_link", (-0.070, 0.0, 0.097), 0.215),
    SphereSpec("torso_fixed_high", "torso_fixed_link", (-0.070, 0.0, 0.328), 0.215),
    SphereSpec("torso_low", "torso_lift_link", (-0.007, 0.0, 0.124), 0.235),
    SphereSpec("torso_mid", "torso_lift_link", (-0.007, 0.0, 0.315), 0.235),
    SphereSpec("torso_high", "torso_lift_link", (-0.026, 0.0, 0.495), 0.225),
    SphereSpec("head", "head_pan_link", (0.036, 0.0, 0.055), 0.215),
    SphereSpec("shoulder_pan", "shoulder_pan_link", (0.063, -0.011, 0.036), 0.15),
    SphereSpec("shoulder_lift_0", "shoulder_lift_link", (0.001, 0.019, 0.0), 0.09),
    SphereSpec("shoulder_lift_1", "shoulder_lift_link", (0.112, 0.009, 0.0), 0.09),
    SphereSpec("upperarm_0", "upperarm_roll_link", (0.012, -0.007, 0.0), 0.09),
    SphereSpec("upperarm_1", "upperarm_roll_link", (0.124, -0.019, 0.0), 0.085),
    SphereSpec("elbow_0", "elbow_flex_link", (0.006, 0.019, 0.0), 0.085),
    SphereSpec("elbow_1", "elbow_flex_link", (0.109, 0.008, 0.0), 0.085),
    SphereSpec("forearm_0", "forearm_roll_link", (0.023, -0.014, 0.0), 0.09),
    SphereSpec("forearm_1", "forearm_roll_link", (0.116, -0.040, 0.0), 0.08),
    SphereSpec("wrist_flex_0", "wrist_flex_link", (-0.010, 0.007, 0.0), 0.09),
    SphereSpec("wrist_flex_1", "wrist_flex_link", (0.074, 0.007, 0.0), 0.09),
    SphereSpec("wrist_roll", "wrist_roll_link", (-0.002, 0.0, 0.0), 0.06),
    SphereSpec("gripper_back", "gripper_link", (-0.123, 0.0, 0.0), 0.08),
    SphereSpec("gripper_front", "gripper_link", (-0.063, 0.0, 0.001), 0.08),
    SphereSpec("finger_r", "r_gripper_finger_link", (0.001, -0.0086, 0.0), 0.035),
    SphereSpec("finger_l", "l_gripper_finger_link", (0.001, 0.0086, 0.0), 0.035),
)
