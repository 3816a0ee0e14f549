"""Where the copies of a world go, and what the simulator is sized for: the tiles of the CPU
backend's one scene, PhysX GPU's contact buffers, and the quaternion of a yawed, pitched box.

What it does: ``tile_offsets`` lays N copies out on a near-square grid that never overlaps;
``gpu_memory_config`` sizes PhysX GPU's contact buffers for N sub-scenes; ``yaw_pitch_quat`` is
the wxyz quaternion the tasks build tilted boxes (a ramp) and yawed objects with.
What it doesn't: build anything (the tasks in ``envs/`` do).
"""

from __future__ import annotations

import math

import numpy as np
from mani_skill.utils.structs.types import GPUMemoryConfig

__all__ = ["TILE_MARGIN", "GPU_CONTACTS_PER_COPY", "tile_offsets", "gpu_memory_config", "yaw_pitch_quat"]

TILE_MARGIN = 3.0  # metres of empty floor between tiled copies
# PhysX GPU contact buffers: ManiSkill's own Fetch task (OpenCabinetDrawer) raises them to 2**21
# contacts and 2**19 patches; here they also grow with the copies, by this many contacts per copy
# (not measured on a GPU yet: on overflow PhysX drops contacts with a printed warning only)
GPU_CONTACTS_PER_COPY = 512


def tile_offsets(n: int, extent: tuple[float, float], margin: float = TILE_MARGIN) -> np.ndarray:
    """(n, 2) xy offsets of n copies laid out on a near-square grid without overlap."""
    cols = max(1, math.ceil(math.sqrt(n)))
    sx, sy = extent[0] + margin, extent[1] + margin
    i = np.arange(n)
    return np.stack([(i % cols) * sx, (i // cols) * sy], axis=1).astype(np.float64)


def gpu_memory_config(num_envs: int) -> GPUMemoryConfig:
    """PhysX GPU buffers for ``num_envs`` sub-scenes: ManiSkill's Fetch task's at least, and
    ``GPU_CONTACTS_PER_COPY`` contacts (a quarter as many patches) per copy, in powers of two."""
    contacts = max(2**21, 1 << math.ceil(math.log2(max(1, num_envs) * GPU_CONTACTS_PER_COPY)))
    return GPUMemoryConfig(max_rigid_contact_count=contacts, max_rigid_patch_count=contacts // 4)


def yaw_pitch_quat(yaw: float, pitch: float) -> list[float]:
    """wxyz quaternion of R = Rz(yaw) @ Ry(pitch)."""
    cy, sy = math.cos(yaw / 2), math.sin(yaw / 2)
    cp, sp = math.cos(pitch / 2), math.sin(pitch / 2)
    return [cy * cp, -sy * sp, cy * sp, sy * cp]
