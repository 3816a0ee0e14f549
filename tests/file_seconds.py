"""Seconds each test file takes, read from a pytest ``--durations=0`` log: the order of ``make test``.

``make test`` hands whole files to its worker processes (``--dist loadfile``). A file handed out
last keeps one worker busy while the others idle, so ``conftest.py`` hands out the longest files
first (longest-processing-time order), by the seconds in ``tests/fixtures/file_seconds.json``.
Stale numbers change only the order, never what runs. Re-record them after a change that moves
a file's time a lot::

    .venv/bin/python -m pytest -m "not slow" -q --durations=0 -n 2 --dist loadfile > LOG
    .venv/bin/python tests/file_seconds.py LOG
"""

from __future__ import annotations

import json
import re
import sys
from collections import defaultdict
from pathlib import Path

TABLE = Path(__file__).parent / "fixtures" / "file_seconds.json"
# a file the table does not know yet: about the median file
UNKNOWN_S = 5.0
_ROW = re.compile(r"^([0-9.]+)s +(?:setup|call|teardown) +tests/([^:]+)::")


def seconds_per_file(log: str) -> dict[str, float]:
    """Setup, call and teardown seconds summed per test file (``test_x.py``) from a durations log."""
    out: dict[str, float] = defaultdict(float)
    for line in log.splitlines():
        m = _ROW.match(line)
        if m:
            out[m.group(2)] += float(m.group(1))
    return {k: round(v, 1) for k, v in sorted(out.items())}


def load_table(path: Path = TABLE) -> dict[str, float]:
    """The recorded seconds per file; empty where the table is missing (then collection order stays)."""
    return json.loads(path.read_text())["files"] if path.is_file() else {}


def file_weight(nodeid: str, table: dict[str, float]) -> float:
    """The seconds recorded for a test's file, ``UNKNOWN_S`` for a file not in the table."""
    name = nodeid.split("::", 1)[0].rsplit("/", 1)[-1]
    return table.get(name, UNKNOWN_S)


if __name__ == "__main__":  # pragma: no cover - re-records the table
    if len(sys.argv) != 2:
        sys.exit("usage: tests/file_seconds.py DURATIONS_LOG")
    files = seconds_per_file(Path(sys.argv[1]).read_text())
    if not files:
        sys.exit(f"{sys.argv[1]}: no duration rows (run pytest with --durations=0)")
    TABLE.write_text(json.dumps({"about": "seconds per test file in make test, from tests/file_seconds.py; "
                                 "only the order matters", "files": files}, indent=1) + "\n")
    print(f"{TABLE}: {len(files)} files, {sum(files.values()):.0f} s")
