"""Batched rollout: realize N parameterized plans at once and score them by eq. (2) of the paper.

What it does: for a sample matrix Z (M, D) (M <= the scene's N copies) it resets the batched
scene, runs a per-plan action state machine (each plan is in one action of the task's plan at a
time; a plan whose action fails or times out stops there and is held still), steps physics for
all plans together, and returns a ``RolloutResult``: cost (steps until each action finished +
the final cost), per-action success, goal success psi_g read from the simulator, feasibility,
a progress score and a distance proxy for ranking infeasible plans, and optionally downsampled
trajectories. A goal that reads the cube is read ``goal_settle_s`` after the plan's last action
(physics only, not counted in the cost), so a pushed or dropped cube has landed. Plans that
diverge (NaN or exploding joint speeds) are failed with a reason and do not disturb the others. ``PlanRealizer.evaluate`` adapts this to the cross-entropy optimizer.
What it doesn't: choose parameters (``realize.ce``) or know any backend details
(``realize.scene``).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field, fields
from typing import Any, Mapping, Sequence

import torch
from torch import Tensor

from envs.move_and_push import cube_in_container
from realize.actions import FAIL, FAILURES, TEMPLATES, Template
from realize.controllers.occupancy import grid_from_bounds, occupancy_from_boxes
from realize.controllers.pid import PIDConfig
from realize.controllers.whole_body import FabricState, WholeBodyConfig, WholeBodyFabric
from realize.searcher import EvalResult
from realize.regions import Box
from realize.scene import BatchedScene
from realize.task import TaskSpec


class RolloutConfigError(ValueError):
    """A controller / rollout setting is invalid; the message names the key."""


@dataclass
class AStarConfig:
    """Base path planning (Hydra ``controller.astar``)."""

    resolution: float = 0.05  # m per grid cell
    padding: float = 0.2  # m around every obstacle (paper: 20 cm), on top of the robot radius


@dataclass
class RolloutConfig:
    """Action tolerances, timeouts and controller settings (Hydra ``controller``)."""

    move_tolerance: float = 0.1  # m, move_to success  ||x_base - x_loc|| <= eps
    move_timeout_s: float = 20.0
    reach_tolerance: float = 0.015  # m, ee_in(g_p): the TCP settled this close to the grasp point
    grip_tolerance: float = 0.005  # m, close at once when this close
    settle_s: float = 0.5  # s after the straight move before a settled TCP counts as arrived
    pregrasp_tolerance: float = 0.03  # m, pre-pose reached
    axis_tolerance: float = 0.1  # rad, approach axis alignment at the pre-pose
    grasp_offset: float = 0.0  # m, extra back-off of the TCP target along the approach
    grasp_clearance: float = 0.006  # m, fingertips stay this far above the supporting surface
    place_drop: float = 0.004  # m, the held cube is released this high above its place point
    place_pre_height: float = 0.12  # m, pre-place above a release point (place with a 3-D box region)
    retreat_share: float = 0.6  # retreat done once the TCP is this share of the way back out
    grip_s: float = 0.5  # s to close / open the gripper
    approach_speed: float = 0.15  # m/s of the straight moves in to and out from the object
    rest_speed: float = 0.05  # m/s, the cube counts as resting below this
    manip_timeout_s: float = 15.0
    push_pre_distance: float = 0.15  # m, push: the straight move starts this far before the push point
    push_depth: float = 0.1  # m, push: and ends this far past it
    push_speed: float = 0.15  # m/s of the straight push (faster: the fabric lags behind the sliding goal)
    goal_settle_s: float = 1.5  # s of physics after a plan's last action before a cube goal is read (uncounted)
    max_time_s: float = 120.0  # horizon of a whole plan
    record_every: int = 5  # control steps between recorded trajectory samples
    diverge_speed: float = 50.0  # joint speed that marks a plan as diverged
    base_feedback: float = 3.0  # 1/s, base position feedback onto the fabric's base velocity
    freeze_finished: bool = True  # put robots of finished / failed plans to sleep (saves physics)
    pid: PIDConfig = field(default_factory=PIDConfig)
    astar: AStarConfig = field(default_factory=AStarConfig)
    fabric: WholeBodyConfig = field(default_factory=WholeBodyConfig)

    def validate(self, prefix: str = "controller") -> None:
        for f in fields(self):
            if f.name in ("pid", "astar", "fabric", "freeze_finished"):
                continue
            v = getattr(self, f.name)
            zero_ok = f.name in ("grasp_offset", "grasp_clearance", "place_drop", "goal_settle_s", "push_depth")
            if not (isinstance(v, (int, float)) and math.isfinite(v) and (v >= 0 if zero_ok else v > 0)):
                raise RolloutConfigError(
                    f"{prefix}.{f.name} = {v!r} is invalid: must be a finite number {'>= 0' if zero_ok else '> 0'}")
        for f in fields(self.astar):
            v = getattr(self.astar, f.name)
            lo_ok = v >= 0 if f.name == "padding" else v > 0
            if not (isinstance(v, (int, float)) and math.isfinite(v) and lo_ok):
                raise RolloutConfigError(f"{prefix}.astar.{f.name} = {v!r} is invalid: must be a finite number "
                                         f"{'>= 0' if f.name == 'padding' else '> 0'}")
        self.fabric.validate(f"{prefix}.fabric")

    @classmethod
    def from_dict(cls, d: Mapping[str, Any] | None, prefix: str = "controller") -> "RolloutConfig":
        d = dict(d or {})
        known = {f.name for f in fields(cls)}
        bad = set(d) - known
        if bad:
            raise RolloutConfigError(f"{prefix}: unknown keys {sorted(bad)}; allowed: {sorted(known)}")
        kw: dict[str, Any] = {}
        for k, v in d.items():
            if k == "fabric":
                kw[k] = WholeBodyConfig.from_dict(v, f"{prefix}.fabric")
            elif k in ("pid", "astar"):
                sub = PIDConfig if k == "pid" else AStarConfig
                sk = {f.name for f in fields(sub)}
                sbad = set(v or {}) - sk
                if sbad:
                    raise RolloutConfigError(f"{prefix}.{k}: unknown keys {sorted(sbad)}; allowed: {sorted(sk)}")
                try:
                    kw[k] = sub(**dict(v or {}))
                except ValueError as e:  # PIDConfig validates itself and names the field
                    raise RolloutConfigError(f"{prefix}.{k}: {e}") from None
            else:
                kw[k] = v
        cfg = cls(**kw)
        cfg.validate(prefix)
        return cfg


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
    traj_cube: Tensor | None = None  # (N, T, 3)
    wall_time_s: float = 0.0
    sim_steps: int = 0
    horizon_cost: float = math.nan  # cost of a plan cut by the horizon: max steps + final cost

    def to_eval(self) -> EvalResult:
        return EvalResult(cost=self.cost.double(), feasible=self.feasible, progress=self.progress.double(),
                          distance=self.distance.double(),
                          failure_cost=self.horizon_cost if math.isfinite(self.horizon_cost) else None)


class StepContext:
    """Per-step view shared by the templates: measured state and the command buffers."""

    def __init__(self, scene: BatchedScene, cfg: RolloutConfig, fabric: WholeBodyFabric, grid, occupancy):
        self.scene, self.cfg, self.fabric = scene, cfg, fabric
        self.grid, self.occupancy = grid, occupancy
        self.n, self.device = scene.n_envs, scene.device
        self.dt = scene.control_dt
        n, dev = self.n, self.device
        self.base_cmd = torch.zeros(n, 3, device=dev)
        self.arm_cmd = torch.zeros(n, 8, device=dev)
        self.arm_vel_cmd = torch.zeros(n, 8, device=dev)
        self.grip_cmd = torch.zeros(n, dtype=torch.bool, device=dev)
        self.arm_hold = torch.zeros(n, 8, device=dev)
        self.fab_state = FabricState(torch.zeros(n, 11, dtype=fabric.dtype), torch.zeros(n, 11, dtype=fabric.dtype))
        self.fab_rows: list[Tensor] = []
        self.fab_goals: list[Tensor] = []
        self.fab_approach: list[Tensor] = []
        self.fab_closing: list[Tensor] = []
        self.fab_invalid = torch.zeros(n, dtype=torch.bool, device=dev)
        self._holds: Tensor | None = None

    def steps(self, seconds: float) -> int:
        return max(1, int(round(seconds / self.dt)))

    def read(self) -> None:
        s = self.scene
        self.q = s.whole_body_q()
        self.qd = s.whole_body_qd()
        self.base = self.q[:, :3]
        tcp, approach, closing = self.fabric.kin.tcp_and_axes(self.q.to(self.fabric.dtype))
        self.tcp, self.approach, self.closing = tcp.float(), approach.float(), closing.float()
        cube = s.cube_pose()
        self.cube = cube
        self.cube_speed = s.cube_velocity()[:, :3].norm(dim=1)
        self._holds = None

    def holds(self, rows: Tensor) -> Tensor:
        if self._holds is None:
            self._holds = self.scene.holds_cube()
        return self._holds[rows]

    def hold_arm(self, rows: Tensor) -> None:
        self.arm_hold[rows] = self.q[rows, 3:]

    def start_fabric(self, rows: Tensor) -> None:
        st = self.fabric.start(self.q[rows], torch.zeros_like(self.qd[rows]))
        self.fab_state.q[rows] = st.q
        self.fab_state.qd[rows] = st.qd

    def fabric_goal(self, rows: Tensor, position: Tensor, approach: Tensor, closing: Tensor) -> None:
        self.fab_rows.append(rows)
        self.fab_goals.append(position)
        self.fab_approach.append(approach)
        self.fab_closing.append(closing)

    def begin_step(self) -> None:
        self.base_cmd.zero_()
        self.arm_cmd.copy_(self.arm_hold)
        self.arm_vel_cmd.zero_()
        self.fab_rows, self.fab_goals, self.fab_approach, self.fab_closing = [], [], [], []
        self.fab_invalid.zero_()

    def run_fabric(self) -> None:
        """One batched fabric step for every plan that asked for it this step."""
        if not self.fab_rows:
            return
        rows = torch.cat(self.fab_rows)
        dt = self.fabric.dtype
        goal = self.fabric.goal_points(torch.cat(self.fab_goals).to(dt), torch.cat(self.fab_approach).to(dt),
                                       torch.cat(self.fab_closing).to(dt))
        st = FabricState(self.fab_state.q[rows], self.fab_state.qd[rows])
        new, valid = self.fabric.step(st, self.q[rows], goal)
        self.fab_state.q[rows] = new.q
        self.fab_state.qd[rows] = new.qd
        # the base is velocity-driven: feed back its position error to the fabric's reference
        base_err = (new.q[:, :3] - self.q[rows, :3].to(new.q)).float()
        self.base_cmd[rows] = new.qd[:, :3].float() + self.cfg.base_feedback * base_err
        self.arm_cmd[rows] = new.q[:, 3:].float()
        self.arm_vel_cmd[rows] = new.qd[:, 3:].float()
        self.arm_hold[rows] = new.q[:, 3:].float()
        self.fab_invalid[rows] = ~valid


class PlanRealizer:
    """Realizes a task's plan for batches of parameter samples in one batched scene."""

    def __init__(self, task: TaskSpec, scene: BatchedScene, cfg: RolloutConfig | None = None, seed: int = 0,
                 fabric_dtype: torch.dtype = torch.float32):
        self.task, self.scene = task, scene
        self.cfg = cfg or RolloutConfig()
        self.cfg.validate()
        self.seed = seed
        self.layout = task.layout
        self.device = scene.device
        g = scene.geometry
        self.grid = grid_from_bounds((g.bounds_low[0], g.bounds_low[1], g.bounds_high[0], g.bounds_high[1]),
                                     self.cfg.astar.resolution)
        obs = g.obstacles
        centers = torch.tensor([[b.center[0], b.center[1]] for b in obs], dtype=torch.float32)
        halves = torch.tensor([list(b.footprint_half_size()) for b in obs], dtype=torch.float32)
        yaws = torch.tensor([b.yaw for b in obs], dtype=torch.float32)
        self.occupancy = occupancy_from_boxes(self.grid, centers, halves, yaws,
                                              padding=self.cfg.astar.padding + g.robot_radius).to(self.device)
        self.fabric = WholeBodyFabric(g, self.cfg.fabric, dt=scene.control_dt, device=self.device,
                                      dtype=fabric_dtype)
        self.templates: dict[str, Template] = {name: cls(scene.n_envs, self.device) for name, cls in TEMPLATES.items()}
        self.last: RolloutResult | None = None

    # ------------------------------------------------------------------ goal predicate
    def goal_reached(self, ctx: StepContext) -> tuple[Tensor, Tensor]:
        """psi_g per plan, and how far (m) each plan is from it: the cube's distance to the goal
        table's top (or the container's inside) plus the base's distance to its goal rectangle.
        The distance is the fallback's distance-to-success for plans whose actions all succeeded
        but whose goal did not hold (e.g. the cube was let go beside the table)."""
        g = self.scene.geometry
        goal = self.task.goal
        ok = torch.ones(self.scene.n_envs, dtype=torch.bool, device=self.device)
        dist = torch.zeros(self.scene.n_envs, device=self.device)
        p = ctx.cube[:, :3]

        def outside(center: Sequence[float], half: Sequence[float]) -> Tensor:
            c = torch.tensor(center[:2], dtype=p.dtype, device=p.device)
            h = torch.tensor(half[:2], dtype=p.dtype, device=p.device)
            return ((p[:, :2] - c).abs() - h).clamp(min=0.0).norm(dim=1)

        if goal.cube_on is not None:
            t = g.table(goal.cube_on)
            top = 2 * t.half_size[2] + g.cube_half_size
            ok &= ((p[:, 0] - t.center[0]).abs() <= t.half_size[0]) & ((p[:, 1] - t.center[1]).abs() <= t.half_size[1])
            ok &= (p[:, 2] - top).abs() <= 0.02
            ok &= ctx.cube_speed <= self.cfg.rest_speed
            dz = ((p[:, 2] - top).abs() - 0.02).clamp(min=0.0)
            dist += torch.sqrt(outside(t.center, t.half_size) ** 2 + dz ** 2)
        if goal.cube_in_box is not None:
            ok &= cube_in_container(p, ctx.cube_speed, g, goal.cube_in_box, self.cfg.rest_speed)
            box, w = g.container(goal.cube_in_box), g.container_wall
            dz = (p[:, 2] - 2 * box.half_size[2]).clamp(min=0.0)
            dist += torch.sqrt(outside(box.center, (box.half_size[0] - w, box.half_size[1] - w)) ** 2 + dz ** 2)
        if goal.base_in is not None:
            region = self.layout.regions[goal.base_in]
            assert isinstance(region, Box)
            base = ctx.base[:, :2].double()
            ok &= region.contains(base).to(self.device)
            dist += (region.project(base) - base).norm(dim=1).to(dist)
        return ok, dist

    # ------------------------------------------------------------------ rollout
    def rollout(self, Z: Tensor, record: bool = False) -> RolloutResult:
        """Simulate the plan for every row of Z (M, D), M <= scene.n_envs, and score it."""
        t0 = time.perf_counter()
        scene, cfg, task = self.scene, self.cfg, self.task
        n, dev = scene.n_envs, self.device
        m = Z.shape[0]
        if Z.ndim != 2 or Z.shape[1] != self.layout.dim:
            raise ValueError(f"Z must be (M, {self.layout.dim}), got {tuple(Z.shape)}")
        if m > n:
            raise ValueError(f"{m} samples but the scene has only {n} copies (ce.n_envs)")
        scene.reset(seed=self.seed)
        ctx = StepContext(scene, cfg, self.fabric, self.grid, self.occupancy)
        params = {k: v.to(dev, torch.float32) for k, v in self.layout.split(Z.to(dev)).items()}
        A = task.n_actions
        action = torch.zeros(n, dtype=torch.long, device=dev)
        running = torch.arange(n, device=dev) < m
        success = torch.zeros(n, A, dtype=torch.bool, device=dev)
        fail_code = torch.zeros(n, dtype=torch.long, device=dev)
        fail_action = torch.full((n,), -1, dtype=torch.long, device=dev)
        distance = torch.zeros(n, device=dev)
        steps = torch.zeros(n, dtype=torch.long, device=dev)
        max_steps = ctx.steps(cfg.max_time_s)
        rec_t, rec_base, rec_ee, rec_cube = [], [], [], []

        def padded(name: str, rows: Tensor) -> Tensor:
            full = torch.zeros(n, self.layout.regions[name].dim, device=dev)
            full[:m] = params[name]
            return full[rows]

        def begin(a: int, rows: Tensor) -> None:
            spec = task.plan[a]
            tpl = self.templates[spec.template]
            name = spec.params[0]
            ctx.beginning = rows
            code = tpl.begin(ctx, rows, padded(name, rows), self.layout.regions[name])
            bad = code > 0
            if bad.any():
                r = rows[bad]
                fail_code[r] = code[bad]
                fail_action[r] = a
                running[r] = False
                ctx.hold_arm(r)

        # psi_g of a plan is read goal_settle_s after its last action (a pushed or dropped cube
        # must land first); plans that never finish are read at the end
        goal = torch.zeros(n, dtype=torch.bool, device=dev)
        goal_read = torch.zeros(n, dtype=torch.bool, device=dev)
        goal_dist = torch.zeros(n, device=dev)
        settle_left = torch.full((n,), -1, dtype=torch.long, device=dev)
        reads_cube = task.goal.cube_on is not None or task.goal.cube_in_box is not None
        settle_steps = int(round(cfg.goal_settle_s / ctx.dt)) if reads_cube else 0

        def settle_tick() -> None:
            settle_left[settle_left > 0] -= 1

        def read_due_goals() -> None:
            due = (settle_left == 0) & ~goal_read
            if due.any():
                ok, dist = self.goal_reached(ctx)
                goal[due], goal_dist[due] = ok[due], dist[due]
                goal_read[due] = True

        def record_sample() -> None:
            if record and step % cfg.record_every == 0:
                rec_t.append(step * ctx.dt)
                rec_base.append(ctx.base[:, :2].clone())
                rec_ee.append(ctx.tcp.clone())
                rec_cube.append(ctx.cube[:, :3].clone())

        ctx.read()
        ctx.arm_hold[:] = ctx.q[:, 3:]
        begin(0, torch.nonzero(running).flatten())
        step = 0
        while step < max_steps and bool(running.any()):
            # ---- controllers
            ctx.begin_step()
            for a, spec in enumerate(task.plan):
                rows = torch.nonzero(running & (action == a)).flatten()
                if len(rows):
                    self.templates[spec.template].act(ctx, rows)
            ctx.run_fabric()
            idle = ~running
            ctx.base_cmd[idle] = 0.0
            scene.set_base_velocity(ctx.base_cmd)
            scene.set_arm_targets(ctx.arm_cmd, ctx.arm_vel_cmd)
            scene.set_gripper(ctx.grip_cmd)
            if cfg.freeze_finished:
                scene.freeze(~running)
            # ---- physics
            scene.step()
            step += 1
            steps += running.long()
            ctx.read()
            settle_tick()
            record_sample()
            # ---- faults: a diverged plan stops, the others go on
            bad = running & (~torch.isfinite(ctx.q).all(1) | (ctx.qd.abs().max(1).values > cfg.diverge_speed)
                             | ctx.fab_invalid)
            if bad.any():
                fail_code[bad] = torch.where(ctx.fab_invalid[bad], FAIL["controller_invalid"], FAIL["diverged"])
                fail_action[bad] = action[bad]
                running &= ~bad
            # ---- success / failure of the current actions, then start the next ones
            for a, spec in enumerate(task.plan):
                rows = torch.nonzero(running & (action == a)).flatten()
                if not len(rows):
                    continue
                tpl = self.templates[spec.template]
                done, ok, code = tpl.check(ctx, rows)
                failed = done & ~ok
                if failed.any():
                    r = rows[failed]
                    fail_code[r] = code[failed]
                    fail_action[r] = a
                    distance[r] = tpl.distance(ctx, rows)[failed]
                    running[r] = False
                    ctx.hold_arm(r)
                if ok.any():
                    r = rows[ok]
                    success[r, a] = True
                    action[r] = a + 1
                    finished = action[r] >= A
                    running[r[finished]] = False
                    settle_left[r[finished]] = settle_steps
                    nxt = r[~finished]
                    if len(nxt) and a + 1 < A:
                        begin(a + 1, nxt)
            read_due_goals()
        # the last finished plans settle with every robot asleep (physics only, no cost)
        while bool((settle_left > 0).any()):
            ctx.begin_step()  # every robot idle: held as in the loop above
            ctx.base_cmd.zero_()
            scene.set_base_velocity(ctx.base_cmd)
            scene.set_arm_targets(ctx.arm_cmd, ctx.arm_vel_cmd)
            scene.set_gripper(ctx.grip_cmd)
            if cfg.freeze_finished:
                scene.freeze(torch.ones(n, dtype=torch.bool, device=dev))
            scene.step()
            step += 1
            ctx.read()
            settle_tick()
            record_sample()
            read_due_goals()
        # plans cut by the horizon
        cut = running.clone()
        if cut.any():
            fail_code[cut] = FAIL["timeout"]
            fail_action[cut] = action[cut]
            for a, spec in enumerate(task.plan):
                rows = torch.nonzero(cut & (action == a)).flatten()
                if len(rows):
                    distance[rows] = self.templates[spec.template].distance(ctx, rows)
        unread = ~goal_read
        ok, dist = self.goal_reached(ctx)
        goal[unread], goal_dist[unread] = ok[unread], dist[unread]
        all_ok = success.all(dim=1)
        feasible = all_ok & goal
        goal_fail = all_ok & ~goal
        fail_code[goal_fail] = FAIL["goal_not_reached"]
        fail_action[goal_fail] = A
        distance[goal_fail] = goal_dist[goal_fail]
        cost = steps.to(torch.float32) + float(task.final_cost)
        progress = success.sum(dim=1).to(torch.float32) + goal.to(torch.float32) * all_ok
        failure = []
        codes, acts = fail_code.tolist(), fail_action.tolist()
        for i in range(m):
            if feasible[i]:
                failure.append("")
            else:
                a = acts[i]
                where = task.plan[a].template if 0 <= a < A else "goal"
                failure.append(f"{a}:{where}:{FAILURES[codes[i]]}")
        res = RolloutResult(
            cost=cost[:m].cpu(), feasible=feasible[:m].cpu(), action_success=success[:m].cpu(),
            goal=goal[:m].cpu(), steps=steps[:m].cpu(), progress=progress[:m].cpu(),
            distance=distance[:m].cpu(), failure=failure, wall_time_s=time.perf_counter() - t0, sim_steps=step,
            horizon_cost=float(max_steps) + float(task.final_cost),
        )
        if record and rec_t:
            res.traj_t = torch.tensor(rec_t)
            res.traj_base = torch.stack(rec_base, dim=1)[:m].cpu()
            res.traj_ee = torch.stack(rec_ee, dim=1)[:m].cpu()
            res.traj_cube = torch.stack(rec_cube, dim=1)[:m].cpu()
        self.last = res
        return res

    def evaluate(self, Z: Tensor, record: bool = False) -> EvalResult:
        """Cross-entropy adapter: rollout, keep the full result in ``self.last``."""
        return self.rollout(Z, record=record).to_eval()
