"""Every command block of the docs (README.md and docs/*.md) says what runs it, and what it
says holds. The line before each ```bash, ```python or ```yaml block is a marker
(``helpers.MARKER``): the block runs in a named test (which reads that page), or it is not run,
with a reason. A block whose marker adds "arguments checked" has every command checked here
without running it:

- ``realize ...``: the command line's own edge (``realize.cli.main.preflight``: group choices,
  key names, run directories, every job of a sweep) and, for a single run, the composed config
  validated (``check_sweep``, which reads a warm start's files); nothing is simulated;
- ``python scripts/X.py ...``: the script's own argument parser, in one child process that stops
  each script once its arguments are parsed;
- ``make X``: the Makefile has the target.

Placeholders (``RUN``, ``outputs/.../RUN``, a dated run directory, ``state.json``, ``my_task.yaml``) stand for real
files: the run that the README's Python quickstart writes (run here, at its own small budget),
the grasped state fixture, and the task file example of docs/task_files.md. Pictures and trees
are ```text blocks. What this does not do: run the searches the commands describe (minutes
each), or check prose outside the fences.
"""

from __future__ import annotations

import json
import os
import re
import shlex
import subprocess
import sys
from pathlib import Path

import pytest

from helpers import DOC_PAGES, REPO, DocBlock, doc_block, doc_blocks
from realize.cli.main import preflight
from realize.cli.sweep_check import check_sweep
from realize.config import ConfigError
from realize.run_dir.names import RESULT_FILE

COMMAND_LANGS = {"bash", "python", "yaml"}
STATE = Path(__file__).parent / "fixtures" / "state_grasped.json"


def _blocks() -> list[DocBlock]:
    return [b for page in DOC_PAGES for b in doc_blocks(page)]


def test_every_block_says_what_runs_it() -> None:
    problems = []
    for b in _blocks():
        m = b.marker
        if b.lang not in COMMAND_LANGS | {"text"}:
            problems.append(f"{b.where}: a fence needs a language: bash, python, yaml, or text (a picture, a tree)")
        elif b.lang != "text" and m is None:
            problems.append(f"{b.where}: no marker on the line before the block (tests/helpers.py MARKER)")
        elif m is not None and m["test"]:
            path, name = m["test"].split("::")
            source = (REPO / path).read_text() if (REPO / path).is_file() else ""
            if f"def {name}(" not in source:
                problems.append(f"{b.where}: {m['test']} does not exist")
            elif Path(b.page).name not in source:
                problems.append(f"{b.where}: {path} never names {Path(b.page).name}, so it cannot run the block")
        elif m is not None and m["checked"] and b.lang != "bash":
            problems.append(f"{b.where}: only bash blocks have their arguments checked")
    assert not problems, "\n".join(problems)


# ------------------------------------------------------------------------------ the Python quickstart
@pytest.fixture(scope="module")
def quickstart_run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The README's Python quickstart, run as written in a fresh directory: its run directory."""
    code = doc_block("README.md", "python").text
    where = tmp_path_factory.mktemp("quickstart")
    here = os.getcwd()
    os.chdir(where)
    try:
        exec(compile(code, "README.md:Python quickstart", "exec"), {"__name__": "__readme__"})
    finally:
        os.chdir(here)
    return where / "outputs" / "api_example"


@pytest.mark.slow  # a whole stitched run: make test keeps one (tests/test_golden_default.py) and
# the Python API's (tests/test_stitched_run.py)
def test_python_quickstart_runs(quickstart_run: Path) -> None:
    """README.md's Python quickstart writes its run; docs/python_api.md shows the same code."""
    doc = json.loads((quickstart_run / RESULT_FILE).read_text())
    # experiment=seed_paper searches stitched segments: 2 prefix batches, 1 suffix batch, the confirmation
    assert doc["status"] == "done" and doc["iterations_done"] == doc["iterations"] == 4 and doc["feasible"]
    assert doc_block("docs/python_api.md", "python").text == doc_block("README.md", "python").text


# ------------------------------------------------------------------------------ the checked commands
def _commands(text: str) -> list[list[str]]:
    """The command lines of a bash block as argument lists: continuations joined, comments and
    ``NAME=value`` assignments dropped."""
    lines = []
    for line in text.replace("\\\n", " ").splitlines():
        tokens = shlex.split(line, comments=True)
        if tokens and not re.fullmatch(r"[A-Z_]+=\S*", tokens[0]):
            lines.append(tokens)
    return lines


def _substitute(tokens: list[str], files: dict[str, Path]) -> list[str]:
    """The placeholders of a command (module docstring) replaced by the real files."""
    out = []
    for t in tokens:
        for name, path in files.items():
            t = re.sub(rf"(?<![\w./-]){re.escape(name)}(?![\w.-])", str(path), t)
        out.append(t)
    return out


def _check_realize(args: list[str]) -> str:
    """'' if the command line's edge accepts ``args``; else what it said."""
    try:
        preflight(list(args))
        plain = [a for a in args if not a.startswith("-")]
        if "-m" not in args and "--multirun" not in args and not any(a.startswith("resume=") for a in args):
            check_sweep(plain)  # one job: composed, validated, a warm start's files read
    except ConfigError as e:
        return f"error: {e}"
    return ""


# each script, run to the end of its argument parsing and no further (module docstring)
PARSE_ONLY = r"""
import argparse, contextlib, io, json, runpy, sys

class Parsed(Exception):
    pass

parse_args, parse_known_args = argparse.ArgumentParser.parse_args, argparse.ArgumentParser.parse_known_args
depth = [0]

def stop_after(parse):
    def parse_then_stop(self, *a, **k):
        if depth[0]:
            return parse(self, *a, **k)
        depth[0] += 1
        try:
            parse(self, *a, **k)
        finally:
            depth[0] -= 1
        raise Parsed
    return parse_then_stop

argparse.ArgumentParser.parse_args = stop_after(parse_args)
argparse.ArgumentParser.parse_known_args = stop_after(parse_known_args)
said = []
for argv in json.loads(sys.argv[1]):
    sys.argv, err = list(argv), io.StringIO()
    try:
        with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
            runpy.run_path(argv[0], run_name="__main__")
        said.append("it ran to the end without parsing its arguments")
    except Parsed:
        said.append("")
    except SystemExit as e:
        said.append(f"exit {e.code}: {err.getvalue().strip()[-400:]}")
    except BaseException as e:
        said.append(f"{type(e).__name__}: {e}")
print("SAID" + json.dumps(said))
"""


@pytest.mark.slow  # a whole run or several processes: make test-all (make test keeps a smoke test)
def test_checked_commands_are_accepted(quickstart_run: Path, tmp_path: Path) -> None:
    task_file = tmp_path / "my_task.yaml"
    task_file.write_text(doc_block("docs/task_files.md", "yaml").text)
    files = {"outputs/.../RUN": quickstart_run, "$RUN": quickstart_run, "RUN": quickstart_run,
             "REPLAN_RUN": quickstart_run,
             "outputs/2026-11-23/10-00-00": quickstart_run, "runs/seed0": quickstart_run, "state.json": STATE,
             "my_task.yaml": task_file, "multirun/<date>/<time>": tmp_path}
    targets = set(re.findall(r"^([\w-]+):", (REPO / "Makefile").read_text(), re.M))
    problems, scripts = [], []
    checked = [b for b in _blocks() if b.marker is not None and b.marker["checked"]]
    assert checked
    for b in checked:
        for tokens in _commands(b.text):
            tokens = _substitute(tokens, files)
            head = tokens[0]
            if Path(head).name == "realize":
                said = _check_realize(tokens[1:])
            elif Path(head).name.startswith("python") and len(tokens) > 1 and tokens[1].startswith("scripts/"):
                scripts.append((b.where, tokens[1:]))
                continue
            elif head == "make":
                said = "" if all(t in targets for t in tokens[1:]) else f"the Makefile has no target {tokens[1:]}"
            else:
                said = "not a realize, scripts/ or make command: mark the block 'not run' instead"
            if said:
                problems.append(f"{b.where}: {shlex.join(tokens)}\n    {said}")
    r = subprocess.run([sys.executable, "-c", PARSE_ONLY, json.dumps([argv for _, argv in scripts])], cwd=REPO,
                       capture_output=True, text=True, timeout=300)
    assert r.returncode == 0 and "SAID" in r.stdout, r.stderr[-3000:]
    for (where, argv), said in zip(scripts, json.loads(r.stdout.split("SAID", 1)[1])):
        if said:
            problems.append(f"{where}: python {shlex.join(argv)}\n    {said}")
    assert not problems, "\n".join(problems)


@pytest.mark.slow  # the guard of test_checked_commands_are_accepted (slow), on the quickstart's run
def test_a_wrong_command_is_caught(quickstart_run: Path) -> None:
    """The check can fail: a misspelled key, a missing run, an unknown script flag."""
    assert "did you mean" in _check_realize(["ce.n_envz=3"])
    assert "not a realize run directory" in _check_realize([f"resume={quickstart_run / 'nope'}"])
    assert _check_realize([f"warm_start={quickstart_run}", "ce.iterations=3"]) == ""
    r = subprocess.run([sys.executable, "-c", PARSE_ONLY, json.dumps([["scripts/replay.py", "--no-such-flag"]])],
                       cwd=REPO, capture_output=True, text=True, timeout=300)
    assert json.loads(r.stdout.split("SAID", 1)[1])[0].startswith("exit 2")
