"""The README's and docs/results.md's table of fresh-clone runs, from their record.

Usage: python scripts/fresh_clone_table.py [--all] [--csv scripts/bench_data/fresh_clones.csv]

Each row of ``scripts/bench_data/fresh_clones.csv`` is one fresh clone (``git clone . DIR``) on
which the README's two commands ran: its date, commit, host (named in docs/results.md), pip
cache, what else ran beside it (empty: not recorded), ``make run``'s wall time with its setup
and the run's own (search, validation), the best cost, whether ``best_z`` was the recorded one
(``scripts/bench_data/same_seed.json``), the returned plan's validated share, and ``make test``'s
wall time (pytest's own) with its counts. Without ``--all`` it prints the newest two rows (the
README's table); with it every row (docs/results.md's archive). tests/test_fresh_clone_table.py
fails while the README's table is not what this prints.
What it doesn't: run anything (append a row after running the two commands from a fresh clone).
"""

from __future__ import annotations

import argparse
import csv
import sys
from pathlib import Path

RECORD = Path(__file__).resolve().parent / "bench_data" / "fresh_clones.csv"
HEADER = ("| date, commit, host | `make run` (with setup) | the run: search, validation | best cost, `best_z`, "
          "validated | `make test` (pytest) | tests |\n|---|---|---|---|---|---|")


def _mmss(seconds: str) -> str:
    if not seconds:
        return "-"
    s = round(float(seconds))
    return f"{s // 60}:{s % 60:02d}"


def _s(seconds: str) -> str:
    return f"{float(seconds):g} s" if seconds else "-"


def row(r: dict[str, str]) -> str:
    """One Markdown row of a record row."""
    where = f"{r['date']}, `{r['commit']}`, {r['host']}" + (f", {r['cache']}" if r["cache"] else "")
    if r["beside"]:
        where += f", {r['beside']} beside it"
    run = f"{_s(r['run_s'])}: {_s(r['search_s'])}, {_s(r['validation_s'])}"
    z = {"yes": "the recorded `best_z`", "no": "another `best_z`"}.get(r["same_best_z"], "`best_z` not compared")
    test = _mmss(r["make_test_s"]) + (f" ({_mmss(r['pytest_s'])})" if r["pytest_s"] else "")
    return (f"| {where} | {_mmss(r['make_run_s'])} | {run} | {r['best_cost']}, {z}, {r['validated']} | {test} "
            f"| {r['passed']} passed, {r['skipped']} skipped |")


def table(path: Path = RECORD, newest: int | None = 2) -> str:
    """The Markdown table of the record's rows (newest first, as written), ``newest`` of them (None: all)."""
    with path.open(newline="") as f:
        rows = list(csv.DictReader(f))
    return "\n".join([HEADER, *(row(r) for r in rows[:newest])])


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=" ".join(__doc__.split("\n\n")[0].split()))
    ap.add_argument("--all", action="store_true", help="every row (default: the newest two)")
    ap.add_argument("--csv", type=Path, default=RECORD)
    a = ap.parse_args(argv)
    print(table(a.csv, None if a.all else 2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
