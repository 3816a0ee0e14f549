"""ManiSkill tasks and robots of realize. Importing this package registers them with gym.

What it does: registers ``RealizePickPlace-v1`` (``plain``/``wall``/``ramp`` worlds),
``RealizeMoveAndPush-v1`` (the ``push`` world) and every robot of ``configs/robot/`` (one agent class
built from a robot spec, ``envs.robot_agent``), and maps a world
variant to the task that builds it (``env_id_for``).
What it doesn't: hold world geometry (``realize.world.geometry``) or batch copies for the realizer
(``realize.scene``).
"""

from envs import robot_agent
from envs.move_and_push import ENV_ID as MOVE_AND_PUSH_ID, RealizeMoveAndPushEnv  # noqa: F401
from envs.pick_place import ENV_ID, RealizePickPlaceEnv  # noqa: F401

robot_agent.register_known_robots()


def env_id_for(variant: str) -> str:
    """The ManiSkill task id that builds a scene variant (``realize.world.geometry.VARIANTS``)."""
    return MOVE_AND_PUSH_ID if variant in RealizeMoveAndPushEnv.VARIANTS else ENV_ID
