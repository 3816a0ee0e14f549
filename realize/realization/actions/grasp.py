"""The ``grasp`` action template: pick an object from a pre-grasp pose on a hemisphere around it.

What it does: ``Grasp`` runs the shared manipulation phases (``manipulate``) closing the gripper,
and decides success from the fingers' contact forces on the object the plan names. With
``controller.preshape_margin`` it pre-shapes the open fingers to the object's width across the
goal closing axis plus that margin for the approach and the move in (null: fully open), so a
closing axis tilted out of the horizontal (a turned box grasped off vertical) does not put an
open finger on the table. With ``controller.grasp_square_turn`` it turns a box's sampled approach,
by at most that angle, toward the plane of the face the fingers close on, so the closing axis
stays that face's normal (horizontal on an upright box, however the box is turned). The gap's
joint target and, for a one-sided jaw, where the held object's centre sits come from the fingers'
kinematics (``realize.robot.grip_geometry``).
What it doesn't: carry the object anywhere (``move_to`` and ``place`` do).
"""

from __future__ import annotations

import torch
from torch import Tensor

from realize.realization.actions.base import Outcome
from realize.realization.actions.manipulate import GRIP, RETREAT, Manipulate
from realize.realization.context import StepContext
from realize.realization.failures import Failure
from realize.robot.grip_geometry import GripGeometry, grip_geometry
from realize.tasks.regions import Region


class Grasp(Manipulate):
    """grasp(o, g_p): fabric to the pre-grasp g_p on the hemisphere around object o, straight in
    to it, close, retreat to g_p.

    Success: the TCP reached the grasp point within ``reach_tolerance`` (paper ``ee_in(g_p)``)
    AND both fingers press on o (contact forces) after the retreat.
    """

    name = "grasp"
    closes_gripper = True

    def __init__(self, n_envs: int, device: torch.device):
        super().__init__(n_envs, device)
        self.opening = torch.zeros(n_envs, device=device)  # finger joint target before GRIP (pre-shape)
        self._geo: GripGeometry | None = None

    def _geometry(self, ctx: StepContext) -> GripGeometry:
        """The gripper's geometry from its fingers' kinematics (measured once per template)."""
        if self._geo is None:
            self._geo = grip_geometry(ctx.scene.robot)
        return self._geo

    def _reach_tolerance(self, ctx: StepContext, rows: Tensor, obj: int) -> Tensor:
        """``Manipulate``'s; with the robot's ``gripper.reach_share``, capped at that share of the
        clearance the open pads leave on each side of the object across the closing axis,
        ``(width_open - width) / 2``: settled farther off, a pad closes onto the object's top or side
        instead of around it (a 3 cm cube in the SO-100's 56 mm jaw: 13 mm of clearance)."""
        tol = super()._reach_tolerance(ctx, rows, obj)
        share = ctx.scene.robot.gripper.reach_share
        if share is None:
            return tol
        clearance = 0.5 * (self._geometry(ctx).width_open - self._width_across(ctx, rows, obj))
        return torch.minimum(tol, share * clearance.clamp(min=0.0))

    def _target(self, ctx: StepContext, rows: Tensor, centre: Tensor, approach: Tensor, obj: int) -> Tensor:
        """``Manipulate``'s goal; a one-sided jaw's TCP goal is moved along the closing axis so that
        the object's centre lies half way between the open pads' midpoint (where the moving jaw
        clears it most) and the midpoint of pads closed on it (where it is held): the fixed jaw
        clears the object by a quarter of the open jaw's slack on the way in, and the closing jaw
        slides it that far onto the fixed one. (The TCP itself may be anywhere between the pads.)"""
        target = super()._target(ctx, rows, centre, approach, obj)
        geo = self._geometry(ctx)
        if not geo.one_sided:
            return target
        width = self._width_across(ctx, rows, obj)
        shift = 0.5 * (geo.centre_for_width(width) + geo.centre_for_width(torch.full_like(width, geo.width_open)))
        return target - self.closing[rows] * shift[:, None]

    def begin(self, ctx: StepContext, rows: Tensor, params: Tensor, region: Region, obj: int = -1,
              shift: Tensor | None = None, support: int = -1) -> Tensor:
        code = super().begin(ctx, rows, params, region, obj, shift, support)
        margin = ctx.cfg.preshape_margin
        if margin is not None:
            gap = self._width_across(ctx, rows, obj) + margin  # m between the pads
            self.opening[rows] = self._geometry(ctx).joint_for_width(gap)
        return code

    def _approach_turn(self, ctx: StepContext, obj: int) -> float | None:
        turn = ctx.cfg.grasp_square_turn
        return turn if turn is not None and ctx.scene.geometry.objects[obj].shape == "box" else None

    def act(self, ctx: StepContext, rows: Tensor) -> None:
        super().act(ctx, rows)
        if ctx.cfg.preshape_margin is not None:
            hand = ctx.scene.robot.gripper
            ctx.grip_open[rows] = torch.where(self.phase[rows] < GRIP, self.opening[rows],
                                              torch.full_like(self.opening[rows], hand.open))

    def check(self, ctx: StepContext, rows: Tensor) -> Outcome:
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
        fail = torch.where(not_held, Failure.GRASP_NOT_HELD,
                           torch.where(dropped, Failure.OBJECT_DROPPED,
                                       torch.where(timeout & ~ok, Failure.TIMEOUT, 0)))
        return Outcome(ok | (fail > 0), ok, fail)
