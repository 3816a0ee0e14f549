"""Fig. 2 of the seed paper from a run directory: sampled plans projected on the ground plane.

Usage: python scripts/fig2.py RUN_DIR [--iterations 0 4 9] [--out PNG] [--max-plans N]

Reads RUN_DIR/trajectories_iter{k}.npz (written by a run when trajectories are recorded),
history.npz and scene.json (or the config in result.json); writes the PNG and the CSV of the
plotted points next to it (default RUN_DIR/figures/fig2.{png,csv}). See realize/figures/fig2.py.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # run from a checkout without install

from realize.figures.fig2 import fig2  # noqa: E402
from realize.figures.common import report_written  # noqa: E402


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=" ".join(__doc__.split("\n\n")[0].split()))
    ap.add_argument("run_dir", type=Path, help="a run directory written by `realize`")
    ap.add_argument("--iterations", type=int, nargs="+", default=None,
                    help="CE iterations to show (default: first, middle and last with trajectories)")
    ap.add_argument("--out", type=Path, default=None, help="PNG path (the CSV goes beside it)")
    ap.add_argument("--max-plans", type=int, default=None, help="draw at most this many plans per panel")
    args = ap.parse_args(argv)
    return report_written(lambda: fig2(args.run_dir, args.iterations, out_png=args.out, max_plans=args.max_plans))


if __name__ == "__main__":
    sys.exit(main())
