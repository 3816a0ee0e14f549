"""Validation replicas: re-simulate the plan a run returns K times at once under small perturbations
and write the success share into RUN_DIR/result.json under `plan_validation` (the plan: the one
the run's candidate validation returned, else best_z; --nominal: best_z). With --candidates K:
validate the run's K best distinct plans and pick the one to return, into `validation`.

Usage: python scripts/validate.py RUN_DIR [--replicas R] [--seed S] [--friction LOW HIGH|none]
            [--mass LOW HIGH|none] [--no-randomize] [--object-noise M] [--object-yaw RAD] [--robot-noise M]
            [--no-track] [--nominal] [--candidates [K] [--min-success P]]
            [--backend cpu|gpu|auto] [--dry-run] [--json]

R and S default to the run's (its validation.replicas, its seed): the worlds the run chose its
plan in; another --seed gives held-out worlds. --candidates without K redoes the run's own
validation (its K, min_success and iterations as well) and rewrites `validation`, the plan a
replay executes (--dry-run: report only).

Perturbations: the run task's perturbation model (``perturbation`` in its task config,
realize/tasks/perturbation.py: each object's xy and yaw where it rests, the robot start's xy,
each object's friction and mass scaled per replica by factors drawn uniformly from their ranges;
CPU backend for friction and mass), any field overridden by the flags (``none``: unchanged);
replica r meets world r of ``realize.tasks.worlds.draw_worlds(model, objects, K + 1, seed, nominal_first=True)``
(world 0: the unperturbed one), the worlds a run's candidates met for the same seed and K.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # run from a checkout without install

from realize.validation.replay import ReplayError  # noqa: E402
from realize.validation.candidates import validate_candidates  # noqa: E402
from realize.validation.returned_plan import validate  # noqa: E402
from realize.config import ConfigError  # noqa: E402

RUNS_OWN = "the run's"  # --candidates without K: the run's validation.candidates


def _range(ap: argparse.ArgumentParser, values: list[str] | None, flag: str) -> tuple[float, float] | None:
    if values is None:
        return None
    if values == ["none"]:
        return (1.0, 1.0)
    try:
        lo, hi = (float(v) for v in values)
    except ValueError:
        ap.error(f"{flag} takes LOW HIGH or 'none'")
    return (lo, hi)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=" ".join(__doc__.split("\n\n")[0].split()))
    ap.add_argument("run_dir", type=Path, help="a run directory written by `realize`")
    ap.add_argument("--replicas", type=int, default=None,
                    help="worlds per plan, simulated at once (default: the run's validation.replicas, 64 if it had none)")
    ap.add_argument("--seed", type=int, default=None,
                    help="seed of the worlds (default: the run's seed, the worlds its candidates met)")
    ap.add_argument("--friction", nargs="+", default=None, metavar="LOW HIGH",
                    help="object friction factor range, or 'none' (default: the task's perturbation model)")
    ap.add_argument("--mass", nargs="+", default=None, metavar="LOW HIGH",
                    help="object mass factor range, or 'none' (default: the task's)")
    ap.add_argument("--no-randomize", action="store_true", help="no start-state randomization")
    ap.add_argument("--object-noise", type=float, default=None, help="object xy noise (m), the task's if unset")
    ap.add_argument("--object-yaw", type=float, default=None, help="object yaw noise (rad), the task's if unset")
    ap.add_argument("--robot-noise", type=float, default=None, help="robot start xy noise (m), the task's if unset")
    ap.add_argument("--no-track", action="store_true",
                    help="aim at objects' config poses, not where they lie (controller.track_objects=false)")
    ap.add_argument("--candidates", type=int, nargs="?", const=RUNS_OWN, default=None, metavar="K",
                    help="validate the K cheapest distinct feasible plans of the last iterations (no K: the run's "
                         "validation.candidates), not only the best, name the one to return and rewrite the run's "
                         "validation block (realize/validation/candidates.py)")
    ap.add_argument("--min-success", type=float, default=None,
                    help="with --candidates: return the cheapest plan whose 95%% lower bound reaches this "
                         "(default: the run's validation.min_success)")
    ap.add_argument("--nominal", action="store_true",
                    help="validate the search's nominal best_z, not the plan the run's validation returned")
    ap.add_argument("--backend", choices=("cpu", "gpu", "auto"), default=None,
                    help="simulator backend (default: the run's own sim.backend)")
    ap.add_argument("--dry-run", action="store_true", help="report only, leave result.json unchanged")
    ap.add_argument("--json", action="store_true", help="print the report as JSON")
    args = ap.parse_args(argv)
    overrides = dict(friction=_range(ap, args.friction, "--friction"), mass=_range(ap, args.mass, "--mass"),
                     object_xy=args.object_noise, object_yaw=args.object_yaw, robot_xy=args.robot_noise)
    if args.no_randomize:
        overrides.update(object_xy=0.0, object_yaw=0.0, robot_xy=0.0)
    track = False if args.no_track else None
    try:
        if args.candidates is not None:
            return _candidates(args, track, overrides)
        rep = validate(args.run_dir, args.replicas, args.seed, backend=args.backend, write=not args.dry_run,
                       track_objects=track, nominal=args.nominal, **overrides)
    except (ReplayError, ConfigError) as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    if args.json:
        print(json.dumps(rep.to_dict(), indent=2))
    else:
        ok = round(rep.success_share * rep.replicas)
        which = rep.plan + ("" if rep.candidate is None else f" [{rep.candidate}]")
        print(f"validation of {which} ({rep.backend}, seed {rep.seed}): {ok}/{rep.replicas} replicas reach the goal "
              f"(success share {rep.success_share:.2f})")
        for reason, n in rep.failures.items():
            print(f"  {n:3d} x {reason}")
        for line in weak_lines(rep.per_action or []):  # where the failed replicas stopped
            print(f"  {line}")
        if rep.cost_mean is not None:
            print(f"cost of the successful replicas {rep.cost_mean:.1f} +- {rep.cost_std:.1f} "
                  f"(the plan's search cost {rep.saved_cost})")
        print(f"wall time {rep.wall_time_s:.1f} s" + ("" if args.dry_run else f"; wrote plan_validation to "
                                                       f"{args.run_dir / 'result.json'}"))
    return 0


def _candidates(args: argparse.Namespace, track: bool | None, overrides: dict) -> int:
    k = None if args.candidates == RUNS_OWN else args.candidates
    rep = validate_candidates(args.run_dir, k, args.replicas, min_success=args.min_success,
                              seed=args.seed, backend=args.backend, track_objects=track, write=not args.dry_run,
                              **overrides)
    if args.json:
        print(json.dumps(rep.to_dict(), indent=2))
        return 0
    print(f"validation of {len(rep.candidates)} candidate(s) ({rep.backend}, seed {rep.seed}, {rep.replicas} replicas each):")
    for j, c in enumerate(rep.candidates):
        mark = "  <- returned" if j == rep.returned else ""
        print(f"  {j}: cost {c.cost:.0f} (iteration {c.iteration}): success {c.success_share:.2f} "
              f"[{c.ci95[0]:.2f}, {c.ci95[1]:.2f}]{mark}")
        for reason, n in c.failures.items():
            print(f"       {n:3d} x {reason}")
    print(f"returned: candidate {rep.returned} ({rep.reason}, min_success {rep.min_success}); "
          f"wall time {rep.wall_time_s:.1f} s" + ("" if args.dry_run else f"; wrote validation to "
                                                  f"{args.run_dir / 'result.json'}"))
    return 0


if __name__ == "__main__":
    sys.exit(main())
