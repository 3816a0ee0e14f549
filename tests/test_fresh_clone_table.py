"""The fresh-clone tables of the README and docs/results.md are what their record gives
(``scripts/bench_data/fresh_clones.csv`` through ``scripts/fresh_clone_table.py``): a number in
them has its date, commit and host, and changes only by a row of the record."""

from __future__ import annotations

import csv
import re
from pathlib import Path

from helpers import load_script

REPO = Path(__file__).resolve().parents[1]


def test_the_readme_and_results_tables_are_the_records() -> None:
    script = load_script("fresh_clone_table")
    readme = (REPO / "README.md").read_text()
    results = (REPO / "docs" / "results.md").read_text()
    assert script.table() in readme, "README.md: paste `python scripts/fresh_clone_table.py`"
    assert script.table() in results, "docs/results.md: paste `python scripts/fresh_clone_table.py`"
    assert script.table(newest=None) in results, "docs/results.md: paste `python scripts/fresh_clone_table.py --all`"


def test_every_record_row_names_its_date_commit_host_and_counts() -> None:
    with (REPO / "scripts" / "bench_data" / "fresh_clones.csv").open(newline="") as f:
        rows = list(csv.DictReader(f))
    assert rows
    # the hosts docs/results.md names once, at its top ("- **NAME**: ...")
    hosts = set(re.findall(r"^- \*\*([^*]+)\*\*:", (REPO / "docs" / "results.md").read_text().split("## ")[0], re.M))
    assert {"Intel", "EPYC"} <= hosts
    for r in rows:
        assert len(r["date"]) == 10 and r["commit"] and r["host"] in hosts, r
        assert float(r["make_run_s"]) > 0 and float(r["make_test_s"]) > 0 and int(r["passed"]) > 0, r
        assert r["same_best_z"] in ("yes", "no", ""), r
    assert [r["date"] for r in rows] == sorted((r["date"] for r in rows), reverse=True)  # newest first
