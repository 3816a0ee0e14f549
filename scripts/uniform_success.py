"""How many uniformly sampled realizations of the seed task succeed (CE iteration 0 of the paper).

What it does: composes the app's config (``configs/config.yaml`` with its default groups, the task
read from ``--task-file``, default ``configs/task/pick_place.yaml``) through the same edge the
``realize`` command uses (``realize.spec.run_spec.build_run_spec``), draws ``--n`` parameter vectors
uniformly over the task's regions exactly as the cross-entropy search draws iteration 0 (one CPU
``torch.Generator`` seeded with ``--seed``, the CE dtype), realizes them all at once in one
batched scene (``realize.workers.realizers.open_realization``, as a run does) and prints where they fail: failure reasons, per-action success shares (of all
plans and of the plans that reached the action), and, for grasps, success against the angle
between the base position and the grasp approach around the cube.
It ends with two lines::

    iteration0_success: X     (share of feasible plans, 0..1)
    rollout_wall_s: Y         (seconds spent in the rollout, scene build excluded)

What it doesn't: refit anything (that is ``realize`` / ``realize.search.ce``).

Usage::

    python scripts/uniform_success.py --n 200 --seed 0 [--save out.npz] [key=value ...]

Trailing ``key=value`` arguments are Hydra overrides of the run config (e.g. ``sim=...``,
``controller.manip_timeout_s=20``). The paper reports about 10 % successes at iteration 0.
"""

from __future__ import annotations

import argparse
import math
import os
import sys
import time
from collections import Counter
from pathlib import Path
from typing import Any, Sequence

import numpy as np
import torch

REPO = Path(__file__).resolve().parent.parent
if str(REPO) not in sys.path:  # run from a checkout without installing
    sys.path.insert(0, str(REPO))

from realize.config import ConfigError  # noqa: E402
from realize.paths import CONFIG_DIR  # noqa: E402
from realize.run.assembly import plain_config  # noqa: E402
from realize.workers.realizers import open_realization  # noqa: E402
from realize.spec.run_spec import RunSpec, build_run_spec  # noqa: E402


def load_spec(task_file: str, seed: int, device: str, overrides: Sequence[str] = ()) -> RunSpec:
    """The run spec the ``realize`` app would build for these overrides (Hydra compose API)."""
    from hydra import compose, initialize_config_dir

    with initialize_config_dir(config_dir=str(CONFIG_DIR), version_base="1.3", job_name="uniform_success"):
        cfg = compose(config_name="config",
                      overrides=[f"task_file={task_file}", f"seed={seed}", f"device={device}", *overrides])
    plain = plain_config(cfg)
    plain.pop("hydra", None)
    return build_run_spec(plain)


def grasp_alignment_deg(spec: RunSpec, Z: torch.Tensor) -> torch.Tensor | None:
    """(N,) angle (deg) between the move_to-before-grasp base position and the horizontal grasp
    approach side, both seen from the grasp region's centre: 0 = the gripper comes in from the
    robot's side of the cube, 180 = from the far side. None if the plan has no such pair."""
    plan, parts = spec.task.plan, spec.task.layout.split(Z)
    for i, a in enumerate(plan):
        if a.template == "grasp" and i > 0 and plan[i - 1].template == "move_to":
            region = spec.task.layout.regions[a.params[0]]
            c = torch.tensor(region.center[:2], dtype=Z.dtype)
            base = parts[plan[i - 1].params[0]][:, :2] - c
            side = parts[a.params[0]][:, :2] - c
            cos = (base * side).sum(1) / (base.norm(dim=1) * side.norm(dim=1)).clamp(min=1e-9)
            return torch.rad2deg(torch.arccos(cos.clamp(-1.0, 1.0)))
    return None


def report(spec: RunSpec, Z: torch.Tensor, res: Any) -> list[str]:
    """Human-readable breakdown of one rollout result."""
    n = Z.shape[0]
    lines = [f"plan: {spec.task.describe()}", f"samples: {n}"]
    reasons = Counter(f or "success" for f in res.failure)
    lines.append("outcomes (action index:template:reason):")
    for reason, k in sorted(reasons.items(), key=lambda kv: (-kv[1], kv[0])):
        lines.append(f"  {reason:<34s} {k:5d}  {100.0 * k / n:5.1f} %")
    lines.append("per-action success (share of all plans | of the plans that started the action):")
    ok = res.action_success
    started = torch.ones(n, dtype=torch.bool)
    for i, a in enumerate(spec.task.plan):
        s_all = int(ok[:, i].sum())
        n_start = int(started.sum())
        cond = f"{100.0 * s_all / n_start:5.1f} % of {n_start}" if n_start else "  n/a"
        lines.append(f"  {i}:{str(a):<20s} {100.0 * s_all / n:5.1f} %  | {cond}")
        started = ok[:, i].clone()
    reached_goal = ok.all(dim=1)
    n_goal = int((res.goal & reached_goal).sum())
    lines.append(f"  goal psi_g (after all actions) {n_goal} of {int(reached_goal.sum())}")
    ang = grasp_alignment_deg(spec, Z.double())
    if ang is not None:
        gi = next(i for i, a in enumerate(spec.task.plan) if a.template == "grasp")
        at_grasp = ok[:, gi - 1]
        lines.append("grasp success by approach side (0 deg: from the robot's side of the cube; "
                     "plans that started grasp):")
        for lo in range(0, 180, 45):
            m = at_grasp & (ang >= lo) & ((ang < lo + 45) | (lo == 135))
            k = int(m.sum())
            s = int((m & ok[:, gi]).sum())
            lines.append(f"  {lo:3d}-{lo + 45:3d} deg: {s:4d} of {k:4d}" + (f"  ({100.0 * s / k:5.1f} %)" if k else ""))
    feas = res.feasible
    if bool(feas.any()):
        c = res.cost[feas]
        lines.append(f"cost of feasible plans (control steps): min {c.min().item():.0f}, "
                     f"median {c.median().item():.0f}, max {c.max().item():.0f}")
    return lines


def main(argv: Sequence[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=" ".join(__doc__.split("\n\n")[0].split()),
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--n", type=int, default=200, help="number of uniform samples (parallel plans)")
    ap.add_argument("--seed", type=int, default=0, help="sampler and simulator seed")
    ap.add_argument("--task-file", default="configs/task/pick_place.yaml", help="task YAML (params, plan, goal)")
    ap.add_argument("--device", default="auto", choices=["auto", "cpu", "cuda"], help="simulator backend")
    ap.add_argument("--save", default=None, help="write samples and per-plan results to this .npz")
    ap.add_argument("overrides", nargs="*", help="Hydra overrides of the run config (key=value)")
    args = ap.parse_args(argv)
    if args.n < 1:
        ap.error("--n must be >= 1")

    try:
        spec = load_spec(args.task_file, args.seed, args.device, args.overrides)
    except ConfigError as e:
        print(f"error: {e}", file=sys.stderr)
        return 2

    gen = torch.Generator(device="cpu")
    gen.manual_seed(args.seed)
    Z = spec.task.layout.sample_uniform(args.n, gen, spec.placement.dtype)

    load0 = os.getloadavg()[0]
    t0 = time.perf_counter()
    scene, (realizer,) = open_realization(spec, n_envs=args.n)  # seeded with spec.seed = --seed
    build_s = time.perf_counter() - t0
    t1 = time.perf_counter()
    res = realizer.rollout(Z)
    wall = time.perf_counter() - t1
    load1 = os.getloadavg()[0]

    print(f"task: {spec.task.name} ({spec.task.source}), backend {scene.backend}, device {scene.device}")
    for line in report(spec, Z, res):
        print(line)
    robot_s = float(res.steps.sum()) * scene.control_dt
    print(f"scene build: {build_s:.1f} s; control steps simulated: {res.sim_steps} "
          f"({res.sim_steps * scene.control_dt:.1f} s of sim time); robot-seconds per wall-second: "
          f"{robot_s / max(wall, 1e-9):.1f}")
    print(f"load average (1 min) before / after: {load0:.2f} / {load1:.2f} on {os.cpu_count()} cores")
    if args.save:
        np.savez(args.save, Z=Z.numpy(), columns=np.array(spec.task.layout.column_names), cost=res.cost.numpy(),
                 feasible=res.feasible.numpy(), action_success=res.action_success.numpy(), goal=res.goal.numpy(),
                 steps=res.steps.numpy(), failure=np.array(res.failure))
        print(f"saved: {args.save}")
    scene.close()
    share = float(res.feasible.double().mean())
    print(f"iteration0_success: {share:.3f}")
    print(f"rollout_wall_s: {wall:.1f}")
    return 0 if math.isfinite(share) else 1


if __name__ == "__main__":
    sys.exit(main())
