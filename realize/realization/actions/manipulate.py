"""The steps grasp and place share: a whole-body fabric move to a pre-pose, straight in, grip, out.

What it does: ``Manipulate``, the phase machine of ``grasp`` and ``place`` (APPROACH the pre-pose
on the parameter's hemisphere with the gripper aligned, DESCEND straight in along a goal sliding
at ``approach_speed``, GRIP: close / open the gripper with the arm still, RETREAT straight back
out) on the object the plan names, with the target geometry (TCP goal backed off so the
fingertips clear the supporting surface, closing axis on two faces of a box, or across a
cylinder's axis).
With ``controller.avoid_movable`` the fabric keeps off the movable objects, save the one the
action handles (``_avoid``; ``place`` adds its support and the held object).
What it doesn't: decide success (``grasp`` and ``place`` do, from finger contacts and the object).
"""

from __future__ import annotations

import math

import torch
from torch import Tensor

from realize.tasks.hemisphere import Hemisphere
from realize.realization.actions.base import Template
from realize.realization.context import StepContext
from realize.tasks.regions import Region
from realize.scene import quat_to_matrix
from realize.robot.kinematics import RobotKinematics
from realize.robot.spec import GripperSpec


# phases of grasp / place
APPROACH, DESCEND, GRIP, RETREAT = 0, 1, 2, 3


def tcp_target(centre: Tensor, approach: Tensor, support_z: Tensor, hand: GripperSpec, clearance: float,
               offset: float) -> Tensor:
    """(n, 3) TCP goal at an object's centre (n, 3) for unit approaches (n, 3): backed off
    along the approach just enough that the fingertips (``hand``'s reach and pad width) stay
    ``clearance`` above the surface at height ``support_z`` (n,) the object rests on, plus
    ``offset``. (``realize.realization.screening`` reads the same pose before simulating.)"""
    a_z = approach[:, 2].clamp(max=-0.2)  # approaches from below the horizon are not useful
    tilt = torch.sqrt((1.0 - approach[:, 2] ** 2).clamp(min=0.0))
    lowest = hand.fingertip_reach * a_z - hand.pad_half_width * tilt  # fingertip height below the TCP
    back = (support_z + clearance - centre[:, 2] - lowest) / (-a_z)
    back = back.clamp(min=0.0) + offset
    return centre - approach * back[:, None]


def base_axis_xy(kin: RobotKinematics, q: Tensor) -> Tensor:
    """(n, 2) where the axis of the arm's first joint (a 5-joint arm's pan) stands, for whole-body
    ``q`` (n, n_dof): the origin of the link that joint moves, which lies on its axis."""
    link = {j.name: j for j in kin.joints.values()}[kin.spec.upper.joints[0]].child
    return kin.link_positions(q.to(kin.dtype), [link])[:, 0, :2]


def _bearing(v: Tensor) -> Tensor:
    return torch.atan2(v[:, 1], v[:, 0])


def turn_about_z(v: Tensor, angle: Tensor) -> Tensor:
    """(n, 3) vectors ``v`` turned by ``angle`` (n,) rad about the vertical."""
    c, s = torch.cos(angle), torch.sin(angle)
    return torch.stack([c * v[:, 0] - s * v[:, 1], s * v[:, 0] + c * v[:, 1], v[:, 2]], dim=1)


def square_approach(approach: Tensor, face: Tensor, max_turn: float) -> Tensor:
    """(n, 3) unit approaches turned, by at most ``max_turn`` rad each, toward the plane
    perpendicular to the unit face normals ``face`` (n, 3) (turned all the way, the face normal
    is itself a closing axis across the approach: no tilt of the closing axis out of the face).
    An approach already in that plane is returned as it is."""
    dot = (approach * face).sum(-1, keepdim=True)
    angle = torch.asin(dot.abs().clamp(max=1.0))
    toward = -dot * (face - dot * approach)  # in the plane of approach and face, perpendicular to the approach
    toward = toward / toward.norm(dim=-1, keepdim=True).clamp(min=1e-12)
    turn = angle.clamp(max=max_turn)
    return approach * torch.cos(turn) + toward * torch.sin(turn)


class Manipulate(Template):
    """Common phase machine of grasp and place (whole-body fabric to a hemisphere pre-pose)."""

    param_doc = "a hemisphere region (pre-pose on its surface, approach towards its centre)"
    closes_gripper = True  # gripper command in the GRIP phase
    takes_object = True

    def __init__(self, n_envs: int, device: torch.device):
        super().__init__(n_envs, device)
        n = n_envs
        self.phase = torch.zeros(n, dtype=torch.long, device=device)
        self.phase_t = torch.zeros(n, dtype=torch.long, device=device)
        self.pre = torch.zeros(n, 3, device=device)
        self.target = torch.zeros(n, 3, device=device)
        self.approach = torch.zeros(n, 3, device=device)
        self.closing = torch.zeros(n, 3, device=device)
        self.obj = torch.zeros(n, dtype=torch.long, device=device)  # the object each plan handles
        self.reach_tol = torch.zeros(n, device=device)  # m: the settle rule's tolerance of each plan

    @classmethod
    def accepts(cls, region: Region) -> bool:
        return isinstance(region, Hemisphere)

    def _centre_and_pre(self, ctx: StepContext, params: Tensor, region: Region,
                        shift: Tensor | None = None) -> tuple[Tensor, Tensor]:
        """(object point, pre-pose) of the action: a hemisphere parameter is the pre-pose around
        the region's fixed centre (moved by ``shift``: the tracked object lies elsewhere); a 3-D
        box parameter (place only) is the point itself, reached straight down from
        ``place_pre_height`` above it."""
        p = params[:, :3].to(torch.float32)
        if isinstance(region, Hemisphere):
            centre = torch.tensor(region.center, dtype=torch.float32, device=self.device).expand(len(p), 3)
            return (centre if shift is None else centre + shift.to(torch.float32)), p
        up = torch.tensor([0.0, 0.0, ctx.cfg.place_pre_height], device=self.device)
        return p, p + up

    def begin(self, ctx: StepContext, rows: Tensor, params: Tensor, region: Region, obj: int = -1,
              shift: Tensor | None = None, support: int = -1) -> Tensor:
        centre, pre = self._centre_and_pre(ctx, params, region, shift)
        near = ctx.closing[rows]  # the goal closing axis: the face normal nearest the gripper's now
        if isinstance(region, Hemisphere) and region.facing == "robot":  # in the plane through the arm's base axis
            axis = base_axis_xy(ctx.fabric.kin, ctx.q[rows]).to(pre.dtype)
            pre = region.turn_toward(pre, centre, axis)
            # an arm that turns only about that axis carries its closing axis round with it: the
            # face normal nearest the closing axis turned as the arm turns from its TCP to the centre
            near = turn_about_z(near, _bearing(centre[:, :2] - axis) - _bearing(ctx.tcp[rows, :2] - axis))
        d = centre - pre
        approach = d / d.norm(dim=1, keepdim=True).clamp(min=1e-6)
        turn = self._approach_turn(ctx, obj)
        if turn is not None:  # the approach turned toward the plane of the face the fingers will close on
            approach = square_approach(approach, self._closing_axis(ctx, rows, approach, obj, raw=True, near=near), turn)
            pre = centre - approach * d.norm(dim=1, keepdim=True)
        self.obj[rows] = obj
        self.pre[rows] = pre
        self.approach[rows] = approach
        self.closing[rows] = self._closing_axis(ctx, rows, approach, obj, near=near)
        self.target[rows] = self._target(ctx, rows, centre, approach, obj)
        self.reach_tol[rows] = self._reach_tolerance(ctx, rows, obj)
        self.phase[rows] = APPROACH
        self.phase_t[rows] = 0
        self.t[rows] = 0
        ctx.start_fabric(rows)
        return torch.zeros(len(rows), dtype=torch.long, device=self.device)

    def _reach_tolerance(self, ctx: StepContext, rows: Tensor, obj: int) -> Tensor:
        """(len(rows),) m: how close a settled TCP must be to its goal: the robot's
        ``gripper.reach_tolerance``, else ``controller.reach_tolerance``."""
        tol = ctx.scene.robot.gripper.reach_tolerance
        return torch.full((len(rows),), ctx.cfg.reach_tolerance if tol is None else tol, device=self.device)

    def _approach_turn(self, ctx: StepContext, obj: int) -> float | None:
        """rad the approach may turn toward its closing face (``square_approach``); None: as sampled."""
        return None

    def _target(self, ctx: StepContext, rows: Tensor, centre: Tensor, approach: Tensor, obj: int) -> Tensor:
        """TCP goal of the plans ``rows`` that begin the action now: the region centre (the
        object's centre), backed off along the approach just enough that the fingertips stay
        ``grasp_clearance`` above the surface the object rests on."""
        support = centre[:, 2] - ctx.scene.geometry.objects[obj].half_height
        return tcp_target(centre, approach, support, ctx.scene.robot.gripper, ctx.cfg.grasp_clearance,
                          ctx.cfg.grasp_offset)

    def _closing_axis(self, ctx: StepContext, rows: Tensor, approach: Tensor, obj: int, raw: bool = False,
                      near: Tensor | None = None) -> Tensor:
        """Closing axis of the goal pose: the object's face normal (perpendicular to the
        approach) nearest to the gripper's current closing axis, so the fingers close on two
        faces; a cylinder offers only the axes across its own (it is never squeezed end to end).
        ``raw``: the chosen face normal itself, before its projection across the approach."""
        frame = quat_to_matrix(ctx.objects[rows, obj, 3:7])  # (n, 3, 3), columns = object axes
        if ctx.scene.geometry.objects[obj].shape == "cylinder":
            frame = frame[:, :, :2]
        return self._face_axis(frame, approach, ctx.closing[rows] if near is None else near, raw)

    def _face_axis(self, frame: Tensor, approach: Tensor, near: Tensor, raw: bool = False) -> Tensor:
        """(n, 3): of the axes ``frame`` (n, 3, k) and their opposites, projected perpendicular
        to ``approach`` and normalised, the most perpendicular to it first (a true face
        normal), then the nearest to ``near`` (``raw``: that axis unprojected)."""
        axes = torch.cat([frame, -frame], dim=2).transpose(1, 2)  # (n, 2k, 3)
        cand = axes - (axes * approach[:, None, :]).sum(-1, keepdim=True) * approach[:, None, :]
        norm = cand.norm(dim=-1)
        cand = cand / norm.clamp(min=1e-6)[..., None]
        score = 2.0 * norm + 0.5 * (cand * near[:, None, :]).sum(-1)
        best = score.argmax(dim=1)
        return (axes if raw else cand)[torch.arange(len(frame), device=frame.device), best]

    def _width_across(self, ctx: StepContext, rows: Tensor, obj: int) -> Tensor:
        """(len(rows),) m: the object's extent along the goal closing axis (``self.closing``), from
        its shape, size and the pose seen now: a box's projection ``2 sum_i |c_i| h_i`` on its own
        axes, a cylinder's ``2 (r sqrt(1 - c_z^2) + h |c_z|)``. The gap the fingers must clear."""
        o = ctx.scene.geometry.objects[obj]
        frame = quat_to_matrix(ctx.objects[rows, obj, 3:7])  # (n, 3, 3), columns = object axes
        c = (frame.transpose(1, 2) @ self.closing[rows][:, :, None]).squeeze(2).abs()  # in the object's frame
        hx, hy, hz = (float(h) for h in o.half_size)
        if o.shape == "cylinder":
            return 2.0 * (hx * torch.sqrt((1.0 - c[:, 2] ** 2).clamp(min=0.0)) + hz * c[:, 2])
        return 2.0 * (c[:, 0] * hx + c[:, 1] * hy + c[:, 2] * hz)

    def _goal(self, rows: Tensor, ctx: StepContext | None = None) -> Tensor:
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

    def act(self, ctx: StepContext, rows: Tensor) -> None:
        ph = self.phase[rows]
        # the arm stands still while the fingers close / open (ctx.arm_hold was set on entry)
        moving = ph != GRIP
        mr = rows[moving]
        if len(mr):
            ignore, held = self._avoid(ctx, mr) if ctx.cfg.avoid_movable else (None, None)
            ctx.fabric_goal(mr, self._goal(mr, ctx), self.approach[mr], self.closing[mr], ignore, held)
        grip = (ph >= GRIP) if self.closes_gripper else (ph < GRIP)
        ctx.grip_cmd[rows] = grip
        self.t[rows] += 1
        self.phase_t[rows] += 1

    def _avoid(self, ctx: StepContext, rows: Tensor) -> tuple[Tensor, Tensor | None]:
        """``controller.avoid_movable``: the movable objects ``rows`` leave out of the fabric's
        collision leaves ((len, m) bool) and the object each carries as a sphere ((len,), -1 none;
        None: none). Here the object the action handles, through all its phases: the hand must
        close on it (a grasp) or hold it (a place)."""
        m = ctx.objects.shape[1]
        return torch.nn.functional.one_hot(self.obj[rows], m).bool(), None

    def _advance(self, ctx: StepContext, rows: Tensor) -> tuple[Tensor, Tensor]:
        """Shared phase transitions; returns (tcp error to current goal, reached-target flag)."""
        cfg = ctx.cfg
        tcp = ctx.tcp[rows]
        ph = self.phase[rows]
        err = (tcp - self._goal(rows)).norm(dim=1)
        axis_ok = (ctx.approach[rows] * self.approach[rows]).sum(dim=1) >= math.cos(cfg.axis_tolerance)
        to_descend = (ph == APPROACH) & (err <= cfg.pregrasp_tolerance) & axis_ok
        # close when at the target, or when settled within the reach tolerance of it (the fingers
        # or the robot's own collision terms may hold the TCP a few mm off; _reach_tolerance)
        ramp_done = self.phase_t[rows] * ctx.dt * cfg.approach_speed >= (self.pre[rows] - self.target[rows]).norm(dim=1)
        settled = ramp_done & (self.phase_t[rows] >= self._settle_steps(ctx, rows)) & (err <= self.reach_tol[rows])
        to_grip = (ph == DESCEND) & ((err <= cfg.grip_tolerance) | settled)
        new = torch.where(to_descend, DESCEND, torch.where(to_grip, GRIP, ph))
        changed = new != ph
        if to_grip.any():
            ctx.hold_arm(rows[to_grip])
        self.phase[rows] = new
        self.phase_t[rows] = torch.where(changed, 0, self.phase_t[rows])
        return err, to_grip

    def _grip_step(self, ctx: StepContext, rows: Tensor) -> tuple[Tensor, Tensor, Tensor, Tensor, Tensor]:
        """Advance the shared phases; returns (TCP error, phase, steps in phase, holds, and
        whether the gripper has had ``grip_s`` to close / open)."""
        err, _ = self._advance(ctx, rows)
        ph, pt = self.phase[rows], self.phase_t[rows]
        done = (ph == GRIP) & (pt >= ctx.steps(ctx.cfg.grip_s))
        return err, ph, pt, ctx.holds(rows, self.obj[rows]), done

    def _retreated(self, ctx: StepContext, rows: Tensor, err: Tensor) -> Tensor:
        """Back at the pre-pose, or most of the way back out along the approach line."""
        span = (self.pre[rows] - self.target[rows]).norm(dim=1)
        out = (ctx.tcp[rows] - self.target[rows]).norm(dim=1)
        return (self.phase_t[rows] > 0) & ((err <= ctx.cfg.pregrasp_tolerance) | (out >= ctx.cfg.retreat_share * span))

    def _settle_steps(self, ctx: StepContext, rows: Tensor) -> Tensor:
        ramp = (self.pre[rows] - self.target[rows]).norm(dim=1) / (ctx.cfg.approach_speed * ctx.dt)
        settle = ctx.scene.robot.gripper.settle_s
        return ramp.ceil().long() + ctx.steps(ctx.cfg.settle_s if settle is None else settle)

    def distance(self, ctx: StepContext, rows: Tensor) -> Tensor:
        return (ctx.tcp[rows] - self.target[rows]).norm(dim=1)
