"""The seed runs behind Fig. 4: one ``python -m realize`` subprocess per seed.

What it does: ``launch_runs(seeds, root)`` runs ``realize`` once per seed into ``<root>/seed<S>``
(``jobs`` at a time; each run's output goes to ``<root>/seed<S>.log``), keeps runs whose
``result.json`` says ``done`` (unless ``force``) and resumes interrupted ones
(``run_command``); ``run_status`` reads a run directory's status.
What it doesn't: plot (``realize.figures.fig4``) or simulate in this process.
"""

from __future__ import annotations

import os
import subprocess
import sys
from collections.abc import Callable, Mapping, Sequence
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

from realize.run_dir.directory import RunDir

__all__ = ["run_status", "run_command", "launch_runs"]


def _hydra_value(path: Path) -> str:
    """A path as a Hydra override value (quoted if it holds characters Hydra would parse)."""
    s = str(path)
    safe = all(ch.isalnum() or ch in "/._-~+:" for ch in s)
    return s if safe else "'" + s.replace("\\", "\\\\").replace("'", "\\'") + "'"


def run_status(run_dir: str | Path) -> str | None:
    """``status`` of a run directory's ``result.json`` (``done``, ``running``, ``interrupted``,
    ``failed``), ``"unknown"`` if it has none, ``None`` without a readable ``result.json``."""
    return RunDir(run_dir).status()


def run_command(
    seed: int,
    run_dir: str | Path,
    experiment: str = "seed_paper",
    overrides: Sequence[str] = (),
    module: str = "realize",
    python: str | None = None,
) -> list[str]:
    """The command line of one run: ``python -m realize experiment=E seed=S hydra.run.dir=D``;
    an interrupted run (its ``checkpoint.json`` exists, status not ``done``/``failed``) is
    continued with ``resume=D`` instead."""
    py = python or sys.executable
    run_dir = Path(run_dir)
    if run_status(run_dir) in ("running", "interrupted") and RunDir(run_dir).checkpoint_path.is_file():
        return [py, "-m", module, f"resume={_hydra_value(run_dir)}", f"hydra.run.dir={_hydra_value(run_dir)}"]
    return [py, "-m", module, f"experiment={experiment}", f"seed={int(seed)}",
            f"hydra.run.dir={_hydra_value(run_dir)}", *overrides]


def launch_runs(
    seeds: Sequence[int],
    root: str | Path,
    experiment: str = "seed_paper",
    overrides: Sequence[str] = (),
    *,
    module: str = "realize",
    jobs: int = 1,
    force: bool = False,
    env: Mapping[str, str] | None = None,
    echo: Callable[[str], None] = print,
) -> tuple[list[Path], list[tuple[int, int]]]:
    """Run ``realize`` once per seed into ``<root>/seed<S>`` (subprocesses, ``jobs`` at a time; the
    output of each goes to ``<root>/seed<S>.log``). Runs whose ``result.json`` says ``done`` are
    kept unless ``force``; interrupted ones are resumed. Returns the run directories that
    finished (status ``done``) and ``(seed, exit code)`` of those that did not."""
    root = Path(root)
    root.mkdir(parents=True, exist_ok=True)
    run_env = dict(os.environ if env is None else env)

    def one(seed: int) -> tuple[int, Path, int]:
        d = root / f"seed{seed}"
        if not force and run_status(d) == "done":
            echo(f"seed {seed}: {d} already done, kept")
            return seed, d, 0
        cmd = run_command(seed, d, experiment, overrides, module=module)
        echo(f"seed {seed}: {' '.join(cmd[1:])}")
        with (root / f"seed{seed}.log").open("w") as logf:
            rc = subprocess.run(cmd, stdout=logf, stderr=subprocess.STDOUT, env=run_env, check=False).returncode
        echo(f"seed {seed}: exit code {rc}, status {run_status(d)}")
        return seed, d, rc

    with ThreadPoolExecutor(max_workers=max(1, int(jobs))) as ex:
        results = list(ex.map(one, [int(s) for s in seeds]))
    done = [d for _, d, _ in results if run_status(d) == "done"]
    failed = [(s, rc) for s, d, rc in results if run_status(d) != "done"]
    return done, failed
