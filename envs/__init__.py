"""ManiSkill tasks and robots of realize. Importing this package registers them with gym."""

from envs import fetch_omni  # noqa: F401
from envs.pick_place import ENV_ID, RealizePickPlaceEnv  # noqa: F401
