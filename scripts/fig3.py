"""Fig. 3 of the seed paper from a run directory: each parameter's sampling distribution per
CE iteration as 2-sigma ellipses (x, y of 3-D parameters), coloured by iteration.

Usage: python scripts/fig3.py RUN_DIR [--out PNG] [--no-final]

Reads RUN_DIR/history.npz and scene.json (or the config in result.json); writes the PNG and the
CSV of the plotted ellipses next to it (default RUN_DIR/figures/fig3.{png,csv}).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # run from a checkout without install

from realize.figures.fig3 import fig3  # noqa: E402
from realize.figures.common import report_written  # noqa: E402


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=" ".join(__doc__.split("\n\n")[0].split()))
    ap.add_argument("run_dir", type=Path, help="a run directory written by `realize`")
    ap.add_argument("--out", type=Path, default=None, help="PNG path (the CSV goes beside it)")
    ap.add_argument("--no-final", action="store_true", help="leave out the distribution refit after the last iteration")
    args = ap.parse_args(argv)
    return report_written(lambda: fig3(args.run_dir, out_png=args.out, show_final=not args.no_final))


if __name__ == "__main__":
    sys.exit(main())
