"""One scene state as the rows a backend's ``set_state`` takes: what ``BatchedScene.reset(state=...)`` restores.

What it does: ``state_row(scene, state)`` turns a ``realize.world.state.SceneState`` into the
backend's joint row (the base joints relative to the task's robot start, every other joint by
name; joints the state leaves out at the robot's rest pose) and the objects' poses ((m, 7),
position and wxyz quaternion; objects left out at their rest pose), checking joint and object
names against the scene (one ``ConfigError`` naming the state's source).
What it doesn't: write the simulator (``BatchedScene.reset``) or read a state from it
(``BatchedScene.capture_state``).
"""

from __future__ import annotations

import math
from typing import Any

import torch

from realize.config import ConfigError
from realize.world.state import SceneState

__all__ = ["state_row"]


def state_row(scene: Any, state: SceneState) -> tuple[torch.Tensor, torch.Tensor]:
    """One state as the backend's joint row (n_joints,) and object poses (m, 7) of ``scene`` (a
    ``realize.scene.batched.BatchedScene``, not imported here: it imports this module)."""
    row = torch.zeros(len(scene.joint_names))
    base = torch.tensor(state.base, dtype=torch.float32)
    base[:2] -= scene._start_xy.cpu()  # the base joints are relative to the task's robot start
    for name, v in zip(scene.robot.base.joints, base.tolist()):  # a fixed base has none: it stays where it is
        row[scene.joint_names.index(name)] = v
    scene.robot.check_state_joints(state.joints, state.source or "state")
    for name in scene.state_joints:  # joints a state leaves out take the robot's rest pose
        row[scene.joint_names.index(name)] = state.joints.get(name, scene.robot.rest_value(name))
    unknown = sorted(set(state.objects) - set(scene.object_names))
    if unknown:
        raise ConfigError(f"{state.source or 'state'}: objects {unknown} are not in the scene; its objects: "
                          f"{list(scene.object_names)}")
    poses = []
    for o in scene.geometry.objects:  # objects a state leaves out start at their rest pose
        pose = state.objects.get(o.name)
        if pose is None:
            q = (math.cos(o.yaw / 2), 0.0, 0.0, math.sin(o.yaw / 2))
            poses.append([*o.position, *q])
        else:
            poses.append([*pose.position, *pose.quaternion])
    return row, torch.tensor(poses, dtype=torch.float32)
