"""Benchmark: simulated robot-seconds per wall-second, batched scene vs. naive per-plan envs.

Ours: ``realize.scene.BatchedScene`` with N copies (N = 1, 50, 200), stepped together.
Naive baseline (same run, same machine): one ManiSkill env (N = 1) per plan, stepped with
``env.step``, the plans run one after another; its throughput does not depend on N, so it is
measured on a few plans and reported per plan.
Both drive the same scripted motion: the base sweeps a slow figure-eight, the arm swings.

Usage: python scripts/bench_sim.py [--quick] [--seconds S]
Last line: ``sim_speedup_vs_naive: X`` (X at the largest N).
"""

from __future__ import annotations

import argparse
import math
import time

import gymnasium as gym
import numpy as np
import torch

import envs  # noqa: F401
from realize.robot.spec import load_robot_spec
from realize.scene import BatchedScene, SimSettings


def scripted_targets(t: float, n: int, rest_arm: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Base velocity (n, 3) and torso+arm targets (n, 8) at time t; phase differs per copy."""
    phase = torch.linspace(0, 1, n)
    w = 2 * math.pi * 0.25
    v = torch.stack(
        [0.4 * torch.cos(w * t + phase), 0.3 * torch.sin(2 * w * t + phase), 0.3 * torch.sin(w * t + phase)], dim=1
    )
    arm = rest_arm.repeat(n, 1).clone()
    arm[:, 1] += 0.4 * torch.sin(w * t + phase)
    arm[:, 3] += 0.3 * torch.sin(w * t + 2 * phase)
    return v, arm


def bench_batched(n: int, seconds: float, sim: SimSettings) -> tuple[float, float]:
    t0 = time.perf_counter()
    scene = BatchedScene(n, sim=sim)
    build = time.perf_counter() - t0
    scene.reset()
    rest_arm = scene.whole_body_q()[0, 3:]
    steps = int(seconds * sim.control_freq)
    t0 = time.perf_counter()
    for k in range(steps):
        v, arm = scripted_targets(k * scene.control_dt, n, rest_arm)
        scene.set_base_velocity(v)
        scene.set_arm_targets(arm)
        scene.step()
        scene.whole_body_q()  # the controllers read state every step
    wall = time.perf_counter() - t0
    scene.close()
    return n * steps * scene.control_dt / wall, build


def bench_naive(plans: int, seconds: float, sim: SimSettings) -> float:
    """One env per plan, env.step, one after another; returns robot-seconds per wall-second."""
    env = gym.make(
        "RealizePickPlace-v1", obs_mode="state", sim_backend="physx_cpu", sim_freq=sim.sim_freq,
        control_freq=sim.control_freq, solver_position_iterations=sim.solver_position_iterations,
        solver_velocity_iterations=sim.solver_velocity_iterations, lean_robot=sim.lean_robot,
        robot_solver_position_iterations=sim.solver_position_iterations_robot,
    )  # the same robot model and solver settings as the batched scene
    robot = load_robot_spec("fetch_omni")
    rest_arm = torch.tensor(robot.rest_q()[3:])
    steps = int(seconds * sim.control_freq)
    t0 = time.perf_counter()
    for p in range(plans):
        env.reset(seed=p)
        for k in range(steps):
            v, arm = scripted_targets(k / sim.control_freq, 1, rest_arm)
            # action layout of the fetch_omni controller (envs.robot_agent): torso(1), arm(7), gripper(1),
            # held(2: head pan, head tilt), base(3)
            action = np.concatenate([arm[0].numpy(), [robot.gripper.open], [0.0, 0.0], v[0].numpy()])
            env.step(action)
    wall = time.perf_counter() - t0
    env.close()
    return plans * steps / sim.control_freq / wall


def main() -> None:
    ap = argparse.ArgumentParser(description=" ".join(__doc__.split("\n\n")[0].split()))
    ap.add_argument("--quick", action="store_true", help="short horizons (whole run under a minute)")
    ap.add_argument("--seconds", type=float, default=None, help="robot seconds simulated per plan")
    ap.add_argument("--sizes", type=int, nargs="+", default=[1, 50, 200])
    args = ap.parse_args()
    seconds = args.seconds or (1.0 if args.quick else 5.0)
    sim = SimSettings()
    naive = bench_naive(plans=2 if args.quick else 5, seconds=seconds, sim=sim)
    print(f"naive (1 env per plan, env.step, sequential): {naive:8.2f} robot-s / wall-s")
    ratio = 0.0
    for n in args.sizes:
        rate, build = bench_batched(n, seconds, sim)
        ratio = rate / naive
        print(f"batched N={n:5d}: {rate:8.2f} robot-s / wall-s  (build {build:5.1f} s)  speedup {ratio:6.2f}x")
    print(f"sim_speedup_vs_naive: {ratio:.2f}")


if __name__ == "__main__":
    main()
