"""The edge between Hydra and the library: a whole run config, checked once into a ``RunSpec``.

What it does: ``build_run_spec(d)`` takes the resolved config of one run (a plain mapping with
the groups ``task``, ``scene``, ``robot``, ``sim``, ``controller``, ``ce``, ``logging``, ``workers``, ``validation`` and
the top-level keys ``seed``, ``device``, ``resume``, ``task_file``, ``task_origin``, ``warm_start``, ``replan_from``,
``replan``, ``stitch``) and returns a
``RunSpec`` of validated objects (``TaskSpec`` (a replan's: the remaining actions, ``realize.spec.replan_from``), ``GeometryCfg``/``SceneGeometry``, ``SimSettings``, ``RolloutConfig``,
``CEConfig``, ``LoggingSettings``, ``PlannerSettings`` and the ``Placement``: where the run's
tensors live and the search's dtype). Every problem raises ``realize.config.ConfigError`` with
a one-line message naming the key (or file), the value and what is allowed; nothing later
validates again. Nothing here builds a simulator; the only outside process it may start is the
PDDL planner when ``task.planner.enabled`` is set (``task.planner.top_k > 1``: its k best plans
become candidate tasks, and the halving budget of ``realize.search.budget`` is checked before the
planner runs).
What it doesn't: read Hydra objects (``realize.run.one_run`` converts them to plain data first), or run.

``CEConfig.seed`` is the top-level ``seed``. ``device`` (auto|cpu|cuda) picks the simulator
backend unless ``sim.backend`` says otherwise; ``auto`` is resolved here (the CPU, also where torch
sees CUDA: ``realize.scene.backends.resolve_backend``).

A run keeps the task it ran: with ``task_file`` set, ``RunSpec.config`` (what result.json and
the checkpoint save) holds the file's content as ``task``, ``task_file: null`` and
``task_origin: {path, sha256}`` (``realize.spec.task_plans.TaskOrigin``). Built again from that
config (replay, validation, resume, warm start, replan), the run's copy is used and the file
is never read again; ``task_origin.path`` stays the task's ``source`` in messages.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field, fields
from typing import TYPE_CHECKING, Any

import torch

from realize.search.budget import HalvingBudget, plan_budget
from realize.search.ce.config import CEConfig
from realize.spec.run_settings import LoggingSettings, ValidationSettings
from realize.spec.stitch_settings import StitchSettings, read_stitch
from realize.search.segments import StitchConfig
from realize.config import ConfigError, Settings, as_mapping, check_unknown, setting
from realize.spec.task_plans import (PlannerSettings, TaskOrigin, build_task_candidates, check_halving_budget,
                                load_task_file)
from realize.spec.workers_settings import WorkersSettings, worker_count
from realize.run_dir.upgrade import check_retired

if TYPE_CHECKING:  # the simulator modules are imported where used: `realize` starts fast
    from realize.world.geometry import GeometryCfg, SceneGeometry
    from realize.spec.replan_from import ReplanSpec
    from realize.robot.spec import RobotSpec
    from realize.scene.settings import SimSettings
    from realize.world.state import SceneState
    from realize.tasks.spec import TaskSpec
    from realize.tasks.worlds import Worlds

__all__ = ["LoggingSettings", "ValidationSettings", "StitchSettings", "read_stitch", "Placement", "RunSpec",
           "build_run_spec", "TOP_LEVEL_KEYS", "DEVICES"]

GROUPS = ("task", "scene", "robot", "sim", "controller", "ce", "logging", "workers", "validation")
TOP_LEVEL_KEYS = GROUPS + ("seed", "device", "resume", "task_file", "task_origin", "warm_start", "replan_from",
                            "replan", "stitch")
DEVICES = ("auto", "cpu", "cuda")
_DEVICE_BACKEND = {"cpu": "cpu", "cuda": "gpu"}  # device -> scene backend
_BACKEND_DEVICE = {"cpu": "cpu", "gpu": "cuda"}


@dataclass
class _TopLevel(Settings):
    """The run config's own keys (the groups are read by their own classes)."""

    seed: int = setting(0, ge=0)
    device: str = setting("auto", choices=DEVICES)
    resume: str | None = None
    task_file: str | None = None
    warm_start: str | None = None
    replan_from: str | None = None  # an earlier run whose remaining actions to realize (realize.spec.replan_from)


@dataclass(frozen=True)
class Placement:
    """Where a run's tensors live and in which dtype the search keeps its books.

    ``backend``: the batched scene's (``"cpu"``: copies tiled in one PhysX CPU scene; ``"gpu"``:
    PhysX GPU); ``device``: the torch device of the scene, the rollout and the batches handed to
    it; ``dtype``: the search's sampling/ranking/refit dtype (``ce.dtype``; always on the CPU)."""

    backend: str
    device: torch.device
    dtype: torch.dtype


@dataclass
class RunSpec:
    """One run, validated. ``config`` is the plain resolved mapping it was built from."""

    seed: int
    resume: str | None
    task: TaskSpec
    geometry_cfg: GeometryCfg
    geometry: SceneGeometry
    robot: RobotSpec
    sim: SimSettings
    rollout: Any  # realize.realization.config.RolloutConfig (imported lazily: it pulls in the controllers)
    ce: CEConfig
    logging: LoggingSettings
    config: dict[str, Any]
    placement: Placement
    planner: PlannerSettings = field(default_factory=PlannerSettings)
    workers: WorkersSettings = field(default_factory=WorkersSettings)  # who simulates (never changes the numbers)
    # the candidate plans' tasks ([task] unless planner.top_k > 1) and their halving budget
    candidates: list[TaskSpec] = field(default_factory=list)
    budget: HalvingBudget | None = None
    warm_start: str | None = None  # an earlier run directory the search starts from (realize.search.warm_start)
    validation: ValidationSettings | None = None  # after the search (realize.validation.candidates); None: off
    # copy k of the run's scene meets worlds[k] (realize.tasks.worlds; validation's scenes); None: the
    # task's world, or with ce.replicas > 1 the robust search's worlds (realize.workers.replicas)
    worlds: Worlds | None = None
    # replan_from: the plan's remaining actions from a given state (realize.spec.replan_from); None otherwise
    replan: ReplanSpec | None = None
    stitch: StitchConfig | None = None  # stitched segments (realize.search.chain); None: one CE over the plan

    @property
    def start(self) -> SceneState | None:
        """The state every rollout starts from (a replan's), or None: the task's initial state."""
        return None if self.replan is None else self.replan.state

    @property
    def keep_best(self) -> int | None:
        """``ce.prune``: the rows of a batch that must end as they would unpruned, the ``n_elite``
        cheapest feasible (or the validation's candidates, if it runs and they are more); a
        rollout may stop any other row (``realize.realization.pruning``). None: pruning off, or
        a robust or kNN-ranked search, where a row's score depends on other rows or worlds."""
        ce = self.ce
        if not ce.prune or ce.replicas > 1 or ce.knn_robust > 0:
            return None
        val = self.validation
        return max(ce.n_elite, val.candidates if val is not None and val.replicas > 0 else 0)

    @property
    def halving(self) -> bool:
        """Successive halving over candidate plans (``task.planner.top_k > 1``)."""
        return self.planner.top_k > 1


def read_ce(d: Any, seed: int, where: str = "ce") -> CEConfig:
    """The ``ce`` group -> ``CEConfig`` with the run seed (the group has no ``seed`` key)."""
    d = as_mapping(d, where)
    check_unknown(d, [f.name for f in fields(CEConfig) if f.name != "seed"], where)
    return CEConfig.from_mapping({**d, "seed": seed}, where)


def read_sim(d: Any, where: str = "sim") -> SimSettings:
    """The ``sim`` group -> ``SimSettings`` (types, unknown keys, bounds, its own checks)."""
    from realize.scene.settings import SimSettings

    return SimSettings.from_mapping(d, where)


def read_robot(d: Any, where: str = "robot") -> RobotSpec:
    """The ``robot`` group -> ``RobotSpec`` (None: the default robot's config file), its joint and
    link names and its gripper (``realize.robot.grip_geometry``) checked against its URDF."""
    from realize.robot.spec import DEFAULT_ROBOT, RobotSpec, load_robot_spec
    from realize.robot.urdf_names import check_urdf_names

    spec = load_robot_spec(DEFAULT_ROBOT) if d is None else RobotSpec.from_mapping(as_mapping(d, where), where)
    check_urdf_names(spec, where)  # a name the URDF lacks, a gripper it cannot build: one line, not a traceback
    return spec


def resolve_placement(device: str, sim: SimSettings, ce: CEConfig) -> Placement:
    """``device`` and ``sim.backend`` -> one ``Placement``; ``sim.backend`` is set to the result
    (the scene then has nothing left to choose)."""
    want = _DEVICE_BACKEND.get(device)
    if want is not None:
        if sim.backend not in ("auto", want):
            raise ConfigError(
                f"device = {device!r} conflicts with sim.backend = {sim.backend!r}; set one of them "
                f"(device=cuda goes with sim.backend=gpu, device=cpu with sim.backend=cpu)"
            )
        sim.backend = want
    from realize.scene.backends import resolve_backend

    try:
        backend = resolve_backend(sim.backend)  # refuses gpu without CUDA
    except ConfigError as e:
        raise ConfigError(f"device = {device!r}: {e}") from None
    dev = torch.device(_BACKEND_DEVICE[backend])
    sim.backend = backend
    return Placement(backend, dev, ce.torch_dtype)


def _read_geometry(d: Any) -> tuple[GeometryCfg, SceneGeometry]:
    from realize.world.geometry import GeometryCfg, build_geometry

    try:
        geometry_cfg = GeometryCfg.from_mapping(as_mapping(d, "scene"), "scene")
        return geometry_cfg, build_geometry(geometry_cfg)
    except ConfigError:
        raise
    except (ValueError, TypeError) as e:
        msg = str(e)
        raise ConfigError(msg if msg.startswith("scene") else f"scene: {msg}") from None


def _read_rollout(d: Any) -> Any:
    from realize.realization.config import RolloutConfig

    try:
        return RolloutConfig.from_mapping(as_mapping(d, "controller"), "controller")
    except (ValueError, TypeError) as e:
        msg = str(e)
        raise ConfigError(msg if msg.startswith("controller") else f"controller: {msg}") from None


def _replan_start_held(keys: Any, d: Mapping[str, Any]) -> str | None:
    """What the hand holds where the task's plan starts: a replan of a whole new plan (replan.action
    0, a re-sequence) from a state holding an object may begin with its place; a replan of later
    actions of an earlier run's plan starts that plan where the earlier run started it (followed
    back through the runs it replanned: a re-sequenced restack that begins by setting the held
    block down, replanned from its second action); else nothing."""
    from realize.spec.replan_from import saved_config
    from realize.world.state import load_state

    r, source = d.get("replan"), keys.replan_from
    for _ in range(64):  # a chain of replans, each of the one before
        if source is None or not isinstance(r, Mapping):
            return None
        if r.get("action") == 0:
            return load_state(r["state"], "replan.state").held if r.get("state") else None
        try:
            earlier = saved_config(source)
        except ConfigError:
            return None
        r, source = earlier.get("replan"), earlier.get("replan_from")
    return None


def build_run_spec(d: Mapping[str, Any]) -> RunSpec:
    """Validate a whole resolved run config (plain data). Raises ``ConfigError``."""
    d = as_mapping(d, "config")
    check_unknown(d, list(TOP_LEVEL_KEYS), "config")
    check_retired(d)  # a saved run's are dropped when it is read (realize.run_dir.upgrade)
    top = {k: v for k, v in d.items() if k not in GROUPS and k not in ("replan", "task_origin", "stitch")}
    for k in ("resume", "task_file", "warm_start", "replan_from"):
        if top.get(k) is not None:
            top[k] = str(top[k])
    keys = _TopLevel.from_mapping(top, "")

    ce = read_ce(d.get("ce"), keys.seed)
    sim = read_sim(d.get("sim"))
    placement = resolve_placement(keys.device, sim, ce)
    robot = read_robot(d.get("robot"))
    from realize.world.geometry import check_robot_start, with_fixed_base_start

    scene_d, start_key = with_fixed_base_start(as_mapping(d.get("scene"), "scene"), robot.base.fixed)
    geometry_cfg, geometry = _read_geometry(scene_d)
    check_robot_start(geometry, robot.base.footprint_radius, key=start_key)

    config = dict(d)
    config["scene"] = scene_d  # the run's files say where the robot stood
    origin = TaskOrigin.from_json(d.get("task_origin"))
    if keys.task_file is not None:  # the run keeps the file's content: its config is the task it ran
        task_d, source = load_task_file(keys.task_file)
        origin = TaskOrigin.of_file(source)
        config.update(task=task_d, task_file=None, task_origin=origin.to_json())
    else:
        task_d = as_mapping(d.get("task"), "task")
        source = "task" if origin is None else origin.path
        if not task_d:
            raise ConfigError("task: no task given (choose task=<name> or task_file=<path.yaml>)")
    planner = PlannerSettings.from_mapping(task_d.get("planner"), f"{source}:planner")
    check_halving_budget(planner, ce, source)  # before the planner runs
    if ce.replicas > 1 and planner.top_k > 1:
        raise ConfigError(f"ce.replicas = {ce.replicas}: a robust search realizes one plan; {source}:planner.top_k = "
                          f"{planner.top_k} searches several (set one of them to 1)")
    if keys.warm_start is not None and planner.top_k > 1:
        raise ConfigError(f"warm_start = {keys.warm_start!r}: a warm start seeds one plan's search; "
                          f"{source}:planner.top_k = {planner.top_k} searches several (set it to 1)")
    task, candidates = build_task_candidates(task_d, geometry, source, planner, held=_replan_start_held(keys, d))
    if robot.base.fixed:
        from realize.realization.actions import TEMPLATES
        from realize.tasks.spec import check_fixed_base

        for i, t in enumerate(candidates):
            check_fixed_base(t.plan, TEMPLATES, robot.name, f"{source}:plan" if len(candidates) == 1 else
                             f"{source}:planner[{i}]")
    from realize.spec.replan_from import check_no_replan, read_replan

    replan = None
    if keys.replan_from is None:
        check_no_replan(d.get("replan"))
    else:  # the plan's remaining actions only, from the given state
        task, replan = read_replan(keys.replan_from, d.get("replan"), task, planner.top_k)
        robot.check_state_joints(replan.state.joints, f"replan.state {replan.state_file}")  # before anything runs
        candidates = [task]
    workers = WorkersSettings.from_mapping(d.get("workers"))
    from realize.scene.backends import shardable
    from realize.scene.shards import shard_rows

    split = shardable(placement.backend)
    n_shards = len(shard_rows(ce.n_envs, sim.shard_rows if split else ce.n_envs, ce.replicas))
    worker_count(workers, n_shards, split, cores=n_shards)  # refuses what cannot work
    budget = None
    if planner.top_k > 1:
        budget = plan_budget(len(candidates), ce.iterations, ce.n_envs, planner.round_iterations)

    stitch = read_stitch(d.get("stitch"), ce, task, planner.top_k, replan is not None, keys.warm_start is not None)
    rollout = _read_rollout(d.get("controller"))
    robot.fabric_exclusions(rollout.fabric.collision_exclude, [s.name for s in robot.spheres()])  # at the edge
    from realize.realization.reach_check import check_reach_all

    check_reach_all(candidates, geometry, robot, rollout, source)  # a region a fixed arm never reaches: one line
    return RunSpec(
        seed=keys.seed,
        resume=keys.resume,
        task=task,
        geometry_cfg=geometry_cfg,
        geometry=geometry,
        robot=robot,
        sim=sim,
        rollout=rollout,
        ce=ce,
        logging=LoggingSettings.from_mapping(d.get("logging")),
        workers=workers,
        config=config,
        placement=placement,
        planner=planner,
        candidates=candidates,
        budget=budget,
        warm_start=keys.warm_start,
        replan=replan,
        validation=ValidationSettings.from_mapping(d.get("validation")),
        stitch=stitch,
    )
