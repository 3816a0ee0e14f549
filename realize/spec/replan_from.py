"""Replan from a state: realize the rest of an earlier run's plan, from where execution stands.

``realize replan_from=RUN_DIR replan.action=K replan.state=FILE [changes of the world]`` runs a
search over the parameters of actions ``K, K+1, ...`` (0-based) of RUN_DIR's plan only, every
rollout starting from the scene state in FILE (``realize.world.state``; written by
``scripts/replay.py RUN_DIR --state-at K --state-out FILE``, by a robot, or by hand).

What it does:
  * ``replan_config(current, overrides)``: the config of a replan run: RUN_DIR's saved config
    (as ``resume=`` uses it) with the command line's overrides on top, each taken from the
    composed command line (``scene.tables.1.center=[0.3,-1.2]``, ``task.params.Table2.center=...``,
    ``ce.n_envs=100``, ``seed=1``, ``scene=wall``, ...). What would change the plan itself
    (``task=``, ``task_file``, ``task.plan``, ``task.goal``, ``task.planner``, ``experiment=``)
    and deletions are refused: a replan continues that run's plan;
  * ``read_replan(...)``: the ``replan`` keys checked into a ``ReplanSpec`` (run directory,
    action, state file and state, the plans) and the suffix task (``realize.tasks.suffix``),
    with one-line ``ConfigError``s: a missing run directory, K out of range, a missing or bad
    state file, a state the remaining actions cannot start from;
  * the search starts from RUN_DIR's final distribution of the remaining actions' parameters
    (``replan.warm: true``, the default; ``realize.search.warm_start``: the marginal over their
    columns, moved with the objects their regions follow, widened); ``replan.warm=false``
    samples iteration 0 uniformly, as a cold run does.
What it doesn't: simulate, or write result.json (``realize.run.assembly`` adds ``ReplanSpec.to_json``
under the key ``replan``).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from realize.spec.run_settings import ReplanSettings
from realize.config import ConfigError, as_mapping
from realize.world.state import SceneState, load_state
from realize.tasks.spec import TaskSpec
from realize.tasks.suffix import check_suffix_start, task_suffix

__all__ = ["ReplanSettings", "ReplanSpec", "replan_config", "replan_overrides_config", "one_search", "read_replan",
           "saved_config", "check_no_replan", "REFUSED_OVERRIDES"]

# overrides a replan refuses: they would change the plan, not the world or the search
REFUSED_OVERRIDES = ("task", "task_file", "task.plan", "task.goal", "task.planner", "task.name", "experiment",
                     "resume")


@dataclass(frozen=True)
class ReplanSpec:
    """Where a replan starts: ``run_dir``'s plan from action ``action`` on, in ``state`` (read
    from ``state_file``); ``plan`` is the whole plan, ``remaining`` the realized part, and
    ``columns`` the names of the remaining parameters' columns (the same in the earlier run)."""

    run_dir: str
    action: int
    state_file: str
    state: SceneState
    plan: str
    remaining: str
    columns: tuple[str, ...]
    warm: bool = True  # the search starts from the earlier run's distribution (realize.search.warm_start)

    def to_json(self, warm_start: Any = None) -> dict[str, Any]:
        return {"from": self.run_dir, "action": self.action, "state_file": self.state_file,
                "state": self.state.to_json(), "plan": self.plan, "remaining": self.remaining,
                "columns": list(self.columns), "warm_start": warm_start}


def saved_config(run_dir: str | Path, key: str = "replan_from") -> dict[str, Any]:
    """The resolved config a run directory saved (a deep copy); one ``ConfigError`` line naming
    ``key`` where it has none."""
    from realize.run_dir.directory import RunDir

    try:
        cfg = RunDir.existing(run_dir).config()
    except (FileNotFoundError, OSError, ValueError) as e:
        raise ConfigError(f"{key} = {str(run_dir)!r}: {e}") from None
    if not isinstance(cfg, Mapping) or not cfg:
        raise ConfigError(f"{key} = {str(run_dir)!r}: neither its result.json nor its checkpoint holds a config")
    import json

    return json.loads(json.dumps(dict(cfg)))


def _refused(key: str) -> bool:
    """A group choice or key in ``REFUSED_OVERRIDES``, or a key below one of its dotted keys."""
    return any(key == r or ("." in r and key.startswith(r + ".")) for r in REFUSED_OVERRIDES)


def replan_config(current: Mapping[str, Any], overrides: Sequence[str]) -> dict[str, Any]:
    """The config a replan runs with (module docstring): ``current`` is the composed command
    line (plain data), ``overrides`` its override strings."""
    from hydra.core.override_parser.overrides_parser import OverridesParser
    from omegaconf import OmegaConf

    run_dir = str(current["replan_from"])
    base = OmegaConf.create(saved_config(run_dir))
    cur = OmegaConf.create(dict(current))
    parser = OverridesParser.create()
    for text in overrides:
        try:
            (o,) = parser.parse_overrides([str(text)])
        except Exception:
            raise ConfigError(f"replan_from: cannot parse the override {text!r}") from None
        key = o.key_or_group
        if key.startswith("hydra") or key in ("replan_from", "replan") or key.startswith("replan."):
            continue
        if o.is_delete():
            raise ConfigError(f"replan_from: {text!r}: a replan cannot delete keys of the run's config")
        if _refused(key) or o.package is not None:
            raise ConfigError(f"replan_from: {text!r} would change the plan of {run_dir}; a replan keeps its task "
                              f"(refused: {', '.join(REFUSED_OVERRIDES)}); change the world (scene.*, task.params.*) "
                              "or the search (ce.*, seed) instead")
        value = OmegaConf.select(cur, key, throw_on_missing=False)
        OmegaConf.update(base, key, value, merge=False, force_add=True)
    out = OmegaConf.to_container(base, resolve=True)
    assert isinstance(out, dict)
    out["replan_from"] = run_dir
    out["replan"] = current.get("replan")
    out["resume"] = None
    return one_search(out)


def replan_overrides_config(base: Mapping[str, Any], run_dir: str, changes: Sequence[str], *, action: int,
                            state: str, warm: bool = True, check_plan: bool = True) -> dict[str, Any]:
    """The config of a replan of ``run_dir`` (its saved config ``base``) from action ``action``
    of its plan, starting from the state file ``state``, with ``changes`` (override strings
    whose values are read as the command line reads them) on top: the Python API's side of
    ``replan_config`` (``realize.run.planner.Planner.replan``). What would change the plan is
    refused (``check_plan=False``: the caller sets a new plan itself)."""
    from realize.spec.compose import apply_overrides, parse_overrides

    for o in parse_overrides(changes):
        key = o.key_or_group
        if key.startswith("hydra") or key in ("replan_from", "replan") or key.startswith("replan."):
            raise ConfigError(f"replan: change {o.input_line!r}: the replan itself is set by the call's arguments")
        if check_plan and (_refused(key) or o.package is not None):
            raise ConfigError(f"replan: change {o.input_line!r} would change the plan of {run_dir}; a replan keeps its "
                              f"task (refused: {', '.join(REFUSED_OVERRIDES)}); change the world (scene.*, "
                              "task.params.*) or the search (ce.*, seed) instead")
    out = apply_overrides(base, changes, where="replan: changes")
    out["replan_from"] = str(run_dir)
    out["replan"] = {"action": action, "state": str(state), "warm": bool(warm)}
    out["resume"] = None
    return one_search(out)


def one_search(cfg: dict[str, Any]) -> dict[str, Any]:
    """``cfg`` with stitched segments off (``stitch.enabled``): a replan searches the remaining
    actions with one cross-entropy search, warm-started from the run's final distribution, also
    where the run itself was stitched (``levers=stitched``)."""
    if isinstance(cfg.get("stitch"), Mapping):
        cfg["stitch"] = {**cfg["stitch"], "enabled": False}
    return cfg


def read_replan(replan_from: str, d: Any, task: TaskSpec, top_k: int) -> tuple[TaskSpec, ReplanSpec]:
    """``(suffix task, ReplanSpec)`` of the ``replan`` group ``d`` for ``task`` (the whole plan)."""
    settings = ReplanSettings.from_mapping(as_mapping(d, "replan"), "replan")
    if not Path(replan_from).is_dir():
        raise ConfigError(f"replan_from = {replan_from!r}: no such run directory")
    if top_k > 1:
        raise ConfigError("replan_from: a top-k run (task.planner.top_k > 1) cannot be replanned yet; "
                          "replan a single-plan run")
    if settings.action is None or settings.state is None:
        miss = [k for k, v in (("replan.action", settings.action), ("replan.state", settings.state)) if v is None]
        raise ConfigError(f"replan_from is set but {' and '.join(miss)} not: give the first action to realize "
                          "again (0-based) and the state file it starts from")
    suffix = task_suffix(task, settings.action)
    state = load_state(settings.state, "replan.state")
    check_suffix_start(suffix, state, f"replan (replan.action = {settings.action})")
    spec = ReplanSpec(run_dir=replan_from, action=settings.action, state_file=settings.state, state=state,
                      plan=task.describe(), remaining=suffix.describe(),
                      columns=tuple(suffix.layout.column_names), warm=settings.warm)
    return suffix, spec


def check_no_replan(d: Any) -> None:
    """``replan.*`` set without ``replan_from``: refused (it would be silently ignored)."""
    settings = ReplanSettings.from_mapping(as_mapping(d, "replan"), "replan")
    if settings.action is not None or settings.state is not None:
        raise ConfigError("replan.action / replan.state are set but replan_from is not: name the run to replan "
                          "(replan_from=RUN_DIR)")
