"""Benchmark: where a late-iteration rollout of the seed task spends its wall time.

Rolls out a fixed, deterministic batch of 200 plans: the samples a seed-paper run drew at CE
iteration 5 (``scripts/bench_data/late_batch.json``; ~93 % of them feasible), in the seed
task's scene built from the app's config (``experiment=seed_paper`` plus any overrides given on
the command line, e.g. ``sim.solver_position_iterations=4``), and prints the wall time of the
rollout split into phases, measured by wrapping the functions that do each job with
``time.perf_counter``:

* physics: the PhysX substeps of every control step (``step``);
* fabric: the whole-body fabric step, its goal points and restarts, and the forward kinematics
  of the measured joints every step (``tcp_and_axes``);
* astar: A* + waypoints at the start of every ``move_to``;
* pid: the base's waypoint tracker;
* state_reads: joint positions/velocities, cube and gripper poses read from the simulator;
* target_writes: drive targets written to the simulator, freezing finished robots;
* contact_forces: the finger-cube contact forces (grasp checks);
* reset: the history-free scene reset before the rollout;
* other: the rest (templates' checks, bookkeeping, goal reads).

A wrapped call inside another wrapped call counts for the outer one only. ``--n N`` rolls out
the batch's first N plans in a scene of N copies (``--n 100``: what one of the two default
worker processes holds, ``sim.shard_rows``); ``--uniform`` rolls out N plans drawn from the
task's uniform iteration-0 distribution instead (seed 0, as the search draws them), whose
rollouts are longer and end in a tail of few running plans; it works for any task
(``--uniform experiment=wall``), the late batch only for the seed task's columns. After the
phases, the control steps are split by how many plans were still running, with the wall time
per step in that band: the per-step cost that does not shrink with the running plans shows
there.
``robot_steps_per_s`` is the robots simulated per wall second (copies x control steps / rollout
wall time). The last line is ``non_physics_share: X`` = 1 - physics / rollout wall time.
``--reps R`` rolls out the batch R times in the same scene (the results must repeat bit for
bit) and reports the fastest.

What it doesn't: include the scene build (printed apart) or the search; compare with a
baseline (run it on two checkouts on the same machine for that).

Usage: python scripts/bench_rollout.py [--quick] [--reps R] [--n N] [--uniform] [override ...]
"""

from __future__ import annotations

import argparse
import functools
import importlib
import json
import sys
import time
from collections import defaultdict
from pathlib import Path
from typing import Any, Callable

import torch

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from realize.spec.compose import compose_config  # noqa: E402  (the public composer, checked as the command line is)
from realize.workers.realizers import open_realization  # noqa: E402
from realize.spec.run_spec import build_run_spec  # noqa: E402

BATCH_FILE = REPO / "scripts" / "bench_data" / "late_batch.json"
PHASES = ("physics", "fabric", "astar", "pid", "state_reads", "target_writes", "contact_forces", "reset")


class PhaseTimers:
    """Wall time per phase; a wrapped call inside another wrapped call counts for the outer."""

    def __init__(self) -> None:
        self.total: dict[str, float] = defaultdict(float)
        self.calls: dict[str, int] = defaultdict(int)
        self._depth = 0
        self._undo: list[Callable[[], None]] = []

    def wrap(self, phase: str, owner: Any, name: str) -> bool:
        """Wrap ``owner.name`` (a module, class or instance attribute); False if it is missing."""
        fn = getattr(owner, name, None)
        if fn is None:
            return False

        @functools.wraps(fn)
        def timed(*args: Any, **kwargs: Any) -> Any:
            if self._depth:
                return fn(*args, **kwargs)
            self._depth += 1
            t0 = time.perf_counter()
            try:
                return fn(*args, **kwargs)
            finally:
                self.total[phase] += time.perf_counter() - t0
                self.calls[phase] += 1
                self._depth -= 1

        had = name in vars(owner) if hasattr(owner, "__dict__") else True
        setattr(owner, name, timed)
        self._undo.append((lambda: setattr(owner, name, fn)) if had else (lambda: delattr(owner, name)))
        return True

    def reset(self) -> None:
        self.total.clear()
        self.calls.clear()

    def undo(self) -> None:
        for u in reversed(self._undo):
            u()
        self._undo.clear()


class RunningBands:
    """Wall time and physics time of each counted control step, grouped by the share of plans
    still running when the step began. A step runs from one ``Rollout.act`` to the next; the
    last counted step (followed by the uncounted settling steps) is left out."""

    EDGES = (0.75, 0.5, 0.25, 0.1, 0.0)

    def __init__(self, n: int, timers: PhaseTimers):
        self.n, self.timers = n, timers
        self.rows: list[tuple[int, float, float]] = []  # (running, wall s, physics s) per step
        self._last: tuple[int, float, float] | None = None  # the step in progress: running, t0, physics0
        self._act: Callable[..., None] | None = None

    def install(self) -> None:
        cls = importlib.import_module("realize.realization.rollout").Rollout
        act = self._act = cls.act

        def timed_act(r: Any) -> None:
            now, phys = time.perf_counter(), self.timers.total["physics"]
            if self._last is not None:
                running, t0, phys0 = self._last
                self.rows.append((running, now - t0, phys - phys0))
            self._last = (int(r.running.sum()), now, phys)
            act(r)

        cls.act = timed_act

    def reset(self) -> None:
        self.rows.clear()
        self._last = None

    def undo(self) -> None:
        if self._act is not None:
            importlib.import_module("realize.realization.rollout").Rollout.act = self._act
            self._act = None

    def summary(self) -> list[str]:
        lines, hi = [], 1.01
        for lo in self.EDGES:
            sel = [(w, p) for k, w, p in self.rows if lo * self.n < k <= hi * self.n]
            if sel:
                wall = sum(w for w, _ in sel)
                phys = sum(p for _, p in sel)
                lines.append(f"  running {100 * lo:3.0f}-{min(100, 100 * hi):3.0f} %: {len(sel):4d} steps, {wall:6.2f} s, "
                             f"{wall / len(sel) * 1e3:6.2f} ms/step, physics {phys / len(sel) * 1e3:6.2f} ms/step")
            hi = lo
        return lines


def instrument(timers: PhaseTimers, scene: Any, realizer: Any) -> list[str]:
    """Wrap the functions of every phase; returns the hooks that were found."""
    impl = scene._impl
    hooks = {
        "physics": [(impl, "step")],
        "state_reads": [(impl, n) for n in ("qpos", "qvel", "ee_pose", "object_poses", "object_velocities", "read_state")],
        "target_writes": [(impl, "apply_targets"), (impl, "freeze")],
        "contact_forces": [(impl, "finger_forces")],
        "reset": [(scene.env, "reset"), (impl, "after_reset")],
        "fabric": [(realizer.fabric, n) for n in ("step", "goal_points", "start")]
                  + [(realizer.fabric.kin, "tcp_and_axes")],
    }
    move_to = importlib.import_module("realize.realization.actions.move_to")
    hooks["astar"] = [(move_to, n) for n in ("astar_world", "path_to_waypoints", "plan_paths")]
    hooks["pid"] = [(move_to, n) for n in ("pid_step", "pid_init")]
    found = []
    for phase, targets in hooks.items():
        for owner, name in targets:
            if timers.wrap(phase, owner, name):
                found.append(f"{phase}:{name}")
    return found


def load_batch() -> tuple[list[str], torch.Tensor]:
    doc = json.loads(BATCH_FILE.read_text())
    return doc["columns"], torch.tensor(doc["Z"], dtype=torch.float64)


def main() -> None:
    ap = argparse.ArgumentParser(description=" ".join(__doc__.split("\n\n")[0].split()))
    ap.add_argument("--quick", action="store_true", help="one rollout (default: --reps 2)")
    ap.add_argument("--reps", type=int, default=None, help="rollouts of the batch (fastest reported)")
    ap.add_argument("--n", type=int, default=None, help="plans (and copies): the batch's first N (default: all 200)")
    ap.add_argument("--uniform", action="store_true", help="N plans from the uniform iteration-0 distribution (seed 0)")
    ap.add_argument("overrides", nargs="*", help="config overrides, e.g. sim.solver_position_iterations=4")
    args = ap.parse_args()
    reps = args.reps or (1 if args.quick else 2)
    columns, Z = load_batch()
    cfg = compose_config(["device=cpu", "experiment=seed_paper", *args.overrides])
    spec = build_run_spec(cfg)
    if not args.uniform and list(spec.task.layout.column_names) != columns:
        raise SystemExit(f"{BATCH_FILE.name} holds columns {columns}, the task has {list(spec.task.layout.column_names)}")
    n = Z.shape[0] if args.n is None else args.n
    if n < 1 or (n > Z.shape[0] and not args.uniform):
        raise SystemExit(f"--n {n}: must be 1..{Z.shape[0]} for {BATCH_FILE.name} (any N >= 1 with --uniform)")
    if args.uniform:
        g = torch.Generator()
        g.manual_seed(0)
        Z, source = spec.task.layout.sample_uniform(n, g, spec.placement.dtype), "uniform iteration-0 samples (seed 0)"
    else:
        Z, source = Z[:n], f"{BATCH_FILE.name}"
    t0 = time.perf_counter()
    scene, (realizer,) = open_realization(spec, n_envs=n)
    build = time.perf_counter() - t0
    timers = PhaseTimers()
    bands = RunningBands(n, timers)
    best: dict[str, float] | None = None
    first = None
    with scene:
        found = instrument(timers, scene, realizer)
        bands.install()
        try:
            for rep in range(reps):
                timers.reset()
                bands.reset()
                res = realizer.rollout(Z)
                key = (res.cost.tolist(), res.feasible.tolist())
                if first is None:
                    first = key
                elif key != first:
                    raise SystemExit(f"rollout {rep} differs from rollout 0: results must repeat bit for bit")
                t = dict(timers.total)
                t["wall"] = res.wall_time_s
                t["steps"] = float(res.sim_steps)
                if best is None or t["wall"] < best["wall"]:
                    best = t
                    best_bands = bands.summary()
        finally:
            timers.undo()
            bands.undo()
    assert best is not None and res is not None
    wall, steps = best["wall"], max(best["steps"], 1.0)
    feas = res.feasible.float().mean().item()
    cost = res.cost[res.feasible].float().mean().item() if bool(res.feasible.any()) else float("nan")
    print(f"torch threads {torch.get_num_threads()}, physics threads (sim.cpu_workers) {spec.sim.cpu_workers}; "
          f"overrides: {' '.join(args.overrides) or '(none)'}")
    print(f"hooks: {', '.join(found)}")
    print(f"batch: {n} plans, {source}, {steps:.0f} control steps; feasible {feas:.3f}, "
          f"mean feasible cost {cost:.1f}, best {res.cost[res.feasible].min().item() if bool(res.feasible.any()) else float('nan'):.0f}")
    print(f"scene build {build:.1f} s; rollout wall {wall:.2f} s (fastest of {reps})")
    accounted = 0.0
    for phase in PHASES:
        v = best.get(phase, 0.0)
        accounted += v
        print(f"  {phase:15s} {v:8.2f} s  {v / wall * 100:5.1f} %  {v / steps * 1e3:7.2f} ms/step")
    other = wall - accounted
    print(f"  {'other':15s} {other:8.2f} s  {other / wall * 100:5.1f} %  {other / steps * 1e3:7.2f} ms/step")
    print("control steps by plans still running (wall per step; physics per step):")
    for line in best_bands:
        print(line)
    print(f"robot_steps_per_s: {n * steps / wall:.0f}")
    print(f"non_physics_share: {1.0 - best.get('physics', 0.0) / wall:.3f}")


if __name__ == "__main__":
    main()
