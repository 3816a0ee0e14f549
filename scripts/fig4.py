"""Fig. 4 of the seed paper: best sampled cost per CE iteration and share of successful samples,
mean over runs with a +-1 sigma band.

Usage:
  python scripts/fig4.py --runs 10                 # run the seed experiment for seeds 0..9, then plot
  python scripts/fig4.py --run-dirs DIR [DIR ...]  # only plot existing runs (a multirun folder works too)

Launching runs `python -m realize experiment=seed_paper seed=S hydra.run.dir=<root>/seed<S>` one
after another (``--jobs`` for more at a time); runs already done are kept (``--force`` reruns
them), interrupted ones are resumed. Writes the PNG and the CSV with the plotted numbers and each
run's series (default <root>/../fig4.{png,csv}, i.e. outputs/fig4/fig4.png).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # run from a checkout without install

from realize.figures.fig4 import fig4, find_run_dirs  # noqa: E402
from realize.figures.common import report_written  # noqa: E402
from realize.figures.launch import launch_runs, run_status  # noqa: E402


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=" ".join(__doc__.split("\n\n")[0].split()))
    ap.add_argument("--runs", type=int, default=10, help="number of runs (seeds --seed0 .. --seed0 + runs - 1)")
    ap.add_argument("--seed0", type=int, default=0, help="first seed")
    ap.add_argument("--run-dirs", type=Path, nargs="+", default=None,
                    help="plot these run directories (or folders of them) instead of launching runs")
    ap.add_argument("--root", type=Path, default=Path("outputs/fig4/runs"), help="where launched runs go")
    ap.add_argument("--experiment", default="seed_paper", help="experiment preset of the launched runs")
    ap.add_argument("--override", action="append", default=[], metavar="KEY=VALUE",
                    help="extra Hydra override for the launched runs (repeatable), e.g. ce.iterations=5")
    ap.add_argument("--jobs", type=int, default=1, help="runs at a time")
    ap.add_argument("--force", action="store_true", help="rerun seeds whose run is already done")
    ap.add_argument("--module", default="realize", help=argparse.SUPPRESS)  # tests swap the app
    ap.add_argument("--out", type=Path, default=None, help="PNG path (the CSV goes beside it)")
    args = ap.parse_args(argv)

    if args.run_dirs:
        dirs = find_run_dirs(args.run_dirs)
        if not dirs:
            print(f"fig4: no run directories (with result.json) in {[str(d) for d in args.run_dirs]}", file=sys.stderr)
            return 1
        out = args.out or Path("outputs/fig4/fig4.png")
    else:
        if args.runs < 1:
            print("fig4: --runs must be >= 1", file=sys.stderr)
            return 2
        seeds = list(range(args.seed0, args.seed0 + args.runs))
        dirs, failed = launch_runs(seeds, args.root, args.experiment, args.override, module=args.module,
                                   jobs=args.jobs, force=args.force)
        for seed, rc in failed:
            print(f"fig4: seed {seed} did not finish (exit code {rc}); see {args.root / f'seed{seed}.log'}",
                  file=sys.stderr)
        if not dirs:
            print("fig4: no run finished; nothing to plot", file=sys.stderr)
            return 1
        out = args.out or args.root.parent / "fig4.png"
    not_done = [d for d in dirs if run_status(d) not in ("done", "unknown")]
    for d in not_done:
        print(f"fig4: warning: {d} has status {run_status(d)!r}; its series may be incomplete", file=sys.stderr)
    return report_written(lambda: fig4(dirs, out), prefix=f"{len(dirs)} runs\n")


if __name__ == "__main__":
    sys.exit(main())
