"""Print execution studies as one Markdown table (the README's and docs/replanning.md's).

Usage: python scripts/execution_table.py RUN/execution/FAMILY [RUN/execution/OTHER ...]

Each argument is a directory ``scripts/execute.py`` wrote (its ``summary.json``); one row per
study: open and closed loop successes, replans (and the checks before them, with how many let
the plan go on), needless and harmful replans, the replans' wall time median and p95, and the
world time lost to thinking per closed-loop world (mean and most).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

HEADER = ("| study | open loop | closed loop | replans (checks, gone on) | needless / harmful | replan median / p95 "
          "| world time lost per world, mean / most |\n|---|---|---|---|---|---|---|")


def row(study: Path) -> str:
    d = json.loads((study / "summary.json").read_text())
    n = d["worlds"]
    hold = d.get("hold_s") or [0.0]
    fmt = (lambda v: "-" if v is None else f"{v:.1f} s")  # noqa: E731
    opened = "-" if d["open_successes"] is None else f"{d['open_successes']}/{n}"
    closed = "-" if d["closed_successes"] is None else f"{d['closed_successes']}/{n}"
    judged = "-" if d.get("needless_replans") is None else f"{d['needless_replans']} / {d['harmful_replans']}"
    return (f"| {study.name} | {opened} | {closed} | {sum(d['replans'])} ({d.get('checks', 0)}, "
            f"{d.get('checks_gone_on', 0)}) | {judged} | {fmt(d['replan_s_median'])} / {fmt(d['replan_s_p95'])} | "
            f"{np.mean(hold):.1f} s / {max(hold):.1f} s |")


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("studies", nargs="+", help="directories with a summary.json")
    a = p.parse_args(argv)
    missing = [s for s in a.studies if not (Path(s) / "summary.json").is_file()]
    if missing:
        print(f"error: no summary.json in {missing}", file=sys.stderr)
        return 2
    print(HEADER)
    for s in a.studies:
        print(row(Path(s)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
