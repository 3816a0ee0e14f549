"""Screening by the robot's own kinematics: samples that physics would fail for certain, found
before they are simulated (``ce.screen``).

What it does: ``HandDepthScreen`` reads, for every ``grasp`` of a box whose parameter is a
hemisphere pre-pose, the pose the grasp will drive the TCP to (the object's centre backed off
along the approach, ``tcp_target``, as the rollout computes it), turns the hand's collision
spheres (the robot spec's spheres on the links rigid with the TCP, fingers open) into that pose
for every closing axis the grasp could pick (the box's face normals across the approach that
can win ``Manipulate``'s choice, each way round; with ``controller.grasp_square_turn``, each with
the approach turned toward its face as the grasp turns it), and rejects a sample when, for all of them,
the hand would reach more than ``depth`` below the top of the surface the box stands on. The
hand cannot be there: the table holds it off, and the grasp times out. The spheres hold the
links with a margin, so ``depth`` (``ce.screen_depth``, 2.5 cm) is what makes the check conservative; measured in
``scripts/screen_check.py``: of 1,000 uniform seed-task samples, the rejected ones simulated.
What it doesn't: check places, pushes, reach from the base (the whole-body fabric moves the
base during a grasp), or cylinders (any axis across one can close on it); draw the samples
again (``realize.search.ce.optimizer``).
"""

from __future__ import annotations

import math

import torch
from torch import Tensor

from realize.realization.actions.manipulate import square_approach, tcp_target
from realize.realization.config import RolloutConfig
from realize.robot.kinematics import RobotKinematics
from realize.robot.spec import RobotSpec
from realize.search.ce.config import CEConfig
from realize.tasks.hemisphere import Hemisphere
from realize.tasks.spec import TaskSpec
from realize.world.geometry import SceneGeometry

__all__ = ["HandDepthScreen", "hand_spheres_in_tcp", "plan_screen"]

SCORE_SPAN = 0.5  # Manipulate's closing-axis score: 2 |projection| + 0.5 cos(to the current axis)


def hand_spheres_in_tcp(kin: RobotKinematics) -> tuple[Tensor, Tensor]:
    """Centres (k, 3) in the TCP frame and radii (k,) of the spheres rigid with the TCP: those
    whose TCP-frame centre is the same at the rest pose and at the rest pose with every joint
    moved by 0.3 (the hand, the fingers at their fixed opening, the last link)."""
    spec = kin.spec
    rest = torch.tensor([[spec.rest_value(j) for j in kin.joint_names]], dtype=kin.dtype)
    q = torch.cat([rest, rest + 0.3])
    frame = kin.ee_pose(q)
    centres, radii = kin.collision_spheres(q)
    local = torch.einsum("nji,nkj->nki", frame[:, :3, :3], centres - frame[:, None, :3, 3])
    rigid = (local[0] - local[1]).norm(dim=1) < 1e-9
    if not bool(rigid.any()):
        raise ValueError(f"robot {spec.name!r}: no collision sphere is rigid with its TCP link {spec.tcp.link!r}")
    return local[0][rigid], radii[rigid]


class HandDepthScreen:
    """``screen(Z) -> (N,) bool``: the samples a grasp of them would fail for certain (see the
    module docstring). Built once per plan; rows are independent (a batch equals its rows)."""

    def __init__(self, task: TaskSpec, geometry: SceneGeometry, robot: RobotSpec, rollout: RolloutConfig,
                 depth: float, dtype: torch.dtype = torch.float64) -> None:
        self.depth, self.dtype = float(depth), dtype
        kin = RobotKinematics(robot, dtype=dtype)
        self.offsets, self.radii = hand_spheres_in_tcp(kin)
        self.approach_local = torch.tensor(robot.tcp.approach_axis, dtype=dtype)
        self.closing_local = torch.tensor(robot.tcp.closing_axis, dtype=dtype)
        self.hand, self.clearance, self.offset = robot.gripper, rollout.grasp_clearance, rollout.grasp_offset
        self.turn = rollout.grasp_square_turn  # the grasp turns its approach toward the closing face
        self.grasps: list[tuple[slice, Tensor, Tensor, float]] = []  # columns, centre, box axes, support top
        for action in task.plan:
            region = task.layout.regions[action.params[0]]
            if action.template != "grasp" or not isinstance(region, Hemisphere) or action.obj is None:
                continue
            obj = geometry.object(action.obj)
            if obj.shape != "box":
                continue
            c, s = math.cos(obj.yaw), math.sin(obj.yaw)
            # columns: the box's axes at its config pose (turned by its yaw about the vertical)
            axes = torch.tensor([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]], dtype=dtype)
            centre = torch.tensor(region.center, dtype=dtype)
            top = float(region.center[2] - obj.half_height)
            self.grasps.append((task.layout.slices[action.params[0]], centre, axes, top))

    @property
    def active(self) -> bool:
        """Whether the plan has anything to screen."""
        return bool(self.grasps)

    def __call__(self, Z: Tensor) -> Tensor:
        reject = torch.zeros(Z.shape[0], dtype=torch.bool)
        for cols, centre, axes, top in self.grasps:
            reject |= self._too_deep(Z[:, cols][:, :3].to(self.dtype), centre, axes, top)
        return reject

    def _too_deep(self, pre: Tensor, centre: Tensor, axes: Tensor, top: float) -> Tensor:
        n = pre.shape[0]
        a = centre - pre
        a = a / a.norm(dim=1, keepdim=True).clamp(min=1e-9)
        cand = torch.cat([axes, -axes], dim=1).T  # (6, 3) face normals
        proj = cand[None] - (a @ cand.T)[..., None] * a[:, None, :]  # (n, 6, 3)
        norm = proj.norm(dim=-1)
        plausible = norm >= norm.max(dim=1, keepdim=True).values - SCORE_SPAN  # could win for some current axis
        approach = a[:, None, :].expand(n, 6, 3)
        if self.turn is not None:  # each candidate face turns the approach toward its own plane
            approach = square_approach(approach, cand[None].expand(n, 6, 3), self.turn)
            proj = cand[None] - (approach * cand[None]).sum(-1, keepdim=True) * approach
        closing = proj / proj.norm(dim=-1).clamp(min=1e-9)[..., None]
        tops = torch.full((n * 6,), top, dtype=self.dtype)
        tcp = tcp_target(centre.expand(n * 6, 3), approach.reshape(n * 6, 3), tops, self.hand, self.clearance,
                         self.offset).reshape(n, 6, 3)
        # the hand's rotation: its approach and closing axes onto a and the closing candidate
        local = torch.stack([self.approach_local, self.closing_local,
                             torch.linalg.cross(self.approach_local, self.closing_local)], dim=1)  # (3, 3) columns
        world = torch.stack([approach, closing, torch.linalg.cross(approach, closing, dim=-1)], dim=-1)
        rot = world @ local.T  # (n, 6, 3, 3): local axes -> world axes
        spheres = tcp[:, :, None, :] + torch.einsum("ncij,kj->ncki", rot, self.offsets)
        below = top - (spheres[..., 2] - self.radii)  # (n, 6, k): how far each sphere reaches under the top
        deepest = below.max(dim=2).values
        deepest = torch.where(plausible & (norm > 1e-6), deepest, torch.full_like(deepest, float("inf")))
        return deepest.min(dim=1).values > self.depth


def plan_screen(task: TaskSpec, geometry: SceneGeometry, robot: RobotSpec, rollout: RolloutConfig,
                ce: CEConfig) -> HandDepthScreen | None:
    """The plan's screen at ``ce.screen_depth``, or None where the plan has nothing to screen
    (the search then draws as without one). A top-k search screens nothing (one plan's screen)."""
    screen = HandDepthScreen(task, geometry, robot, rollout, ce.screen_depth, ce.torch_dtype)
    return screen if screen.active else None
