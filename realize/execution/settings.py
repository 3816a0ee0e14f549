"""The settings of an execution (an ``execute`` preset, ``configs/execute/*.yaml``), read and checked.

What it does: ``ExecuteSettings`` holds how many worlds to execute in (``worlds``), their
``seed``, ``max_replans`` per world, the ``time_limit_s`` of control time per world,
``monitor_every`` (control steps between the executor's checks), the ``tolerance`` of each
check (``Tolerance``: object, table and base distances in m) and the raw ``disturbances`` list
(checked against the scene and plan by ``realize.execution.disturbances.read_disturbances``
once they are known), the observation model ``noise``
(``realize.execution.perception.Noise``; all zero: the robot sees its world exactly), the check
before a repair (``precheck``: ``PrecheckSettings``) and what the world does while the planner thinks
(``think``: ``measured``, the replan's own wall time in control steps; ``frozen``, the world
waits; or a number of control steps, fixed, so that a study repeats bit for bit), and
``pickup_m``, the radii of the base annulus from which a re-sequence picks an object off the
floor (``realize.repair.resequence``), and ``budget``, the search of each replan
(``realize.execution.replan_budget.ReplanBudget``). Unknown keys and bad values are one-line ``ConfigError``\\ s naming the
key. ``load_preset(name)`` reads ``configs/execute/<name>.yaml`` (or a path to a YAML file)
over these defaults; a study's config is composed by Hydra (``configs/execution.yaml``: the
``execute`` and ``noise`` groups, ``realize.spec.execution_config.compose_execution``), which
gives the same settings for a preset.
What it doesn't: check disturbances against a scene (that needs the run's geometry and plan), or
execute anything.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, ClassVar

from realize.config import Settings, read_preset, setting
from realize.execution.perception import Noise
from realize.execution.replan_budget import ReplanBudget
from realize.paths import CONFIG_DIR

__all__ = ["Tolerance", "PrecheckSettings", "ExecuteSettings", "PRESET_DIR", "presets", "load_preset"]

PRESET_DIR = CONFIG_DIR / "execute"


@dataclass
class Tolerance(Settings):
    """How far the observed world may be from the plan's belief before the monitor reports it (m).

    ``object_m``: an object the remaining actions act on (the plan tracks objects, so a few cm
    need no replan: the seed plan reaches the goal with the cube anywhere within +-25 cm);
    ``table_m``: a table's centre; ``base_m``: the base from its target at a move_to's end
    (the move_to's own success tolerance is ``controller.move_tolerance``, 0.1 m)."""

    config_key: ClassVar[str] = "execute.tolerance"

    object_m: float = setting(0.3, gt=0)
    table_m: float = setting(0.05, gt=0)
    base_m: float = setting(0.15, gt=0)


@dataclass
class PrecheckSettings(Settings):
    """Before a repair: the remaining plan simulated from the believed state in ``copies``
    copies (the belief's objects scattered by ``scatter_m``, each copy's friction and mass
    drawn from the task's perturbation model); it goes on unchanged where at least
    ``min_success`` of them reach the goal. ``copies: 0``: no check (every deviation repairs)."""

    config_key: ClassVar[str] = "execute.precheck"

    copies: int = setting(8, ge=0)
    min_success: float = setting(0.75, gt=0, le=1)
    scatter_m: float = setting(0.01, ge=0)


def _think(v: Any) -> str | None:
    if v in ("measured", "frozen") or (isinstance(v, int) and not isinstance(v, bool) and v >= 0):
        return None
    return "must be measured, frozen or a number of control steps >= 0"


def _pickup(v: Any) -> str | None:
    ok = isinstance(v, (list, tuple)) and len(v) == 2 and all(isinstance(x, (int, float)) and not isinstance(x, bool)
                                                               for x in v) and 0 < v[0] < v[1]
    return None if ok else "must be [r_min, r_max] in m with 0 < r_min < r_max"


@dataclass
class ExecuteSettings(Settings):
    """One execution study (module docstring)."""

    config_key: ClassVar[str] = "execute"

    worlds: int = setting(16, ge=1)
    seed: int = setting(0, ge=0)
    max_replans: int = setting(3, ge=0)
    time_limit_s: float = setting(180.0, gt=0)
    monitor_every: int = setting(5, ge=1)  # control steps between checks (and at every action's end)
    tolerance: Tolerance = field(default_factory=Tolerance)
    noise: Noise = field(default_factory=Noise)
    precheck: PrecheckSettings = field(default_factory=PrecheckSettings)
    pickup_m: list[float] = setting(default_factory=lambda: [0.45, 0.75], check=_pickup)  # base annulus around an object on the floor
    think: Any = setting("measured", check=_think)  # the world while the planner thinks (module docstring)
    budget: ReplanBudget = field(default_factory=ReplanBudget)  # each replan's search
    # rad: a repair of a plan that stacks sets a held box down level, turning the hand by at most
    # this (controller.place_level; realize.repair.on_deviation.stack_changes); null: as the run's controller
    stack_level_rad: float | None = setting(0.8, ge=0)
    # a repair of a plan that stacks also keeps the fabric off the movable objects where they stand
    # (controller.avoid_movable): its carries go around the tower it rebuilds; false: as the run's controller
    stack_avoid_movable: bool = True
    disturbances: list[Any] = field(default_factory=list)  # raw entries: realize.execution.disturbances


def presets() -> list[str]:
    """The preset names of ``configs/execute/``."""
    return sorted(p.stem for p in PRESET_DIR.glob("*.yaml"))


def load_preset(name: str | Path) -> ExecuteSettings:
    """``configs/execute/<name>.yaml`` (or the YAML file ``name``) as ``ExecuteSettings``."""
    d, stem = read_preset(name, PRESET_DIR, "execute preset")
    return ExecuteSettings.from_mapping(d, f"execute[{stem}]")
