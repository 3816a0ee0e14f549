"""The ``logging``, ``validation`` and ``replan`` config groups: what a run writes, how it validates,
and where a replan starts.

What it does: ``LoggingSettings`` (the Hydra ``logging`` group: the rerun recording, its file,
the sample trajectories, the progress bar) and ``ValidationSettings`` (the ``validation`` group:
after the search the run's K cheapest distinct feasible plans meet the task's perturbation
model, R replicas each, and the plan returned is the cheapest whose 95 % Wilson lower bound
reaches ``min_success``, else the most robust; ``replicas: 0``, or ``validation=off``, turns it
off), and ``ReplanSettings`` (the ``replan`` group: the action and state a replan of
``replan_from`` starts from). The classes' defaults are their groups' one option, ``default``
(``realize.spec.hydra_edge.register_schema``), so they are written here only. This module imports
nothing heavy: the config edge reads it before anything is simulated.
What it doesn't: validate (``realize.validation.candidates``) or write anything
(``realize.sinks``); ``realize.spec.run_spec`` reads the groups with these classes.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from realize.config import Settings, setting

__all__ = ["LoggingSettings", "ValidationSettings", "ReplanSettings"]


def _check_rrd(name: str) -> str | None:
    if Path(name).is_absolute() or ".." in Path(name).parts or not name.endswith(".rrd"):
        return "a file name ending in .rrd inside the run directory"
    return None


@dataclass
class LoggingSettings(Settings):
    """Hydra ``logging`` group: what a run writes besides result.json/history/checkpoint."""

    config_key = "logging"

    rerun: bool = True  # write a rerun recording (.rrd) in the run directory (no viewer needed)
    rrd: str = setting("realize.rrd", check=_check_rrd)  # its file name (relative to the run directory)
    # record sample trajectories (base, end effector, objects) in the rollout: the rerun scene view
    # and trajectories_iter{k}.npz per iteration (paper Fig. 2; about 2 MB per 200 plans)
    record: bool = True
    progress: bool = True  # tqdm progress bar per CE iteration (success share, best cost)


@dataclass
class ValidationSettings(Settings):
    """Hydra ``validation`` group (module docstring; ``realize.validation.candidates``, called
    by ``realize.run.one_run``). These defaults are also the ones a config without the group gets; a
    run saved before the group existed reads as ``replicas: 0`` (``realize.run_dir.upgrade``), as
    it ran. 64 x 5 replicas add about a sixth to a seed-paper run (docs/validation.md)."""

    config_key = "validation"

    replicas: int = setting(64, ge=0)  # R replicas of the task's perturbations per candidate (0: off)
    candidates: int = setting(5, ge=1)  # K cheapest distinct feasible samples of the last iterations
    min_success: float = setting(0.9, ge=0, le=1)  # return the cheapest whose 95 % lower bound reaches this
    # the last iterations the candidates come from (the run's best joins them where it came earlier)
    iterations: int = setting(3, ge=1)


@dataclass
class ReplanSettings(Settings):
    """The ``replan`` keys (with the top-level ``replan_from``)."""

    config_key = "replan"

    action: int | None = setting(None, ge=0, help="the first action to realize again (0-based)")
    state: str | None = None  # the scene state file the remaining actions start from
    warm: bool = True  # start from the earlier run's distribution of the remaining actions (else uniform)
