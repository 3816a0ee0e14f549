"""One scene state as the rows a backend's ``set_state`` takes: what ``BatchedScene.reset(state=...)`` restores.

What it does: ``state_row(scene, state)`` turns a ``realize.world.state.SceneState`` into the
backend's joint row (the base joints relative to the task's robot start, every other joint by
name; joints the state leaves out at the robot's rest pose) and the objects' poses ((m, 7),
position and wxyz quaternion; objects left out at their rest pose), checking joint and object
names against the scene (one ``ConfigError`` naming the state's source). A fixed base has no
joints: ``reset_offsets(scene, states, offsets)`` gives the reset's per-copy offsets that bolt
each copy's base where its state has it (x, y and yaw), so a state captured where the base
stood elsewhere (an executed world's base, off the task's start by its ``robot_xy`` draw, seen
with the localizer's error) is restored with the hand, and what it holds, where the state has them.
What it doesn't: write the simulator (``BatchedScene.reset``) or read a state from it
(``BatchedScene.capture_state``).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

import torch

from realize.config import ConfigError
from realize.world.state import SceneState

__all__ = ["state_row", "reset_offsets"]


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


def reset_offsets(scene: Any, states: Sequence[SceneState], offsets: Mapping[str, Any] | None
                  ) -> Mapping[str, Any] | None:
    """The offsets a reset of ``scene`` into ``states`` takes (``envs.pick_place``: ``robot_xy``
    (N, 2), ``robot_yaw`` (N,), the objects' ``object_xy`` and ``object_yaw`` by name):
    ``offsets`` (the scene's perturbed worlds; None: none) as they are, but for a fixed base
    restored into states, with the base's put where copy i's state has it (copies past the
    states' end at the first's; the objects' entries zeros where ``offsets`` is None: a restore
    sets their poses anyway)."""
    if not states or not scene.robot.base.fixed:
        return offsets
    n = scene.n_envs
    base = torch.tensor([s.base for s in states] + [states[0].base] * (n - len(states)), dtype=torch.float32)
    start = torch.tensor(scene.geometry.robot_start, dtype=torch.float32)
    names = scene.object_names
    out: dict[str, Any] = dict(offsets) if offsets is not None else {
        "object_xy": {o: torch.zeros(n, 2) for o in names}, "object_yaw": {o: torch.zeros(n) for o in names}}
    out["robot_xy"] = base[:, :2] - start[:2]
    out["robot_yaw"] = base[:, 2] - start[2]
    return out
