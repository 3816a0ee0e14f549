"""The robot side of the optimization fabric: forward maps, leaf maps and their jets.

What it does: defines what the fabric (``realize.controllers.fabrics``) needs from a robot
(``FabricKinematics``: end-effector and collision-sphere maps, optionally with closed-form
jets), a plain function-backed implementation (``Kinematics``), the reference sphere-sphere
collision leaf map (``sphere_distance``), and the jets of the fabric's leaves: value, Jacobian,
velocity ``J qd`` and true curvature ``qd^T (d^2 x / dq^2) qd``, by forward-mode AD
(``torch.func.jvp``, vmapped over joint directions) or in closed form (``sphere_jets``).
Everything is batched over N plans, device- and dtype-agnostic and differentiable.
What it doesn't: combine the leaves into accelerations (``realize.controllers.fabrics``), or
know a particular robot (``realize.robot.kinematics`` implements ``FabricKinematics`` for any
robot from its robot config).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Protocol

import torch
from torch import Tensor
from torch.func import jvp, vmap

__all__ = ["FabricKinematics", "Kinematics", "Jets", "sphere_distance", "kinematic_jets", "sphere_jets",
           "distance_jets"]


class FabricKinematics(Protocol):
    """What the fabric needs from a robot.

    ``body_radii``: radii of the K collision spheres, shape (K,) or (N, K).
    ``__call__(q)``: for q (N, n) return ``(x_ee (N, d), points (N, K, d))``.
    Must be a differentiable torch function of q, without in-place writes to q,
    and work under ``torch.func`` forward-mode AD (vmap over tangents unless
    ``vectorize=False`` is passed to :func:`fabric_acceleration`). For gradients
    through the fabric (reverse over forward-over-forward), avoid ops whose
    forward-mode rule is in place (e.g. ``torch.linalg.vector_norm``; write
    ``sqrt((x * x).sum(-1))``).

    Optional fast path: a method ``jets(q, qd)`` returning the same as
    :func:`kinematic_jets` (values, Jacobians, velocities and curvature terms
    ``qd^T (d^2 x / dq^2) qd`` of the end effector and of the sphere centres),
    e.g. from closed forms. Without it the fabric differentiates ``__call__``
    with nested forward-mode AD, which is exact but costs about one Python-level
    op dispatch per op of the map per directional derivative.
    """

    body_radii: Tensor

    def __call__(self, q: Tensor) -> tuple[Tensor, Tensor]: ...


@dataclass
class Kinematics:
    """Plain implementation of :class:`FabricKinematics` from a function."""

    forward: Callable[[Tensor], tuple[Tensor, Tensor]]
    body_radii: Tensor

    def __call__(self, q: Tensor) -> tuple[Tensor, Tensor]:
        return self.forward(q)


def sphere_distance(points: Tensor, body_radii: Tensor, obstacles: Tensor) -> Tensor:
    """Reference sphere-sphere leaf map ``|p - c| / (r_obst + r_body) - 1``.

    points (N, K, d), body_radii (N, K), obstacles (N, M, d + 1) = centre, radius.
    Returns (N, K, M). Any function with this signature can replace it (e.g. a
    signed distance to boxes), as long as it is differentiable in ``points``.
    """
    centre, radius = obstacles[..., :-1], obstacles[..., -1]
    diff = points[:, :, None, :] - centre[:, None, :, :]
    # not torch.linalg.vector_norm: its forward-mode rule writes in place, which
    # breaks reverse mode through the nested jvp used for the curvature terms
    dist = torch.sqrt((diff * diff).sum(-1))
    return dist / (radius[:, None, :] + body_radii[:, :, None]) - 1.0


def _jets(fn: Callable[[Tensor], Tensor], q: Tensor, qd: Tensor, vectorize: bool
          ) -> tuple[Tensor, Tensor, Tensor, Tensor]:
    """Value y (N, L), Jacobian J (N, L, n), velocity J qd (N, L), curvature qd^T H qd (N, L)."""

    def velocity(z: Tensor) -> tuple[Tensor, Tensor]:
        return jvp(fn, (z,), (qd,))

    (y, yd), (_, curvature) = jvp(velocity, (q,), (qd,))
    n = q.shape[-1]
    basis = torch.eye(n, dtype=q.dtype, device=q.device)[:, None, :].expand(n, *q.shape)
    if vectorize:
        J = vmap(lambda v: jvp(fn, (q,), (v,))[1], out_dims=-1)(basis)
    else:
        J = torch.stack([jvp(fn, (q,), (basis[j],))[1] for j in range(n)], dim=-1)
    return y, J, yd, curvature


Jets = tuple[Tensor, Tensor, Tensor, Tensor]


def kinematic_jets(kin: FabricKinematics, q: Tensor, qd: Tensor, d: int, vectorize: bool = True
                   ) -> tuple[Jets, Jets]:
    """Jets of the robot maps: ``((x_ee, J_ee, xd_ee, a_ee), (p, J_p, pd, a_p))``.

    Shapes (N, d), (N, d, n), (N, d), (N, d) and (N, K, d'), (N, K, d', n),
    (N, K, d'), (N, K, d'); ``a = qd^T (d^2 x / dq^2) qd`` is the true curvature
    term. Uses ``kin.jets(q, qd)`` when the kinematics provides it (e.g. closed
    forms), otherwise forward-mode AD through ``kin(q)``.
    """
    if hasattr(kin, "jets"):
        return kin.jets(q, qd)
    N = q.shape[0]

    def flat(z: Tensor) -> Tensor:
        x_ee, points = kin(z)
        return torch.cat([x_ee, points.flatten(1)], dim=1)

    y, J, yd, a = _jets(flat, q, qd, vectorize)
    K = int(torch.as_tensor(kin.body_radii).shape[-1])
    dp = (y.shape[1] - d) // max(K, 1)
    ee = (y[:, :d], J[:, :d], yd[:, :d], a[:, :d])
    pts = (y[:, d:].reshape(N, K, dp), J[:, d:].reshape(N, K, dp, -1),
           yd[:, d:].reshape(N, K, dp), a[:, d:].reshape(N, K, dp))
    return ee, pts


def sphere_jets(p: Tensor, Jp: Tensor, pd: Tensor, ap: Tensor, radii: Tensor,
                 obstacles: Tensor) -> Jets:
    """Closed-form jets of :func:`sphere_distance` composed with the point jets."""
    centre, radius = obstacles[..., :-1], obstacles[..., -1]
    u = p[:, :, None, :] - centre[:, None, :, :]  # (N, K, M, d)
    rho = torch.sqrt((u * u).sum(-1))
    R = radius[:, None, :] + radii[:, :, None]
    phi = rho / R - 1.0
    g = u / (rho * R)[..., None]  # d phi / d p
    J = torch.einsum("nkmd,nkdj->nkmj", g, Jp)
    pdm = pd[:, :, None, :]
    phid = (g * pdm).sum(-1)
    u_pd = (u * pdm).sum(-1)
    a = (g * ap[:, :, None, :]).sum(-1) + ((pdm * pdm).sum(-1) - u_pd ** 2 / rho ** 2) / (rho * R)
    return phi.flatten(1), J.flatten(1, 2), phid.flatten(1), a.flatten(1)


def distance_jets(distance: Callable[[Tensor, Tensor, Tensor], Tensor], p: Tensor, Jp: Tensor,
                   pd: Tensor, ap: Tensor, radii: Tensor, obstacles: Tensor, vectorize: bool) -> Jets:
    """Jets of a generic leaf map ``distance(p, radii, obstacles)`` by forward-mode AD."""

    def f(z: Tensor) -> Tensor:
        return distance(z, radii, obstacles)

    (phi, phid), (_, a2) = jvp(lambda z: jvp(f, (z,), (pd,)), (p,), (pd,))
    a1 = jvp(f, (p,), (ap,))[1]
    cols = Jp.movedim(-1, 0)  # (n, N, K, d)
    if vectorize:
        J = vmap(lambda v: jvp(f, (p,), (v,))[1], out_dims=-1)(cols)
    else:
        J = torch.stack([jvp(f, (p,), (c,))[1] for c in cols], dim=-1)
    return phi.flatten(1), J.flatten(1, 2), phid.flatten(1), (a1 + a2).flatten(1)
