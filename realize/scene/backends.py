"""Which backend runs a batched scene: ``sim.backend`` resolved and opened.

What it does: ``resolve_backend`` turns ``auto`` into ``cpu``, also where torch sees CUDA: the
GPU backend has not been verified on a GPU yet, so it runs only where asked for (``gpu``, or
``device=cuda``), which warns once per process (``UnverifiedBackendWarning``) and is refused in
one line (``ConfigError``: callers check it at the config edge) without CUDA or without SAPIEN's
PhysX GPU library whole on disk (``realize.physx_gpu``);
``open_backend`` builds the chosen one (``realize.scene.cpu_tiled`` or
``realize.scene.gpu``) for N copies. This module, ``cpu_tiled`` and ``gpu`` are the only ones
that may ask which backend runs.
What it doesn't: read or write the simulation (``realize.scene.batched`` does, through the
backend's ``realize.scene.physics.PhysicsBackend`` contract).
"""

from __future__ import annotations

import warnings

import torch

from realize.config import ConfigError
from realize.world.geometry import GeometryCfg
from realize.physx_gpu import check_library
from realize.robot.spec import RobotSpec
from realize.scene.cpu_tiled import CpuTiledBackend
from realize.scene.gpu import GpuBackend
from realize.scene.physics import PhysicsBackend
from realize.scene.settings import EnvOptions, SimSettings

__all__ = ["resolve_backend", "open_backend", "shardable", "UnverifiedBackendWarning"]

UNVERIFIED = ("the PhysX GPU backend (sim.backend=gpu, device=cuda) has not been verified on a GPU yet: "
              "its physics and results are unchecked (docs/gpu.md says what was checked)")
_warned = False


class UnverifiedBackendWarning(UserWarning):
    """A run asked for a backend that has not been verified on its hardware yet."""


def resolve_backend(backend: str, where: str = "sim.backend") -> str:
    """``cpu`` or ``gpu`` for a ``sim.backend`` value (``auto``: cpu, even where torch sees CUDA).
    ``gpu`` is checked (CUDA, the PhysX GPU library) and warns once per process."""
    global _warned
    if backend == "auto":
        return "cpu"
    if backend == "gpu":
        if not torch.cuda.is_available():
            raise ConfigError(f"{where} = 'gpu' but torch sees no CUDA device; use device=cpu or {where}=cpu/auto")
        check_library(where)
        if not _warned:
            _warned = True
            warnings.warn(UNVERIFIED, UnverifiedBackendWarning, stacklevel=2)
    return backend


def shardable(backend: str) -> bool:
    """Whether a resolved backend's copies may be cut into several scenes (shards of
    ``sim.shard_rows``, ``realize.workers``): the CPU's tiled scenes may; the GPU backend holds
    every copy in one scene on its device."""
    return backend == "cpu"


def open_backend(n_envs: int, geometry: GeometryCfg, sim: SimSettings, options: EnvOptions,
                 robot: RobotSpec) -> PhysicsBackend:
    """Build N copies of ``geometry``'s world with ``robot`` on the backend ``sim.backend`` resolves to."""
    if resolve_backend(sim.backend) == "cpu":
        return CpuTiledBackend(n_envs, geometry, sim, options, robot)
    return GpuBackend(n_envs, geometry, sim, options, robot)
