"""Batched rollout: realize N parameterized plans at once and score them by eq. (2) of the paper.

What it does: for a sample matrix Z (M, D) (M <= the scene's N copies) ``PlanRealizer.rollout``
resets the batched scene (to the realizer's ``start`` state, if it has one) and runs a per-plan
action state machine (one action of the task's plan at a time per plan; a plan whose action fails
or times out stops there, held still), stepping physics for all plans together. One ``Rollout``
object holds the per-plan state and runs the phases of every control step: ``act`` (templates -> controllers -> commands), ``physics``,
``check_faults`` (a plan that diverges, NaN or exploding joint speeds, fails alone),
``check_actions`` (success / failure of the current actions, begin the next), ``read_due_goals``,
``stop_hopeless`` (``ce.prune``: plans that can no longer be an elite stop, ``.pruning``);
then ``settle`` (physics only, uncounted, until the last goals are due), ``cut_at_horizon`` and
``finish`` (a ``RolloutResult``: cost, per-action success, goal psi_g read from the simulator,
feasibility, progress and a distance proxy for ranking infeasible plans, trajectories). A goal
that reads an object is read ``goal_settle_s`` after the plan's last action, so a pushed or
dropped object has landed. ``PlanRealizer.evaluate`` adapts this to the cross-entropy optimizer.
What it doesn't: choose parameters (``realize.search.ce``), implement the actions
(``realize.realization.actions``) or the goal predicates (``realize.tasks.goals``), or
know any backend details (``realize.scene``).
"""

from __future__ import annotations

import time
from collections.abc import Callable

import torch
from torch import Tensor

from realize.robot.layout import BASE_XY, UPPER
from realize.controllers.occupancy import grid_from_bounds, occupancy_from_boxes
from realize.controllers.whole_body import WholeBodyFabric
from realize.search.protocol import EvalResult
from realize.realization.actions import TEMPLATES
from realize.realization.actions.base import Template
from realize.realization.config import RealizerSpec, RolloutConfig
from realize.realization.context import StepContext
from realize.realization.failures import Failure
from realize.realization.pruning import EliteBound
from realize.tasks.goals import goal_reached
from realize.realization.result import RolloutResult, TrajectoryRecorder
from realize.realization.tracking import track_region
from realize.scene import BatchedScene
from realize.world.geometry import SceneGeometry
from realize.world.state import SceneState
from realize.tasks.regions import Region
from realize.tasks.spec import TaskSpec, check_fixed_base


class Rollout:
    """One rollout of a batch Z in progress: the per-plan state (N,) and the phases of a step."""

    def __init__(self, realizer: PlanRealizer, Z: Tensor, record: bool, starts: list[SceneState] | None = None,
                 resume: bool = False):
        scene, task = realizer.scene, realizer.task
        self.realizer, self.scene, self.task, self.cfg = realizer, scene, task, realizer.cfg
        self.templates = realizer.templates
        n, dev = scene.n_envs, realizer.device
        self.n_envs, self.device, self.m = n, dev, Z.shape[0]
        if resume:  # an executed world goes on as it is (BatchedScene.resume)
            scene.resume()
        else:
            scene.reset(seed=realizer.seed, state=realizer.start if starts is None else starts)
        self.ctx = StepContext(scene, self.cfg, realizer.fabric, realizer.grid, realizer.occupancy,
                               realizer.occupancy_tight, realizer.geometry)
        self.ctx.base_offset = realizer.base_error
        self.params = {k: v.to(dev, torch.float32) for k, v in realizer.layout.split(Z.to(dev)).items()}
        self.n_actions = task.n_actions
        self.action = torch.zeros(n, dtype=torch.long, device=dev)  # the action each plan is in
        self.running = torch.arange(n, device=dev) < self.m
        self.success = torch.zeros(n, self.n_actions, dtype=torch.bool, device=dev)
        self.fail_code = torch.zeros(n, dtype=torch.long, device=dev)
        self.fail_action = torch.full((n,), -1, dtype=torch.long, device=dev)
        self.distance = torch.zeros(n, device=dev)
        self.steps = torch.zeros(n, dtype=torch.long, device=dev)  # counted control steps (the cost)
        self.step = 0  # control steps simulated
        self.max_steps = self.ctx.steps(self.cfg.max_time_s)
        self.recorder = TrajectoryRecorder(self.cfg.record_every) if record else None
        # psi_g of a plan is read goal_settle_s after its last action (a pushed or dropped object
        # must land first); plans that never finish are read at the end
        self.goal = torch.zeros(n, dtype=torch.bool, device=dev)
        self.goal_read = torch.zeros(n, dtype=torch.bool, device=dev)
        self.goal_dist = torch.zeros(n, device=dev)
        self.settle_left = torch.full((n,), -1, dtype=torch.long, device=dev)
        self.settle_steps = int(round(self.cfg.goal_settle_s / self.ctx.dt)) if task.goal.reads_objects else 0
        # ce.prune: plans that can no longer be among the keep_best cheapest feasible ones stop
        self.elite_bound = None if realizer.keep_best is None else EliteBound(realizer.keep_best)
        self.stopped = torch.zeros(n, dtype=torch.bool, device=dev)

    # ------------------------------------------------------------------ the whole rollout
    def run(self, t0: float) -> RolloutResult:
        """Every phase until each plan finished, failed or hit the horizon (``t0``: wall start)."""
        self.start()
        while self.step < self.max_steps and bool(self.running.any()):
            self.act()
            self.physics(counted=True)
            self.check_faults()
            self.check_actions()
            if self.read_due_goals():
                self.stop_hopeless()  # the bound can only move when a goal was read
        # the last finished plans settle (physics only, no cost); stop_hopeless already stopped those past the bound
        while bool((self.settle_left > 0).any()):
            self.settle()
        self.cut_at_horizon()
        return self.finish(t0)

    # ------------------------------------------------------------------ phases
    def start(self) -> None:
        """Read the reset scene, hold every arm, keep the gripper as the scene starts it (closed
        on a held object of a restored state), begin the first action."""
        ctx = self.ctx
        ctx.read()
        ctx.arm_hold[:] = ctx.q[:, UPPER]
        ctx.grip_cmd[:] = self.scene.gripper_command()
        self.begin_action(0, torch.nonzero(self.running).flatten())

    def _rows_in(self, a: int, mask: Tensor) -> Tensor:
        return torch.nonzero(mask & (self.action == a)).flatten()

    def _padded(self, name: str, rows: Tensor) -> Tensor:
        """Parameter ``name`` of plans ``rows`` (zeros for copies beyond the M samples)."""
        full = torch.zeros(self.n_envs, self.realizer.layout.regions[name].dim, device=self.device)
        full[:self.m] = self.params[name]
        return full[rows]

    def _template(self, a: int) -> Template:
        return self.templates[self.task.plan[a].template]

    def _fail(self, rows: Tensor, code: Tensor | int, action: Tensor | int) -> None:
        self.fail_code[rows] = code
        self.fail_action[rows] = action
        self.running[rows] = False

    def begin_action(self, a: int, rows: Tensor) -> None:
        """Plans ``rows`` enter action ``a``; those that fail at once stop, arm held."""
        spec = self.task.plan[a]
        name = spec.params[0]
        if self.realizer.action_hook is not None:
            self.realizer.action_hook(a, rows)
        obj = -1 if spec.obj is None else self.scene.object_index(spec.obj)
        region = self.realizer.layout.regions[name]
        frame, g = self.task.frame_of(name), self.scene.geometry
        support = g.object_index(frame) if frame in g.object_names else -1  # a movable object, or -1
        params, shift = self._tracked(region, self._padded(name, rows), rows, support)
        code = self._template(a).begin(self.ctx, rows, params, region, obj, shift, support)
        bad = code > 0
        if bad.any():
            r = rows[bad]
            self._fail(r, code[bad], a)
            self.ctx.hold_arm(r)

    def _tracked(self, region: Region, params: Tensor, rows: Tensor, frame: int) -> tuple[Tensor, Tensor | None]:
        """Parameters of ``rows`` resolved against where the movable object ``frame`` (index; -1: none)
        framing their region is seen now (``controller.track_objects``; ``realize.realization.tracking``),
        and that object's shift (len, 3), or None: untracked."""
        if not self.cfg.track_objects or frame < 0:
            return params, None
        seen = self.ctx.objects if self.realizer.seen_objects is None else self.realizer.seen_objects()
        return track_region(region, params, self.scene.geometry.objects[frame], seen[rows, frame, :3].to(self.ctx.objects),
                            self.cfg.track_min_shift)

    def _write_commands(self, asleep: Tensor) -> None:
        scene, ctx = self.scene, self.ctx
        scene.set_base_velocity(ctx.base_cmd)
        scene.set_arm_targets(ctx.arm_cmd, ctx.arm_vel_cmd)
        scene.set_gripper(ctx.grip_cmd, ctx.grip_open)
        if self.cfg.freeze_finished:
            scene.freeze(asleep)

    def act(self) -> None:
        """Controllers of every running plan's current action -> commands -> the scene."""
        ctx = self.ctx
        ctx.begin_step()
        for a in range(self.n_actions):
            rows = self._rows_in(a, self.running)
            if len(rows):
                self._template(a).act(ctx, rows)
        ctx.run_fabric()
        idle = ~self.running
        ctx.base_cmd[idle] = 0.0
        self._write_commands(idle)

    def physics(self, counted: bool) -> None:
        """One control step of physics, then read the scene (``counted``: running plans pay it)."""
        self.scene.step()
        self.step += 1
        if counted:
            self.steps += self.running.long()
        self.ctx.read()
        self.settle_left[self.settle_left > 0] -= 1
        if self.recorder is not None:
            self.recorder.sample(self.step, self.ctx, self.action)

    def check_faults(self) -> None:
        """A diverged plan (or one the fabric flagged invalid) stops; the others go on."""
        ctx, running = self.ctx, self.running
        bad = running & (~torch.isfinite(ctx.q).all(1) | (ctx.qd.abs().max(1).values > self.cfg.diverge_speed)
                         | ctx.fab_invalid)
        if bad.any():
            self.fail_code[bad] = torch.where(ctx.fab_invalid[bad], Failure.CONTROLLER_INVALID, Failure.DIVERGED)
            self.fail_action[bad] = self.action[bad]
            running &= ~bad

    def check_actions(self) -> None:
        """Success / failure of the current actions; succeeded plans begin their next action."""
        ctx = self.ctx
        for a in range(self.n_actions):
            rows = self._rows_in(a, self.running)
            if not len(rows):
                continue
            tpl = self._template(a)
            done, ok, code = tpl.check(ctx, rows)
            failed = done & ~ok
            if failed.any():
                r = rows[failed]
                self.distance[r] = tpl.distance(ctx, rows)[failed]
                self._fail(r, code[failed], a)
                ctx.hold_arm(r)
            if ok.any():
                r = rows[ok]
                self.success[r, a] = True
                self.action[r] = a + 1
                finished = self.action[r] >= self.n_actions
                self.running[r[finished]] = False
                self.settle_left[r[finished]] = self.settle_steps
                nxt = r[~finished]
                if len(nxt) and a + 1 < self.n_actions:
                    self.begin_action(a + 1, nxt)

    def _goal_now(self) -> tuple[Tensor, Tensor]:
        ctx = self.ctx
        return goal_reached(self.task.goal, self.realizer.geometry, self.realizer.layout.regions, ctx.objects[:, :, :3],
                            ctx.object_speed, ctx.base[:, BASE_XY], self.cfg.rest_speed, self.task.frames)

    def read_due_goals(self) -> bool:
        """Read psi_g of the plans whose settling time just ran out; whether there were any."""
        due = (self.settle_left == 0) & ~self.goal_read
        if not due.any():
            return False
        ok, dist = self._goal_now()
        self.goal[due], self.goal_dist[due] = ok[due], dist[due]
        self.goal_read[due] = True
        return True

    def stop_hopeless(self) -> None:
        """``ce.prune``: plans that can no longer be among the ``keep_best`` cheapest feasible
        stop (``realize.realization.pruning``): running ones at or past the bound, held as failed
        plans are, and finished ones still settling past it (their goal is never read)."""
        if self.elite_bound is None:
            return
        bound = self.elite_bound.update(self.goal_read & self.goal & self.success.all(dim=1), self.steps)
        if bound is None:
            return
        cut = self.running & (self.steps >= bound)
        if cut.any():
            self.stopped |= cut
            self._stop_where(cut, Failure.STOPPED)
            self.ctx.hold_arm(torch.nonzero(cut).flatten())
        late = (self.settle_left > 0) & (self.steps > bound)  # a tie (== bound) may still win by row
        if late.any():
            self.stopped |= late
            self.settle_left[late] = -1
            self.goal_read[late] = True  # never read: goal False, the failure says stopped
            self.fail_code[late], self.fail_action[late] = Failure.STOPPED, self.n_actions

    def settle(self) -> None:
        """A physics-only step with every robot idle and held (no cost), then due goals."""
        ctx = self.ctx
        ctx.begin_step()
        ctx.base_cmd.zero_()
        self._write_commands(torch.ones(self.n_envs, dtype=torch.bool, device=self.device))
        self.physics(counted=False)
        if self.read_due_goals():
            self.stop_hopeless()

    def cut_at_horizon(self) -> None:
        """Plans still running at the horizon time out where they are."""
        self._stop_where(self.running.clone(), Failure.TIMEOUT)

    def _stop_where(self, cut: Tensor, code: Failure) -> None:
        """Running plans ``cut`` (N,) stop in their current action with ``code``, and their
        distance to that action's success is read (for ranking infeasible plans)."""
        self.fail_code[cut] = code
        self.fail_action[cut] = self.action[cut]
        self.running &= ~cut
        for a in range(self.n_actions):
            rows = self._rows_in(a, cut)
            if len(rows):
                self.distance[rows] = self._template(a).distance(self.ctx, rows)

    def finish(self, t0: float) -> RolloutResult:
        """Read the goals not read yet, score every plan (eq. (2)), build the result."""
        task, m, A = self.task, self.m, self.n_actions
        unread = ~self.goal_read
        ok, dist = self._goal_now()
        self.goal[unread], self.goal_dist[unread] = ok[unread], dist[unread]
        goal, success = self.goal, self.success
        all_ok = success.all(dim=1)
        feasible = all_ok & goal
        goal_fail = all_ok & ~goal & ~self.stopped  # a stopped plan's goal was never read
        self.fail_code[goal_fail] = Failure.GOAL_NOT_REACHED
        self.fail_action[goal_fail] = A
        self.distance[goal_fail] = self.goal_dist[goal_fail]
        cost = self.steps.to(torch.float32) + float(task.final_cost)
        progress = success.sum(dim=1).to(torch.float32) + goal.to(torch.float32) * all_ok
        failure = []
        codes, acts = self.fail_code.tolist(), self.fail_action.tolist()
        for i in range(m):
            if feasible[i]:
                failure.append("")
            else:
                a = acts[i]
                where = task.plan[a].template if 0 <= a < A else "goal"
                failure.append(f"{a}:{where}:{Failure(codes[i]).label}")
        res = RolloutResult(
            cost=cost[:m].cpu(), feasible=feasible[:m].cpu(), action_success=success[:m].cpu(),
            goal=goal[:m].cpu(), steps=self.steps[:m].cpu(), progress=progress[:m].cpu(),
            distance=self.distance[:m].cpu(), failure=failure, wall_time_s=time.perf_counter() - t0,
            sim_steps=self.step, horizon_cost=float(self.max_steps) + float(task.final_cost),
            stopped=None if self.elite_bound is None else self.stopped[:m].cpu(),
        )
        if self.recorder is not None:
            self.recorder.store(res, m)
        return res


class PlanRealizer:
    """Realizes a task's plan for batches of parameter samples in one batched scene."""

    def __init__(self, task: TaskSpec, scene: BatchedScene, cfg: RolloutConfig | None = None, seed: int = 0,
                 fabric_dtype: torch.dtype = torch.float32, start: SceneState | None = None,
                 geometry: SceneGeometry | None = None, keep_best: int | None = None):
        self.task, self.scene = task, scene
        # ce.prune: a plan stops once it cannot be among the keep_best cheapest feasible (None: never; .pruning)
        self.keep_best = keep_best
        self.start = start  # every rollout starts from this state (None: the task's initial state)
        # hook(a, rows) when plans ``rows`` (copies) are about to begin action a (replay captures states)
        self.action_hook: Callable[[int, Tensor], None] | None = None
        # what an executor's robot believes (None: the scene's exact state): the objects (n_envs, n_objects, >= 3),
        # read as an action aims at a region framed by one; its base's error (n_envs, 3), read every control step
        self.seen_objects: Callable[[], Tensor] | None = None
        self.base_error: Callable[[], Tensor] | None = None
        self.cfg = cfg or RolloutConfig()  # checked when it was built
        self.seed = seed
        self.layout = task.layout
        self.device = scene.device
        # the map the controllers plan in: the scene's own, or what a robot believes of its world
        # (an executor's, where the world changed and the robot has not seen it yet)
        g = self.geometry = scene.geometry if geometry is None else geometry
        self.grid = grid_from_bounds((g.bounds_low[0], g.bounds_low[1], g.bounds_high[0], g.bounds_high[1]),
                                     self.cfg.astar.resolution)
        obs = g.obstacles
        centers = torch.tensor([[b.center[0], b.center[1]] for b in obs], dtype=torch.float32)
        halves = torch.tensor([list(b.footprint_half_size()) for b in obs], dtype=torch.float32)
        yaws = torch.tensor([b.yaw for b in obs], dtype=torch.float32)
        footprint = scene.robot.base.footprint_radius  # the robot spec's, not the world's
        self.occupancy = occupancy_from_boxes(self.grid, centers, halves, yaws,
                                              padding=self.cfg.astar.padding + footprint).to(self.device)
        tight = self.cfg.astar.fallback_padding
        self.occupancy_tight = None if tight is None else occupancy_from_boxes(
            self.grid, centers, halves, yaws, padding=tight + footprint).to(self.device)
        self.fabric = WholeBodyFabric(g, self.cfg.fabric, dt=scene.control_dt, device=self.device,
                                      dtype=fabric_dtype, robot=scene.robot)
        self.templates: dict[str, Template] = {name: cls(scene.n_envs, self.device) for name, cls in TEMPLATES.items()}
        if scene.robot.base.fixed:  # as the run config checks it, for every caller
            check_fixed_base(task.plan, TEMPLATES, scene.robot.name, f"{task.source}:plan")
        self.last: RolloutResult | None = None

    @classmethod
    def from_spec(cls, spec: RealizerSpec, task: TaskSpec | None, scene: BatchedScene,
                  seed: int | None = None) -> PlanRealizer:
        """The realizer of a run spec: its task (or ``task``, e.g. a candidate plan's), its
        controller settings and its seed (or ``seed``), in ``scene``."""
        return cls(spec.task if task is None else task, scene, spec.rollout,
                   seed=spec.seed if seed is None else seed, start=spec.start, keep_best=spec.keep_best)

    def rollout(self, Z: Tensor, record: bool = False, starts: list[SceneState] | None = None,
                capture_end: bool = False, resume: bool = False) -> RolloutResult:
        """Simulate the plan for every row of Z (M, D), M <= the scene's copies, and score it; row i
        starts from ``starts[i]`` (else ``self.start``); ``capture_end``: fill ``end_states``;
        ``resume``: no reset, the scene goes on as it is (``BatchedScene.resume``)."""
        t0 = time.perf_counter()
        n, m = self.scene.n_envs, Z.shape[0]
        if Z.ndim != 2 or Z.shape[1] != self.layout.dim:
            raise ValueError(f"Z must be (M, {self.layout.dim}), got {tuple(Z.shape)}")
        if m > n or (starts is not None and len(starts) != m):
            raise ValueError(f"{m} samples ({n} copies, ce.n_envs), {'no' if starts is None else len(starts)} starts")
        # inference mode: no version counters or autograd bookkeeping on the ~1,700 small ops of
        # a control step; the result is copied out as ordinary tensors (callers may edit them)
        with torch.inference_mode():
            res = Rollout(self, Z, record, starts, resume).run(t0)
            if capture_end:  # finished copies are frozen: the state each feasible plan ended in
                res.end_states = [self.scene.capture_state(i, "stitched segment") if bool(ok) else None
                                  for i, ok in enumerate(res.feasible.tolist())]
        res = res.ordinary()
        self.last = res
        return res

    def evaluate(self, Z: Tensor, record: bool = False) -> EvalResult:
        """Cross-entropy adapter: rollout, keep the full result in ``self.last``."""
        return self.rollout(Z, record=record).to_eval()
