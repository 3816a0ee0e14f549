"""What a rollout returns: per-plan cost, success, failure and (optionally) trajectories.

What it does: ``RolloutResult`` (one row per plan; ``to_eval`` adapts it to the cross-entropy
optimizer's ``EvalResult``) and ``TrajectoryRecorder``, which samples base, TCP and object
positions and orientations, the whole-body joints and each plan's current action every
``record_every`` control steps and stores them into a result (``TRAJECTORIES``: their fields).
What it doesn't: simulate (``realize.realization.rollout``) or write files (the run directory's
sinks do).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import torch
from torch import Tensor

from realize.robot.layout import BASE_XY
from realize.search.protocol import EvalResult
from realize.realization.context import StepContext
from realize.world.state import SceneState

# the recorded per-copy trajectories of a RolloutResult, each (N, T, ...): what joining row blocks
# or folding a robust search's worlds carries along
TRAJECTORIES = ("traj_base", "traj_ee", "traj_objects", "traj_object_quats", "traj_q", "traj_action")


@dataclass
class RolloutResult:
    """Outcome of N realized plans (one row per plan)."""

    cost: Tensor  # (N,) eq. (2): steps until each action finished + final cost
    feasible: Tensor  # (N,) every action succeeded and psi_g holds
    action_success: Tensor  # (N, A)
    goal: Tensor  # (N,) psi_g at the end (read from the simulator)
    steps: Tensor  # (N,) control steps simulated for the plan
    progress: Tensor  # (N,) actions completed
    distance: Tensor  # (N,) distance proxy of the failing action (0 if feasible)
    failure: list[str]  # per plan: "" or "<action index>:<action>:<reason>"
    traj_t: Tensor | None = None  # (T,) seconds
    traj_base: Tensor | None = None  # (N, T, 2)
    traj_ee: Tensor | None = None  # (N, T, 3)
    traj_objects: Tensor | None = None  # (N, T, m, 3) every object's centre
    traj_object_quats: Tensor | None = None  # (N, T, m, 4) every object's orientation (w, x, y, z)
    traj_q: Tensor | None = None  # (N, T, n_dof) whole-body joints (the rerun recording's robot in 3-D)
    traj_action: Tensor | None = None  # (N, T) the action each plan was in (its index in the plan)
    wall_time_s: float = 0.0
    sim_steps: int = 0
    horizon_cost: float = math.nan  # cost of a plan cut by the horizon: max steps + final cost
    share: Tensor | None = None  # robust search: each sample's success share over its worlds
    world_cost: Tensor | None = None  # robust search: (N, R) each sample's cost in each world
    world_feasible: Tensor | None = None  # robust search: (N, R) its success in each world
    stopped: Tensor | None = None  # (N,) bool, ce.prune: stopped as it could not be an elite (None: off)
    # per plan, the scene state it ended in where it was feasible (None: not feasible), if asked (``capture_end``)
    end_states: list[SceneState | None] | None = None

    def ordinary(self) -> RolloutResult:
        """A copy whose tensors are ordinary ones (a rollout runs in inference mode, whose tensors
        cannot be changed in place outside it)."""
        return dataclasses.replace(self, **{f.name: getattr(self, f.name).clone() for f in dataclasses.fields(self)
                                            if isinstance(getattr(self, f.name), Tensor)})

    def to_eval(self) -> EvalResult:
        return EvalResult(cost=self.cost.double(), feasible=self.feasible, progress=self.progress.double(),
                          distance=self.distance.double(),
                          failure_cost=self.horizon_cost if math.isfinite(self.horizon_cost) else None,
                          share=self.share, stopped=self.stopped, end_states=self.end_states)


class TrajectoryRecorder:
    """Base (x, y), TCP, object positions and orientations of every copy, every ``every`` control steps."""

    def __init__(self, every: int):
        self.every = every
        self.t: list[float] = []
        self.base: list[Tensor] = []
        self.ee: list[Tensor] = []
        self.objects: list[Tensor] = []
        self.quats: list[Tensor] = []
        self.q: list[Tensor] = []
        self.action: list[Tensor] = []

    def sample(self, step: int, ctx: StepContext, action: Tensor | None = None) -> None:
        """Record the state just read by ``ctx`` (and each plan's current ``action``) if ``step``
        is a recording step."""
        if step % self.every == 0:
            self.t.append(step * ctx.dt)
            self.base.append(ctx.base[:, BASE_XY].clone())
            self.ee.append(ctx.tcp.clone())
            self.objects.append(ctx.objects[:, :, :3].clone())
            self.quats.append(ctx.objects[:, :, 3:7].clone())
            self.q.append(ctx.q.clone())
            if action is not None:
                self.action.append(action.clone())

    def store(self, res: RolloutResult, m: int) -> None:
        """Put the first ``m`` copies' trajectories into ``res`` (nothing if none was recorded)."""
        if not self.t:
            return
        res.traj_t = torch.tensor(self.t)
        res.traj_base = torch.stack(self.base, dim=1)[:m].cpu()
        res.traj_ee = torch.stack(self.ee, dim=1)[:m].cpu()
        res.traj_objects = torch.stack(self.objects, dim=1)[:m].cpu()
        res.traj_object_quats = torch.stack(self.quats, dim=1)[:m].cpu()
        res.traj_q = torch.stack(self.q, dim=1)[:m].cpu()
        if len(self.action) == len(self.t):
            res.traj_action = torch.stack(self.action, dim=1)[:m].cpu()
