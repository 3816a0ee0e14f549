"""Validation replicas: re-simulate a run's best plan K times at once under small perturbations
and write the success share into RUN_DIR/result.json under `validation`.

Usage: python scripts/validate.py RUN_DIR [--replicas 16] [--seed 0] [--friction 0.8 1.2]
                                  [--no-randomize] [--object-noise M] [--robot-noise M]
                                  [--backend cpu|gpu|auto] [--dry-run] [--json]

Perturbations: the task's reset randomization (each object's xy and yaw where it rests, robot
start xy; amplitudes from the task unless --object-noise/--robot-noise) and each object's
friction scaled per replica by a factor drawn uniformly from --friction (CPU backend only;
--friction none: off).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # run from a checkout without install

from realize.app.replay import ReplayError  # noqa: E402
from realize.app.validation import validate  # noqa: E402
from realize.config import ConfigError  # noqa: E402


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("run_dir", type=Path, help="a run directory written by `realize`")
    ap.add_argument("--replicas", type=int, default=16, help="K copies simulated at once (default 16)")
    ap.add_argument("--seed", type=int, default=0, help="seed of the perturbations (default 0)")
    ap.add_argument("--friction", nargs="+", default=["0.8", "1.2"], metavar="LOW HIGH",
                    help="object friction factor range (default 0.8 1.2), or 'none'")
    ap.add_argument("--no-randomize", action="store_true", help="no start-state randomization")
    ap.add_argument("--object-noise", type=float, default=None, help="object xy noise (m), task default if unset")
    ap.add_argument("--robot-noise", type=float, default=None, help="robot start xy noise (m)")
    ap.add_argument("--backend", choices=("cpu", "gpu", "auto"), default="cpu")
    ap.add_argument("--dry-run", action="store_true", help="report only, leave result.json unchanged")
    ap.add_argument("--json", action="store_true", help="print the report as JSON")
    args = ap.parse_args(argv)
    if args.friction == ["none"]:
        friction = None
    else:
        try:
            lo, hi = (float(v) for v in args.friction)
        except ValueError:
            ap.error("--friction takes LOW HIGH or 'none'")
        friction = (lo, hi)
    try:
        rep = validate(args.run_dir, args.replicas, args.seed, friction_range=friction,
                       randomize=not args.no_randomize, object_xy_noise=args.object_noise,
                       robot_xy_noise=args.robot_noise, backend=args.backend, write=not args.dry_run)
    except (ReplayError, ConfigError) as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    if args.json:
        print(json.dumps(rep.to_dict(), indent=2))
    else:
        ok = round(rep.success_share * rep.replicas)
        print(f"validation ({rep.backend}, seed {rep.seed}): {ok}/{rep.replicas} replicas reach the goal "
              f"(success share {rep.success_share:.2f})")
        for reason, n in rep.failures.items():
            print(f"  {n:3d} x {reason}")
        if rep.cost_mean is not None:
            print(f"cost of the successful replicas {rep.cost_mean:.1f} +- {rep.cost_std:.1f} "
                  f"(result.json best_cost {rep.saved_cost})")
        print(f"wall time {rep.wall_time_s:.1f} s" + ("" if args.dry_run else f"; wrote validation to "
                                                       f"{args.run_dir / 'result.json'}"))
    return 0


if __name__ == "__main__":
    sys.exit(main())
