"""The edge between Hydra and the library: a whole run config, checked into plain dataclasses.

What it does: ``build_run_spec(d)`` takes the resolved config of one run (a plain mapping with
the groups ``task``, ``scene``, ``sim``, ``controller``, ``ce``, ``logging`` and the top-level keys
``seed``, ``device``, ``resume``, ``task_file``) and returns a ``RunSpec`` of validated objects
(``TaskSpec``, ``GeometryCfg``/``SceneGeometry``, ``SimSettings``, ``RolloutConfig``,
``CEConfig``, ``LoggingSettings``). Every problem raises ``ConfigError`` with a one-line message
naming the key (or file), the value and what is allowed. Nothing here builds a simulator; the
only outside process it may start is the PDDL planner when ``task.planner.enabled`` is set
(``task.planner.top_k > 1``: its k best plans become candidate tasks, and the halving budget of
``realize.candidates`` is checked before the planner runs).
What it doesn't: read Hydra objects (``realize.app`` converts them to plain data first), or run.

Key mapping: the ``ce`` group speaks the paper's language, ``ce.n_envs`` (samples = parallel
plans per iteration) and ``ce.n_envs_end`` (last iteration, linear schedule); they map onto
``CEConfig.n_samples`` / ``n_samples_end``. ``CEConfig.seed`` is the top-level ``seed``.
``device`` (auto|cpu|cuda) picks the simulator backend unless ``sim.backend`` says otherwise.
"""

from __future__ import annotations

import math
import typing
from collections.abc import Mapping
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import TYPE_CHECKING, Any

import yaml

if TYPE_CHECKING:  # the library modules are imported where used: `realize` starts fast
    from realize.geometry import GeometryCfg, SceneGeometry
    from realize.candidates import HalvingBudget
    from realize.cross_entropy import CEConfig
    from realize.scene.settings import SimSettings
    from realize.task import TaskSpec

__all__ = [
    "ConfigError",
    "LoggingSettings",
    "PlannerSettings",
    "RunSpec",
    "build_run_spec",
    "build_task",
    "build_task_candidates",
    "planner_from_dict",
    "REPO_ROOT",
    "TOP_LEVEL_KEYS",
]

REPO_ROOT = Path(__file__).resolve().parent.parent
TOP_LEVEL_KEYS = ("task", "scene", "sim", "controller", "ce", "logging", "seed", "device", "resume", "task_file")
DEVICES = ("auto", "cpu", "cuda")
_CE_RENAME = {"n_envs": "n_samples", "n_envs_end": "n_samples_end"}


class ConfigError(ValueError):
    """A run config is invalid; the message is one line naming the key/file and the value."""


# --------------------------------------------------------------------------------------------
# small typed readers
# --------------------------------------------------------------------------------------------


def _int(v: Any, key: str, lo: int | None = None) -> int:
    if isinstance(v, float) and v.is_integer():
        v = int(v)
    if isinstance(v, bool) or not isinstance(v, int):
        raise ConfigError(f"{key} = {v!r} is invalid: must be an integer")
    if lo is not None and v < lo:
        raise ConfigError(f"{key} = {v} is invalid: must be >= {lo}")
    return v


def _float(v: Any, key: str) -> float:
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
        raise ConfigError(f"{key} = {v!r} is invalid: must be a finite number")
    return float(v)


def _bool(v: Any, key: str) -> bool:
    if not isinstance(v, bool):
        raise ConfigError(f"{key} = {v!r} is invalid: must be true or false")
    return v


def _str(v: Any, key: str) -> str:
    if not isinstance(v, str) or not v:
        raise ConfigError(f"{key} = {v!r} is invalid: must be a non-empty string")
    return v


def _mapping(v: Any, key: str) -> dict[str, Any]:
    if v is None:
        return {}
    if not isinstance(v, Mapping):
        raise ConfigError(f"{key} = {v!r} is invalid: must be a mapping")
    return dict(v)


def _unknown(d: Mapping[str, Any], allowed: list[str], key: str) -> None:
    bad = sorted(str(k) for k in d if k not in allowed)
    if bad:
        raise ConfigError(f"{key}: unknown key(s) {bad}; allowed: {sorted(allowed)}")


# --------------------------------------------------------------------------------------------
# groups
# --------------------------------------------------------------------------------------------


@dataclass
class LoggingSettings:
    """Hydra ``logging`` group: what a run writes besides result.json/history/checkpoint."""

    rerun: bool = True  # write a rerun recording (.rrd) in the run directory
    rrd: str = "realize.rrd"  # its file name (relative to the run directory)
    record: bool = True  # record sample trajectories in the rollout (for the rerun scene view)
    progress: bool = True  # tqdm progress bar per CE iteration

    @classmethod
    def from_dict(cls, d: Mapping[str, Any], prefix: str = "logging") -> LoggingSettings:
        d = _mapping(d, prefix)
        _unknown(d, [f.name for f in fields(cls)], prefix)
        out = cls()
        for k in ("rerun", "record", "progress"):
            if k in d:
                setattr(out, k, _bool(d[k], f"{prefix}.{k}"))
        if "rrd" in d:
            name = _str(d["rrd"], f"{prefix}.rrd")
            if Path(name).is_absolute() or ".." in Path(name).parts or not name.endswith(".rrd"):
                raise ConfigError(
                    f"{prefix}.rrd = {name!r} is invalid: a file name ending in .rrd inside the run directory"
                )
            out.rrd = name
        return out


def _typed(v: Any, hint: Any, key: str) -> Any:
    """Check/convert ``v`` against a simple annotation (int, float, str, bool, X | None)."""
    args = typing.get_args(hint)
    if args and type(None) in args:
        if v is None:
            return None
        hint = next(a for a in args if a is not type(None))
    if hint is bool:
        return _bool(v, key)
    if hint is int:
        return _int(v, key)
    if hint is float:
        return _float(v, key)
    if hint is str:
        return _str(v, key)
    return v


def dataclass_from_dict(cls: type, d: Mapping[str, Any], prefix: str) -> Any:
    """``cls(**d)`` for a flat dataclass of simple fields, unknown keys and wrong types refused."""
    d = _mapping(d, prefix)
    _unknown(d, [f.name for f in fields(cls)], prefix)
    hints = typing.get_type_hints(cls)
    return cls(**{k: _typed(v, hints.get(k), f"{prefix}.{k}") for k, v in d.items()})


def sim_from_dict(d: Mapping[str, Any], prefix: str = "sim") -> SimSettings:
    from realize.scene.settings import SimSettings

    try:
        return SimSettings.from_mapping(d, prefix)
    except ValueError as e:
        raise ConfigError(str(e)) from None


def ce_from_dict(d: Mapping[str, Any], seed: int, prefix: str = "ce") -> CEConfig:
    """The ``ce`` group (``n_envs`` naming) -> ``CEConfig`` with the run seed."""
    from realize.cross_entropy import CEConfig

    d = _mapping(d, prefix)
    allowed = [_inv(f.name) for f in fields(CEConfig) if f.name != "seed"]
    _unknown(d, allowed, prefix)
    n = _int(d.get("n_envs", 200), f"{prefix}.n_envs", lo=1)
    iters = _int(d.get("iterations", 10), f"{prefix}.iterations", lo=1)
    elite = _int(d.get("n_elite", 10), f"{prefix}.n_elite", lo=1)
    sched = d.get("schedule", "constant")
    end = d.get("n_envs_end")
    if sched == "linear" and end is not None:
        end = _int(end, f"{prefix}.n_envs_end", lo=1)
        if elite > min(n, end):
            raise ConfigError(
                f"{prefix}.n_elite = {elite} is invalid: must be <= {prefix}.n_envs = {n} and "
                f"<= {prefix}.n_envs_end = {end} (elites are chosen among the samples of an iteration)"
            )
    elif elite > n:
        raise ConfigError(
            f"{prefix}.n_elite = {elite} is invalid: must be <= {prefix}.n_envs = {n} "
            "(elites are chosen among the samples of an iteration)"
        )
    mapped = {_CE_RENAME.get(k, k): v for k, v in d.items()}
    mapped["seed"] = seed
    try:
        return CEConfig.from_dict(mapped, prefix)
    except ValueError as e:
        msg = str(e)
        for new, old in _CE_RENAME.items():
            msg = msg.replace(f"{prefix}.{old}", f"{prefix}.{new}").replace(f"'{old}'", f"'{new}'")
        raise ConfigError(msg) from None


def _inv(name: str) -> str:
    for new, old in _CE_RENAME.items():
        if old == name:
            return new
    return name


def load_task_file(path_value: Any, key: str = "task_file") -> tuple[dict[str, Any], str]:
    """Read a YAML task file (``yaml.safe_load``); errors name the file."""
    path = Path(_str(path_value, key)).expanduser()
    if not path.is_absolute() and not path.exists() and (REPO_ROOT / path).exists():
        path = REPO_ROOT / path
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


def _resolve_path(p: Any, key: str) -> Path:
    path = Path(_str(p, key)).expanduser()
    if not path.is_absolute() and not path.exists() and (REPO_ROOT / path).exists():
        path = REPO_ROOT / path
    return path


PLANNER_KEYS = ("enabled", "domain", "problem", "timeout_s", "top_k", "round_iterations")


@dataclass(frozen=True)
class PlannerSettings:
    """``task.planner``: the PDDL planner and, with ``top_k > 1``, the search over candidates.

    ``top_k`` (default 1): realize the planner's k best distinct plans by successive halving
    with one shared sample budget (``realize.candidates``; needs ``enabled: true`` and
    ``ce.schedule: constant``); 1 is a single plan, as without the key.
    ``round_iterations`` (default null = automatic): CE iterations per surviving candidate and
    halving round; ignored with ``top_k = 1``. ``domain``/``problem``/``timeout_s`` are read
    only when ``enabled``."""

    enabled: bool = False
    domain: str | None = None
    problem: str | None = None
    timeout_s: float = 30.0
    top_k: int = 1
    round_iterations: int | None = None


def planner_from_dict(d: Any, source: str = "task") -> PlannerSettings:
    """The task's ``planner`` mapping -> ``PlannerSettings`` (keys ``<source>:planner.<key>``)."""
    where = f"{source}:planner"
    d = _mapping(d, where)
    _unknown(d, list(PLANNER_KEYS), where)
    enabled = _bool(d.get("enabled", False), f"{where}.enabled")
    top_k = _int(d.get("top_k", 1), f"{where}.top_k", lo=1)
    m = d.get("round_iterations")
    if m is not None:
        m = _int(m, f"{where}.round_iterations", lo=1)
    if top_k > 1 and not enabled:
        raise ConfigError(
            f"{where}.top_k = {top_k} needs {where}.enabled = true: candidate plans come from the PDDL "
            f"planner (a fixed plan is one candidate; use top_k = 1)"
        )
    if not enabled:
        return PlannerSettings(top_k=top_k, round_iterations=m)
    return PlannerSettings(
        enabled=True,
        domain=_str(d.get("domain"), f"{where}.domain"),
        problem=_str(d.get("problem"), f"{where}.problem"),
        timeout_s=_float(d.get("timeout_s", 30.0), f"{where}.timeout_s"),
        top_k=top_k,
        round_iterations=m,
    )


def check_halving_budget(planner: PlannerSettings, ce: CEConfig, source: str = "task") -> None:
    """With ``top_k > 1``: the CE settings must cover the halving rounds of ``top_k`` candidates
    (checked before the planner runs; fewer candidates never need more). ``ConfigError``."""
    if planner.top_k == 1:
        return
    from realize.candidates import BudgetError, plan_budget

    where = f"{source}:planner"
    if ce.schedule != "constant":
        raise ConfigError(
            f"ce.schedule = {ce.schedule!r} is invalid with {where}.top_k = {planner.top_k}: candidates share "
            f"the budget in CE iterations of ce.n_envs samples (use ce.schedule=constant)"
        )
    try:
        plan_budget(planner.top_k, ce.iterations, ce.n_samples, planner.round_iterations,
                    keys=(f"{where}.top_k", "ce.iterations", f"{where}.round_iterations"))
    except BudgetError as e:
        raise ConfigError(str(e)) from None


def build_task(d: Mapping[str, Any], geometry: SceneGeometry, source: str) -> TaskSpec:
    """Task mapping -> checked ``TaskSpec``; runs the PDDL planner if ``planner.enabled``
    (the plan is the planner's first, cheapest one)."""
    return build_task_candidates(d, geometry, source)[0]


def build_task_candidates(
    d: Mapping[str, Any], geometry: SceneGeometry, source: str, planner: PlannerSettings | None = None
) -> tuple[TaskSpec, list[TaskSpec]]:
    """The task (its plan: the given one, or the planner's first) and the candidate tasks.

    Without ``top_k > 1`` the candidates are ``[task]``. With it, one ``TaskSpec`` per distinct
    planned plan (cheapest first; fewer than ``top_k`` if the planner finds fewer), each over
    only the parameters its plan uses (``realize.task.task_for_plan``)."""
    from realize.realization.actions import TEMPLATES
    from realize.task import plan_from_actions, task_for_plan, task_from_dict

    try:
        task = task_from_dict(d, geometry, TEMPLATES, source=source)
    except ValueError as e:
        raise ConfigError(str(e)) from None
    if planner is None:
        planner = planner_from_dict(task.planner, source)
    candidates = [task]
    if planner.enabled:
        from realize.pddl import plan_from_pddl

        domain = _resolve_path(planner.domain, f"{source}:planner.domain")
        problem = _resolve_path(planner.problem, f"{source}:planner.problem")
        try:
            plans = plan_from_pddl(domain, problem, list(TEMPLATES), task.layout.names, top_k=planner.top_k,
                                   timeout_s=planner.timeout_s)
            if not plans:
                raise ConfigError(f"{source}:planner: the PDDL planner found no plan for {problem}")
            checked = [plan_from_actions(p, task.layout, TEMPLATES, f"{source}:planner[{i}]")
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


# --------------------------------------------------------------------------------------------
# the whole run
# --------------------------------------------------------------------------------------------


@dataclass
class RunSpec:
    """One run, validated. ``config`` is the plain resolved mapping it was built from."""

    seed: int
    device: str
    resume: str | None
    task: TaskSpec
    geometry_cfg: GeometryCfg
    geometry: SceneGeometry
    sim: SimSettings
    rollout: Any  # realize.rollout.RolloutConfig (imported lazily: it pulls in the controllers)
    ce: CEConfig
    logging: LoggingSettings
    config: dict[str, Any]
    planner: PlannerSettings = field(default_factory=PlannerSettings)
    # the candidate plans' tasks ([task] unless planner.top_k > 1) and their halving budget
    candidates: list[TaskSpec] = field(default_factory=list)
    budget: HalvingBudget | None = None

    @property
    def halving(self) -> bool:
        """Successive halving over candidate plans (``task.planner.top_k > 1``)."""
        return self.planner.top_k > 1

    @property
    def n_envs_max(self) -> int:
        """Parallel copies the scene needs: the largest sample count over the schedule."""
        return max(self.ce.n_samples_at(i) for i in range(self.ce.iterations))


def build_run_spec(d: Mapping[str, Any]) -> RunSpec:
    """Validate a whole resolved run config (plain data). Raises ``ConfigError``."""
    d = _mapping(d, "config")
    _unknown(d, list(TOP_LEVEL_KEYS), "config")
    seed = _int(d.get("seed", 0), "seed", lo=0)
    device = d.get("device", "auto")
    if device not in DEVICES:
        raise ConfigError(f"device = {device!r} is invalid: allowed {list(DEVICES)}")
    resume = d.get("resume")
    if resume is not None:
        resume = _str(str(resume), "resume")

    ce = ce_from_dict(d.get("ce"), seed)
    sim = sim_from_dict(d.get("sim"))
    backend_for_device = {"cpu": "cpu", "cuda": "gpu"}.get(device)
    if backend_for_device is not None:
        if sim.backend not in ("auto", backend_for_device):
            raise ConfigError(
                f"device = {device!r} conflicts with sim.backend = {sim.backend!r}; set one of them "
                f"(device=cuda goes with sim.backend=gpu, device=cpu with sim.backend=cpu)"
            )
        sim.backend = backend_for_device
    from realize.scene.backends import resolve_backend

    try:
        resolve_backend(sim.backend)  # refuses gpu without CUDA
    except ValueError as e:
        raise ConfigError(f"device = {device!r}: {e}") from None

    from realize.geometry import GeometryCfg, build_geometry

    try:
        geometry_cfg = GeometryCfg.from_mapping(_mapping(d.get("scene"), "scene"), "scene")
        geometry = build_geometry(geometry_cfg)
    except ConfigError:
        raise
    except (ValueError, TypeError) as e:
        msg = str(e)
        raise ConfigError(msg if msg.startswith("scene") else f"scene: {msg}") from None

    if d.get("task_file") is not None:
        task_d, source = load_task_file(d["task_file"])
    else:
        task_d, source = _mapping(d.get("task"), "task"), "task"
        if not task_d:
            raise ConfigError("task: no task given (choose task=<name> or task_file=<path.yaml>)")
    planner = planner_from_dict(task_d.get("planner"), source)
    check_halving_budget(planner, ce, source)  # before the planner runs
    task, candidates = build_task_candidates(task_d, geometry, source, planner)
    budget = None
    if planner.top_k > 1:
        from realize.candidates import plan_budget

        budget = plan_budget(len(candidates), ce.iterations, ce.n_samples, planner.round_iterations)

    from realize.realization.config import RolloutConfig

    try:
        rollout = RolloutConfig.from_mapping(_mapping(d.get("controller"), "controller"), "controller")
    except (ValueError, TypeError) as e:
        msg = str(e)
        raise ConfigError(msg if msg.startswith("controller") else f"controller: {msg}") from None

    logging = LoggingSettings.from_dict(d.get("logging"))
    return RunSpec(
        seed=seed,
        device=device,
        resume=resume,
        task=task,
        geometry_cfg=geometry_cfg,
        geometry=geometry,
        sim=sim,
        rollout=rollout,
        ce=ce,
        logging=logging,
        config=dict(d),
        planner=planner,
        candidates=candidates,
        budget=budget,
    )
