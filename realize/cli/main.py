"""The ``realize`` command: check the command line, hand it to Hydra, run, exit with a clear code.

What it does: ``main()`` (console script ``realize`` and ``python -m realize``) runs
``preflight`` on the arguments (config group choices such as ``experiment=``, a ``resume=`` or
``replan_from=`` directory, and, for a single run, the whole composition), then Hydra, whose
task function calls ``realize.run.one_run.run``. Bad input ends with one line ``error: <message>`` on stderr and exit code 2
(``realize.run.guard.EXIT_CONFIG``) before any simulator is built; a sweep (``-m``) has every
job's config checked first (``realize.cli.sweep_check``), and a job that still fails on its
config when it starts is marked failed by Hydra (``SweepJobConfigError``) while the other jobs run. An interrupted run
exits with 130 (SIGINT) or 143 (SIGTERM); an interrupted sweep stops.
What it doesn't: validate the config itself (``realize.spec.run_spec``) or run anything
(``realize.run.one_run``).
"""

from __future__ import annotations

import logging
import sys
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from hydra.errors import CompactHydraException
from omegaconf import DictConfig

from realize.spec.keys import check_override_keys
from realize.spec.compose import CONFIG_GROUPS, check_group_choices, compose_or_error, override_values, parse_overrides
from realize.config import ConfigError
from realize.run.guard import EXIT_CONFIG, EXIT_FAILED
from realize.paths import CONFIG_DIR
from realize.cli.sweep_check import check_sweep
from realize.run_dir.names import CHECKPOINT_FILE, RESULT_FILE
from realize.workers.errors import WorkerFailed

__all__ = ["main", "preflight", "SweepJobConfigError", "CONFIG_GROUPS"]


class SweepJobConfigError(CompactHydraException):
    """A sweep job's ``ConfigError``: Hydra marks the job failed and prints just the message."""

    def __init__(self, error: ConfigError) -> None:
        super().__init__(f"error: {error}")
        self.error = error


def preflight(args: list[str]) -> list[str]:
    """Check the command line before Hydra runs; returns the (possibly extended) arguments.

    Checks config group choices (``experiment=foo`` -> one-line error listing the presets), that
    every key exists (``secne=wall`` -> "did you mean 'scene'", ``realize.spec.keys``) and
    ``resume=`` (must be a run directory); a resumed single run writes its Hydra files into
    the resumed directory. A sweep has every job's config validated (``check_sweep``). For a single run without Hydra flags it also composes the config
    once, so composition errors become one line too.
    """
    flags = [a for a in args if a.startswith("-")]
    plain = [a for a in args if not a.startswith("-")]
    if any(f not in ("-m", "--multirun") for f in flags):
        if any(f in ("--cfg", "-c") for f in flags) and any(a.startswith("task_file=") for a in plain):
            print("note: --cfg shows the task group; task_file replaces it when the run starts (result.json's "
                  "config.task then holds the file's content)", file=sys.stderr, flush=True)
        return args  # --cfg, --config-dir, --help, ...: Hydra's own business (and its own checks)
    multirun = bool(flags)
    parsed = parse_overrides(plain)
    resume_dir: str | None = None
    has_run_dir = False
    # config dirs added through hydra.searchpath may hold more group options than configs/ does
    check_groups = not any(o.key_or_group.startswith("hydra.searchpath") for o in parsed)
    for o in parsed:
        key = o.key_or_group
        if key == "hydra.run.dir":
            has_run_dir = True
        if o.is_delete():
            continue
        values = override_values(o)
        if key == "resume":
            for v in values:
                if v in ("null", "None"):
                    continue
                if not (Path(v) / CHECKPOINT_FILE).is_file():
                    raise ConfigError(f"resume: {v} is not a realize run directory (no {CHECKPOINT_FILE})")
                resume_dir = v
        if key == "replan_from":
            for v in values:
                if v not in ("null", "None") and not (Path(v) / RESULT_FILE).is_file():
                    raise ConfigError(f"replan_from: {v} is not a realize run directory (no {RESULT_FILE})")
    if check_groups:  # experiment=foo; secne=wall, ce.n_envz=3: one line with the closest known names
        check_group_choices(parsed)
        check_override_keys(parsed, CONFIG_GROUPS)
        if multirun:  # ce.n_envs=20,abc: refused before job 0 simulates
            check_sweep(plain)
    if resume_dir is not None and not multirun and not has_run_dir:
        stamp = time.strftime("%Y%m%d-%H%M%S")
        args = args + [f"hydra.run.dir={resume_dir}", f"hydra.output_subdir=.hydra/resume-{stamp}"]
    if not flags and not multirun:
        _trial_compose([a for a in args if not a.startswith("-")])
    return args


def _trial_compose(overrides: list[str]) -> None:
    """Compose once; composition errors become one ``ConfigError``."""
    compose_or_error(overrides)


def _hydra_task(cfg: DictConfig) -> Any:
    from hydra.core.hydra_config import HydraConfig
    from hydra.types import RunMode

    hc = HydraConfig.get()
    multirun = hc.mode == RunMode.MULTIRUN
    out_dir = Path(hc.runtime.output_dir)
    # imported here, not at the top: a refused command never imports the simulator. Hydra's job
    # logging is on by now, so matplotlib's one-time font-cache note would reach the console
    logging.getLogger("matplotlib").setLevel(logging.WARNING)
    from realize.run.one_run import run

    try:
        outcome = run(cfg, out_dir, cli_overrides=list(hc.overrides.task))
    except ConfigError as e:
        if multirun:  # Hydra records the job as failed; the other jobs still run
            raise SweepJobConfigError(e) from None
        print(f"error: {e}", file=sys.stderr, flush=True)
        sys.exit(EXIT_CONFIG)
    except WorkerFailed as e:  # the run's files (error.txt included) are written; no traceback here
        print(f"error: {e}", file=sys.stderr, flush=True)
        if multirun:
            raise
        sys.exit(EXIT_FAILED)
    if outcome.interrupted:
        if multirun:
            raise KeyboardInterrupt  # stop the sweep, as a user's Ctrl-C means
        sys.exit(outcome.exit_code)
    return outcome.objective  # what a sweeper minimizes (hydra/sweeper=optuna; realize.run.objective)


def main(argv: Sequence[str] | None = None) -> None:
    """Console entry point: ``realize [overrides]`` / ``python -m realize [overrides]``."""
    import hydra

    args = list(sys.argv[1:] if argv is None else argv)
    try:
        args = preflight(args)
    except ConfigError as e:
        print(f"error: {e}", file=sys.stderr, flush=True)
        sys.exit(EXIT_CONFIG)
    sys.argv = [sys.argv[0] if sys.argv else "realize"] + args
    entry = hydra.main(config_path=str(CONFIG_DIR), config_name="config", version_base="1.3")(_hydra_task)
    entry()


if __name__ == "__main__":  # pragma: no cover
    main()
