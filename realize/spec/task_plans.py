"""A run's task and its candidate plans: from the task group or a YAML task file, with the plan
written in the task or planned by PDDL (the planner's k best with ``planner.top_k > 1``).

What it does:
  * ``PlannerSettings``: the task's ``planner`` mapping (``realize.config.Settings``);
  * ``load_task_file``: read a YAML task file, errors naming the file;
  * ``TaskOrigin``: which file a run's task came from and its SHA-256 when the run started
    (a run keeps the file's content in its config; ``TaskOrigin.note()`` says if the file has
    changed since);
  * ``check_halving_budget``: with ``top_k > 1`` the CE settings must cover the halving rounds
    (``realize.search.budget``), checked before the planner runs;
  * ``build_task`` / ``build_task_candidates``: task mapping -> checked ``TaskSpec`` (and the
    candidate tasks, each over only the parameters its plan binds).
Every problem is a ``realize.config.ConfigError``. The only outside process started here is the
PDDL planner (``realize.tasks.pddl``), and only with ``planner.enabled``.
What it doesn't: parse regions or plans itself (``realize.tasks.spec``, ``realize.tasks.regions``), or
simulate.
"""

from __future__ import annotations

import hashlib
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import yaml

from realize.search.budget import plan_budget
from realize.config import ConfigError, Settings, setting
from realize.paths import REPO_ROOT

if TYPE_CHECKING:
    from realize.world.geometry import SceneGeometry
    from realize.search.ce.config import CEConfig
    from realize.tasks.spec import TaskSpec

__all__ = ["PlannerSettings", "TaskOrigin", "load_task_file", "check_halving_budget", "build_task", "build_task_candidates"]


@dataclass
class PlannerSettings(Settings):
    """``task.planner``: the PDDL planner and, with ``top_k > 1``, the search over candidates.

    ``top_k`` (default 1): realize the planner's k best distinct plans by successive halving
    with one shared sample budget (``realize.search.candidates``; needs ``enabled: true`` and
    ``ce.schedule: constant``); 1 is a single plan, as without the key.
    ``round_iterations`` (default null = automatic): CE iterations per surviving candidate and
    halving round; ignored with ``top_k = 1``. ``domain``/``problem`` are needed only when
    ``enabled``."""

    config_key = "task:planner"

    enabled: bool = False
    domain: str | None = None
    problem: str | None = None
    timeout_s: float = setting(30.0, gt=0)
    top_k: int = setting(1, ge=1)
    round_iterations: int | None = setting(None, ge=1, help="null: automatic")

    def check(self, where: str) -> None:
        if self.top_k > 1 and not self.enabled:
            raise ConfigError(
                f"{where}.top_k = {self.top_k} needs {where}.enabled = true: candidate plans come from the PDDL "
                f"planner (a fixed plan is one candidate; use top_k = 1)"
            )
        if self.enabled:
            for key in ("domain", "problem"):
                if getattr(self, key) is None:
                    raise ConfigError(f"{where}.{key} = None is invalid: must be a non-empty string")


def _resolve_path(p: Any, key: str) -> Path:
    if not isinstance(p, str) or not p:
        raise ConfigError(f"{key} = {p!r} is invalid: must be a non-empty string")
    path = Path(p).expanduser()
    if not path.is_absolute() and not path.exists() and (REPO_ROOT / path).exists():
        path = REPO_ROOT / path
    return path


def load_task_file(path_value: Any, key: str = "task_file") -> tuple[dict[str, Any], str]:
    """Read a YAML task file (``yaml.safe_load``); errors name the file."""
    path = _resolve_path(path_value, key)
    if not path.is_file():
        raise ConfigError(f"{key} = {str(path_value)!r}: file not found")
    try:
        d = yaml.safe_load(path.read_text())
    except yaml.YAMLError as e:
        mark = getattr(e, "problem_mark", None)
        where = f" at line {mark.line + 1}, column {mark.column + 1}" if mark is not None else ""
        problem = getattr(e, "problem", None) or type(e).__name__
        raise ConfigError(f"{key}: {path} is not valid YAML{where}: {problem}") from None
    except (OSError, UnicodeDecodeError) as e:
        raise ConfigError(f"{key}: cannot read {path}: {e}") from None
    if not isinstance(d, Mapping):
        raise ConfigError(f"{key}: {path} must hold a mapping (params, plan, goal, ...), got {type(d).__name__}")
    return dict(d), str(path)


@dataclass(frozen=True)
class TaskOrigin:
    """The task file a run's task was read from: its ``path`` as resolved when the run started
    and the ``sha256`` of its bytes then. The run itself uses the copy of the file's content in
    its config (``task``), never the file again."""

    path: str
    sha256: str

    @classmethod
    def of_file(cls, path: str | Path) -> TaskOrigin:
        return cls(str(path), hashlib.sha256(Path(path).read_bytes()).hexdigest())

    def to_json(self) -> dict[str, str]:
        return {"path": self.path, "sha256": self.sha256}

    @classmethod
    def from_json(cls, d: Any, where: str = "task_origin") -> TaskOrigin | None:
        """``None`` for ``None``; ``ConfigError`` for anything but ``{path, sha256}`` strings."""
        if d is None:
            return None
        if not (isinstance(d, Mapping) and set(d) == {"path", "sha256"}
                and all(isinstance(v, str) and v for v in d.values())):
            raise ConfigError(f"{where} = {d!r} is invalid: must be a mapping {{path: str, sha256: str}}")
        return cls(str(d["path"]), str(d["sha256"]))

    def note(self) -> str | None:
        """A line saying the file has changed or gone since the run started (``None``: unchanged)."""
        p = Path(self.path)
        if not p.is_file():
            return f"the task file {self.path} is gone; the run's own copy of the task was used"
        if hashlib.sha256(p.read_bytes()).hexdigest() != self.sha256:
            return f"the task file {self.path} has changed since the run; the run's own copy of the task was used"
        return None


def check_halving_budget(planner: PlannerSettings, ce: CEConfig, source: str = "task") -> None:
    """With ``top_k > 1``: the CE settings must cover the halving rounds of ``top_k`` candidates
    (checked before the planner runs; fewer candidates never need more). ``ConfigError``."""
    if planner.top_k == 1:
        return
    where = f"{source}:planner"
    if ce.schedule != "constant":
        raise ConfigError(
            f"ce.schedule = {ce.schedule!r} is invalid with {where}.top_k = {planner.top_k}: candidates share "
            f"the budget in CE iterations of ce.n_envs samples (use ce.schedule=constant)"
        )
    plan_budget(planner.top_k, ce.iterations, ce.n_envs, planner.round_iterations,
                keys=(f"{where}.top_k", "ce.iterations", f"{where}.round_iterations"))


def build_task(d: Mapping[str, Any], geometry: SceneGeometry, source: str) -> TaskSpec:
    """Task mapping -> checked ``TaskSpec``; runs the PDDL planner if ``planner.enabled``
    (the plan is the planner's first, cheapest one)."""
    return build_task_candidates(d, geometry, source)[0]


def build_task_candidates(
    d: Mapping[str, Any], geometry: SceneGeometry, source: str, planner: PlannerSettings | None = None,
    held: str | None = None,
) -> tuple[TaskSpec, list[TaskSpec]]:
    """The task (its plan: the given one, or the planner's first) and the candidate tasks.

    Without ``top_k > 1`` the candidates are ``[task]``. With it, one ``TaskSpec`` per distinct
    planned plan (cheapest first; fewer than ``top_k`` if the planner finds fewer), each over
    only the parameters its plan uses (``realize.tasks.spec.task_for_plan``)."""
    from realize.realization.actions import TEMPLATES
    from realize.tasks.spec import plan_from_actions, task_for_plan, task_from_dict

    try:
        task = task_from_dict(d, geometry, TEMPLATES, source=source, held=held)  # held: where the plan starts
    except ConfigError:
        raise
    except ValueError as e:
        raise ConfigError(str(e)) from None
    if planner is None:
        planner = PlannerSettings.from_mapping(task.planner, f"{source}:planner")
    candidates = [task]
    if planner.enabled:
        from realize.tasks.pddl import plan_from_pddl

        domain = _resolve_path(planner.domain, f"{source}:planner.domain")
        problem = _resolve_path(planner.problem, f"{source}:planner.problem")
        try:
            plans = plan_from_pddl(domain, problem, list(TEMPLATES), task.layout.names,
                                   objects=geometry.object_names, top_k=planner.top_k, timeout_s=planner.timeout_s)
            if not plans:
                raise ConfigError(f"{source}:planner: the PDDL planner found no plan for {problem}")
            checked = [plan_from_actions(p, task.layout, TEMPLATES, f"{source}:planner[{i}]", geometry.object_names)
                       for i, p in enumerate(plans)]
        except ConfigError:
            raise
        except ValueError as e:
            raise ConfigError(f"{source}:planner: {e}") from None
        task.plan = checked[0]
        if planner.top_k > 1:
            candidates = [task_for_plan(task, p) for p in checked]
    if not task.plan:
        raise ConfigError(f"{source}:plan is empty (give a plan or set planner.enabled: true)")
    return task, candidates
