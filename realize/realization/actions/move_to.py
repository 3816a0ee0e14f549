"""The ``move_to`` action template: drive the base to a 2-D location, arm static.

What it does: A* on the padded occupancy grid from where the base is to the parameter, then
PID waypoint tracking (``realize.controllers.astar``, ``realize.controllers.pid``), for every
plan of its rows at once. A plan whose held arm reaches past the padded base beside an obstacle
it is not above (a wall) plans on its own grid that keeps the arm off it
(``realize.controllers.carry_footprint``, ``controller.astar.carry_footprint``).
What it doesn't: move the arm (it holds still) or avoid obstacles A* did not plan around.
"""

from __future__ import annotations

from dataclasses import fields

import torch
from torch import Tensor

from realize.controllers.astar import astar_world
from realize.robot.layout import BASE_XY, YAW
from realize.controllers.carry_footprint import carry_blocked
from realize.controllers.obstacles import boxes_tensor
from realize.controllers.pid import PIDState, pid_init, pid_step
from realize.controllers.waypoints import path_to_waypoints
from realize.realization.actions.base import Outcome, Template
from realize.realization.context import StepContext
from realize.realization.failures import Failure
from realize.tasks.regions import Annulus, Box, Fixed, Region


def _pad_to(points: Tensor, length: int) -> Tensor:
    """(n, L, 2) waypoints -> (n, length, 2), the last point repeated."""
    return torch.cat([points, points[:, -1:].expand(-1, length - points.shape[1], -1)], 1)


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
    moves_base = True
    param_doc = "a 2-D base location (annulus, box or fixed point in R^2)"

    def __init__(self, n_envs: int, device: torch.device):
        super().__init__(n_envs, device)
        n = n_envs
        self._boxes: Tensor | None = None  # the scene's static obstacle boxes, built at the first begin
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

    def _carry_grids(self, ctx: StepContext, rows: Tensor) -> Tensor | None:
        """(len(rows), H, W) extra blocked cells where the held arm would hit a tall obstacle
        (``realize.controllers.carry_footprint``); None when it is off or the scene has none."""
        cfg = ctx.cfg.astar
        if not cfg.carry_footprint:
            return None
        if self._boxes is None:
            self._boxes = boxes_tensor(ctx.geometry, floor=False)
        if self._boxes.shape[0] == 0:
            return None
        kin = ctx.fabric.kin
        centres, radii = kin.collision_spheres(ctx.q[rows].to(ctx.fabric.dtype))
        offsets = centres[..., :2].float() - ctx.base[rows, None, :2]
        reach = cfg.padding + ctx.scene.robot.base.footprint_radius
        return carry_blocked(ctx.grid, self._boxes, offsets, centres[..., 2].float(), radii.float(), reach,
                             cfg.carry_margin)

    def _paths(self, ctx: StepContext, start: Tensor, goal: Tensor, extra: Tensor | None) -> tuple[Tensor, Tensor, Tensor]:
        """(points (n, L, 2), lengths (n,), found (n,)) of the waypoints from start to goal on the
        padded grid (OR ``extra`` (n, H, W), the carried arm's cells); plans with no path there
        retry on the grid padded by ``astar.fallback_padding``."""
        planner = ctx.cfg.astar.planner

        def on(occ: Tensor, m: Tensor | None) -> tuple[Tensor, Tensor, Tensor]:
            s, g = (start, goal) if m is None else (start[m], goal[m])
            if extra is not None:
                occ = occ | (extra if m is None else extra[m])
            res = astar_world(occ, ctx.grid, s, g, planner=planner)
            wps = path_to_waypoints(res, ctx.grid, occupied=occ, start_xy=s, goal_xy=g)
            return wps.points.to(start), wps.lengths, res.found.to(self.device)

        pts, lens, found = on(ctx.occupancy, None)
        if ctx.occupancy_tight is None or bool(found.all()):
            return pts, lens, found
        m = ~found
        p2, n2, f2 = on(ctx.occupancy_tight, m)
        length = max(pts.shape[1], p2.shape[1])
        pts = _pad_to(pts, length)
        pts[m], lens[m], found[m] = _pad_to(p2, length), n2.to(lens), f2
        return pts, lens, found

    def begin(self, ctx: StepContext, rows: Tensor, params: Tensor, region: Region, obj: int = -1,
              shift: Tensor | None = None, support: int = -1) -> Tensor:
        start = ctx.base[rows, BASE_XY]
        goal = params[:, :2].to(start)
        extra = self._carry_grids(ctx, rows)
        if extra is None or not bool(extra.any()):
            pts, lens, found = self._paths(ctx, start, goal, None)
        else:  # plans whose arm reaches past the padded base beside a tall obstacle: their own grids
            carried = extra.flatten(1).any(1)
            parts = [(m, self._paths(ctx, start[m], goal[m], e)) for m, e in
                     ((~carried, None), (carried, extra[carried])) if bool(m.any())]
            length = max(p[0].shape[1] for _, p in parts)
            pts = start.new_zeros(len(rows), length, 2)
            lens = torch.zeros(len(rows), dtype=torch.long, device=self.device)
            found = torch.zeros(len(rows), dtype=torch.bool, device=self.device)
            for m, (p, n, f) in parts:
                pts[m] = _pad_to(p, length)
                lens[m], found[m] = n.to(lens), f
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
        return torch.where(found, 0, Failure.NO_PATH)

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
