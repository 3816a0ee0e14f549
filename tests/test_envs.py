"""Every ManiSkill task this project registers works with ``gym.make(id)`` and its defaults.

As ManiSkill's own env tests do: make the env (only ``render_mode`` set, so that ``render`` has
something to return), ``reset(seed=0)`` twice gives equal observations, 5 random steps,
``render()``, ``close()``. The ids come from ManiSkill's registry (every env whose class lives in
the ``envs`` package), not from a hand-written list. Plus: a geometry of a variant a task does
not build is refused by name before any scene is built.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
import pytest
import torch
from mani_skill.utils.registration import REGISTERED_ENVS

import envs
from realize.config import ConfigError

ENV_IDS = sorted(k for k, spec in REGISTERED_ENVS.items() if spec.cls.__module__.partition(".")[0] == envs.__name__)


def _equal(a: Any, b: Any) -> bool:
    if isinstance(a, dict):
        return a.keys() == b.keys() and all(_equal(a[k], b[k]) for k in a)
    if isinstance(a, torch.Tensor):
        return torch.equal(a, b)
    return bool(np.array_equal(np.asarray(a), np.asarray(b)))


def test_the_registry_lists_our_tasks() -> None:
    assert envs.ENV_ID in ENV_IDS and envs.MOVE_AND_PUSH_ID in ENV_IDS


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_make_with_defaults_reset_step_render_close(env_id: str) -> None:
    env = gym.make(env_id, render_mode="rgb_array")
    try:
        obs0, _ = env.reset(seed=0)
        obs1, _ = env.reset(seed=0)
        assert _equal(obs0, obs1)
        env.action_space.seed(0)
        for _ in range(5):
            obs, reward, terminated, truncated, info = env.step(env.action_space.sample())
        assert "success" in info
        frame = env.render()
        frame = frame.cpu().numpy() if isinstance(frame, torch.Tensor) else np.asarray(frame)
        assert frame.shape[-1] == 3 and frame.std() > 0
    finally:
        env.close()


@pytest.mark.parametrize("env_id, geometry, words", [
    (envs.MOVE_AND_PUSH_ID, {"variant": "plain"}, "geometry.variant = 'plain'"),
    (envs.ENV_ID, {"variant": "push", "tables": []}, "geometry.variant = 'push'"),
    (envs.ENV_ID, {"cube_size": 1.0}, "geometry.cube_size"),
])
def test_wrong_geometry_is_refused_by_kwarg_name(env_id: str, geometry: dict, words: str) -> None:
    with pytest.raises(ConfigError) as e:
        gym.make(env_id, geometry=geometry)
    assert words in str(e.value)
