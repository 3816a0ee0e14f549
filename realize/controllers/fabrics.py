"""Batched, differentiable static optimization fabrics in pure torch.

What it does
------------
Computes the joint accelerations ``qdd`` of a *speed-controlled static fabric*
(Ratliff et al. 2020, "Optimization Fabrics"; eq. (4) of the seed paper:
``M qdd + f + gamma * d_q psi + B qd = 0``) for N plans at once, with the same
conventions, default expressions and constants as the reference ``fabrics``
package (M. Spahn, ``ParameterizedFabricPlanner``, ``forcing_type =
'speed-controlled'``). The fabric is a sum of leaves pulled back into joint
space:

* a base energy ``0.5 * base_inertia * |qd|^2`` (zero geometry);
* one collision-avoidance leaf per (collision sphere on the robot, obstacle),
  leaf coordinate ``x = |p_k(q) - c| / (r_obst + r_body) - 1`` by default,
  geometry ``h = -lam / x^5 * s(xd) * xd^2`` with ``s(xd) = 1`` while
  approaching (``xd < 0``), ``0.5`` at ``xd == 0`` and ``0`` when leaving,
  Finsler energy ``0.1 / x * xd^2``;
* two joint-limit leaves per joint, ``x = q_i - lower_i`` and
  ``x = upper_i - q_i``, geometry ``-0.1 / x * xd^2``, energy
  ``0.1 / x * s(xd) * xd^2``;
* a goal attractor on the end-effector position, ``x = x_ee(q) - goal``,
  potential ``gamma * k * (|x| + log(1 + exp(-2 a |x|)) / a)`` and metric
  ``((m_max - m_min) exp(-(a_m |x|)^2) + m_min) I``;
* speed control: execution energy ``|qd|^2``, interpolation ``eta`` between the
  energized unforced and forced systems, and the damper ``beta`` that switches
  from ``beta_distant`` to ``beta_close + beta_distant`` near the goal.

Pull-backs follow the reference package exactly, including its convention
``Jdot = -d(J qd)/dq`` (``Jdot_sign = -1``): a spec ``(M, f)`` in leaf
coordinates is pulled back as ``J^T M J`` and ``J^T (f - M a)`` with
``a = qd^T (d^2 x / dq^2) qd`` (the true curvature term), whereas the leaf
energies are pulled back through their Lagrangians, i.e. with ``+a``. The
energization coefficients ``alpha`` use both, as in the package. Inverses are
``(M + eps I)^-1`` with ``eps = 1e-6`` and actions whose norm is below ``eps``
or above ``1 / eps`` are zeroed, as ``compute_action`` does.

The robot enters only through a differentiable forward map supplied by the
caller (``realize.controllers.fabric_jets``: ``FabricKinematics``, ``Kinematics``):
end-effector position ``x_ee(q)`` (N, d) and collision-sphere centres ``p(q)``
(N, K, d); that module computes the leaves' Jacobians and curvature terms.
Everything is batched over N plans with no Python loop over N, device- and
dtype-agnostic, and differentiable w.r.t. ``q``, ``qd``, the goal, obstacles
and gains.

Bad input: invalid *configuration* constants (non-positive gains, ...) raise
``realize.config.ConfigError`` naming the parameter when the ``FabricConfig`` is
built; the step itself checks no constant again. Invalid *per-plan* data (NaN/inf in
``q``, ``qd``, goal, goal weight or an unmasked obstacle, a non-positive goal
weight, a non-finite result) never fails the batch: such rows get ``qdd = 0``
and ``valid = False`` in the returned ``(N,)`` mask.

What it does not do
-------------------
No dynamic fabrics (moving obstacles, reference-path tracking), no
self-collision or capsule leaves, no orientation goals and no secondary
goals. The obstacle leaf coordinate is pluggable (``obstacle_distance``):
spheres here, boxes through ``realize.controllers.obstacles.BoxDistance``
(the whole-body fabric's tables and walls), without touching the fabric.
Like the reference, the leaves have no distance cut-off, and a goal reached exactly gives zero attractor force (the
reference gives NaN there).
"""

from __future__ import annotations

import math
from typing import Callable

import torch
from torch import Tensor

from realize.controllers.settings import FabricConfig
from realize.controllers.fabric_jets import (
    FabricKinematics,
    distance_jets,
    kinematic_jets,
    sphere_distance,
    sphere_jets,
)

__all__ = ["FabricConfig", "fabric_acceleration", "integrate"]


def _one_sided(xd: Tensor) -> Tensor:
    """Reference switch ``-0.5 * (sign(xd) - 1)``: 1 approaching, 0.5 at rest, 0 leaving."""
    return -0.5 * (torch.sign(xd) - 1.0)


# The leaf sums below are broadcast products reduced over the leaves, not batched matrix
# products: a batched BLAS product may give a row different last bits depending on the other
# rows of the batch (seen with MKL on AMD CPUs), and the fabric runs on a changing subset of
# plans; an elementwise product reduced inside one row does not depend on its batch mates.


def _pull(Jt: Tensor, m: Tensor) -> Tensor:
    """Sum over scalar leaves of m_l J_l^T J_l: Jt (N, n, L) (transposed Jacobians), m (N, L) -> (N, n, n)."""
    return ((Jt * m[:, None, :])[:, :, None, :] * Jt[:, None, :, :]).sum(-1)


def _pull_force(Jt: Tensor, f: Tensor) -> Tensor:
    """Sum over scalar leaves of J_l^T f_l: Jt (N, n, L), f (N, L) -> (N, n)."""
    return (Jt * f[:, None, :]).sum(-1)


def _safe_norm(x: Tensor) -> Tensor:
    tiny = torch.finfo(x.dtype).tiny ** 0.5
    return torch.sqrt((x * x).sum(-1) + tiny)


def fabric_acceleration(
    q: Tensor,
    qd: Tensor,
    goal: Tensor,
    kin: FabricKinematics,
    cfg: FabricConfig = FabricConfig(),
    *,
    obstacles: Tensor | None = None,
    obstacle_mask: Tensor | None = None,
    lower: Tensor | None = None,
    upper: Tensor | None = None,
    weight: Tensor | float | None = None,
    obstacle_distance: Callable[[Tensor, Tensor, Tensor], Tensor] = sphere_distance,
    vectorize: bool = True,
) -> tuple[Tensor, Tensor]:
    """Joint accelerations of the speed-controlled static fabric for N plans.

    Args:
        q, qd: joint positions and velocities (N, n).
        goal: end-effector goal positions (N, d).
        kin: forward maps of the robot, see ``fabric_jets.FabricKinematics``.
        cfg: fabric constants (reference defaults).
        obstacles: (N, M, P) obstacle parameters for ``obstacle_distance``; for the
            default spheres/circles P = d + 1 (centre, radius). None: no obstacles.
        obstacle_mask: (N, M) bool, False marks padding. Default: all True.
        lower, upper: joint limits (n,) or (N, n), +-inf for an unlimited joint;
            None: no joint-limit leaves.
        weight: attractor weight gamma, float or (N,); default ``cfg.gamma``.
        obstacle_distance: leaf map ``(points (N,K,d), body_radii (N,K),
            obstacles (N,M,P)) -> (N,K,M)``. If it has a method ``jets(p, Jp, pd,
            ap, radii, obstacles)`` returning flattened (value, J, velocity,
            curvature) leaves, that closed form is used instead of forward AD.
        vectorize: vmap the Jacobian over joint directions (else a loop over n).

    Returns:
        ``(qdd, valid)``: accelerations (N, n), zero where ``valid`` (N,) is False.
    """
    if q.ndim != 2 or qd.shape != q.shape:
        raise ValueError(f"q and qd must both be (N, n), got {tuple(q.shape)} and {tuple(qd.shape)}")
    N, n = q.shape
    if goal.ndim != 2 or goal.shape[0] != N:
        raise ValueError(f"goal must be (N, d) with N={N}, got {tuple(goal.shape)}")
    dtype, device = q.dtype, q.device
    eps = cfg.eps

    # ---- per-plan validity and sanitised inputs (invalid rows never poison the batch)
    if weight is None:
        weight = cfg.gamma  # checked once, when the FabricConfig was built
    elif not torch.is_tensor(weight):
        if not math.isfinite(weight) or weight <= 0:
            raise ValueError(f"weight (attractor gain gamma) must be finite and > 0, got {weight}")
    w = torch.as_tensor(weight, dtype=dtype, device=device).expand(N)
    finite = lambda t: torch.isfinite(t).flatten(1).all(1)  # noqa: E731
    valid = finite(q) & finite(qd) & finite(goal) & torch.isfinite(w) & (w > 0)
    if obstacles is not None and (obstacles.ndim != 3 or obstacles.shape[0] != N):
        raise ValueError(f"obstacles must be (N, M, P), got {tuple(obstacles.shape)}")
    if obstacles is not None and obstacles.shape[1] == 0:
        obstacles = None
    if obstacles is not None:
        M = obstacles.shape[1]
        if obstacle_mask is None:  # no padding: every obstacle is real
            mask = None
            valid = valid & torch.isfinite(obstacles).flatten(1).all(1)
            keep = valid[:, None, None]
        else:
            mask = obstacle_mask.to(device=device, dtype=torch.bool)
            obs_ok = torch.isfinite(obstacles).all(-1) | ~mask
            valid = valid & obs_ok.all(1)
            keep = mask[..., None] & valid[:, None, None]
        # padding -> a harmless far-away unit sphere; its leaves are masked out below
        far = torch.cat([torch.full_like(obstacles[..., :-1], 1e3),
                         torch.ones_like(obstacles[..., -1:])], dim=-1)
        obstacles = torch.where(keep, obstacles, far)
    v2 = valid[:, None]
    if (lower is None) != (upper is None):
        raise ValueError("give both joint limits lower and upper, or neither")
    if lower is not None and upper is not None:
        # +-inf entries are allowed: such a joint gets no limit leaf (h = M = 0)
        lo = torch.as_tensor(lower, dtype=dtype, device=device).expand(N, n)
        up = torch.as_tensor(upper, dtype=dtype, device=device).expand(N, n)
        mid = 0.5 * (lo + up)
        q = torch.where(v2, q, torch.where(torch.isfinite(mid), mid, torch.zeros_like(mid)))
    else:
        q = torch.where(v2, q, torch.zeros_like(q))
    qd = torch.where(v2, qd, torch.zeros_like(qd))
    w = torch.where(valid, w, torch.ones_like(w))

    # ---- leaf maps: attractor (x_ee - goal) and all (sphere, obstacle) pairs
    body_radii = torch.as_tensor(kin.body_radii, dtype=dtype, device=device)
    d = goal.shape[1]

    ee_jets, point_jets = kinematic_jets(kin, q, qd, d, vectorize=vectorize)
    parts = [ee_jets]
    if obstacles is not None:
        radii = body_radii.expand(N, point_jets[0].shape[1])
        if obstacle_distance is sphere_distance:
            parts.append(sphere_jets(*point_jets, radii, obstacles))
        elif hasattr(obstacle_distance, "jets"):  # closed-form leaf jets of a custom map
            parts.append(obstacle_distance.jets(*point_jets, radii, obstacles))
        else:
            parts.append(distance_jets(obstacle_distance, *point_jets, radii, obstacles, vectorize))
    # leaves in one layout: [attractor (d) | collision pairs (K * M, index k * M + m)]
    y, J, yd, curv = (torch.cat(t, dim=1) for t in zip(*parts))
    goal = torch.where(valid[:, None], goal, y[:, :d].detach() + 1.0)

    # ---- unforced geometry: base + collision leaves + joint-limit leaves
    # M_g, f_g: spec pulled with the package's Jdot sign (f - M a);
    # f_le: pulled energies (Lagrangian pull-back, f + M a); their M equals M_g.
    eye = torch.eye(n, dtype=dtype, device=device).expand(N, n, n)
    M_g = cfg.base_inertia * eye
    f_g = torch.zeros(N, n, dtype=dtype, device=device)
    f_le = torch.zeros(N, n, dtype=dtype, device=device)
    if obstacles is not None:
        x, xd, a, Jc = y[:, d:], yd[:, d:], curv[:, d:], J[:, d:].transpose(1, 2).contiguous()
        if mask is not None:
            on_b = mask[:, None, :].expand(N, (y.shape[1] - d) // M, M).flatten(1)
            # masked (padding) leaves: neutral values so that nothing non-finite is formed
            x = torch.where(on_b, x, torch.ones_like(x))
            xd = torch.where(on_b, xd, torch.zeros_like(xd))
            a = torch.where(on_b, a, torch.zeros_like(a))
            Jc = torch.where(on_b[:, None, :], Jc, torch.zeros_like(Jc))
        h = -cfg.collision_lam / x ** cfg.collision_exp * _one_sided(xd) * xd ** 2
        m = 2.0 * cfg.collision_metric_lam / x ** cfg.collision_metric_exp
        f_le_x = (-cfg.collision_metric_exp * cfg.collision_metric_lam
                  / x ** (cfg.collision_metric_exp + 1.0) * xd ** 2)
        if mask is not None:
            on = on_b.to(dtype)
            m, f_le_x = m * on, f_le_x * on
        M_g = M_g + _pull(Jc, m)
        f_g = f_g + _pull_force(Jc, m * (h - a))
        f_le = f_le + _pull_force(Jc, m * a + f_le_x)
    if lower is not None and upper is not None:
        # x = q - lower (J = +1) and x = upper - q (J = -1); linear maps, a = 0
        for sign, x, lim in ((1.0, q - lo, lo), (-1.0, up - q, up)):
            # an infinite limit has no leaf; keep x finite so gradients stay finite too
            fin = torch.isfinite(lim)
            x = torch.where(fin, x, torch.ones_like(x))
            xd = sign * qd
            s = _one_sided(xd) * fin.to(dtype)
            h = -cfg.limit_lam / x ** cfg.limit_exp * xd ** 2
            m = 2.0 * cfg.limit_metric_lam / x ** cfg.limit_metric_exp * s
            f_le_x = (-cfg.limit_metric_exp * cfg.limit_metric_lam
                      / x ** (cfg.limit_metric_exp + 1.0) * s * xd ** 2)
            M_g = M_g + torch.diag_embed(m)
            f_g = f_g + sign * m * h
            f_le = f_le + sign * f_le_x

    # ---- forcing: attractor leaf on x = x_ee(q) - goal
    xa = y[:, :d] - goal
    xda, aa, Ja = yd[:, :d], curv[:, :d], J[:, :d]
    r = _safe_norm(xa)
    grad_psi = (w * cfg.k_psi * torch.tanh(cfg.a_psi * r) / r)[:, None] * xa
    m_att = 2.0 * ((cfg.m_max - cfg.m_min) * torch.exp(-(cfg.a_m * r) ** 2) + cfg.m_min)
    Jat = Ja.transpose(1, 2).contiguous()
    M_f = M_g + m_att[:, None, None] * _pull(Jat, torch.ones_like(xa))
    f_f = f_g + m_att[:, None] * _pull_force(Jat, grad_psi - aa)

    # ---- energization and speed control
    reg = eps * eye
    h_g = torch.linalg.solve_ex(M_g + reg, f_g)[0]
    h_f = torch.linalg.solve_ex(M_f + reg, f_f)[0]
    qd2 = (qd * qd).sum(-1)
    alpha_geo = -(qd * (f_g - f_le)).sum(-1) / (eps + ((M_g * qd[:, None, :]).sum(-1) * qd).sum(-1))
    alpha_ex = -2.0 * (qd * h_g).sum(-1) / (eps + 2.0 * qd2)
    alpha_fex = -2.0 * (qd * h_f).sum(-1) / (eps + 2.0 * qd2)
    eta = 0.5 * (torch.tanh(-cfg.alpha_eta * qd2 * (1.0 - cfg.ex_factor) - 0.5) + 1.0)
    a_ex = eta * alpha_ex + (1.0 - eta) * alpha_fex
    beta = (0.5 * (torch.tanh(-cfg.alpha_b * (r - cfg.radius_shift)) + 1.0) * cfg.beta_close
            + cfg.beta_distant + torch.clamp(alpha_geo - a_ex, min=0.0))
    qdd = -h_f - (a_ex + beta)[:, None] * qd

    # ---- outputs
    valid = valid & torch.isfinite(qdd).all(-1)
    if cfg.zero_extreme_actions:
        norm = torch.linalg.vector_norm(qdd.detach(), dim=-1)
        keep = valid & (norm >= eps) & (norm <= 1.0 / eps)
    else:
        keep = valid
    qdd = torch.where(keep[:, None], qdd, torch.zeros_like(qdd))
    return qdd, valid


def integrate(q: Tensor, qd: Tensor, qdd: Tensor, dt: float) -> tuple[Tensor, Tensor]:
    """Semi-implicit Euler step to position/velocity targets for PD drives.

    ``qd_next = qd + dt * qdd``, ``q_next = q + dt * qd_next``; returns
    ``(q_next, qd_next)`` (N, n) each.
    """
    if not dt > 0:
        raise ValueError(f"dt must be > 0, got {dt}")
    qd_next = qd + dt * qdd
    return q + dt * qd_next, qd_next
