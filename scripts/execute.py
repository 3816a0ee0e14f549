"""Carry a run's returned plan out in changing worlds, open loop beside closed loop (watch and replan).

Usage: python scripts/execute.py RUN_DIR [--disturbance FAMILY|FILE.yaml] [--worlds W] [--seed S]
            [--max-replans N] [--noise PRESET|FILE.yaml] [--think measured|frozen|STEPS] [--check-copies K]
            [--open-only | --closed-only] [--n-envs N] [--iterations T] [--validation R]
            [--video] [--no-rerun] [--out DIR] [--json] [--export ros2,lerobot] [--accel-limit A]
            [execute.KEY=VALUE ...]

The study's settings are a Hydra config (configs/execution.yaml, realize.compose_execution):
FAMILY is an option of its execute group (configs/execute/: none, cube_moved, table_moved,
knocked_out, obstacle, pushed, tower_knocked, block_moved, grasp_slip) or a YAML file of the same
keys, PRESET an option of its noise group (configs/noise/); the flags set their keys
(--worlds is execute.worlds, --n-envs execute.budget.n_envs, ...), and trailing overrides set
any key of realize.execution.settings.ExecuteSettings (execute.tolerance.object_m=0.2), after
the flags. Each world is its own one-copy scene drawn from the task's perturbation model with seed
S * 1000 + k, plus the family's disturbances; the replans search --n-envs copies for at most --iterations iterations and stop at
the first plan that reaches the goal (the preset's budget: realize.execution.replan_budget). Results go to
RUN_DIR/execution/FAMILY/ (summary.json, world-K-{open,closed}.json/.npz/.rrd; format of the .npz in
docs/execution_format.md). The last lines print the study's table row.

    python scripts/execute.py runs/seed0 --worlds 16 --disturbance table_moved --seed 0
"""

from __future__ import annotations

import argparse
import json
import logging
import sys
from pathlib import Path


def main(argv: list[str] | None = None) -> int:
    from realize.execution.replan_budget import ReplanBudget
    from realize.execution.settings import ExecuteSettings

    study = ExecuteSettings()  # the defaults the help names (written once, there)
    budget = study.budget

    p = argparse.ArgumentParser(description=" ".join(__doc__.split("\n\n")[0].split()), epilog=__doc__.split("\n\n", 1)[1],
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("run_dir")
    p.add_argument("overrides", nargs="*", help="keys of the execution config, after the flags (execute.KEY=VALUE)")
    p.add_argument("--disturbance", default="none", help="preset of configs/execute/ or a YAML file (default none)")
    p.add_argument("--worlds", type=int, default=None, help="worlds (default: the preset's)")
    p.add_argument("--seed", type=int, default=None, help="study seed (default: the preset's)")
    p.add_argument("--max-replans", type=int, default=None)
    p.add_argument("--noise", default=None,
                   help="observation model: a preset of configs/noise/ (none, realistic) or a YAML file (default: the "
                        "family's, else none)")
    p.add_argument("--think", default=None,
                   help="the world while the planner thinks: measured (its wall time), frozen, or a number of control "
                        f"steps (fixed: a study repeats bit for bit) (default: the preset's, else {study.think})")
    p.add_argument("--check-copies", type=int, default=None,
                   help=f"copies of the check before a repair (0: none; default: the preset's, else "
                        f"{study.precheck.copies})")
    mode = p.add_mutually_exclusive_group()
    mode.add_argument("--open-only", action="store_true", help="no replanning")
    mode.add_argument("--closed-only", action="store_true", help="no open-loop baseline")
    p.add_argument("--n-envs", type=int, default=None,
                   help=f"copies per replan iteration (default: the preset's, else {budget.n_envs}, {budget.n_elite} "
                        f"elites; with N given, {ReplanBudget.elites_for(32)} of 32: an eighth from 32 on, a quarter "
                        f"below)")
    p.add_argument("--iterations", type=int, default=None,
                   help=f"most CE iterations per replan (default: the preset's, else {budget.iterations})")
    p.add_argument("--validation", type=int, default=None,
                   help=f"replicas each replan validates its candidates in, returning the most robust (default: the "
                        f"preset's, else {budget.validation}; 0: none, the first plan that reaches the goal)")
    p.add_argument("--video", action="store_true", help="an MP4 per world")
    p.add_argument("--no-rerun", action="store_true", help="no .rrd per world")
    p.add_argument("--out", default=None, help="output directory (default RUN_DIR/execution/FAMILY)")
    p.add_argument("--json", action="store_true", help="print summary.json")
    p.add_argument("--export", default="", help="also write each world as ros2 (an MCAP bag) and/or lerobot (a "
                   "LeRobot dataset per mode), comma-separated (docs/execution_format.md)")
    p.add_argument("--accel-limit", type=float, default=None,
                   help="the exported arm trajectories' acceleration limit, rad/s^2 (m/s^2 prismatic), every joint "
                        "(default: realize.execution.time_param.DEFAULT_ACCELERATION_LIMIT)")
    a = p.parse_intermixed_args(argv)

    from realize.repair.study import execute
    from realize.config import ConfigError
    from realize.execution.export import DEFAULT_ACCELERATION_LIMIT, ExportOptions, export_formats
    from realize.spec.execution_config import compose_execution

    logging.basicConfig(level=logging.WARNING, format="%(message)s")
    try:
        if not (Path(a.run_dir) / "result.json").is_file():
            raise ConfigError(f"{a.run_dir}: not a realize run directory (no result.json)")
        formats = export_formats(a.export)  # a bad name is refused before anything runs
        accel = DEFAULT_ACCELERATION_LIMIT if a.accel_limit is None else a.accel_limit
        ExportOptions(acceleration_limit=accel)
        files = {}
        overrides = []
        for flag, group in ((a.disturbance, "execute"), (a.noise, "noise")):
            if flag is None:
                continue
            if Path(flag).suffix in (".yaml", ".yml"):
                files[group] = flag
            else:
                overrides.append(f"{group}={flag}")
        for flag, key in ((a.worlds, "worlds"), (a.seed, "seed"), (a.max_replans, "max_replans"), (a.think, "think"),
                          (a.check_copies, "precheck.copies"), (a.n_envs, "budget.n_envs"),
                          (a.iterations, "budget.iterations"), (a.validation, "budget.validation")):
            if flag is not None:
                overrides.append(f"execute.{key}={flag}")
        if a.n_envs is not None:
            overrides.append(f"execute.budget.n_elite={ReplanBudget.elites_for(a.n_envs)}")
        settings = compose_execution([*overrides, *a.overrides], preset_file=files.get("execute"),
                                     noise_file=files.get("noise"))
        name = Path(a.disturbance).stem
        s = execute(a.run_dir, settings, name=name, open_loop=not a.closed_only, closed_loop=not a.open_only,
                    out=a.out, rerun=not a.no_rerun, video=a.video, export=formats, export_acceleration=accel)
    except ConfigError as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    d = s.to_dict()
    if a.json:
        print(json.dumps(d, indent=2))
    med, p95 = d["replan_s_median"], d["replan_s_p95"]
    fmt = (lambda v: "-" if v is None else f"{v:.1f} s")
    print(f"{name}: {s.worlds} worlds; open loop {s.open_successes if s.open_successes is not None else '-'}"
          f"/{s.worlds}; closed loop {s.closed_successes if s.closed_successes is not None else '-'}/{s.worlds}; "
          f"replans per world {s.replans}; replan wall time median {fmt(med)}, p95 {fmt(p95)}; "
          f"needless replans {s.needless_replans}, harmful {s.harmful_replans}; checks {s.checks} "
          f"({s.checks_gone_on} went on); world time lost to thinking {sum(s.hold_s):.1f} s")
    print(f"files: {Path(a.out) if a.out else Path(a.run_dir) / 'execution' / name}/summary.json")
    return 0


if __name__ == "__main__":
    sys.exit(main())
