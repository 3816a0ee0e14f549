"""Conservativeness of the kinematic screen (``ce.screen``): how many rejected samples would
have succeeded.

Draws N samples uniformly over the task's regions (seed S, as a search's iteration 0 draws
them), screens them (``realize.realization.screening.HandDepthScreen`` at ``ce.screen_depth``),
simulates the rejected ones in one batch and prints how many of them were feasible: the screen
is conservative when that is at most 1 % of them. Also prints where the rejected ones failed
and the share of the N that the screen rejects.

What it doesn't: simulate the samples it keeps (their share of success is the search's own
business), or change any file.

Usage: python scripts/screen_check.py [--n 1000] [--seed 0] [override ...]
       (overrides as on the command line: experiment=seed_paper robot=mobile_panda ce.screen_depth=0.03)
"""

from __future__ import annotations

import argparse
import collections
import sys
import time
from pathlib import Path

import torch

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from realize.spec.compose import compose_config  # noqa: E402  (the public composer, checked as the command line is)
from realize.workers.realizers import open_realization  # noqa: E402
from realize.spec.run_spec import build_run_spec  # noqa: E402
from realize.realization.screening import HandDepthScreen  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--n", type=int, default=1000, help="uniform samples drawn (default 1000)")
    ap.add_argument("--seed", type=int, default=0, help="seed of the draw (default 0)")
    ap.add_argument("overrides", nargs="*", help="config overrides (default: experiment=seed_paper)")
    args = ap.parse_args()
    overrides = args.overrides or ["experiment=seed_paper"]
    spec = build_run_spec(compose_config(["device=cpu", *overrides]))
    screen = HandDepthScreen(spec.task, spec.geometry, spec.robot, spec.rollout, spec.ce.screen_depth,
                             spec.ce.torch_dtype)
    if not screen.active:
        raise SystemExit(f"{spec.task.describe()}: no grasp of a box to screen")
    g = torch.Generator()
    g.manual_seed(args.seed)
    Z = spec.task.layout.sample_uniform(args.n, g, spec.ce.torch_dtype)
    rejected = screen(Z)
    k = int(rejected.sum())
    print(f"{overrides}, robot {spec.robot.name}, screen_depth {spec.ce.screen_depth} m: "
          f"{k} of {args.n} uniform samples rejected ({k / args.n:.1%})")
    if k == 0:
        return
    t0 = time.perf_counter()
    scene, (realizer,) = open_realization(spec, n_envs=k)
    with scene:
        res = realizer.rollout(Z[rejected])
    feasible = int(res.feasible.sum())
    print(f"simulated the {k} rejected in {time.perf_counter() - t0:.0f} s: {feasible} feasible "
          f"({feasible / k:.2%}; conservative: at most 1 %)")
    for where, count in collections.Counter(res.failure).most_common():
        print(f"  {where or 'feasible'}: {count}")


if __name__ == "__main__":
    main()
