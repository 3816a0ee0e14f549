"""Which backend runs a batched scene: ``sim.backend`` resolved and opened.

What it does: ``resolve_backend`` turns ``auto`` into ``gpu`` where torch sees CUDA and ``cpu``
elsewhere, and refuses ``gpu`` without CUDA (``ConfigError``: callers check it at the config
edge); ``open_backend`` builds the chosen one (``realize.scene.cpu_tiled`` or
``realize.scene.gpu``) for N copies. This module, ``cpu_tiled`` and ``gpu`` are the only ones
that may ask which backend runs.
What it doesn't: read or write the simulation (``realize.scene.batched`` does, through the
backend's ``realize.scene.physics.PhysicsBackend`` contract).
"""

from __future__ import annotations

import torch

from realize.config import ConfigError
from realize.geometry import GeometryCfg
from realize.scene.cpu_tiled import CpuTiledBackend
from realize.scene.gpu import GpuBackend
from realize.scene.physics import PhysicsBackend
from realize.scene.settings import EnvOptions, SimSettings

__all__ = ["resolve_backend", "open_backend", "shardable"]


def resolve_backend(backend: str, where: str = "sim.backend") -> str:
    """``cpu`` or ``gpu`` for a ``sim.backend`` value (``auto``: gpu where torch sees CUDA)."""
    if backend == "auto":
        return "gpu" if torch.cuda.is_available() else "cpu"
    if backend == "gpu" and not torch.cuda.is_available():
        raise ConfigError(f"{where} = 'gpu' but torch sees no CUDA device; use device=cpu or {where}=cpu/auto")
    return backend


def shardable(backend: str) -> bool:
    """Whether a resolved backend's copies may be cut into several scenes (shards of
    ``sim.shard_rows``, ``realize.workers``): the CPU's tiled scenes may; the GPU backend holds
    every copy in one scene on its device."""
    return backend == "cpu"


def open_backend(n_envs: int, geometry: GeometryCfg, sim: SimSettings, options: EnvOptions) -> PhysicsBackend:
    """Build N copies of ``geometry``'s world on the backend ``sim.backend`` resolves to."""
    if resolve_backend(sim.backend) == "cpu":
        return CpuTiledBackend(n_envs, geometry, sim, options)
    return GpuBackend(n_envs, geometry, sim, options)
