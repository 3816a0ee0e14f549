"""The ``move_to`` action template: drive the base to a 2-D location, arm static.

What it does: A* on the padded occupancy grid from where the base is to the parameter, then
PID waypoint tracking (``realize.controllers.astar``, ``realize.controllers.pid``), for every
plan of its rows at once.
What it doesn't: move the arm (it holds still) or avoid obstacles A* did not plan around.
"""

from __future__ import annotations

from dataclasses import fields

import torch
from torch import Tensor

from realize.controllers.astar import astar_world
from realize.controllers.body import BASE_XY, YAW
from realize.controllers.pid import PIDState, pid_init, pid_step
from realize.controllers.waypoints import path_to_waypoints
from realize.realization.actions.base import Outcome, Template
from realize.realization.context import StepContext
from realize.realization.failures import Failure
from realize.regions import Annulus, Box, Fixed, Region


def robot_to_world(cmd: Tensor, yaw: Tensor) -> Tensor:
    """(n, 3) robot-frame (forward, left, yaw rate) -> world-frame (vx, vy, yaw rate)."""
    c, s = torch.cos(yaw), torch.sin(yaw)
    return torch.stack([c * cmd[:, 0] - s * cmd[:, 1], s * cmd[:, 0] + c * cmd[:, 1], cmd[:, 2]], dim=1)


class MoveTo(Template):
    """move_to(loc): A* on the padded occupancy grid, PID waypoint tracking, arm static.

    Success: ``||x_base - x_loc|| <= move_tolerance`` (paper ``in(loc)``). Failure: no path
    (goal unreachable or outside the map) or timeout. The last waypoint is the parameter itself,
    even where A* had to snap it to a free cell of the padded grid: the padding is a planning
    margin, the simulator decides whether the robot fits there.
    """

    name = "move_to"
    param_doc = "a 2-D base location (annulus, box or fixed point in R^2)"

    def __init__(self, n_envs: int, device: torch.device):
        super().__init__(n_envs, device)
        n = n_envs
        self.goal = torch.zeros(n, 2, device=device)
        self.wp = torch.zeros(n, 1, 2, device=device)
        self.wp_len = torch.ones(n, dtype=torch.long, device=device)
        z2, z1 = torch.zeros(n, 2, device=device), torch.zeros(n, device=device)
        self.pid = PIDState(index=torch.zeros(n, dtype=torch.long, device=device), yaw_ref=z1.clone(),
                            integral=z2.clone(), prev_error=z2.clone(), yaw_integral=z1.clone(),
                            prev_yaw_error=z1.clone(), has_prev=torch.zeros(n, dtype=torch.bool, device=device),
                            prev_cmd=torch.zeros(n, 3, device=device))

    @classmethod
    def accepts(cls, region: Region) -> bool:
        return region.dim == 2 and isinstance(region, (Annulus, Box, Fixed))

    def _store(self, rows: Tensor, st: PIDState) -> None:
        for f in fields(PIDState):
            getattr(self.pid, f.name)[rows] = getattr(st, f.name).to(getattr(self.pid, f.name).dtype)

    def _rows(self, rows: Tensor) -> PIDState:
        return PIDState(**{f.name: getattr(self.pid, f.name)[rows] for f in fields(PIDState)})

    def begin(self, ctx: StepContext, rows: Tensor, params: Tensor, region: Region) -> Tensor:
        start = ctx.base[rows, BASE_XY]
        goal = params[:, :2].to(start)
        res = astar_world(ctx.occupancy, ctx.grid, start, goal, planner=ctx.cfg.astar.planner)
        wps = path_to_waypoints(res, ctx.grid, occupied=ctx.occupancy, start_xy=start, goal_xy=goal)
        pts, lens = wps.points.to(start), wps.lengths
        # append the parameter itself as the final waypoint
        full = torch.cat([pts, goal[:, None, :]], dim=1)
        idx = torch.arange(full.shape[1], device=self.device)[None]
        full = torch.where((idx < lens[:, None])[..., None], full, goal[:, None, :].expand_as(full))
        lens = lens + 1
        L, Lb = full.shape[1], self.wp.shape[1]
        if L > Lb:
            self.wp = torch.cat([self.wp, self.wp[:, -1:, :].expand(-1, L - Lb, -1)], dim=1)
        elif L < Lb:
            full = torch.cat([full, full[:, -1:, :].expand(-1, Lb - L, -1)], dim=1)
        self.wp[rows] = full
        self.wp_len[rows] = lens
        self.goal[rows] = goal
        self._store(rows, pid_init(ctx.cfg.pid, ctx.base[rows], self.wp[rows], lens))
        self.t[rows] = 0
        ctx.hold_arm(rows)
        return torch.where(res.found.to(self.device), 0, Failure.NO_PATH)

    def act(self, ctx: StepContext, rows: Tensor) -> None:
        out = pid_step(ctx.cfg.pid, self._rows(rows), ctx.base[rows], self.wp[rows], self.wp_len[rows], ctx.dt)
        self._store(rows, out.state)
        ctx.base_cmd[rows] = robot_to_world(out.cmd, ctx.base[rows, YAW])
        self.t[rows] += 1

    def check(self, ctx: StepContext, rows: Tensor) -> Outcome:
        dist = (ctx.base[rows, BASE_XY] - self.goal[rows]).norm(dim=1)
        ok = dist <= ctx.cfg.move_tolerance
        timeout = self.t[rows] >= ctx.steps(ctx.cfg.move_timeout_s)
        fail = torch.where(timeout & ~ok, Failure.TIMEOUT, 0)
        return Outcome(ok | timeout, ok, fail)

    def distance(self, ctx: StepContext, rows: Tensor) -> Tensor:
        return (ctx.base[rows, BASE_XY] - self.goal[rows]).norm(dim=1)
