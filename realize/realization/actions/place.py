"""The ``place`` action template: set the held object down at a place pose or let it go at a point.

What it does: ``Place`` runs the shared manipulation phases (``manipulate``) opening the
gripper, aims the TCP so that the held object's centre lands on the place point, and decides
success from the fingers letting go and the object coming to rest.
What it doesn't: check where the object came to rest (the plan's goal does, ``goals``).
"""

from __future__ import annotations

import torch
from torch import Tensor

from realize.tasks.hemisphere import Hemisphere
from realize.realization.actions.base import Outcome
from realize.realization.actions.manipulate import GRIP, RETREAT, Manipulate
from realize.realization.context import StepContext
from realize.realization.failures import Failure
from realize.tasks.regions import Box, Region


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

    @classmethod
    def accepts(cls, region: Region) -> bool:
        return isinstance(region, Hemisphere) or (isinstance(region, Box) and region.dim == 3)

    def begin(self, ctx: StepContext, rows: Tensor, params: Tensor, region: Region, obj: int = -1,
              shift: Tensor | None = None) -> Tensor:
        code = super().begin(ctx, rows, params, region, obj, shift)
        held = ctx.holds(rows, obj)
        return torch.where(held, code, Failure.NOT_HOLDING)

    def _target(self, ctx: StepContext, rows: Tensor, centre: Tensor, approach: Tensor, obj: int) -> Tensor:
        """TCP goal that puts the held object's centre at the region centre (plus a small drop
        height): the object sits ``s`` ahead of the TCP along the approach axis, measured now."""
        s = ((ctx.objects[rows, obj, :3] - ctx.tcp[rows]) * ctx.approach[rows]).sum(dim=1, keepdim=True)
        lift = torch.tensor([0.0, 0.0, ctx.cfg.place_drop], device=centre.device)
        return centre + lift - approach * s

    def act(self, ctx: StepContext, rows: Tensor) -> None:
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
