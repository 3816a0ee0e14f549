"""One ``realize`` run in one call: ``run(cfg, out_dir)``, what the command line does.

What it does: builds a ``realize.run.planner.Planner`` of ``cfg`` (the command line's overrides
checked when resuming), runs its ``plan`` into ``out_dir`` and closes it; returns the run's
``RunOutcome``. SIGINT/SIGTERM end a run as ``interrupted`` (exit code 130/143).
What it doesn't: assemble or execute the run (``realize.run.assembly``), or keep workers between
runs (a ``Planner`` does).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

from omegaconf import DictConfig

from realize.run.assembly import RESUME_ALLOWED_PREFIXES, RunOutcome, plain_config, prepare_run
from realize.run.planner import Planner

__all__ = ["run", "RunOutcome", "RESUME_ALLOWED_PREFIXES", "plain_config", "prepare_run"]


def run(
    cfg: DictConfig | Mapping[str, Any],
    out_dir: Path | str,
    *,
    cli_overrides: Sequence[str] = (),
    after_iteration: Callable[[int], None] | None = None,
) -> RunOutcome:
    """One realize run into ``out_dir`` (or into the resumed run's directory), through
    ``Planner`` (one path for the command line and the Python API).

    ``cfg`` is the composed config (Hydra's, without the ``hydra`` node, or plain data);
    ``cli_overrides`` the command-line overrides (checked when resuming); ``after_iteration(i)``
    is called after iteration ``i`` (counted over the whole run) is on disk (tests use it to
    interrupt a run). Raises ``ConfigError`` (nothing simulated) for bad input.
    """
    with Planner(cfg, cli_overrides=cli_overrides) as planner:
        return planner.plan(out_dir, after_iteration=after_iteration).outcome
