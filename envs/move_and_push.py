"""RealizeMoveAndPush-v1: the journal paper's move-and-push world, for plan realization.

**Task description.** A mobile manipulator (any robot of ``configs/robot/``, default
``fetch_omni``: omnidirectional planar base, lift or torso, arm, parallel gripper) starts in a free area. A thin stick stands upright on the floor with a
small cube resting on its top; an open box (floor and four low walls, open top) stands on the
floor nearby. The cube must end up in the box. The intended way is to drive to the right side of
the stick and push its upper part over towards the box, so that the cube falls in; the cube can
also be picked off the stick top and placed into the box. Tables, if the scene config lists any,
are plain obstacles. All geometry comes from a ``realize.world.geometry.GeometryCfg`` with
``variant="push"`` (the Hydra ``scene=push`` config), the ``geometry`` kwarg; without it the task
builds its default push world (``configs/scene/push.yaml``'s stick, cube and box, no tables). A
geometry of another variant is refused before anything is built.

**Parallelism.** As ``RealizePickPlace-v1`` (this task extends it): ``num_envs = N`` on PhysX
GPU, or ``n_tiles = N`` copies tiled in one PhysX CPU scene.

**Randomizations** (``reset(options=dict(randomize=...))``, off by default): those of
``RealizePickPlace-v1`` (the cube's xy offset on the stick top by up to ``object_xy_noise`` m,
clipped to the stick's top, its yaw, and the robot's start xy). The stick (an object on the
floor) always starts upright at its configured pose.

**Success conditions** (``evaluate``): the ``goal`` kwarg; by default every object not on the
floor (the cube) has its centre inside the box's inner footprint, below the top of its walls,
and is nearly still.
"""

from __future__ import annotations

from typing import Any

from mani_skill.utils.registration import register_env

from envs.pick_place import RealizePickPlaceEnv
from realize.world.geometry import ContainerCfg, GeometryCfg, SceneGeometry
from realize.world.objects import FLOOR, ObjectCfg

ENV_ID = "RealizeMoveAndPush-v1"


@register_env(ENV_ID, max_episode_steps=2000)
class RealizeMoveAndPushEnv(RealizePickPlaceEnv):
    TASK_ID = ENV_ID
    VARIANTS = ("push",)

    @classmethod
    def default_geometry(cls) -> GeometryCfg:
        stick = ObjectCfg(size=(0.04, 0.04, 0.7), rests_on=FLOOR, mass=0.3, friction=0.8, color=(0.75, 0.6, 0.35, 1.0))
        return GeometryCfg(variant="push", tables=[], objects={"cube": ObjectCfg(rests_on="stick"), "stick": stick},
                           containers=[ContainerCfg()])

    @classmethod
    def default_goal(cls, geometry: SceneGeometry) -> dict[str, Any]:
        """Every object that does not stand on the floor (the cube on the stick) ends in the
        first container."""
        box = geometry.containers[0].name
        return {"rests_in": {o.name: box for o in geometry.objects if o.rests_on != FLOOR}}
