"""Batched PID waypoint tracker for an omnidirectional (holonomic) base, in torch.

What it does
------------
For N plans at once, given padded world waypoints (N, L, 2) with lengths (N,) and the current
base pose (N, 3) = (x, y, yaw), ``pid_step`` returns base velocity commands (N, 3) =
(vx, vy, yaw_rate) with (vx, vy) in the **robot frame** (x forward, y left), ready for the planar
base joints of an omni base. Per step:

  * waypoint switching: the target index advances past every consecutive waypoint that lies
    within ``switch_radius`` of the base (never past the final one);
  * position PID on the world-frame error to the target waypoint
    ``u = kp e + ki integral(e dt) + kd de/dt``; the integral is clamped to ``integral_limit`` (anti-windup)
    and reset, like the derivative history, whenever the target waypoint changes (no derivative
    kick at a switch);
  * speed limit: |u| <= ``max_lin_speed`` by scaling the vector (direction kept); optional
    acceleration limits on the linear command vector and on the yaw rate;
  * heading: the yaw reference is fixed per plan when the tracker starts (``pid_init``):
    ``"hold"`` (default) keeps the yaw the base had (what move_to uses: the arm holds still and
    the base translates), ``"face_goal"`` turns toward the final waypoint as seen from the start,
    ``"target"`` uses a caller-given yaw per plan. A separate PID drives the wrapped yaw error,
    clamped to ``max_yaw_rate``;
  * ``done`` when the target is the final waypoint, the base is within ``goal_tolerance`` of it and
    the yaw error is within ``yaw_tolerance``; done plans (and plans with no waypoints) get a zero
    command. ``done`` is re-evaluated every step (not latched), so a base pushed away recovers.

Differentiable-friendly: a functional step (state in, new state out), no in-place ops on the
outputs, ``torch.where`` instead of boolean indexing, safe norms (no NaN gradient at zero error),
no numpy. Device-agnostic.

What it does not do: no obstacle avoidance (the A* path is assumed free), no pure-pursuit curvature
control or velocity profiling along the path, no dynamics model; it commands velocities for the
robot's own joint drives to track.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch
from torch import Tensor

from realize.controllers.settings import HEADING_MODES, PIDConfig

__all__ = ["PIDConfig", "PIDState", "PIDOutput", "pid_init", "pid_step", "wrap_angle", "HEADING_MODES"]



def wrap_angle(a: Tensor) -> Tensor:
    """Wrap angles to (-pi, pi] (differentiable: atan2 of sin, cos)."""
    return torch.atan2(torch.sin(a), torch.cos(a))


@dataclass
class PIDState:
    """Tracker state, all (N, ...) tensors.

    index: (N,) int64 target waypoint. yaw_ref: (N,) yaw reference.
    integral, prev_error: (N, 2) world-frame position error integral / last error.
    yaw_integral, prev_yaw_error: (N,). has_prev: (N,) bool, False right after start or a switch.
    prev_cmd: (N, 3) last command (world-frame vx, vy, yaw rate) for the acceleration limits.
    """

    index: Tensor
    yaw_ref: Tensor
    integral: Tensor
    prev_error: Tensor
    yaw_integral: Tensor
    prev_yaw_error: Tensor
    has_prev: Tensor
    prev_cmd: Tensor


@dataclass
class PIDOutput:
    """cmd: (N, 3) (vx, vy) robot frame + yaw rate. done: (N,) bool. valid: (N,) bool, False where
    the pose or the target waypoint is not finite (command zeroed). state: the next PIDState.
    target: (N, 2) the waypoint tracked this step. distance: (N,) distance to it."""

    cmd: Tensor
    done: Tensor
    valid: Tensor
    state: PIDState
    target: Tensor
    distance: Tensor


def _check_path(waypoints: Tensor, lengths: Tensor, n: int) -> None:
    if waypoints.ndim != 3 or waypoints.shape[0] != n or waypoints.shape[-1] != 2:
        raise ValueError(f"waypoints must be (N={n}, L, 2); got {tuple(waypoints.shape)}")
    if lengths.shape != (n,):
        raise ValueError(f"lengths must be (N={n},); got {tuple(lengths.shape)}")
    if lengths.dtype.is_floating_point or lengths.dtype == torch.bool:
        raise ValueError(f"lengths must be an integer tensor, got {lengths.dtype}")
    if bool((lengths < 0).any()) or bool((lengths > waypoints.shape[1]).any()):
        raise ValueError(f"lengths must lie in [0, L={waypoints.shape[1]}]")


def _check_pose(pose: Tensor) -> int:
    if pose.ndim != 2 or pose.shape[-1] != 3:
        raise ValueError(f"pose must be (N, 3) = (x, y, yaw); got {tuple(pose.shape)}")
    return pose.shape[0]


def _final_point(waypoints: Tensor, lengths: Tensor) -> Tensor:
    last = (lengths - 1).clamp(min=0)
    return waypoints.gather(1, last[:, None, None].expand(-1, 1, 2))[:, 0]


def pid_init(
    config: PIDConfig,
    pose: Tensor,
    waypoints: Tensor,
    lengths: Tensor,
    target_yaw: Tensor | None = None,
) -> PIDState:
    """Fresh tracker state for N plans starting at ``pose`` (N, 3).

    target_yaw: (N,) required when ``config.heading == "target"``, ignored otherwise.
    """
    n = _check_pose(pose)
    _check_path(waypoints, lengths, n)
    dt_, dev = pose.dtype, pose.device
    if config.heading == "hold":
        yaw_ref = pose[:, 2]
    elif config.heading == "face_goal":
        d = _final_point(waypoints.to(dt_), lengths) - pose[:, :2]
        far = (d * d).sum(-1) > 1e-12
        yaw_ref = torch.where(far & (lengths > 0), torch.atan2(d[:, 1], d[:, 0]), pose[:, 2])
    else:
        if target_yaw is None or target_yaw.shape != (n,):
            raise ValueError("target_yaw of shape (N,) is required when PIDConfig.heading == 'target'")
        yaw_ref = target_yaw.to(dt_)
    z2 = torch.zeros(n, 2, dtype=dt_, device=dev)
    z1 = torch.zeros(n, dtype=dt_, device=dev)
    return PIDState(
        index=torch.zeros(n, dtype=torch.int64, device=dev),
        yaw_ref=yaw_ref,
        integral=z2,
        prev_error=z2,
        yaw_integral=z1,
        prev_yaw_error=z1,
        has_prev=torch.zeros(n, dtype=torch.bool, device=dev),
        prev_cmd=torch.zeros(n, 3, dtype=dt_, device=dev),
    )


def _safe_norm(v: Tensor) -> Tensor:
    return torch.sqrt((v * v).sum(-1) + 1e-12)


def _limit_norm(v: Tensor, limit: float | Tensor) -> Tensor:
    """Scale vectors (..., 2) so their norm is at most ``limit`` (direction kept)."""
    nrm = _safe_norm(v)
    scale = limit / torch.clamp(nrm, min=limit) if not isinstance(limit, Tensor) else \
        limit / torch.maximum(nrm, limit)
    return v * scale[..., None]


def pid_step(
    config: PIDConfig,
    state: PIDState,
    pose: Tensor,
    waypoints: Tensor,
    lengths: Tensor,
    dt: float,
) -> PIDOutput:
    """One control step for all N plans. ``dt``: control period in seconds (> 0).

    The hot path checks nothing: ``config`` was checked when it was built, the path when the
    tracker started (``pid_init``), ``dt`` is the scene's control period."""
    dtype, dev = pose.dtype, pose.device
    wps = waypoints.to(dtype)
    pos, yaw = pose[:, :2], pose[:, 2]
    l = wps.shape[1]
    has_path = lengths > 0

    # ---- waypoint switching: skip consecutive waypoints already within the switch radius ----
    j = torch.arange(l, device=dev)[None]
    dist_all = _safe_norm(wps - pos[:, None])  # (N, L)
    within = dist_all <= config.switch_radius
    last = (lengths - 1).clamp(min=0)
    cand = (j >= state.index[:, None]) & ((~within) | (j >= last[:, None])) & (j < lengths[:, None])
    first = torch.argmax(cand.to(torch.int8), dim=1)
    index = torch.where(cand.any(dim=1), first, last)
    index = torch.maximum(index, torch.minimum(state.index, last))  # never go back
    switched = index != state.index

    target = wps.gather(1, index[:, None, None].expand(-1, 1, 2))[:, 0]
    err = target - pos
    valid = torch.isfinite(pose).all(-1) & torch.isfinite(target).all(-1)
    err = torch.where(valid[:, None], err, torch.zeros_like(err))
    dist = _safe_norm(err)
    fresh = switched | ~state.has_prev  # no derivative kick after a switch or at the start

    # ---- position PID (world frame) ----
    integral = torch.where(switched[:, None], torch.zeros_like(state.integral), state.integral) + err * dt
    if config.integral_limit > 0:
        integral = _limit_norm(integral, config.integral_limit)
    else:
        integral = torch.zeros_like(integral)
    deriv = torch.where(fresh[:, None], torch.zeros_like(err), (err - state.prev_error) / dt)
    u = config.kp * err + config.ki * integral + config.kd * deriv
    u = _limit_norm(u, config.max_lin_speed)

    # ---- yaw PID toward the fixed reference ----
    yerr = wrap_angle(state.yaw_ref - yaw)
    yerr = torch.where(valid, yerr, torch.zeros_like(yerr))
    yint = state.yaw_integral + yerr * dt
    if config.integral_limit > 0:
        yint = torch.clamp(yint, -config.integral_limit, config.integral_limit)
    else:
        yint = torch.zeros_like(yint)
    ydot = torch.where(~state.has_prev, torch.zeros_like(yerr), wrap_angle(yerr - state.prev_yaw_error) / dt)
    wz = config.kp_yaw * yerr + config.ki_yaw * yint + config.kd_yaw * ydot
    wz = torch.clamp(wz, -config.max_yaw_rate, config.max_yaw_rate)

    at_last = index >= last
    done = (~has_path) | (at_last & (dist <= config.goal_tolerance) & (yerr.abs() <= config.yaw_tolerance))
    done = done & (valid | ~has_path)
    stop = done | ~valid
    u = torch.where(stop[:, None], torch.zeros_like(u), u)
    wz = torch.where(stop, torch.zeros_like(wz), wz)

    # ---- optional acceleration limits on the command change ----
    if config.max_lin_accel is not None:
        du = _limit_norm(u - state.prev_cmd[:, :2], config.max_lin_accel * dt)
        u = state.prev_cmd[:, :2] + du
    if config.max_yaw_accel is not None:
        a = config.max_yaw_accel * dt
        wz = state.prev_cmd[:, 2] + torch.clamp(wz - state.prev_cmd[:, 2], -a, a)

    # ---- world -> robot frame ----
    c, s = torch.cos(yaw), torch.sin(yaw)
    c = torch.where(valid, c, torch.ones_like(c))
    s = torch.where(valid, s, torch.zeros_like(s))
    vx = c * u[:, 0] + s * u[:, 1]
    vy = -s * u[:, 0] + c * u[:, 1]
    cmd = torch.stack([vx, vy, wz], dim=-1)

    new_state = PIDState(
        index=index,
        yaw_ref=state.yaw_ref,
        integral=integral,
        prev_error=err,
        yaw_integral=yint,
        prev_yaw_error=yerr,
        has_prev=valid,
        prev_cmd=torch.stack([u[:, 0], u[:, 1], wz], dim=-1),
    )
    return PIDOutput(cmd=cmd, done=done, valid=valid, state=new_state, target=target, distance=dist)
