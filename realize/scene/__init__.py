"""The batched scene: N realizations of a task simulated at once, behind one interface.

Modules:
  * ``batched``: ``BatchedScene``, what the realizer sees ((N, ...) tensors in a copy's local
    frame, target writes, step, reset, freeze, step hooks, per-copy friction, render);
  * ``settings``: ``SimSettings`` (the ``sim`` config group), ``EnvOptions`` and ``Camera``
    (what the task env is built with besides);
  * ``physics``: the contract a simulator backend fulfils (``PhysicsBackend``) and the task
    construction both backends share;
  * ``backends``: which backend runs (``open_backend``), ``cpu_tiled`` (N copies tiled in one
    PhysX CPU scene) and ``gpu`` (ManiSkill ``num_envs = N`` on PhysX GPU): the only modules
    that ask which backend runs.
This package's namespace offers the names the rest of realize uses, each imported when first
asked for (``settings`` alone imports nothing heavy: the config edge reads ``SimSettings`` without
the simulator).
What it doesn't: decide anything (controllers and the rollout do), or hold world geometry
(``realize.world.geometry``) or the ManiSkill tasks (``envs``).
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from realize.scene.batched import BatchedScene, SceneSpec, StepHook
    from realize.scene.quaternion import quat_to_matrix
    from realize.scene.settings import Camera, EnvOptions, SimSettings

__all__ = [
    "BatchedScene", "SceneSpec", "StepHook", "quat_to_matrix", "SimSettings", "EnvOptions", "Camera",
]

_MODULE = {"BatchedScene": "batched", "SceneSpec": "batched", "StepHook": "batched", "quat_to_matrix": "quaternion",
           "SimSettings": "settings", "EnvOptions": "settings", "Camera": "settings"}


def __getattr__(name: str) -> Any:
    """A name of ``__all__`` from its module, imported on first use."""
    if name not in _MODULE:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    return getattr(importlib.import_module(f"{__name__}.{_MODULE[name]}"), name)
