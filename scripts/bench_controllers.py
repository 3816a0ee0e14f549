"""Benchmark: controller time per control step (CPU), and the controllers' share of a rollout.

Part 1, per control step for N = 200 and N = 2000 plans (no simulator; random states of the
seed scene):
  * whole-body fabric: one ``WholeBodyFabric.step`` (float32, the dtype ``PlanRealizer`` uses;
    float64 too for reference);
  * A* + waypoints: ``astar_world`` + ``path_to_waypoints`` from the start pose to N points of
    the seed task's Table1 annulus (what ``MoveTo.begin`` runs once per move), amortised over
    the control steps the move takes at least (A* path length / max base speed / control dt);
  * PID: one ``pid_step`` of the waypoint tracker.
Part 2, N = 200: a real short rollout of the seed task (``PlanRealizer.rollout`` on the
``BatchedScene``, plans cut at ``--horizon`` seconds of sim time), with ``time.perf_counter``
wrapped around the controller calls (template ``begin`` / ``act``, where A* and PID run, and
``StepContext.run_fabric``) and around ``scene.step()`` (physics, including the write of the
drive targets). The rest of the loop (state reads, success checks, bookkeeping) is reported
as "other".

torch runs single-threaded, as it does beside the PhysX workers in the rollout
(``sim.torch_threads_cpu``). Timings on a shared machine are noisy.

Usage: python scripts/bench_controllers.py [--quick] [--horizon S]
Last line: ``controller_share: X`` = controller time / (controller + physics time) at N = 200.
"""

from __future__ import annotations

import argparse
import math
import time
from collections import defaultdict
from pathlib import Path
from typing import Any, Callable

import torch
import yaml

from realize.world.geometry import GeometryCfg, build_geometry
from realize.robot.spec import DEFAULT_ROBOT, load_robot_spec
from realize.controllers.astar import astar_world
from realize.controllers.occupancy import grid_from_bounds, occupancy_from_boxes
from realize.controllers.pid import pid_init, pid_step
from realize.controllers.waypoints import path_to_waypoints
from realize.controllers.whole_body import WholeBodyFabric
from realize.robot.spec import load_robot_spec
from realize.realization.actions import TEMPLATES
from realize.realization.config import RolloutConfig
from realize.realization.context import StepContext
from realize.realization.rollout import PlanRealizer
from realize.scene import BatchedScene, SimSettings
from realize.tasks.spec import task_from_dict

TASK_FILE = Path(__file__).resolve().parents[1] / "configs" / "task" / "pick_place.yaml"


def _load_task(geometry):
    return task_from_dict(yaml.safe_load(TASK_FILE.read_text()), geometry, TEMPLATES, source=TASK_FILE.name)


def _timeit(fn: Callable[[], Any], reps: int, warmup: bool = True) -> tuple[float, Any]:
    """Mean seconds per call over ``reps`` calls (after one warm-up call), and the last result."""
    out = fn() if warmup else None
    t0 = time.perf_counter()
    for _ in range(reps):
        out = fn()
    return (time.perf_counter() - t0) / reps, out


# ---------------------------------------------------------------------------------- part 1


def bench_fabric(n: int, reps: int, dtype: torch.dtype, cfg: RolloutConfig, dt: float) -> float:
    geometry = build_geometry(GeometryCfg())
    fab = WholeBodyFabric(geometry, cfg.fabric, dt=dt, dtype=dtype)
    g = torch.Generator().manual_seed(0)
    robot = load_robot_spec("fetch_omni")
    DOF = robot.n_dof
    q = torch.tensor(robot.rest_q(), dtype=dtype).expand(n, -1).clone()
    q = q + 0.1 * torch.randn(n, DOF, generator=g).to(dtype)
    q[:, 0] = 0.9 + 0.3 * torch.rand(n, generator=g).to(dtype)
    q[:, 1] = 1.2 + 0.3 * (2 * torch.rand(n, generator=g).to(dtype) - 1)
    q[:, 2] = math.pi
    qd = 0.3 * torch.randn(n, DOF, generator=g).to(dtype)
    pos = torch.tensor([0.0, 1.2, 0.82], dtype=dtype).expand(n, 3)
    goal = fab.goal_points(pos, torch.tensor([0.0, 0.0, -1.0], dtype=dtype).expand(n, 3),
                           torch.tensor([0.0, 1.0, 0.0], dtype=dtype).expand(n, 3))
    state = fab.start(q, qd)
    return _timeit(lambda: fab.step(state, q, goal), reps)[0]


def bench_astar_pid(n: int, reps: int, cfg: RolloutConfig, dt: float) -> tuple[float, float, float]:
    """(A* + waypoints per call, the same amortised per control step, PID per step), seconds."""
    geometry = build_geometry(GeometryCfg())
    grid = grid_from_bounds((geometry.bounds_low[0], geometry.bounds_low[1], geometry.bounds_high[0],
                             geometry.bounds_high[1]), cfg.astar.resolution)
    obs = geometry.obstacles
    occ = occupancy_from_boxes(
        grid, torch.tensor([b.center[:2] for b in obs]), torch.tensor([b.footprint_half_size() for b in obs]),
        torch.tensor([b.yaw for b in obs]), padding=cfg.astar.padding + load_robot_spec(DEFAULT_ROBOT).base.footprint_radius)
    task = _load_task(geometry)
    g = torch.Generator().manual_seed(0)
    goal = task.layout.regions["Table1"].sample_uniform(n, g, torch.float32)
    start = torch.tensor(geometry.robot_start, dtype=torch.float32).expand(n, 3).clone()

    def plan():
        res = astar_world(occ, grid, start[:, :2], goal)
        return res, path_to_waypoints(res, grid, occupied=occ, start_xy=start[:, :2], goal_xy=goal)

    t_plan, (res, wps) = _timeit(plan, reps, warmup=False)  # no warm-up: one call takes seconds at N = 2000
    length_m = res.cost_m(grid)
    steps = (length_m[res.found] / cfg.pid.max_lin_speed / dt).mean().clamp(min=1.0)
    state = pid_init(cfg.pid, start, wps.points, wps.lengths)
    pose = start.clone()
    pose[:, :2] += 0.05
    t_pid = _timeit(lambda: pid_step(cfg.pid, state, pose, wps.points, wps.lengths, dt), reps * 5)[0]
    return t_plan, t_plan / float(steps), t_pid


# ---------------------------------------------------------------------------------- part 2


class _Timers:
    """Accumulates perf_counter time per label around wrapped callables."""

    def __init__(self) -> None:
        self.total: dict[str, float] = defaultdict(float)

    def wrap(self, label: str, fn: Callable) -> Callable:
        def timed(*args, **kwargs):
            t0 = time.perf_counter()
            try:
                return fn(*args, **kwargs)
            finally:
                self.total[label] += time.perf_counter() - t0

        return timed


def bench_rollout(n: int, horizon_s: float, cfg: RolloutConfig) -> dict[str, float]:
    t0 = time.perf_counter()
    scene = BatchedScene(n, sim=SimSettings(backend="cpu"))
    build = time.perf_counter() - t0
    try:
        task = _load_task(scene.geometry)
        cfg.max_time_s = horizon_s
        realizer = PlanRealizer(task, scene, cfg, seed=0)
        timers = _Timers()
        # controllers: every template's begin (A* in move_to) and act (PID, fabric goals), and
        # the batched fabric step; physics: scene.step (target writes + PhysX substeps)
        for name, tpl in realizer.templates.items():
            tpl.begin = timers.wrap(f"ctrl:{name}.begin", tpl.begin)
            tpl.act = timers.wrap(f"ctrl:{name}.act", tpl.act)
        original_run_fabric = StepContext.run_fabric
        StepContext.run_fabric = timers.wrap("ctrl:fabric", original_run_fabric)
        scene.step = timers.wrap("physics:scene.step", scene.step)
        scene._apply_targets = timers.wrap("physics:targets", scene._apply_targets)
        try:
            Z = task.layout.sample_uniform(n, torch.Generator().manual_seed(0))
            res = realizer.rollout(Z)
        finally:
            StepContext.run_fabric = original_run_fabric
        out = dict(timers.total)
        out["wall"] = res.wall_time_s
        out["steps"] = float(res.sim_steps)
        out["build"] = build
        out["progress"] = float(res.progress.mean())
        return out
    finally:
        scene.close()


def main() -> None:
    ap = argparse.ArgumentParser(description=" ".join(__doc__.split("\n\n")[0].split()))
    ap.add_argument("--quick", action="store_true", help="fewer repetitions and a shorter rollout")
    ap.add_argument("--horizon", type=float, default=None, help="sim seconds of the N=200 rollout")
    ap.add_argument("--sizes", type=int, nargs="+", default=[200, 2000])
    args = ap.parse_args()
    horizon = args.horizon or (12.0 if args.quick else 30.0)
    reps = 3 if args.quick else 10
    sim = SimSettings()
    if sim.torch_threads_cpu is not None:
        torch.set_num_threads(sim.torch_threads_cpu)
    cfg = RolloutConfig()
    dt = 1.0 / sim.control_freq
    print(f"torch threads: {torch.get_num_threads()}, control dt {dt * 1000:.0f} ms (times per control step)")
    for n in args.sizes:
        f32 = bench_fabric(n, reps, torch.float32, cfg, dt)
        f64 = bench_fabric(n, max(1, reps // 2), torch.float64, cfg, dt)
        plan, plan_amortised, pid = bench_astar_pid(n, 1 if args.quick else 3, cfg, dt)
        print(f"N={n:5d}: fabric step {f32 * 1e3:8.2f} ms (float64 {f64 * 1e3:8.2f} ms) | "
              f"A*+waypoints {plan * 1e3:8.1f} ms per plan call = {plan_amortised * 1e3:6.2f} ms per step amortised | "
              f"PID step {pid * 1e3:6.2f} ms")

    n = 200
    t = bench_rollout(n, horizon, RolloutConfig())
    ctrl = sum(v for k, v in t.items() if k.startswith("ctrl:"))
    phys = t["physics:scene.step"]
    steps = max(t["steps"], 1.0)
    other = t["wall"] - ctrl - phys
    print(f"rollout N={n} (seed task, {t['steps']:.0f} control steps = {t['steps'] * dt:.1f} s sim, "
          f"mean actions done {t['progress']:.2f}; scene build {t['build']:.1f} s): wall {t['wall']:.1f} s")
    for k in sorted(t):
        if k.startswith(("ctrl:", "physics:")):
            print(f"  {k:28s} {t[k]:8.2f} s  {t[k] / steps * 1e3:8.2f} ms/step")
    print(f"  controllers {ctrl / steps * 1e3:.2f} ms/step, physics {phys / steps * 1e3:.2f} ms/step, "
          f"other (reads, checks, bookkeeping) {other / steps * 1e3:.2f} ms/step")
    print(f"controller_share: {ctrl / (ctrl + phys):.3f}")


if __name__ == "__main__":
    main()
