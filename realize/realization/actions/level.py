"""A held box set down level: the hand's goal orientation turned so the box's face lands flat.

What it does: ``level_turn`` predicts how a box held rigidly in the hand will stand when the hand
reaches its goal axes (approach, closing), and returns the hand's goal axes turned, about a
horizontal axis, by the rotation that brings the box's face nearest to horizontal flat, at most
``max_turn`` rad (a box grasped 25 degrees off its vertical axis and placed down a 20 degree
approach otherwise meets the block below on one edge: the impact tips the block or the box off),
with the box's offset from the TCP at the goal (for the TCP target that puts its centre on the
place point).
What it doesn't: choose the place point or move the hand (``realize.realization.actions.place``).
"""

from __future__ import annotations

import torch
from torch import Tensor

__all__ = ["hand_frame", "level_turn", "rotate"]


def hand_frame(approach: Tensor, closing: Tensor) -> Tensor:
    """(n, 3, 3) right-handed orthonormal frames with columns (approach, closing, approach x
    closing); ``closing`` is made perpendicular to ``approach`` first."""
    a = approach / approach.norm(dim=1, keepdim=True).clamp(min=1e-9)
    c = closing - (closing * a).sum(1, keepdim=True) * a
    c = c / c.norm(dim=1, keepdim=True).clamp(min=1e-9)
    return torch.stack([a, c, torch.cross(a, c, dim=1)], dim=2)


def rotate(axis: Tensor, angle: Tensor, v: Tensor) -> Tensor:
    """(n, 3) vectors ``v`` turned by ``angle`` (n,) about the unit ``axis`` (n, 3) (Rodrigues)."""
    c, s = torch.cos(angle)[:, None], torch.sin(angle)[:, None]
    return v * c + torch.cross(axis, v, dim=1) * s + axis * (axis * v).sum(1, keepdim=True) * (1 - c)


def level_turn(box: Tensor, hand_now: Tensor, approach: Tensor, closing: Tensor, offset: Tensor,
               max_turn: float) -> tuple[Tensor, Tensor, Tensor, Tensor]:
    """For boxes held rigidly: ``box`` (n, 3, 3) their frames now (columns: the box's axes),
    ``hand_now`` (n, 3, 3) the hand's frames now (``hand_frame``), ``approach`` and ``closing``
    (n, 3) the hand's goal axes, ``offset`` (n, 3) the box centre minus the TCP now (world).
    Returns (approach, closing, offset at the goal, the turn in rad): the goal axes turned by the
    least rotation that makes the box's axis nearest the vertical vertical (capped at
    ``max_turn``), and the offset the box will have from the TCP there."""
    goal = hand_frame(approach, closing)
    to_goal = goal @ hand_now.transpose(1, 2)  # the hand's rotation from now to its goal
    at_goal = to_goal @ box  # the box's axes when the hand is there
    z = at_goal[:, 2, :]  # each axis' vertical component
    k = z.abs().argmax(dim=1)
    rows = torch.arange(len(box), device=box.device)
    up = at_goal[rows, :, k] * torch.sign(z[rows, k])[:, None]  # that axis, pointing up
    ez = torch.zeros_like(up)
    ez[:, 2] = 1.0
    axis = torch.cross(up, ez, dim=1)
    s = axis.norm(dim=1)
    angle = torch.atan2(s, up[:, 2]).clamp(max=max_turn)
    axis = axis / s.clamp(min=1e-9)[:, None]
    angle = torch.where(s > 1e-9, angle, torch.zeros_like(angle))
    moved = (to_goal @ offset[:, :, None]).squeeze(2)
    return (rotate(axis, angle, goal[:, :, 0]), rotate(axis, angle, goal[:, :, 1]), rotate(axis, angle, moved),
            angle)
