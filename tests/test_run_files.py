"""The README's list of a run's files equals what a run writes: every entry of a run directory
(a command-line run with two rollout workers) is on the list, and every name on the list is one
the code writes (its file-name constants). The list is the README's bullets after "A run writes
to"; ``{k}`` / ``{i}`` stand for numbers and ``<time>`` for a time stamp."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from helpers import REPO, realize_cli, tiny
from realize.repair.study import EXECUTION_DIR
from realize.spec.run_settings import LoggingSettings
from realize.recording.validation_log import VALIDATION_RRD
from realize.run_dir.names import (CHECKPOINT_FILE, ERROR_FILE, HISTORY_FILE, JOB_STATUS_FILE, RESULT_FILE, SCENE_FILE,
                                   WORKER_LOG_DIR, candidate_file, trajectories_name)
from realize.sinks.rerun import recording_name

RRD = LoggingSettings().rrd  # the logging group's default file name
# what the code names: one example of every kind of entry a run directory can hold
WRITTEN_BY_THE_CODE = [
    RESULT_FILE, HISTORY_FILE, CHECKPOINT_FILE, SCENE_FILE, trajectories_name(3), RRD, recording_name(RRD, None, 2),
    "realize.log", ".hydra/", VALIDATION_RRD, WORKER_LOG_DIR + "/", ERROR_FILE, candidate_file(HISTORY_FILE, 1),
    recording_name(RRD, 1, 0), JOB_STATUS_FILE, "figures/", "replans/", EXECUTION_DIR + "/",
]


def readme_run_files() -> list[str]:
    """The names of the README's bullet list after 'A run writes to' (first backticked names
    of each bullet)."""
    lines = (REPO / "README.md").read_text().splitlines()
    start = next(i for i, ln in enumerate(lines) if ln.startswith("A run writes to"))
    names: list[str] = []
    for ln in lines[start + 1:]:
        if names and not ln.startswith("- "):
            break
        if ln.startswith("- "):
            head = ln[2:].split(":", 1)[0]
            names += re.findall(r"`([^`]+)`", head)
    return names


def _pattern(name: str) -> re.Pattern[str]:
    text = re.escape(name).replace(r"\{k\}", r"\d+").replace(r"\{i\}", r"\d+")
    return re.compile(text + ("" if name.endswith("/") else r"$"))


def _listed(entry: str, names: list[str]) -> bool:
    return any(_pattern(n).match(entry) for n in names)


def test_readme_lists_only_what_the_code_writes() -> None:
    names = readme_run_files()
    assert len(names) >= 10, names
    unknown = [n for n in names if not any(_pattern(n).match(w) for w in WRITTEN_BY_THE_CODE)]
    assert not unknown, f"the README lists files the code does not write: {unknown}"
    missing = [w for w in WRITTEN_BY_THE_CODE if not _listed(w, names)]
    assert not missing, f"the README leaves out {missing}"


@pytest.mark.slow  # a whole run or several processes: make test-all (make test keeps a smoke test)
def test_a_runs_files_are_all_in_the_readme(tmp_path: Path) -> None:
    run_dir = tmp_path / "run"
    p = realize_cli(*tiny(ce__iterations=1, controller__max_time_s=3, logging__rerun="true"), "workers.n=2",
                    "sim.shard_rows=2", f"hydra.run.dir={run_dir}", cwd=tmp_path, timeout=300)
    assert p.returncode == 0, p.stderr[-3000:]
    entries = [e.name + ("/" if e.is_dir() else "") for e in run_dir.iterdir()]
    assert {RESULT_FILE, SCENE_FILE, "realize.log", RRD, WORKER_LOG_DIR + "/"} <= set(entries)
    names = readme_run_files()
    assert not [e for e in entries if not _listed(e, names)], f"not in the README's list: {entries}"
