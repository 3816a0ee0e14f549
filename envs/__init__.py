"""ManiSkill tasks and robots of realize. Importing this package registers them with gym."""

from envs import fetch_omni  # noqa: F401
from envs.move_and_push import ENV_ID as MOVE_AND_PUSH_ID, RealizeMoveAndPushEnv  # noqa: F401
from envs.pick_place import ENV_ID, RealizePickPlaceEnv  # noqa: F401


def env_id_for(variant: str) -> str:
    """The ManiSkill task id that builds a scene variant (``envs.geometry.VARIANTS``)."""
    return MOVE_AND_PUSH_ID if variant == "push" else ENV_ID
