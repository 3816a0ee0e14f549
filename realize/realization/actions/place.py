"""The ``place`` action template: set the held object down at a place pose or let it go at a point.

What it does: ``Place`` runs the shared manipulation phases (``manipulate``) opening the
gripper, aims the TCP so that the held object's centre lands on the place point, and decides
success from the fingers letting go and the object coming to rest.
With ``controller.place_align_yaw`` it turns a held box about the approach so that it lands
square on its support (the region's frame), modulo 90 degrees; with ``controller.place_level``
it turns the hand so the held box lands level (``realize.realization.actions.level``); with
``controller.place_lift`` the hand first rises straight up to the pre-place's height and only
then crosses to it: the fabric does not see movable objects, and a held block carried on the
straight way from a low grasp up to a pre-place above a tower sweeps through the tower's top.
With ``controller.avoid_movable`` (``_avoid``) the carry to the pre-place keeps the held object,
as a sphere fixed to the hand, off everything, and the hand off every movable object but the
held one; from the straight move in on, the support is left out too (the held object is set down
on it) and the held object is no sphere any more (it comes down onto its support, a table or a
block, on a straight line the plan chose).
What it doesn't: check where the object came to rest (the plan's goal does, ``goals``).
"""

from __future__ import annotations

import torch
from torch import Tensor

from realize.tasks.hemisphere import Hemisphere
from realize.realization.actions.base import Outcome
from realize.realization.actions.level import hand_frame, level_turn, rotate
from realize.realization.actions.manipulate import APPROACH, GRIP, RETREAT, Manipulate
from realize.realization.context import StepContext
from realize.realization.failures import Failure
from realize.tasks.regions import Box, Region
from realize.scene import quat_to_matrix


class Place(Manipulate):
    """place(o, g_p): while holding object o, fabric to the pre-place g_p on the hemisphere
    around the place point, straight in, open the gripper, retreat to g_p.

    Or, with a 3-D box region, place(o, p): the parameter is the release point p of o's centre
    itself (approached top-down from ``place_pre_height`` above). The point need not be on a
    surface: an object released in the air falls, or slides down a ramp, and the action
    succeeds once it rests; the plan's goal decides whether it came to rest where it should.

    Success: the TCP reached the place point within ``reach_tolerance`` (paper ``ee_in(g_p)``),
    the gripper let go (no finger contact with o) and o rests (speed below ``rest_speed``).
    A plan that does not hold o when the action begins fails there (``not_holding``).
    """

    name = "place"
    param_doc = ("a hemisphere region (pre-pose on its surface, approach towards its centre) or a 3-D box "
                 "of release points (approached top-down)")
    closes_gripper = False

    def __init__(self, n_envs: int, device: torch.device):
        super().__init__(n_envs, device)
        self.via = torch.zeros(n_envs, 3, device=device)  # controller.place_lift: above where the hand began
        self.lifting = torch.zeros(n_envs, dtype=torch.bool, device=device)  # still rising to ``via``
        self.support = torch.full((n_envs,), -1, dtype=torch.long, device=device)  # the movable object set down on, -1: none

    @classmethod
    def accepts(cls, region: Region) -> bool:
        return isinstance(region, Hemisphere) or (isinstance(region, Box) and region.dim == 3)

    def begin(self, ctx: StepContext, rows: Tensor, params: Tensor, region: Region, obj: int = -1,
              shift: Tensor | None = None, support: int = -1) -> Tensor:
        code = super().begin(ctx, rows, params, region, obj, shift, support)
        self.support[rows] = support
        if ctx.cfg.place_align_yaw and ctx.scene.geometry.objects[obj].shape == "box":
            self.closing[rows] = self._square_on(ctx, rows, obj, support)
        if ctx.cfg.place_level is not None and ctx.scene.geometry.objects[obj].shape == "box" \
                and isinstance(region, Hemisphere):
            self._level(ctx, rows, params, region, obj, shift)
        if ctx.cfg.place_lift:
            tcp = ctx.tcp[rows].to(self.via.dtype)
            self.via[rows] = torch.cat([tcp[:, :2], self.pre[rows, 2:]], dim=1)
            self.lifting[rows] = self.pre[rows, 2] - tcp[:, 2] > ctx.cfg.pregrasp_tolerance
        else:
            self.lifting[rows] = False
        held = ctx.holds(rows, obj)
        return torch.where(held, code, Failure.NOT_HOLDING)

    def _level(self, ctx: StepContext, rows: Tensor, params: Tensor, region: Region, obj: int,
               shift: Tensor | None) -> None:
        """``controller.place_level``: the goal axes turned so the held box lands level
        (``level_turn``; the pre-pose stays the sampled one), and the TCP target that puts the box's centre on that point (plus
        ``place_drop``) with the box's whole offset from the TCP as the hand will hold it there."""
        centre, _ = self._centre_and_pre(ctx, params, region, shift)
        box = quat_to_matrix(ctx.objects[rows, obj, 3:7])
        now = hand_frame(ctx.approach[rows], ctx.closing[rows])
        offset = ctx.objects[rows, obj, :3] - ctx.tcp[rows]
        a, c, off, _ = level_turn(box, now, self.approach[rows], self.closing[rows], offset, ctx.cfg.place_level)
        lift = torch.tensor([0.0, 0.0, ctx.cfg.place_drop], device=centre.device)
        self.approach[rows], self.closing[rows] = a, c
        self.target[rows] = centre + lift - off

    def _square_on(self, ctx: StepContext, rows: Tensor, obj: int, support: int) -> Tensor:
        """(len(rows), 3): the goal closing axis that sets the held box down square on its
        support (``controller.place_align_yaw``). The held box turns with the hand, so the hand's
        closing axis is turned about the approach by the angle from the held box's face normal
        (the goal closing axis ``Manipulate.begin`` chose) to the support's face normal nearest
        it: at most 45 degrees. The support is a movable box seen where it stands now, or (-1,
        and a cylinder, whose top is round) the world's axes: tables stand square to them."""
        a = self.approach[rows]
        held = self.closing[rows]
        if support >= 0 and ctx.scene.geometry.objects[support].shape == "box":
            frame = quat_to_matrix(ctx.objects[rows, support, 3:7])
        else:
            frame = torch.eye(3, device=a.device).expand(len(rows), 3, 3)
        want = self._face_axis(frame, a, held)
        angle = torch.atan2((torch.cross(held, want, dim=1) * a).sum(1), (held * want).sum(1))
        hand = ctx.closing[rows]  # where the hand's closing axis is now (the box rigid in it)
        turned = rotate(a, angle, hand)
        turned = turned - (turned * a).sum(1, keepdim=True) * a  # the fabric's closing goal lies across the approach
        return turned / turned.norm(dim=1, keepdim=True).clamp(min=1e-6)

    def _target(self, ctx: StepContext, rows: Tensor, centre: Tensor, approach: Tensor, obj: int) -> Tensor:
        """TCP goal that puts the held object's centre at the region centre (plus a small drop
        height): the object sits ``s`` ahead of the TCP along the approach axis, measured now."""
        s = ((ctx.objects[rows, obj, :3] - ctx.tcp[rows]) * ctx.approach[rows]).sum(dim=1, keepdim=True)
        lift = torch.tensor([0.0, 0.0, ctx.cfg.place_drop], device=centre.device)
        return centre + lift - approach * s

    def _goal(self, rows: Tensor, ctx: StepContext | None = None) -> Tensor:
        """``Manipulate._goal``, but while a plan is still ``lifting`` (``controller.place_lift``)
        its APPROACH goal is ``via``, straight above where its hand began, at the pre-place's
        height. Without ``ctx`` (the phase checks' error) the goal stays the pre-place."""
        goal = super()._goal(rows, ctx)
        if ctx is None or not ctx.cfg.place_lift:
            return goal
        up = self.lifting[rows] & (self.phase[rows] == APPROACH)
        return torch.where(up[:, None], self.via[rows], goal)

    def _avoid(self, ctx: StepContext, rows: Tensor) -> tuple[Tensor, Tensor | None]:
        """``Manipulate._avoid`` for a place: the held object is left out as a box through every
        phase and carried as a sphere in the APPROACH (the carry to the pre-place, where a held
        block swept through a tower's top); from DESCEND on the support is left out as well and
        nothing is carried: the straight move in sets the held object down on the support."""
        ignore, _ = super()._avoid(ctx, rows)
        ph = self.phase[rows]
        sup = self.support[rows]
        down = (ph != APPROACH) & (sup >= 0)
        ignore = ignore | (torch.nn.functional.one_hot(sup.clamp(min=0), ignore.shape[1]).bool() & down[:, None])
        held = torch.where(ph == APPROACH, self.obj[rows], torch.full_like(self.obj[rows], -1))
        return ignore, held

    def act(self, ctx: StepContext, rows: Tensor) -> None:
        if ctx.cfg.place_lift:  # risen to within the pre-pose tolerance of the via point: cross over
            self.lifting[rows] &= ctx.tcp[rows, 2] < self.via[rows, 2] - ctx.cfg.pregrasp_tolerance
        super().act(ctx, rows)
        # keep squeezing until the release phase
        ctx.grip_cmd[rows] = self.phase[rows] < GRIP

    def check(self, ctx: StepContext, rows: Tensor) -> Outcome:
        cfg = ctx.cfg
        err, ph, pt, holds, released = self._grip_step(ctx, rows)
        dropped = (ph < GRIP) & ~holds & (self.t[rows] > 2)
        self.phase[rows] = torch.where(released, RETREAT, ph)
        self.phase_t[rows] = torch.where(released, 0, pt)
        if released.any():
            ctx.start_fabric(rows[released])
        ph = self.phase[rows]
        resting = ctx.object_speed[rows, self.obj[rows]] <= cfg.rest_speed
        retreated = (ph == RETREAT) & self._retreated(ctx, rows, err)
        ok = retreated & ~holds & resting
        timeout = self.t[rows] >= ctx.steps(cfg.manip_timeout_s)
        fail = torch.where(dropped, Failure.OBJECT_DROPPED, torch.where(timeout & ~ok, Failure.TIMEOUT, 0))
        return Outcome(ok | (fail > 0), ok, fail)
