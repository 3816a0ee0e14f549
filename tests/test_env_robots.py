"""Every registered task of ``envs/`` with every robot of ``configs/robot/``: ``gym.make(id, robot_uids=name)`` with the task's
defaults builds, resets reproducibly, steps and closes; each robot renders in the first task."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
import torch

import envs
from mani_skill.utils.registration import REGISTERED_ENVS
from realize.robot.spec import known_robots

ENV_IDS = sorted(k for k, spec in REGISTERED_ENVS.items() if spec.cls.__module__.partition(".")[0] == envs.__name__)


def _flat(obs) -> np.ndarray:
    if isinstance(obs, dict):
        return np.concatenate([_flat(obs[k]) for k in sorted(obs)]) if obs else np.zeros(0)
    return np.asarray(obs.cpu() if isinstance(obs, torch.Tensor) else obs, dtype=np.float64).ravel()


@pytest.fixture(scope="module")
def warm_renderer():
    """One env that has rendered, open for the module: lavapipe builds its renderer (about 12 s on
    a 2-core host) for the first frame and frees it with the last env that renders, so without it
    each robot's first frame would pay that again; with it, a robot's frame costs under a second."""
    env = gym.make(ENV_IDS[0], robot_uids=known_robots()[0], render_mode="rgb_array")
    try:
        env.reset(seed=0)
        env.render()
        yield
    finally:
        env.close()


@pytest.mark.parametrize("robot", known_robots())
@pytest.mark.parametrize("env_id", ENV_IDS)
def test_every_task_with_every_robot(env_id: str, robot: str, request: pytest.FixtureRequest) -> None:
    # each robot renders in one task, beside the module's warm renderer; test_scene.py renders too
    render = env_id == ENV_IDS[0]
    if render:
        request.getfixturevalue("warm_renderer")
    env = gym.make(env_id, robot_uids=robot, render_mode="rgb_array" if render else None)
    try:
        u = env.unwrapped
        assert u.robot_spec.name == robot
        spec = u.robot_spec
        names = list(u.agents[0].robot.active_joints_map)
        assert set(spec.state_joints) | set(spec.base.joints) == set(names)
        first, _ = env.reset(seed=0)
        second, _ = env.reset(seed=0)
        assert np.array_equal(_flat(first), _flat(second))
        qpos = u.agents[0].robot.get_qpos()[0]
        nb = len(spec.base.joints)  # a fixed base has none
        rest = torch.tensor([spec.rest_value(n) for n in names])
        assert torch.allclose(qpos[nb:], rest[nb:], atol=1e-5)  # the arm (and torso) at the robot's rest pose
        # the base at the task's start pose: planar joints at zero (the articulation's root there),
        # or a fixed base's root there itself, its height up, turned by the start's yaw
        assert torch.allclose(qpos[:nb], torch.zeros(nb), atol=1e-5)
        start = u.geometry.robot_start
        root = u.agents[0].robot.pose.p[0].cpu()
        assert torch.allclose(root, torch.tensor([*start[:2], spec.base.height], dtype=root.dtype), atol=1e-5)
        base = u.base_poses()[0].cpu()
        assert torch.allclose(base, torch.tensor(start, dtype=base.dtype), atol=1e-5)
        env.action_space.seed(0)
        for _ in range(5):
            obs, reward, terminated, truncated, info = env.step(env.action_space.sample())
        assert np.isfinite(_flat(obs)).all() and "success" in info
        if render:
            frame = env.render()
            frame = frame.cpu().numpy() if isinstance(frame, torch.Tensor) else np.asarray(frame)
            assert frame.ndim in (3, 4) and frame.shape[-1] == 3 and frame.std() > 0
    finally:
        env.close()


def test_unknown_robot_is_one_line() -> None:
    from realize.config import ConfigError

    with pytest.raises(ConfigError, match="robot_uids = 'no_such_robot' is unknown: known robots"):
        gym.make(envs.ENV_ID, robot_uids="no_such_robot")
