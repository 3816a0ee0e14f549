"""Whether a fixed-base arm reaches TCP poses: batched damped-least-squares inverse kinematics.

What it does: ``reachable(kin, base, targets, approaches)`` asks, for each of ``n`` TCP positions
with a unit approach axis, whether some joint configuration within the URDF's limits puts the
TCP there (within ``pos_tol``) with the gripper's approach axis along it (within ``ang_tol``).
It starts ``seeds`` random configurations per pose (a seeded generator: the answer does not
depend on the global RNG; a pose none of them reaches gets 4x as many once more) and runs damped
least squares on the position error and the approach error (``a x a*``, whose Jacobian is the
angular rows of ``RobotKinematics.tcp_jacobian``), all ``n * seeds`` rows as one batch; every
``CHECK_EVERY`` steps the poses some start already reaches stop, so a region the arm reaches
costs a few steps, not ``iterations``. The robot's own kinematics decide: a 5-joint arm, which can only
tilt its approach in the vertical plane through its base, fails every other tilt.
``pose_ik`` solves one full pose (approach and closing axes) the same way, for scripted set-ups.
What it doesn't: check collisions (a reachable pose may put the hand in the table), move a base
(``q``'s base columns stay at ``base``: a mobile robot reaches further), or run in the control loop.
"""

from __future__ import annotations

import math

import torch
from torch import Tensor

from realize.robot.kinematics import RobotKinematics
from realize.robot.layout import N_BASE

__all__ = ["reachable", "pose_ik"]


def _start(kin: RobotKinematics, base: tuple[float, float, float], rows: int, seed: int) -> Tensor:
    """(rows, n_dof) random joint configurations within the limits (a seeded generator), the base at ``base``."""
    dt = kin.dtype
    gen = torch.Generator(device="cpu").manual_seed(seed)
    lo, hi = _limits(kin)
    u = torch.rand(rows, kin.n_dof, generator=gen, dtype=torch.float64).to(device=kin.device, dtype=dt)
    q = lo + u * (hi - lo)
    q[:, :N_BASE] = torch.tensor(base, dtype=dt, device=kin.device)
    return q


def _limits(kin: RobotKinematics) -> tuple[Tensor, Tensor]:
    lo, hi = kin.lower.clone(), kin.upper.clone()
    lo = torch.where(torch.isfinite(lo), lo, torch.full_like(lo, -torch.pi))
    hi = torch.where(torch.isfinite(hi), hi, torch.full_like(hi, torch.pi))
    return lo, hi


def _iterate(kin: RobotKinematics, q: Tensor, p_goal: Tensor, a_goal: Tensor, c_goal: Tensor | None,
             iterations: int, damping: float) -> Tensor:
    """``iterations`` damped-least-squares steps of every row of ``q`` toward its goal. A row's steps
    depend on that row alone (the kinematics' products are row-independent, and a batched solve
    solves each system by itself), so a subset of the rows steps as it would in the whole batch."""
    dt = kin.dtype
    lo, hi = _limits(kin)
    free = torch.ones(kin.n_dof, dtype=dt, device=kin.device)
    free[:N_BASE] = 0.0  # the base stays
    eye = torch.eye(6, dtype=dt, device=kin.device)
    for _ in range(iterations):
        pose, jac = kin.tcp_jacobian(q)
        r = pose[:, :3, :3]
        turn = torch.linalg.cross(r @ kin.approach_local, a_goal)  # a x a*: the rotation that aligns them
        if c_goal is not None:
            turn = turn + torch.linalg.cross(r @ kin.closing_local, c_goal)
        e = torch.cat([p_goal - pose[:, :3, 3], turn], dim=1)  # (m, 6)
        j = jac * free  # (m, 6, n_dof)
        jjt = j @ j.transpose(1, 2) + (damping ** 2) * eye
        dq = (j.transpose(1, 2) @ torch.linalg.solve(jjt, e[:, :, None])).squeeze(2)
        q = torch.minimum(torch.maximum(q + dq.clamp(-0.5, 0.5), lo), hi)
    return q


def _solve(kin: RobotKinematics, base: tuple[float, float, float], targets: Tensor, approaches: Tensor,
           closings: Tensor | None, seeds: int, iterations: int, damping: float, seed: int) -> Tensor:
    """(n * seeds, n_dof) joint configurations after damped least squares from random starts."""
    dt = kin.dtype
    q = _start(kin, base, len(targets) * seeds, seed)
    c_goal = None if closings is None else closings.to(dt).repeat_interleave(seeds, 0)
    return _iterate(kin, q, targets.to(dt).repeat_interleave(seeds, 0), approaches.to(dt).repeat_interleave(seeds, 0),
                    c_goal, iterations, damping)


def reachable(kin: RobotKinematics, base: tuple[float, float, float], targets: Tensor, approaches: Tensor,
              pos_tol: float = 0.01, ang_tol: float = 0.1, seeds: int = 16, iterations: int = 60,
              damping: float = 0.05, seed: int = 0) -> Tensor:
    """(n,) bool: the TCP reaches ``targets`` (n, 3) with unit ``approaches`` (n, 3), in the world,
    with the base columns of ``q`` at ``base`` (x, y, yaw) (module docstring)."""
    ok = _reached(kin, base, targets, approaches, pos_tol, ang_tol, seeds, iterations, damping, seed)
    again = (~ok).nonzero().flatten()
    if len(again):  # the misses once more from 4x the starts (a local minimum is not out of reach)
        ok[again] = _reached(kin, base, targets[again], approaches[again], pos_tol, ang_tol, 4 * seeds, iterations,
                             damping, seed + 1)
    return ok


# iterations between the checks of which poses some start already reaches (those stop)
CHECK_EVERY = 10


def _reached(kin: RobotKinematics, base: tuple[float, float, float], targets: Tensor, approaches: Tensor,
             pos_tol: float, ang_tol: float, seeds: int, iterations: int, damping: float, seed: int) -> Tensor:
    """(n,) bool: some start of each pose reaches it within ``iterations`` steps. Every
    ``CHECK_EVERY`` steps the poses already reached stop (all their starts): they are answered, and
    the rest step on exactly as in the whole batch (``_iterate``)."""
    n, dt = len(targets), kin.dtype
    q = _start(kin, base, n * seeds, seed)
    p_goal = targets.to(dt).repeat_interleave(seeds, 0)
    a_goal = approaches.to(dt).repeat_interleave(seeds, 0)
    ok = torch.zeros(n, dtype=torch.bool)
    live = torch.arange(n)  # poses still stepping
    done = 0
    while len(live) and done < iterations:
        step = min(CHECK_EVERY, iterations - done)
        rows = (live[:, None] * seeds + torch.arange(seeds)).flatten()
        q[rows] = _iterate(kin, q[rows], p_goal[rows], a_goal[rows], None, step, damping)
        done += step
        pose = kin.ee_pose(q[rows])
        pos_ok = (pose[:, :3, 3] - p_goal[rows]).norm(dim=1) <= pos_tol
        ang_ok = ((pose[:, :3, :3] @ kin.approach_local) * a_goal[rows]).sum(1) >= math.cos(ang_tol)
        hit = (pos_ok & ang_ok).reshape(len(live), seeds).any(dim=1)
        ok[live[hit]] = True
        live = live[~hit]
    return ok


def pose_ik(kin: RobotKinematics, base: tuple[float, float, float], target: Tensor, approach: Tensor,
            closing: Tensor, seeds: int = 32, iterations: int = 200, damping: float = 0.01) -> Tensor:
    """(n_upper,) float32 upper-joint values that put the TCP at ``target`` (3,) with its approach and
    closing axes along ``approach`` and ``closing`` (3,): the best of ``seeds`` solves (a full pose,
    for scripted tests and set-ups; no check that it is reached)."""
    q = _solve(kin, base, target[None], approach[None], closing[None], seeds, iterations, damping, 0)
    pose = kin.ee_pose(q)
    err = (pose[:, :3, 3] - target.to(kin.dtype)).norm(dim=1)
    return q[int(err.argmin()), N_BASE:].float()
