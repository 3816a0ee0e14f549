"""Closed-form geometric Jacobians and curvature terms of points on a serial chain.

What it does
------------
For points ``c`` rigidly attached to links of a serial chain whose degrees of freedom have
axes ``z_j`` and origins ``o_j`` (``realize.robot.chain.KinematicChain.joint_frames``) and a
dof mask ``mask_j`` (1 where joint j moves the point's link):

* :func:`point_jacobian`: ``J[:, j] = mask_j * (z_j x (c - o_j))`` for revolute joints,
  ``mask_j * z_j`` for prismatic ones;
* :func:`jdot_qdot`: ``(dJ/dt) q'`` at ``q'' = 0``:
  ``sum_j mask_j q'_j * (dz_j x (c - o_j) + z_j x (c' - o'_j))`` (revolute),
  ``sum_j mask_j q'_j * dz_j`` (prismatic), with ``dz_j = w_j x z_j``,
  ``w_j = sum_{i<=j, revolute} z_i q'_i`` and ``o'_j`` the velocity of joint j's origin;
* :func:`point_jets`: Jacobian, velocity ``J q'`` and ``(dJ/dt) q'`` in one pass.

On a serial chain whose dofs are in ``q`` order, every point's mask is a prefix
``j <= end`` (:func:`prefix_ends`), so each sum over joints is a prefix sum (``cumsum`` over the
11 joints) read at the point's ``end``: no matrix products at all. Everything is elementwise or
a reduction inside one row, so a row's result does not depend on the other rows of the batch
(batched BLAS products on some CPUs do). These are what ``torch.func`` gives through the forward
kinematics (the tests compare). Out-of-place torch ops only, any leading batch shape.

What it doesn't: compute the joint frames (forward kinematics) or angular Jacobians of frames;
masks that are not prefixes (a branching set of dofs) are refused.
"""

from __future__ import annotations

import torch
from torch import Tensor

__all__ = ["prefix_ends", "point_jacobian", "jdot_qdot", "point_jets"]


def prefix_ends(mask: Tensor) -> Tensor:
    """``(P,)`` long: the last dof that moves each point (-1: none) of a prefix dof mask ``(P, n)``."""
    m = mask > 0.5
    ends = m.sum(-1) - 1
    # a value check cannot run on the meta device (no values there; CI uses it as a stand-in for CUDA);
    # a CPU build of the same model checks the same masks
    if m.device.type != "meta" and not torch.equal(m, torch.arange(m.shape[-1], device=m.device) <= ends[:, None]):
        raise ValueError("dof mask is not a prefix per point: the dofs are not one serial chain in q order")
    return ends


def _split_joints(z: Tensor, o: Tensor, rev_mask: Tensor) -> tuple[Tensor, Tensor, Tensor]:
    """``rev`` (n,), revolute axes ``zr`` (prismatic rows 0) and ``e`` = prismatic axis or ``-z x o``,
    so that column j of a point's Jacobian is ``zr_j x c + e_j``."""
    rev = rev_mask.to(z.dtype)
    zr = z * rev.unsqueeze(-1)
    e = z * (1.0 - rev).unsqueeze(-1) - torch.linalg.cross(zr, o, dim=-1)
    return rev, zr, e


def _columns(zr: Tensor, e: Tensor, pts: Tensor, mask: Tensor) -> Tensor:
    """``(..., P, 3, n)``: ``mask * (zr_j x c + e_j)``, written out per component (elementwise)."""
    zr0, zr1, zr2 = zr.unsqueeze(-3).unbind(-1)  # (..., 1, n)
    e0, e1, e2 = e.unsqueeze(-3).unbind(-1)
    c0, c1, c2 = pts.unsqueeze(-1).unbind(-2)  # (..., P, 1)
    cols = torch.stack([zr1 * c2 - zr2 * c1 + e0, zr2 * c0 - zr0 * c2 + e1, zr0 * c1 - zr1 * c0 + e2], dim=-2)
    return cols * mask.unsqueeze(-2)


def _at(prefix: Tensor, ends: Tensor) -> Tensor:
    """Rows ``ends`` (P,) of prefix sums ``(..., n, F)``, -1 reading zero: ``(..., P, F)``."""
    padded = torch.cat([torch.zeros_like(prefix[..., :1, :]), prefix], dim=-2)
    return padded.index_select(-2, ends + 1)


def point_jacobian(z: Tensor, o: Tensor, pts: Tensor, mask: Tensor, rev_mask: Tensor) -> Tensor:
    """Jacobian ``(..., P, 3, n)`` of points ``(..., P, 3)``, dof mask ``(P, n)``.

    ``z``, ``o``: joint axes and origins ``(..., n, 3)``; ``rev_mask`` ``(n,)`` bool, True for
    revolute joints. Revolute column ``z_j x (c - o_j)``, prismatic column ``z_j``.
    """
    _, zr, e = _split_joints(z, o, rev_mask)
    return _columns(zr, e, pts, mask)


def point_jets(z: Tensor, o: Tensor, pts: Tensor, mask: Tensor, ends: Tensor, qd: Tensor, rev_mask: Tensor
               ) -> tuple[Tensor, Tensor, Tensor]:
    """Jacobian ``(..., P, 3, n)``, velocity ``J q'`` and ``(dJ/dt) q'`` ``(..., P, 3)`` of points
    ``(..., P, 3)`` with prefix dof mask ``(P, n)`` and its ``ends = prefix_ends(mask)``."""
    cross = torch.linalg.cross
    rev, zr, e = _split_joints(z, o, rev_mask)
    jac = _columns(zr, e, pts, mask)
    qd3 = qd.unsqueeze(-1)
    # w_j: angular velocity of joint j's link; E_j: sum_{i<=j} q'_i e_i
    first = torch.cumsum(torch.cat([zr * qd3, e * qd3], dim=-1), dim=-2)
    w, E = first[..., :3], first[..., 3:]
    do = cross(w, o, dim=-1) + E  # velocity of the joint origins
    dz = cross(w, z, dim=-1)
    rq, pq = (rev * qd).unsqueeze(-1), ((1.0 - rev) * qd).unsqueeze(-1)
    rest = dz * pq - (cross(dz, o, dim=-1) + cross(z, do, dim=-1)) * rq
    second = torch.cumsum(torch.cat([dz * rq, rest], dim=-1), dim=-2)
    wc, Ec, adz, rc = _at(torch.cat([first, second], dim=-1), ends).split(3, dim=-1)
    vel = cross(wc, pts, dim=-1) + Ec
    acc = cross(adz, pts, dim=-1) + cross(wc, vel, dim=-1) + rc
    return jac, vel, acc


def jdot_qdot(z: Tensor, o: Tensor, pts: Tensor, mask: Tensor, qd: Tensor, rev_mask: Tensor) -> Tensor:
    """(dJ/dt) q' of points ``(..., P, 3)`` with (prefix) dof mask ``(P, n)``: ``(..., P, 3)``."""
    return point_jets(z, o, pts, mask, prefix_ends(mask), qd, rev_mask)[2]
