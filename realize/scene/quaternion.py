"""Unit quaternions (wxyz, as SAPIEN and ManiSkill give poses) to rotation matrices, batched.

What it does: ``quat_to_matrix``. What it doesn't: normalise (the simulator's quaternions are unit).
"""

from __future__ import annotations

import torch

__all__ = ["quat_to_matrix"]


def quat_to_matrix(q: torch.Tensor) -> torch.Tensor:
    """(..., 4) wxyz unit quaternions -> (..., 3, 3) rotation matrices."""
    w, x, y, z = q.unbind(-1)
    return torch.stack(
        [
            1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y),
            2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x),
            2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y),
        ],
        dim=-1,
    ).reshape(q.shape[:-1] + (3, 3))
