"""The ``push`` action template: push an object at a point with the closed gripper, straight through.

What it does: ``Push`` drives the TCP with the whole-body fabric to a pre-point, then along a
goal sliding horizontally through the push point and past it, then back out; success when the
hand passed the point.
What it doesn't: check where the pushed object went (the plan's goal does, ``goals``).
"""

from __future__ import annotations

import math

import torch
from torch import Tensor

from realize.robot.layout import BASE_XY, YAW
from realize.realization.actions.base import Outcome, Template
from realize.realization.context import StepContext
from realize.realization.failures import Failure
from realize.tasks.regions import Box, Fixed, Region

# phases of push
PUSH_APPROACH, PUSH_THROUGH, PUSH_RETREAT = 0, 1, 2


class Push(Template):
    """push(o, p): push object o at the point p with the closed gripper, straight and horizontally.

    Push direction rule: horizontal, from the base's position at the start of the action towards
    the push point, ``u = normalize((p - x_base)_xy, 0)``. The robot pushes away from where it
    stands, so the base location chosen by the preceding ``move_to`` and the push point together
    decide where the object goes; that coupling is what the parameter search has to discover.
    The gripper points along ``u`` (approach axis), its closing axis horizontal across it.

    Phases: the whole-body fabric brings the TCP to the pre-point ``p - push_pre_distance * u``
    (with the gripper aligned), then a goal sliding at ``push_speed`` drives it straight through
    ``p`` to ``p + push_depth * u``; it stays there ``settle_s`` at most if it cannot get there,
    then a goal sliding at ``approach_speed`` brings it straight back to the pre-point.

    Success: the TCP passed through the push point, ``(tcp - p) . u >= 0`` with the TCP within
    ``pregrasp_tolerance`` of the push line, at some step of the straight move (an object that
    does not give way blocks the hand before it); the action ends when the hand is back out.
    Failure: ``push_blocked`` (back out without passing the point), timeout
    (``manip_timeout_s``), or the fabric / simulation failing (handled by the rollout).
    """

    name = "push"
    takes_object = True  # push(stick, Stick_p): the object pushed (the goal checks where it went)
    param_doc = "a 3-D box region of push points (x, y, z), e.g. around the upper part of the object"

    def __init__(self, n_envs: int, device: torch.device):
        super().__init__(n_envs, device)
        n = n_envs
        self.phase = torch.zeros(n, dtype=torch.long, device=device)
        self.phase_t = torch.zeros(n, dtype=torch.long, device=device)
        self.point = torch.zeros(n, 3, device=device)
        self.pre = torch.zeros(n, 3, device=device)
        self.through = torch.zeros(n, 3, device=device)
        self.dir = torch.zeros(n, 3, device=device)
        self.closing = torch.zeros(n, 3, device=device)
        self.passed = torch.zeros(n, dtype=torch.bool, device=device)

    @classmethod
    def accepts(cls, region: Region) -> bool:
        return region.dim == 3 and isinstance(region, (Box, Fixed))

    def begin(self, ctx: StepContext, rows: Tensor, params: Tensor, region: Region, obj: int = -1,
              shift: Tensor | None = None, support: int = -1) -> Tensor:
        cfg = ctx.cfg
        point = params[:, :3].to(torch.float32)
        d = point[:, :2] - ctx.base[rows, BASE_XY]
        norm = d.norm(dim=1, keepdim=True)
        # a push point straight above the base has no direction: push along the base's heading
        yaw = ctx.base[rows, YAW]
        heading = torch.stack([torch.cos(yaw), torch.sin(yaw)], dim=1)
        d = torch.where(norm > 1e-6, d / norm.clamp(min=1e-6), heading)
        zero = torch.zeros_like(d[:, :1])
        u = torch.cat([d, zero], dim=1)
        self.point[rows] = point
        self.dir[rows] = u
        self.closing[rows] = torch.cat([-d[:, 1:2], d[:, 0:1], zero], dim=1)  # z x u
        self.pre[rows] = point - cfg.push_pre_distance * u
        self.through[rows] = point + cfg.push_depth * u
        self.phase[rows] = PUSH_APPROACH
        self.phase_t[rows] = 0
        self.passed[rows] = False
        self.t[rows] = 0
        ctx.start_fabric(rows)
        return torch.zeros(len(rows), dtype=torch.long, device=self.device)

    def _goal(self, ctx: StepContext, rows: Tensor) -> Tensor:
        """Goal of the current phase; the straight moves follow a goal sliding along the line."""
        cfg = ctx.cfg
        ph = self.phase[rows]
        pre, through = self.pre[rows], self.through[rows]
        start = torch.where((ph == PUSH_RETREAT)[:, None], through, pre)
        final = torch.where((ph == PUSH_THROUGH)[:, None], through, pre)
        speed = torch.where(ph == PUSH_THROUGH, cfg.push_speed, cfg.approach_speed)
        span = (final - start).norm(dim=1).clamp(min=1e-6)
        frac = (self.phase_t[rows].float() * ctx.dt * speed / span).clamp(max=1.0)
        ramp = start + (final - start) * frac[:, None]
        return torch.where((ph == PUSH_APPROACH)[:, None], pre, ramp)

    def act(self, ctx: StepContext, rows: Tensor) -> None:
        # controller.avoid_movable: a push is made to touch movable objects (the one pushed and what
        # rests on it): it leaves every one out
        ignore = torch.ones(len(rows), ctx.objects.shape[1], dtype=torch.bool, device=self.device) \
            if ctx.cfg.avoid_movable else None
        ctx.fabric_goal(rows, self._goal(ctx, rows), self.dir[rows], self.closing[rows], ignore)
        ctx.grip_cmd[rows] = True
        self.t[rows] += 1
        self.phase_t[rows] += 1

    def check(self, ctx: StepContext, rows: Tensor) -> Outcome:
        cfg = ctx.cfg
        tcp, u = ctx.tcp[rows], self.dir[rows]
        ph, pt = self.phase[rows], self.phase_t[rows]
        err = (tcp - self._goal(ctx, rows)).norm(dim=1)
        rel = tcp - self.point[rows]
        along = (rel * u).sum(dim=1)
        lateral = (rel - along[:, None] * u).norm(dim=1)
        passed = self.passed[rows] | ((ph == PUSH_THROUGH) & (along >= 0) & (lateral <= cfg.pregrasp_tolerance))
        self.passed[rows] = passed
        axis_ok = (ctx.approach[rows] * u).sum(dim=1) >= math.cos(cfg.axis_tolerance)
        to_through = (ph == PUSH_APPROACH) & (err <= cfg.pregrasp_tolerance) & axis_ok
        span = cfg.push_pre_distance + cfg.push_depth
        ramp_steps = math.ceil(span / (cfg.push_speed * ctx.dt))
        at_end = (ph == PUSH_THROUGH) & (pt >= ramp_steps) & (
            (err <= cfg.reach_tolerance) | (pt >= ramp_steps + ctx.steps(cfg.settle_s)))
        new = torch.where(to_through, PUSH_THROUGH, torch.where(at_end, PUSH_RETREAT, ph))
        self.phase[rows] = new
        self.phase_t[rows] = torch.where(new != ph, 0, pt)
        back = (tcp - self.through[rows]).norm(dim=1)
        retreated = (new == PUSH_RETREAT) & (self.phase_t[rows] > 0) & (
            ((tcp - self.pre[rows]).norm(dim=1) <= cfg.pregrasp_tolerance) | (back >= cfg.retreat_share * span))
        ok = retreated & passed
        timeout = self.t[rows] >= ctx.steps(cfg.manip_timeout_s)
        fail = torch.where(retreated & ~passed, Failure.PUSH_BLOCKED,
                           torch.where(timeout & ~ok, Failure.TIMEOUT, 0))
        return Outcome(ok | (fail > 0), ok, fail)

    def distance(self, ctx: StepContext, rows: Tensor) -> Tensor:
        """Distance of the TCP from the push point (0 once it passed through it)."""
        d = (ctx.tcp[rows] - self.point[rows]).norm(dim=1)
        return torch.where(self.passed[rows], torch.zeros_like(d), d)
