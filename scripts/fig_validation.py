"""The validation figure from a run directory: each validated candidate's nominal cost against its
success share under the task's perturbations, with 95 % Wilson intervals.

Usage: python scripts/fig_validation.py RUN_DIR [--out PNG]

Reads the `validation` block of RUN_DIR/result.json (a candidate validation: the run's
`validation.replicas=R`, or `scripts/validate.py RUN_DIR --candidates K`); the returned candidate is
highlighted and `min_success` drawn dashed. Writes the PNG and the CSV of the plotted numbers next
to it (default RUN_DIR/figures/fig_validation.{png,csv}).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # run from a checkout without install

from realize.figures.fig_validation import fig_validation  # noqa: E402
from realize.figures.common import report_written  # noqa: E402


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=" ".join(__doc__.split("\n\n")[0].split()))
    ap.add_argument("run_dir", type=Path, help="a run directory written by `realize`")
    ap.add_argument("--out", type=Path, default=None, help="PNG path (the CSV goes beside it)")
    args = ap.parse_args(argv)
    return report_written(lambda: fig_validation(args.run_dir, out_png=args.out))


if __name__ == "__main__":
    sys.exit(main())
