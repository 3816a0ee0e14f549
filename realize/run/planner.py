"""The planner you import: built once from a config, then ``plan()``, ``replan(...)``, ``close()``.

What it does: ``Planner`` holds one run config (composed from overrides, as the ``realize``
command composes its arguments, or given; ``Planner.from_config`` checks a given one at once) and the rollout workers it has opened. ``plan()``
runs the search of that config into a run directory (the command line runs through it: one
path; ``resume`` and ``replan_from`` configs too) and returns a typed ``PlanResult``.
``replan(state, from_action, changes)`` realizes the rest of a plan from a
``realize.world.state.SceneState``: a search over the parameters of actions ``from_action, ...``
only (indices of the whole plan), every rollout starting from ``state``, warm-started from the
plan it repairs (the last result, or ``source``), on a small budget (``ReplanBudget``: few
copies, few iterations, no validation, stopped as soon as a plan reaches the goal).
``changes`` are overrides of the world as it is now (``scene.tables.1.center=[0.1,-1.5]``,
``scene.walls=[...]``) or of the search (``ce.*``); what would change the plan itself is
refused (``realize.spec.replan_from``). ``resequence(task, state, ...)`` realizes another plan
(a new action sequence from the PDDL planner, ``realize.repair.resequence``) from a state.

What stays up between calls: the rollout workers and their scenes, keyed by what they were
built for (processes: copies, shards, workers, backend; scenes: scene, robot, simulator). A
call whose scene is the same takes them over with new realizers (``retask``: a new plan, a new
start state, nothing to build); one whose world changed its static layout (a table moved, a
new obstacle) needs new scenes: the planner says so in the log and in ``PlanResult.scene`` and
builds only those, in the running worker processes (Ray actors are not kept: new ones per call). At most
``max_pools`` sets stay open. ``warm_up(budget)`` opens the replans' workers ahead of the
first replan. ``close()`` ends every worker (a context manager).
What it doesn't: search, simulate or write files itself (``realize.run.assembly`` does, per call),
or carry a plan out (``realize.repair.study``).
"""

from __future__ import annotations

import json
import logging
import re
import time
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

from omegaconf import DictConfig

from realize.reproducible import warn_unpinned
from realize.spec.compose import set_key
from realize.spec.replan_from import saved_config
from realize.run.plan_result import PlanResult, PlanTimings, ReplanBudget
from realize.run.assembly import RunOutcome, plain_config, prepare_run
from realize.workers.pool import RolloutPool, open_pool
from realize.config import ConfigError
from realize.run_dir.directory import RunDir
from realize.world.state import SceneState, save_state

__all__ = ["Planner", "PlanResult", "ReplanBudget", "PlanTimings"]

log = logging.getLogger("realize")

START_STATE_FILE = "start_state.json"  # the state a replan's rollouts start from, in its run directory


def _pool_keys(spec: Any) -> tuple[str, str]:
    """What a set of workers was built for: its processes (copies, shards, workers, backend) and
    its scenes (scene, robot, simulator). Same both: shared as they are; same processes only:
    their scenes are built again."""
    c = spec.config
    procs = json.dumps({"workers": c.get("workers"), "backend": spec.placement.backend,
                        "device": str(spec.placement.device), "n_envs": spec.ce.n_envs, "replicas": spec.ce.replicas,
                        "shard_rows": spec.sim.shard_rows}, sort_keys=True, default=str)
    scenes = json.dumps({"scene": c.get("scene"), "robot": c.get("robot"), "sim": c.get("sim"),
                         "worlds_seed": spec.seed if spec.ce.replicas > 1 else None}, sort_keys=True, default=str)
    return procs, scenes


class Planner:
    """Plans and replans one task with workers kept up between calls (module docstring).

        with Planner(["experiment=seed_paper", "ce.iterations=3"]) as planner:
            result = planner.plan("runs/seed0")
            print(result.plan, result.cost, result.params["Table1"])

    ``config``: a composed config (plain data or a DictConfig) or a list of overrides (composed
    with ``realize.spec.compose.compose_config``). ``cli_overrides``: the command line's (a
    resumed or replanned config checks them and takes what they name on top of the saved
    config; default: the list of overrides given as ``config``). ``max_pools``: sets of workers kept open.
    """

    def __init__(self, config: Sequence[str] | Mapping[str, Any] | DictConfig = (), *,
                 cli_overrides: Sequence[str] = (), max_pools: int = 2) -> None:
        if isinstance(config, (DictConfig, Mapping)):
            self.config = plain_config(config)
        else:
            from realize.spec.compose import compose_config

            if isinstance(config, str):
                raise ConfigError(f"Planner({config!r}): give a list of overrides, e.g. Planner([{config!r}])")
            self.config = compose_config(list(config))
        # what a resumed or replanned config takes on top of the saved one: the command line's,
        # or the overrides given here
        given = not isinstance(config, (DictConfig, Mapping))
        self.cli_overrides = list(cli_overrides) if cli_overrides or not given else [str(o) for o in config]
        self.max_pools = max(1, int(max_pools))
        warn_unpinned()  # numpy or torch loaded before realize pinned their kernels (a notebook): said once here
        self._pools: dict[str, tuple[RolloutPool, str]] = {}  # processes key -> (workers, scenes key)
        self._built: set[str] = set()  # keys whose workers the current call built
        self.last: PlanResult | None = None
        self.closed = False

    @classmethod
    def from_config(cls, cfg: Mapping[str, Any] | DictConfig, **kw: Any) -> Planner:
        """A planner of a composed config (a Hydra app's ``cfg``, whose groups the settings
        dataclasses type: ``realize.spec.hydra_edge.register_schema``; or ``compose_config``'s
        plain data), checked into its ``RunSpec`` at once: a bad value is one ``ConfigError``
        line here, before any worker starts, not at ``plan()``."""
        from realize.spec.run_spec import build_run_spec

        if not isinstance(cfg, (DictConfig, Mapping)):
            raise ConfigError(f"Planner.from_config: give a composed config (a mapping), not {type(cfg).__name__}; "
                              f"a list of overrides goes to Planner(overrides)")
        planner = cls(cfg, **kw)
        build_run_spec(dict(planner.config, resume=None))
        return planner

    @classmethod
    def from_run(cls, run_dir: str | Path, **kw: Any) -> Planner:
        """A planner with an earlier run's saved config, ``last`` that run's result (what
        ``replan`` repairs first)."""
        cfg = saved_config(run_dir, "Planner.from_run")
        cfg = dict(cfg)
        cfg["resume"] = None
        planner = cls(cfg, **kw)
        planner.last = planner._result(Path(run_dir), None, 0.0, 0.0, 0.0, None)
        return planner

    # ------------------------------------------------------------------ workers
    def _pool(self, spec: Any, tasks: Sequence[Any], log_dir: Path) -> RolloutPool:
        procs, scenes = _pool_keys(spec)
        found = self._pools.get(procs)
        if found is not None and not hasattr(getattr(found[0], "inner", found[0]), "retask"):
            self._pools.pop(procs)[0].close()  # Ray actors: new ones for every call
            found = None
        if found is not None:
            pool, built_for = found
            if built_for == scenes:
                pool.retask(spec, tasks)
                return pool
            what = _what_differs(scenes, built_for)
            if hasattr(pool, "rebuild"):
                log.info("planner: the world changed (%s): building its scenes again in the running workers", what)
                pool.rebuild(spec, tasks)
                self._pools[procs] = (pool, scenes)
                self._built.add("scenes")
                return pool
            log.info("planner: the world changed (%s): new workers", what)
            self._pools.pop(procs)[0].close()
        while len(self._pools) >= self.max_pools:  # the oldest set goes
            old = next(iter(self._pools))
            self._pools.pop(old)[0].close()
        pool = open_pool(spec, tasks, log_dir=log_dir)
        self._pools[procs] = (pool, scenes)
        self._built.add("workers")
        return pool

    def _drop(self, spec: Any) -> None:
        """Close the workers of ``spec`` (a run that did not end cleanly may leave them mid-batch)."""
        found = self._pools.pop(_pool_keys(spec)[0], None)
        if found is not None:
            found[0].close()

    def warm_up(self, budget: ReplanBudget | None = None, source: PlanResult | str | Path | None = None) -> float:
        """Open the workers replans on ``budget`` will use (for the plan of ``source``, default
        the last result) before the first replan, so that it does not wait for them: a robot's
        planner is up before the robot moves. Returns the seconds it took."""
        from realize.spec.replan_from import one_search
        from realize.spec.run_spec import build_run_spec

        t0 = time.perf_counter()
        cfg = saved_config(self._source(source))
        for k, v in (budget or ReplanBudget()).overrides().items():
            set_key(cfg, k, v)
        cfg["replan_from"], cfg["resume"] = None, None
        cfg["replan"] = {"action": None, "state": None, "warm": True}
        spec = build_run_spec(one_search(cfg))
        self._pool(spec, [spec.task], self._source(source) / "replans" / "workers")
        return time.perf_counter() - t0

    @property
    def open_pools(self) -> int:
        """How many sets of workers are open now."""
        return len(self._pools)

    # ------------------------------------------------------------------ calls
    def _check_open(self) -> None:
        if self.closed:
            raise RuntimeError("this Planner is closed")

    def _run(self, cfg: Mapping[str, Any], run_dir: Path, *, cli_overrides: Sequence[str] = (),
             after_iteration: Callable[[int], None] | None = None, stop_when_feasible: bool = False,
             min_iterations: int = 1, from_action: int = 0, merged: bool = False) -> PlanResult:
        t0 = time.perf_counter()
        assembly = prepare_run(cfg, run_dir, cli_overrides, merged=merged)
        spec = assembly.spec
        self._built.clear()
        def feasible_now(it: Any) -> bool:  # a replan ends at its first plan that reaches the goal
            return bool(it.report.state.best_feasible) and it.index + 1 >= min_iterations

        until = feasible_now if stop_when_feasible else None
        t_setup: list[float] = []
        source = self._timed(t_setup)
        try:
            outcome = assembly.execute(after_iteration, pools=source, until=until)
        except BaseException:
            self._drop(spec)
            raise
        if outcome.status != "done":
            self._drop(spec)
        total = time.perf_counter() - t0
        v = getattr(assembly, "validation_s", 0.0)
        setup = sum(t_setup)
        search = max(0.0, getattr(assembly, "search_s", total) - setup)
        scene = "kept" if not self._built else ("built" if "workers" in self._built else "rebuilt")
        res = self._result(assembly.run_dir, outcome, setup, search, v, spec, total=total, scene=scene,
                           from_action=from_action, stopped=bool(getattr(assembly, "stopped_early", False)))
        self.last = res
        return res

    def _timed(self, into: list[float]) -> Callable[[Any, Sequence[Any], Path], RolloutPool]:
        def source(spec: Any, tasks: Sequence[Any], log_dir: Path) -> RolloutPool:
            t = time.perf_counter()
            pool = self._pool(spec, tasks, log_dir)
            into.append(time.perf_counter() - t)
            return pool
        return source

    def plan(self, run_dir: str | Path | None = None, *,
             after_iteration: Callable[[int], None] | None = None) -> PlanResult:
        """Search the config's plan into ``run_dir`` (default ``outputs/planner/<date-time>``;
        a ``resume`` config: the resumed run's directory) and validate it as the config says."""
        self._check_open()
        if run_dir is None:
            run_dir = Path("outputs") / "planner" / time.strftime("%Y%m%d-%H%M%S")
        return self._run(self.config, Path(run_dir), cli_overrides=self.cli_overrides,
                         after_iteration=after_iteration)

    def replan(self, state: SceneState, from_action: int, changes: Sequence[str] = (), *,
               source: PlanResult | str | Path | None = None, run_dir: str | Path | None = None,
               budget: ReplanBudget | None = None, warm: bool = True, seed: int | None = None) -> PlanResult:
        """Realize actions ``from_action, ...`` of the plan of ``source`` (default: the last
        result) from ``state``, in the world ``changes`` describe (module docstring). The run
        goes to ``run_dir`` (default ``<source run>/replans/replan-<k>``), ``state`` to its
        ``start_state.json``. ``ConfigError`` (nothing simulated) for a bad action index, a
        state the remaining actions cannot start from, or a change that would change the plan."""
        from realize.spec.replan_from import replan_overrides_config

        self._check_open()
        src = self._source(source)
        budget = budget or ReplanBudget()
        out = Path(run_dir) if run_dir is not None else _next_dir(src / "replans", "replan")
        out.mkdir(parents=True, exist_ok=True)
        state_file = save_state(state, out / START_STATE_FILE)
        base = saved_config(src)
        cfg = replan_overrides_config(base, str(src), list(changes), action=from_action, state=str(state_file),
                                      warm=warm)
        for k, v in budget.overrides().items():
            set_key(cfg, k, v)
        if seed is not None:
            cfg["seed"] = int(seed)
        return self._run(cfg, out, stop_when_feasible=budget.stop_when_feasible,
                         min_iterations=budget.min_iterations, from_action=from_action, merged=True)

    def resequence(self, task: Mapping[str, Any], state: SceneState, changes: Sequence[str] = (), *,
                   source: PlanResult | str | Path | None = None, run_dir: str | Path | None = None,
                   budget: ReplanBudget | None = None, seed: int | None = None) -> PlanResult:
        """Realize another plan, ``task`` (a task mapping: params, plan, goal; e.g. the PDDL
        planner's new sequence, ``realize.repair.resequence``), from ``state`` in the world of
        ``source`` (default: the last result) with ``changes``. Where the new plan is the tail of
        the source's plan the search is warm-started from it (a replan of those actions);
        otherwise it searches the new plan from scratch on ``budget``."""
        from realize.tasks.suffix import tail_index

        self._check_open()
        src = self._source(source)
        base = saved_config(src)
        k = tail_index(realized_task(base.get("task") or {}, src), task)
        if k is not None:
            return self.replan(state, k, changes, source=src, run_dir=run_dir, budget=budget, seed=seed)
        budget = budget or ReplanBudget()
        out = Path(run_dir) if run_dir is not None else _next_dir(src / "replans", "resequence")
        out.mkdir(parents=True, exist_ok=True)
        state_file = save_state(state, out / START_STATE_FILE)
        from realize.spec.replan_from import replan_overrides_config

        # a new task whose action 0 starts from the state: a "replan" of all of it, searched cold
        base["task"] = dict(task)
        base["task_file"], base["task_origin"] = None, None
        cfg = replan_overrides_config(base, str(src), list(changes), action=0, state=str(state_file), warm=False,
                                      check_plan=False)
        for kk, v in budget.overrides().items():
            set_key(cfg, kk, v)
        if seed is not None:
            cfg["seed"] = int(seed)
        return self._run(cfg, out, stop_when_feasible=budget.stop_when_feasible, min_iterations=budget.min_iterations,
                         merged=True)

    def _source(self, source: PlanResult | str | Path | None) -> Path:
        if source is None:
            if self.last is None:
                raise ConfigError("replan: nothing to repair yet: call plan() first, or give source=<run dir>")
            return self.last.run_dir
        return source.run_dir if isinstance(source, PlanResult) else Path(source)

    # ------------------------------------------------------------------ results
    def _result(self, run_dir: Path, outcome: RunOutcome | None, setup: float, search: float, validation: float,
                spec: Any, *, total: float = 0.0, scene: str = "built", from_action: int = 0,
                stopped: bool = False) -> PlanResult:
        import math

        from realize.validation.replay import ReplayError, returned_z, saved_plan

        d = RunDir(run_dir).result_json() or {}
        status = str(d.get("status", "failed"))
        columns = tuple(str(c) for c in d.get("columns") or [])
        z: tuple[float, ...] = ()
        cost = math.inf
        feasible = bool(d.get("feasible"))
        if feasible:
            try:
                choice = returned_z(saved_plan(run_dir))
                z, cost = tuple(float(x) for x in choice.z), float(choice.cost)
            except ReplayError:
                z = tuple(float(x) for x in d.get("best_z") or [])
                cost = float(d.get("best_cost") or math.inf)
        else:  # no plan reached the goal: the search's best-ranked one (cost inf)
            z = tuple(float(x) for x in d.get("best_z") or [] if x is not None)
        params: dict[str, list[float]] = {}
        for name, col in zip(columns, z):
            params.setdefault(name.split("[")[0].split(".")[0], []).append(col)
        plan = str(d.get("plan") or "")
        replan = d.get("replan") if isinstance(d.get("replan"), dict) else {}
        if outcome is None:
            outcome = RunOutcome(run_dir, status, feasible, cost, int(d.get("iterations_done") or 0),
                                 float(d.get("wall_time_s") or 0.0))
        return PlanResult(
            plan=plan, actions=tuple(plan_actions(plan)), params=params, z=z, columns=columns,
            cost=cost, feasible=feasible, status=status, iterations_done=int(d.get("iterations_done") or 0),
            validation=d.get("validation") if isinstance(d.get("validation"), dict) else None, run_dir=run_dir,
            timings=PlanTimings(setup, search, validation, total), outcome=outcome,
            from_action=int(replan.get("action", from_action) or 0) if replan else from_action, scene=scene,
            stopped_early=stopped or bool(d.get("stopped_early")), whole_plan=str(replan.get("plan", plan)))

    # ------------------------------------------------------------------ lifecycle
    def close(self) -> None:
        """End every worker this planner opened."""
        for pool, _ in self._pools.values():
            try:
                pool.close()
            except Exception:  # pragma: no cover
                pass
        self._pools = {}
        self.closed = True

    def __enter__(self) -> Planner:
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()


def plan_actions(plan: str) -> list[str]:
    """``"move_to(A), grasp(cube, G)"`` -> its actions, ``["move_to(A)", "grasp(cube, G)"]``."""
    return re.findall(r"\w+\([^()]*\)", plan)


def _next_dir(parent: Path, stem: str) -> Path:
    k = 0
    while (parent / f"{stem}-{k}").exists():
        k += 1
    return parent / f"{stem}-{k}"


def _what_differs(key: str, other: str) -> str:
    """Which config keys two scene keys differ in (``scene.tables, scene.walls``)."""
    mine, theirs = json.loads(key), json.loads(other)
    diff = []
    for k in mine:
        a, b = mine[k], theirs.get(k)
        if isinstance(a, dict) and isinstance(b, dict):
            diff += [f"{k}.{kk}" for kk in sorted(set(a) | set(b)) if a.get(kk) != b.get(kk)]
        elif a != b:
            diff.append(k)
    return ", ".join(diff) or "nothing"


def realized_task(task: Mapping[str, Any], run_dir: str | Path) -> dict[str, Any]:
    """Task mapping ``task`` of the run in ``run_dir`` with the plan that run realized: where the
    PDDL planner chose it (``task.planner.enabled``, no ``plan`` written), the plan its
    ``result.json`` names, so a re-sequence that plans the same actions again is recognised as
    a replan of them (warm-started) rather than searched cold."""
    out = dict(task)
    if not out.get("plan"):
        done = RunDir(run_dir).result_json() or {}
        out["plan"] = plan_actions(str(done.get("plan") or ""))
    return out
