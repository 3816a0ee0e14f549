"""Action templates (paper eq. 1): parameters, controller, cost and success of each robot skill.

What it does: defines ``move_to`` (A* + PID base tracking, arm static), ``grasp`` and ``place``
(whole-body fabric to a pre-pose on the parameter's hemisphere, straight approach to the object,
close / open the gripper, retreat) and ``push`` (closed gripper straight through a push point,
horizontally away from the base, then back). Each template keeps per-plan state as (N, ...) tensors and
works on index sets of plans, so N plans in different actions advance together. The cost is 1
per control step until the action finishes (counted by the rollout); success predicates read
the simulator (poses, contacts).
What it doesn't: loop over time or decide which action a plan is in (``realize.rollout``), or
talk to the simulator directly (it reads and writes the rollout's ``StepContext``).

Adding a template: subclass ``Template``, implement ``accepts``, ``begin``, ``act``, ``check``,
and register it in ``TEMPLATES``; plans can then name it.
"""

from __future__ import annotations

import math
from dataclasses import fields
from typing import TYPE_CHECKING

import torch
from torch import Tensor

from realize.controllers.astar import astar_world
from realize.controllers.pid import PIDState, pid_init, pid_step
from realize.controllers.waypoints import path_to_waypoints
from realize.fetch_body import FINGERTIP_REACH
from realize.hemisphere import Hemisphere
from realize.regions import Annulus, Box, Fixed, Region

PAD_HALF_WIDTH = 0.013  # m, half width of the finger pads across the closing axis (fetch.urdf)

if TYPE_CHECKING:  # pragma: no cover
    from realize.rollout import StepContext

# failure reasons (index into FAILURES)
FAILURES = (
    "",
    "timeout",
    "no_path",
    "grasp_not_held",
    "cube_dropped",
    "not_holding",
    "controller_invalid",
    "diverged",
    "place_not_released",
    "goal_not_reached",
    "push_blocked",
)
FAIL = {name: i for i, name in enumerate(FAILURES)}


class Template:
    """Base class of action templates; subclasses keep (N, ...) state tensors."""

    name = "template"
    n_params = 1
    param_doc = ""

    def __init__(self, n: int, device: torch.device):
        self.n, self.device = n, device
        self.t = torch.zeros(n, dtype=torch.long, device=device)  # steps spent in the action

    @classmethod
    def accepts(cls, region: Region) -> bool:  # pragma: no cover - abstract
        raise NotImplementedError

    def begin(self, ctx: "StepContext", rows: Tensor, params: Tensor, region: Region) -> Tensor:
        """Start the action for plans ``rows`` with parameters (len(rows), d) drawn from
        ``region``; returns a (len,) failure code (0 = fine) for plans that fail immediately."""
        raise NotImplementedError

    def act(self, ctx: "StepContext", rows: Tensor) -> None:
        """Write commands for ``rows`` into ``ctx``."""
        raise NotImplementedError

    def check(self, ctx: "StepContext", rows: Tensor) -> tuple[Tensor, Tensor, Tensor]:
        """After a step: (done, success, failure code) for ``rows``."""
        raise NotImplementedError

    def distance(self, ctx: "StepContext", rows: Tensor) -> Tensor:
        """Distance-to-success proxy (m) for ranking infeasible plans."""
        return torch.zeros(len(rows), device=self.device)


class MoveTo(Template):
    """move_to(loc): A* on the padded occupancy grid, PID waypoint tracking, arm static.

    Success: ``||x_base - x_loc|| <= move_tolerance`` (paper ``in(loc)``). Failure: no path
    (goal unreachable or outside the map) or timeout. The last waypoint is the parameter itself,
    even where A* had to snap it to a free cell of the padded grid: the padding is a planning
    margin, the simulator decides whether the robot fits there.
    """

    name = "move_to"
    param_doc = "a 2-D base location (annulus, box or fixed point in R^2)"

    def __init__(self, n: int, device: torch.device):
        super().__init__(n, device)
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

    def begin(self, ctx: "StepContext", rows: Tensor, params: Tensor, region: Region) -> Tensor:
        start = ctx.base[rows, :2]
        goal = params[:, :2].to(start)
        res = astar_world(ctx.occupancy, ctx.grid, start, goal)
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
        return torch.where(res.found.to(self.device), 0, FAIL["no_path"])

    def act(self, ctx: "StepContext", rows: Tensor) -> None:
        out = pid_step(ctx.cfg.pid, self._rows(rows), ctx.base[rows], self.wp[rows], self.wp_len[rows], ctx.dt)
        self._store(rows, out.state)
        ctx.base_cmd[rows] = robot_to_world(out.cmd, ctx.base[rows, 2])
        self.t[rows] += 1

    def check(self, ctx: "StepContext", rows: Tensor) -> tuple[Tensor, Tensor, Tensor]:
        dist = (ctx.base[rows, :2] - self.goal[rows]).norm(dim=1)
        ok = dist <= ctx.cfg.move_tolerance
        timeout = self.t[rows] >= ctx.steps(ctx.cfg.move_timeout_s)
        fail = torch.where(timeout & ~ok, FAIL["timeout"], 0)
        return ok | timeout, ok, fail

    def distance(self, ctx: "StepContext", rows: Tensor) -> Tensor:
        return (ctx.base[rows, :2] - self.goal[rows]).norm(dim=1)


def robot_to_world(cmd: Tensor, yaw: Tensor) -> Tensor:
    """(n, 3) robot-frame (forward, left, yaw rate) -> world-frame (vx, vy, yaw rate)."""
    c, s = torch.cos(yaw), torch.sin(yaw)
    return torch.stack([c * cmd[:, 0] - s * cmd[:, 1], s * cmd[:, 0] + c * cmd[:, 1], cmd[:, 2]], dim=1)


# phases of grasp / place
APPROACH, DESCEND, GRIP, RETREAT = 0, 1, 2, 3


class _Manipulate(Template):
    """Common phase machine of grasp and place (whole-body fabric to a hemisphere pre-pose)."""

    param_doc = "a hemisphere region (pre-pose on its surface, approach towards its centre)"
    closes_gripper = True  # gripper command in the GRIP phase

    def __init__(self, n: int, device: torch.device):
        super().__init__(n, device)
        self.phase = torch.zeros(n, dtype=torch.long, device=device)
        self.phase_t = torch.zeros(n, dtype=torch.long, device=device)
        self.pre = torch.zeros(n, 3, device=device)
        self.target = torch.zeros(n, 3, device=device)
        self.approach = torch.zeros(n, 3, device=device)
        self.closing = torch.zeros(n, 3, device=device)

    @classmethod
    def accepts(cls, region: Region) -> bool:
        return isinstance(region, Hemisphere)

    def _centre_and_pre(self, ctx: "StepContext", params: Tensor, region: Region) -> tuple[Tensor, Tensor]:
        """(object point, pre-pose) of the action: a hemisphere parameter is the pre-pose around
        the region's fixed centre; a 3-D box parameter (place only) is the point itself, reached
        straight down from ``place_pre_height`` above it."""
        p = params[:, :3].to(torch.float32)
        if isinstance(region, Hemisphere):
            return torch.tensor(region.center, dtype=torch.float32, device=self.device).expand(len(p), 3), p
        up = torch.tensor([0.0, 0.0, ctx.cfg.place_pre_height], device=self.device)
        return p, p + up

    def begin(self, ctx: "StepContext", rows: Tensor, params: Tensor, region: Region) -> Tensor:
        centre, pre = self._centre_and_pre(ctx, params, region)
        d = centre - pre
        approach = d / d.norm(dim=1, keepdim=True).clamp(min=1e-6)
        self.pre[rows] = pre
        self.approach[rows] = approach
        self.closing[rows] = self._closing_axis(ctx, rows, approach)
        self.target[rows] = self._target(ctx, centre, approach)
        self.phase[rows] = APPROACH
        self.phase_t[rows] = 0
        self.t[rows] = 0
        ctx.start_fabric(rows)
        return torch.zeros(len(rows), dtype=torch.long, device=self.device)

    def _target(self, ctx: "StepContext", centre: Tensor, approach: Tensor) -> Tensor:
        """TCP goal: the region centre (the cube's centre), backed off along the approach just
        enough that the fingertips stay ``grasp_clearance`` above the surface the cube rests on."""
        cfg, g = ctx.cfg, ctx.scene.geometry
        support = centre[:, 2] - g.cube_half_size
        a_z = approach[:, 2].clamp(max=-0.2)  # approaches from below the horizon are not useful
        tilt = torch.sqrt((1.0 - approach[:, 2] ** 2).clamp(min=0.0))
        lowest = FINGERTIP_REACH * a_z - PAD_HALF_WIDTH * tilt  # fingertip height below the TCP
        back = (support + cfg.grasp_clearance - centre[:, 2] - lowest) / (-a_z)
        back = back.clamp(min=0.0) + cfg.grasp_offset
        return centre - approach * back[:, None]

    def _closing_axis(self, ctx: "StepContext", rows: Tensor, approach: Tensor) -> Tensor:
        """Closing axis of the goal pose: the cube's face normal (perpendicular to the approach)
        nearest to the gripper's current closing axis, so the fingers close on two faces."""
        from realize.scene import quat_to_matrix

        frame = quat_to_matrix(ctx.cube[rows, 3:7])  # (n, 3, 3), columns = cube axes
        cand = torch.cat([frame, -frame], dim=2).transpose(1, 2)  # (n, 6, 3)
        cand = cand - (cand * approach[:, None, :]).sum(-1, keepdim=True) * approach[:, None, :]
        norm = cand.norm(dim=-1)
        cand = cand / norm.clamp(min=1e-6)[..., None]
        # most perpendicular to the approach first (a true face normal), then nearest the current axis
        score = 2.0 * norm + 0.5 * (cand * ctx.closing[rows][:, None, :]).sum(-1)
        best = score.argmax(dim=1)
        return cand[torch.arange(len(rows), device=self.device), best]

    def _goal(self, rows: Tensor, ctx: "StepContext | None" = None) -> Tensor:
        """Goal of the current phase. The straight moves in and out (DESCEND, RETREAT) follow a
        goal that slides along the approach line at ``approach_speed``, so the gripper moves
        in a straight line instead of swinging (a swing knocks over or drops the cube)."""
        ph = self.phase[rows]
        final = torch.where(((ph == APPROACH) | (ph == RETREAT))[:, None], self.pre[rows], self.target[rows])
        if ctx is None:
            return final
        start = torch.where((ph == RETREAT)[:, None], self.target[rows], self.pre[rows])
        span = (final - start).norm(dim=1).clamp(min=1e-6)
        frac = (self.phase_t[rows].float() * ctx.dt * ctx.cfg.approach_speed / span).clamp(max=1.0)
        ramp = start + (final - start) * frac[:, None]
        straight = (ph == DESCEND) | (ph == RETREAT)
        return torch.where(straight[:, None], ramp, final)

    def act(self, ctx: "StepContext", rows: Tensor) -> None:
        ph = self.phase[rows]
        # the arm stands still while the fingers close / open (ctx.arm_hold was set on entry)
        moving = ph != GRIP
        mr = rows[moving]
        if len(mr):
            ctx.fabric_goal(mr, self._goal(mr, ctx), self.approach[mr], self.closing[mr])
        grip = (ph >= GRIP) if self.closes_gripper else (ph < GRIP)
        ctx.grip_cmd[rows] = grip
        self.t[rows] += 1
        self.phase_t[rows] += 1

    def _advance(self, ctx: "StepContext", rows: Tensor) -> tuple[Tensor, Tensor]:
        """Shared phase transitions; returns (tcp error to current goal, reached-target flag)."""
        cfg = ctx.cfg
        tcp = ctx.tcp[rows]
        ph = self.phase[rows]
        err = (tcp - self._goal(rows)).norm(dim=1)
        axis_ok = (ctx.approach[rows] * self.approach[rows]).sum(dim=1) >= math.cos(cfg.axis_tolerance)
        to_descend = (ph == APPROACH) & (err <= cfg.pregrasp_tolerance) & axis_ok
        # close when at the target, or when settled within reach_tolerance of it (the fingers
        # or the robot's own collision terms may hold the TCP a few mm off)
        ramp_done = self.phase_t[rows] * ctx.dt * cfg.approach_speed >= (self.pre[rows] - self.target[rows]).norm(dim=1)
        settled = ramp_done & (self.phase_t[rows] >= self._settle_steps(ctx, rows)) & (err <= cfg.reach_tolerance)
        to_grip = (ph == DESCEND) & ((err <= cfg.grip_tolerance) | settled)
        new = torch.where(to_descend, DESCEND, torch.where(to_grip, GRIP, ph))
        changed = new != ph
        if to_grip.any():
            ctx.hold_arm(rows[to_grip])
        self.phase[rows] = new
        self.phase_t[rows] = torch.where(changed, 0, self.phase_t[rows])
        return err, to_grip

    def _grip_step(self, ctx: "StepContext", rows: Tensor) -> tuple[Tensor, Tensor, Tensor, Tensor, Tensor]:
        """Advance the shared phases; returns (TCP error, phase, steps in phase, holds, and
        whether the gripper has had ``grip_s`` to close / open)."""
        err, _ = self._advance(ctx, rows)
        ph, pt = self.phase[rows], self.phase_t[rows]
        done = (ph == GRIP) & (pt >= ctx.steps(ctx.cfg.grip_s))
        return err, ph, pt, ctx.holds(rows), done

    def _retreated(self, ctx: "StepContext", rows: Tensor, err: Tensor) -> Tensor:
        """Back at the pre-pose, or most of the way back out along the approach line."""
        span = (self.pre[rows] - self.target[rows]).norm(dim=1)
        out = (ctx.tcp[rows] - self.target[rows]).norm(dim=1)
        return (self.phase_t[rows] > 0) & ((err <= ctx.cfg.pregrasp_tolerance) | (out >= ctx.cfg.retreat_share * span))

    def _settle_steps(self, ctx: "StepContext", rows: Tensor) -> Tensor:
        ramp = (self.pre[rows] - self.target[rows]).norm(dim=1) / (ctx.cfg.approach_speed * ctx.dt)
        return ramp.ceil().long() + ctx.steps(ctx.cfg.settle_s)

    def distance(self, ctx: "StepContext", rows: Tensor) -> Tensor:
        return (ctx.tcp[rows] - self.target[rows]).norm(dim=1)


class Grasp(_Manipulate):
    """grasp(g_p): fabric to the pre-grasp g_p on the hemisphere around the cube, straight in to
    the cube, close, retreat to g_p.

    Success: the TCP reached the grasp point within ``reach_tolerance`` (paper ``ee_in(g_p)``)
    AND both fingers press on the cube (contact forces) after the retreat.
    """

    name = "grasp"
    closes_gripper = True

    def check(self, ctx: "StepContext", rows: Tensor) -> tuple[Tensor, Tensor, Tensor]:
        cfg = ctx.cfg
        err, ph, pt, holds, gripped = self._grip_step(ctx, rows)
        not_held = gripped & ~holds
        self.phase[rows] = torch.where(gripped & holds, RETREAT, ph)
        self.phase_t[rows] = torch.where(gripped & holds, 0, pt)
        if (gripped & holds).any():
            ctx.start_fabric(rows[gripped & holds])
        ph = self.phase[rows]
        retreated = (ph == RETREAT) & self._retreated(ctx, rows, err)
        dropped = (ph == RETREAT) & ~holds & (self.phase_t[rows] > 2)
        ok = retreated & holds
        timeout = self.t[rows] >= ctx.steps(cfg.manip_timeout_s)
        fail = torch.where(not_held, FAIL["grasp_not_held"],
                           torch.where(dropped, FAIL["cube_dropped"],
                                       torch.where(timeout & ~ok, FAIL["timeout"], 0)))
        return ok | (fail > 0), ok, fail


class Place(_Manipulate):
    """place(g_p): while holding the cube, fabric to the pre-place g_p on the hemisphere around
    the place point, straight in, open the gripper, retreat to g_p.

    Or, with a 3-D box region, place(p): the parameter is the release point p of the cube's
    centre itself (approached top-down from ``place_pre_height`` above). The point need not be
    on a surface: a cube released in the air falls, or slides down a ramp, and the action
    succeeds once it rests; the plan's goal decides whether it came to rest where it should.

    Success: the TCP reached the place point within ``reach_tolerance`` (paper ``ee_in(g_p)``),
    the gripper let go (no finger contact with the cube) and the cube rests (speed below
    ``rest_speed``).
    """

    name = "place"
    param_doc = ("a hemisphere region (pre-pose on its surface, approach towards its centre) or a 3-D box "
                 "of release points (approached top-down)")
    closes_gripper = False

    @classmethod
    def accepts(cls, region: Region) -> bool:
        return isinstance(region, Hemisphere) or (isinstance(region, Box) and region.dim == 3)

    def begin(self, ctx: "StepContext", rows: Tensor, params: Tensor, region: Region) -> Tensor:
        code = super().begin(ctx, rows, params, region)
        held = ctx.holds(rows)
        return torch.where(held, code, FAIL["not_holding"])

    def _target(self, ctx: "StepContext", centre: Tensor, approach: Tensor) -> Tensor:
        """TCP goal that puts the held cube's centre at the region centre (plus a small drop
        height): the cube sits ``s`` ahead of the TCP along the approach axis, measured now."""
        rows = ctx.beginning
        s = ((ctx.cube[rows, :3] - ctx.tcp[rows]) * ctx.approach[rows]).sum(dim=1, keepdim=True)
        lift = torch.tensor([0.0, 0.0, ctx.cfg.place_drop], device=centre.device)
        return centre + lift - approach * s

    def act(self, ctx: "StepContext", rows: Tensor) -> None:
        super().act(ctx, rows)
        # keep squeezing until the release phase
        ctx.grip_cmd[rows] = self.phase[rows] < GRIP

    def check(self, ctx: "StepContext", rows: Tensor) -> tuple[Tensor, Tensor, Tensor]:
        cfg = ctx.cfg
        err, ph, pt, holds, released = self._grip_step(ctx, rows)
        dropped = (ph < GRIP) & ~holds & (self.t[rows] > 2)
        self.phase[rows] = torch.where(released, RETREAT, ph)
        self.phase_t[rows] = torch.where(released, 0, pt)
        if released.any():
            ctx.start_fabric(rows[released])
        ph = self.phase[rows]
        resting = ctx.cube_speed[rows] <= cfg.rest_speed
        retreated = (ph == RETREAT) & self._retreated(ctx, rows, err)
        ok = retreated & ~holds & resting
        timeout = self.t[rows] >= ctx.steps(cfg.manip_timeout_s)
        fail = torch.where(dropped, FAIL["cube_dropped"], torch.where(timeout & ~ok, FAIL["timeout"], 0))
        return ok | (fail > 0), ok, fail


# phases of push
PUSH_APPROACH, PUSH_THROUGH, PUSH_RETREAT = 0, 1, 2


class Push(Template):
    """push(p): push an object at the point p with the closed gripper, straight and horizontally.

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
    param_doc = "a 3-D box region of push points (x, y, z), e.g. around the upper part of the object"

    def __init__(self, n: int, device: torch.device):
        super().__init__(n, device)
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

    def begin(self, ctx: "StepContext", rows: Tensor, params: Tensor, region: Region) -> Tensor:
        cfg = ctx.cfg
        point = params[:, :3].to(torch.float32)
        d = point[:, :2] - ctx.base[rows, :2]
        norm = d.norm(dim=1, keepdim=True)
        # a push point straight above the base has no direction: push along the base's heading
        yaw = ctx.base[rows, 2]
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

    def _goal(self, ctx: "StepContext", rows: Tensor) -> Tensor:
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

    def act(self, ctx: "StepContext", rows: Tensor) -> None:
        ctx.fabric_goal(rows, self._goal(ctx, rows), self.dir[rows], self.closing[rows])
        ctx.grip_cmd[rows] = True
        self.t[rows] += 1
        self.phase_t[rows] += 1

    def check(self, ctx: "StepContext", rows: Tensor) -> tuple[Tensor, Tensor, Tensor]:
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
        fail = torch.where(retreated & ~passed, FAIL["push_blocked"], torch.where(timeout & ~ok, FAIL["timeout"], 0))
        return ok | (fail > 0), ok, fail

    def distance(self, ctx: "StepContext", rows: Tensor) -> Tensor:
        """Distance of the TCP from the push point (0 once it passed through it)."""
        d = (ctx.tcp[rows] - self.point[rows]).norm(dim=1)
        return torch.where(self.passed[rows], torch.zeros_like(d), d)


TEMPLATES: dict[str, type[Template]] = {"move_to": MoveTo, "grasp": Grasp, "place": Place, "push": Push}
