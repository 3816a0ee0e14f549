"""What several test files share (a plain module: pytest does not collect it; fixtures are in
``conftest.py``): the app's composed config and the ``realize`` command in a subprocess (both
with ``validation=off`` unless a test chooses a validation), the tiny
run of the command tests, the seed task's known plans, the scripts as modules, the kinematics
tests' joint vectors, the A* tests' path check, rollouts in a fresh scene with the simulator's
state read back (the rollout and push tests), the thread that kills a worker mid-rollout
(the worker tests, processes and Ray actors), and the docs' fenced blocks with their markers."""

from __future__ import annotations

import importlib.util
import json
import math
import os
import re
import signal
import subprocess
import sys
import threading
import time
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, Callable

import pytest

if TYPE_CHECKING:
    import torch

    from realize.spec.run_spec import RunSpec
    from realize.scene import BatchedScene

REPO = Path(__file__).resolve().parent.parent


# ------------------------------------------------------------------------------ config, command
def quiet_validation(args: tuple[str, ...] | list[str]) -> list[str]:
    """``validation=off`` first unless ``args`` choose a validation themselves: a run validates its
    candidates by default (64 x 5 replicas), which the tests' small runs do not need; the tests of
    validation ask for it."""
    if any(str(a).lstrip("+~").startswith("validation") for a in args):
        return []
    return ["validation=off"]


def compose_config(*overrides: str, cpu: bool = True, plain: bool = True, hydra_cfg: bool = False,
                   job_name: str = "tests") -> Any:
    """The app's config (``configs/config.yaml`` + defaults + ``overrides``), ``device=cpu``
    first unless ``cpu=False``: resolved plain data without Hydra's node, or with ``plain=False``
    the DictConfig (``hydra_cfg``: with Hydra's node)."""
    from hydra import compose, initialize_config_dir
    from omegaconf import OmegaConf

    from realize.spec.hydra_edge import register_resolvers
    from realize.paths import CONFIG_DIR

    register_resolvers()  # ${realize_scaled:...} in the presets
    with initialize_config_dir(config_dir=str(CONFIG_DIR), version_base="1.3", job_name=job_name):
        cfg = compose(config_name="config", overrides=[*(["device=cpu"] if cpu else []), *quiet_validation(overrides),
                                                       *overrides],
                      return_hydra_config=hydra_cfg)
    if not plain:
        return cfg
    d = OmegaConf.to_container(cfg, resolve=True)
    assert isinstance(d, dict)
    d.pop("hydra", None)
    return d


def realize_cli(*args: str, cwd: Path = REPO, timeout: float | None = None, env: dict[str, str] | None = None,
                background: bool = False, **popen: Any) -> Any:
    """``python -m realize ARGS`` as a user runs it, this checkout first on PYTHONPATH, ``env``
    added to the environment: the CompletedProcess (text output captured) after at most
    ``timeout`` s, or with ``background=True`` the running Popen (``popen``: stdout, stderr, ...)."""
    env = dict(os.environ, **(env or {}), PYTHONPATH=str(REPO) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    cmd = [sys.executable, "-m", "realize", *args, *quiet_validation(args)]
    if background:
        return subprocess.Popen(cmd, cwd=cwd, env=env, text=True, **popen)
    return subprocess.run(cmd, cwd=cwd, env=env, capture_output=True, text=True, timeout=timeout)


def realize_result(*args: str, run_dir: Path, timeout: float = 600, env: dict[str, str] | None = None) -> dict:
    """A run of the command into ``run_dir`` (started in its parent) that must succeed: its result.json."""
    p = realize_cli(*args, f"hydra.run.dir={run_dir}", cwd=run_dir.parent, timeout=timeout, env=env)
    assert p.returncode == 0, p.stderr[-3000:]
    return json.loads((run_dir / "result.json").read_text())


def load_script(name: str) -> Any:
    """``scripts/NAME.py`` as a module (its ``main``, ...)."""
    spec = importlib.util.spec_from_file_location(f"_script_{name}", REPO / "scripts" / f"{name}.py")
    mod = importlib.util.module_from_spec(spec)
    assert spec.loader is not None
    sys.modules[spec.name] = mod  # (a script's dataclasses look their module up there)
    spec.loader.exec_module(mod)
    return mod


# ------------------------------------------------------------------------------ the tiny run
# 4 plans, 2 elites, short horizon: every plan gets through at least the first move_to
TINY_D = {
    "ce.n_envs": 4,
    "ce.n_elite": 2,
    "ce.iterations": 2,
    "controller.max_time_s": 6,
    "logging.progress": "false",
    "logging.rerun": "false",
}
TINY = [f"{k}={v}" for k, v in TINY_D.items()]


def tiny(**changes: object) -> list[str]:
    """TINY with some keys changed (``ce__iterations=1`` -> ``ce.iterations=1``)."""
    d = dict(TINY_D)
    d.update({k.replace("__", "."): v for k, v in changes.items()})
    return [f"{k}={v}" for k, v in d.items()]


def tiny_with(extra: list[str]) -> list[str]:
    """TINY with ``extra`` overrides replacing TINY's value of the same key."""
    keys = {e.split("=", 1)[0].lstrip("+~") for e in extra}
    return [o for o in TINY if o.split("=", 1)[0] not in keys] + extra


def cfg_of(overrides: list[str], hydra_cfg: bool = False) -> Any:
    """The config as the command composes it (its device default): a DictConfig."""
    return compose_config(*overrides, cpu=False, plain=False, hydra_cfg=hydra_cfg, job_name="test")


def plain(overrides: list[str]) -> dict:
    """``cfg_of`` as plain data."""
    return compose_config(*overrides, cpu=False, job_name="test")


def comparable(v: Any) -> Any:
    """A config value as a comparison should see it: numbers as floats (YAML's 1 equals a
    dataclass's 1.0), tuples as lists, recursively."""
    if isinstance(v, (list, tuple)):
        return [comparable(a) for a in v]
    if isinstance(v, (int, float)) and not isinstance(v, bool):
        return float(v)
    return v


def expect_config_error(overrides: list[str], needles: list[str], run_dir: Path) -> tuple[str, dict]:
    """Run the tiny config with ``overrides``: it must fail with a one-line ConfigError holding
    every needle; returns the message and the result.json written for it."""
    from realize.config import ConfigError
    from realize.run.one_run import run
    from realize.run_dir.names import RESULT_FILE

    with pytest.raises(ConfigError) as ei:
        run(cfg_of(tiny_with(overrides)), run_dir)
    msg = str(ei.value)
    assert "\n" not in msg
    for n in needles:
        assert n in msg, f"{n!r} not in {msg!r}"
    return msg, json.loads((run_dir / RESULT_FILE).read_text())


# ------------------------------------------------------------------------------ worker runs
# the workers' must-show run, and the result keys that must not depend on where rollouts ran
RUN16 = ["ce.n_envs=16", "ce.n_elite=4", "ce.iterations=2", "seed=3", "sim.shard_rows=8",
         "logging.progress=false", "logging.rerun=false"]
KEYS = ("best_cost", "success_per_iter", "best_cost_per_iter", "best_z", "n_feasible_per_iter", "final_mean",
        "final_std")


# ------------------------------------------------------------------------------ the seed task's plans
SEED_TASK = REPO / "configs" / "task" / "pick_place.yaml"
# columns: Table1.x, Table1.y, Cube_g.x, Cube_g.y, Cube_g.z, Table2.x, Table2.y,
#          Cube_p.x, Cube_p.y, Cube_p.z, Exit.x, Exit.y
GOOD = [-0.85, 1.2, 0.0, 1.2, 0.8925, -0.85, -1.2, 0.0, -1.2, 0.8975, 2.2, 0.0]
_S, _C = math.sin(0.5), math.cos(0.5)
# a second feasible plan: base off-axis, grasp tilted 0.5 rad towards the robot, another exit point
SIDE = [-0.9, 1.1, -0.15 * _S, 1.2, 0.7425 + 0.15 * _C, -0.8, -1.0, 0.0, -1.2, 0.8975, 2.5, 0.3]
# an infeasible one: base in front of table 1 (y = 0.2), grasp from the far side (polar 1 rad)
FAR_SIDE = [0.0, 0.2, 0.0, 1.2 + 0.15 * math.sin(1.0), 0.7425 + 0.15 * math.cos(1.0),
            -0.85, -1.2, 0.0, -1.2, 0.8975, 2.2, 0.0]


def blas_batch_invariant() -> bool:
    """Whether this machine's batched matrix products give a row the same bits whatever the
    other rows of the batch are. Intel CPUs with MKL were seen to; an AMD EPYC with MKL does not
    (float32 (k, 11, 11) products differ in the last bit between k = 8 and k = 7). Where it
    does not hold, a plan's controller output depends on which other plans share its control
    step's batch, so 'batched equals per sample' and 'one plan's fault leaves the others'
    costs untouched' can only hold up to the chaos that rounding seeds in a grasp."""
    import torch

    g = torch.Generator().manual_seed(0)
    for dtype in (torch.float32, torch.float64):
        a = torch.randn(8, 11, 11, generator=g, dtype=dtype)
        b = torch.randn(8, 11, 11, generator=g, dtype=dtype)
        full = a @ b
        keep = [0, 1, 2, 4, 5, 6, 7]
        if not torch.equal((a[keep] @ b[keep])[-1], full[7]) or not torch.equal((a[7:] @ b[7:])[0], full[7]):
            return False
    return True


# ----------------------------------------------------------------------------- kinematics


def full_qpos(kin, q, names):
    """``(..., len(names))``: ``q``'s joints and the kinematics model ``kin``'s fixed (held, finger)
    values in ``names`` order (a joint vector for another implementation or the simulator)."""
    import torch

    cols = [q[..., kin.joint_names.index(n)] if n in kin.joint_names
            else torch.full(q.shape[:-1], kin.fixed_values.get(n, 0.0), dtype=q.dtype) for n in names]
    return torch.stack(cols, dim=-1)


def random_q(kin, n: int, seed: int = 0):
    """``(n, n_dof)`` random configurations of ``kin`` inside its joint limits (base within +-2 m,
    free joints in +-pi), in its dtype."""
    import torch

    g = torch.Generator().manual_seed(seed)
    lo = torch.nan_to_num(kin.lower, neginf=-torch.pi).clamp(min=-2.0)
    hi = torch.nan_to_num(kin.upper, posinf=torch.pi).clamp(max=2.0)
    return lo + (hi - lo) * torch.rand(n, kin.n_dof, generator=g, dtype=kin.dtype)


# ----------------------------------------------------------------------------- A* paths
def assert_path_valid(occ: torch.Tensor, path: torch.Tensor, length: int, start: Any, goal: Any,
                      cost: float) -> None:
    """A planned grid path on the occupancy grid ``occ``: its first ``length`` cells run from
    ``start`` to ``goal``, the rest is ``-1`` padding; consecutive cells are adjacent (8-connected),
    every cell is free, no diagonal step cuts an occupied corner, and the steps (1 orthogonal,
    sqrt 2 diagonal) sum to ``cost``."""
    from realize.controllers.astar_search import SQRT2

    p = path[:length].tolist()
    assert p[0] == list(start) and p[-1] == list(goal)
    assert (path[length:] == -1).all()
    total = 0.0
    for (r0, c0), (r1, c1) in zip(p[:-1], p[1:]):
        dr, dc = r1 - r0, c1 - c0
        assert max(abs(dr), abs(dc)) == 1, (p, (r0, c0), (r1, c1))
        if dr and dc:
            assert not occ[r0 + dr, c0] and not occ[r0, c0 + dc], "corner cut"
            total += SQRT2
        else:
            total += 1.0
    for r, c in p:
        assert not occ[r, c]
    assert total == pytest.approx(cost, abs=1e-9)


# ----------------------------------------------------------------------------- rollouts in a fresh scene
class StepCounter:
    """Counts ``scene.step`` calls (the physics the rollout actually asked for); with
    ``monkeypatch`` the scene gets its own ``step`` back when the test ends."""

    def __init__(self, scene: BatchedScene, monkeypatch: pytest.MonkeyPatch | None = None):
        self.calls = 0
        inner = scene.step

        def step() -> None:
            self.calls += 1
            inner()

        if monkeypatch is not None:
            monkeypatch.setattr(scene, "step", step)
        else:
            scene.step = step  # type: ignore[method-assign]


def run_fresh(spec: RunSpec, Z: torch.Tensor, readback: Callable[[BatchedScene], dict[str, Any]],
              record: bool = False, repeat: int = 1) -> list[dict[str, Any]]:
    """Realize Z ``repeat`` times in one newly built scene of len(Z) copies: per rollout, its
    result (``res``), the ``scene.step`` calls it made (``calls``) and ``readback(scene)`` (the
    simulator's state right after it)."""
    from realize.realization.rollout import PlanRealizer
    from realize.scene import BatchedScene

    out = []
    with BatchedScene(len(Z), spec.geometry_cfg, spec.sim) as scene:
        counter = StepCounter(scene)
        realizer = PlanRealizer.from_spec(spec, None, scene)
        for _ in range(repeat):
            before = counter.calls
            res = realizer.rollout(Z, record=record)
            out.append(dict(res=res, calls=counter.calls - before, **readback(scene)))
    return out


def run_alone(spec: RunSpec, Z: torch.Tensor, readback: Callable[[BatchedScene], dict[str, Any]],
              record: bool = True) -> list[dict[str, Any]]:
    """Each row of Z realized on its own (N = 1), each in its own fresh scene: ``run_fresh``'s
    dict of every row, in Z's order."""
    return [run_fresh(spec, Z[i:i + 1], readback, record=record)[0] for i in range(len(Z))]


# ----------------------------------------------------------------------------- worker faults
def kill_on_rollout(victim: Callable[[list[int]], int | None], times: int,
                    timeout_s: float = 300.0) -> threading.Thread:
    """A started daemon thread that polls ``victim(killed)`` every 50 ms (``killed``: the pids it
    has killed so far, in order) and SIGKILLs the pid it returns (None: nothing to kill yet),
    until it has killed ``times`` times or ``timeout_s`` s have passed. ``victim`` says when the
    worker under test is mid-rollout (from its log) and which process it is."""

    def run() -> None:
        killed: list[int] = []
        deadline = time.monotonic() + timeout_s
        while len(killed) < times and time.monotonic() < deadline:
            pid = victim(killed)
            if pid is not None:
                os.kill(pid, signal.SIGKILL)
                killed.append(pid)
            time.sleep(0.05)

    t = threading.Thread(target=run, daemon=True)
    t.start()
    return t


# ----------------------------------------------------------------------------- the docs' blocks
DOC_PAGES = ("README.md", *sorted(f"docs/{p.name}" for p in (REPO / "docs").glob("*.md")))
# the line before a fenced command block says what a test does with it (tests/test_doc_commands.py):
#   <!-- runs in tests/test_x.py::test_y -->               that test executes the block
#   <!-- arguments checked, not run: reason -->           each command's arguments are checked
#   <!-- not run: reason -->                              nothing runs it
MARKER = re.compile(r"<!-- (?:runs in (?P<test>tests/\w+\.py::\w+)|(?P<checked>arguments checked, )?not run: "
                    r"(?P<reason>.+?)) -->")


@dataclass(frozen=True)
class DocBlock:
    """One fenced block of a docs page: where it starts (1-based line of its opening fence), its
    language tag (\"\" when untagged), the marker on the line before it (None: none), its text."""

    page: str
    line: int
    lang: str
    marker: re.Match | None
    text: str

    @property
    def where(self) -> str:
        return f"{self.page}:{self.line}"


def doc_blocks(page: str) -> list[DocBlock]:
    """The fenced blocks of ``page`` (a path relative to the repository, as in ``DOC_PAGES``)."""
    lines = (REPO / page).read_text().splitlines()
    blocks, i = [], 0
    while i < len(lines):
        if lines[i].startswith("```"):
            j = next(k for k in range(i + 1, len(lines)) if lines[k].startswith("```"))
            marker = MARKER.fullmatch(lines[i - 1].strip()) if i > 0 else None
            blocks.append(DocBlock(page, i + 1, lines[i][3:].strip(), marker, "\n".join(lines[i + 1:j]) + "\n"))
            i = j
        i += 1
    return blocks


def doc_block(page: str, lang: str, index: int = 0) -> DocBlock:
    """The ``index``-th ``lang`` block of ``page`` (a test that runs a block says which)."""
    found = [b for b in doc_blocks(page) if b.lang == lang]
    if len(found) <= index:
        pytest.fail(f"{page} has {len(found)} ```{lang} blocks; the test runs block {index}")
    return found[index]


def turned_worlds(names: tuple[str, ...], turned: str, yaws: list[float]) -> Any:
    """Worlds (``realize.tasks.worlds.Worlds``), one per yaw: object ``turned`` turned by it (rad),
    nothing else moved, friction and mass as configured."""
    import numpy as np

    from realize.tasks.worlds import Worlds

    n, m = len(yaws), len(names)
    yaw = np.zeros((n, m))
    yaw[:, names.index(turned)] = yaws
    return Worlds(names, np.zeros((n, 2)), np.zeros((n, m, 2)), yaw, np.ones((n, m)), np.ones((n, m)))


# ------------------------------------------------------------------ runs, states and worlds
STATE_GRASPED = REPO / "tests" / "fixtures" / "state_grasped.json"  # the cube in the hand above table 1, action 2 next
# the best parameters of a seed-task run, the whole plan (move_to(Table1), grasp(cube, Cube_g) first)
FULL_Z = [-0.9953907433402727, 0.9260304134062874, -0.03445283281557375, 1.189657915463341, 0.8881229501088985,
          -0.9659641240604275, -1.0622591208176722, -0.050928051774466784, -1.1459906667680084, 0.8778431067079995,
          1.9177437232633234, -0.07168660186229141]
# table 2 moved 30 cm in -y 1 s into move_to(Table2) (while the cube is carried): the planned place
# then puts the cube on the table's edge, so the plan carried out as planned misses the goal
TABLE_MOVED = {"trigger": {"action": 2, "delay_s": 1.0}, "move_table": {"table": "table2", "dx": 0.0, "dy": -0.3}}


def on_table2(cube: "torch.Tensor") -> bool:
    """The cube's centre over table 2's top (0.6 x 0.6 m at (0, -1.2), 0.72 m high), resting on it."""
    x, y, z = cube[:3].tolist()
    return abs(x) <= 0.3 and abs(y + 1.2) <= 0.3 and abs(z - (0.72 + 0.0225)) <= 0.01


def write_known_run(run_dir: Path, overrides: tuple[str, ...] = ()) -> Path:
    """A run directory of the seed task whose plan and final distribution are the known feasible
    plan ``GOOD`` (narrow std): what a warm start or an executor starts from."""
    from realize.spec.run_spec import build_run_spec
    from realize.run_dir.jsonio import atomic_write_json
    from realize.run_dir.names import RESULT_FILE

    config = compose_config(*overrides)
    spec = build_run_spec(config)
    run_dir.mkdir(parents=True, exist_ok=True)
    atomic_write_json(run_dir / RESULT_FILE, {
        "status": "done", "feasible": True, "best_cost": 1.5, "best_z": list(GOOD),
        "final_mean": list(GOOD), "final_std": [0.005] * len(GOOD), "plan": spec.task.describe(),
        "columns": list(spec.task.layout.column_names), "n_envs_scene": 1, "backend": "cpu", "config": config,
    })
    return run_dir


def one_world(*disturbances: dict, **keys: object) -> Any:
    """Execute settings for one world; the world runs on for a fixed 40 control steps (2 s) while
    the planner thinks, so that a study repeats bit for bit."""
    from realize.execution.settings import ExecuteSettings

    return ExecuteSettings.from_mapping({"worlds": 1, "seed": 0, "max_replans": 3, "think": 40,
                                         "disturbances": list(disturbances), **keys})


def execute_budget() -> Any:
    """The replan budget of the execution tests: 8 copies, 2 elites, 2 iterations, in this process."""
    from realize.run.planner import ReplanBudget

    return ReplanBudget(n_envs=8, n_elite=2, iterations=2, shard_rows=None, workers=1)


def closed_loop_world(run: Path, settings: Any, out: Path, trajectory: Path | None = None,
                      budget: Any = None) -> Any:
    """World 0 of ``settings`` carried out closed loop from ``run`` by a warmed-up planner (its
    ``WorldLog``), replanning with ``budget`` (default ``execute_budget()``)."""
    from realize.repair.study import execute_world
    from realize.run.planner import Planner

    budget = budget or execute_budget()
    planner = Planner.from_run(run)
    try:
        planner.warm_up(budget)
        return execute_world(run, settings, 0, closed_loop=True, planner=planner, out=out, budget=budget,
                             trajectory=trajectory)
    finally:
        planner.close()


# ------------------------------------------------------------------ the fabric's random batches
FABRIC_ROWS = 96


def row_subsets(seed: int, count: int = 12) -> list["torch.Tensor"]:
    """Random subsets of ``FABRIC_ROWS`` rows in shuffled order, the edge sizes (1, 2, 7, 8, 9, all
    but one) first."""
    import torch

    g = torch.Generator().manual_seed(seed)
    sizes = [1, 2, 7, 8, 9, FABRIC_ROWS - 1] + torch.randint(3, FABRIC_ROWS, (count - 6,), generator=g).tolist()
    return [torch.randperm(FABRIC_ROWS, generator=g)[:k] for k in sizes]


def fabric_states(robot: Any, dtype: "torch.dtype", seed: int) -> tuple["torch.Tensor", "torch.Tensor", "torch.Tensor"]:
    """``FABRIC_ROWS`` whole-body states of ``robot`` in front of table 1 (some arms near it, some
    far), random speeds, goals."""
    import torch

    g = torch.Generator().manual_seed(seed)
    n, dof = FABRIC_ROWS, robot.n_dof
    q = torch.tensor(robot.rest_q(), dtype=torch.float64).expand(n, -1).clone()
    q = q + 0.3 * torch.randn(n, dof, generator=g, dtype=torch.float64)
    q[:, 0] = 0.7 + 0.5 * torch.rand(n, generator=g, dtype=torch.float64)
    q[:, 1] = 1.2 + 0.4 * (2 * torch.rand(n, generator=g, dtype=torch.float64) - 1)
    q[:, 2] = math.pi + 0.3 * torch.randn(n, generator=g, dtype=torch.float64)
    qd = 0.4 * torch.randn(n, dof, generator=g, dtype=torch.float64)
    pos = torch.tensor([0.0, 1.2, 0.82], dtype=torch.float64) + 0.2 * torch.randn(n, 3, generator=g,
                                                                                  dtype=torch.float64)
    return q.to(dtype), qd.to(dtype), pos.to(dtype)


# ----------------------------------------------------------------------------- a carry onto a tower
@dataclass
class TowerCarry:
    """Cube E carried onto a four-block tower (``carry_onto_tower``): the rollout result, each step
    cube E was held as (distance from the tower's axis, its bottom above the tower's top), the
    tower's four centres and cube E's at the end, and where cube A stands."""

    result: Any
    held: list[tuple[float, float]]
    tower: list[list[float]]
    cube_e: list[float]
    cube_a: tuple[float, float, float]


CUBE = 0.045  # m: the tower cubes' edge
CARRY_G_OFF = (0.027, 0.007, 0.147)  # m: cube E's pre-grasp from its centre (tower5's seed-0 run's)
CARRY_P_OFF = (0.010, 0.010, 0.199)  # m: the pre-place from cube D's centre (its region is framed by cube D)
CARRY_BACK = 0.04  # m: the arm's base this much farther from the table (the perturbed worlds' robot_xy reaches 5 cm)


def carry_onto_tower(*overrides: str) -> TowerCarry:
    """``experiment=tower5`` (with ``overrides``), cubes B, C and D stacked on cube A, the arm
    ``CARRY_BACK`` farther back, and the seed-0 search's grasp and place of cube E realized in one
    copy (tests/test_place_lift.py, tests/test_avoid_movable.py)."""
    import torch

    from realize.realization.rollout import PlanRealizer
    from realize.scene import BatchedScene
    from realize.spec.run_spec import build_run_spec
    from realize.tasks.suffix import task_suffix
    from realize.world.state import ObjectPose, SceneState

    spec = build_run_spec(compose_config("experiment=tower5", *overrides))
    g = spec.geometry
    pa, pd, pe = (g.object(n).position for n in ("cube_a", "cube_d", "cube_e"))
    stack = {n: ObjectPose((pa[0], pa[1], pa[2] + CUBE * k)) for k, n in enumerate(("cube_b", "cube_c", "cube_d"), 1)}
    bx, by, yaw = g.robot_start
    task = task_suffix(spec.task, 6)  # grasp(cube_e, CubeE_g), place(cube_e, CubeE_on_d)
    z = {"CubeE_g": [p + o for p, o in zip(pe, CARRY_G_OFF)], "CubeE_on_d": [p + o for p, o in zip(pd, CARRY_P_OFF)]}
    Z = torch.tensor([[v for name in task.layout.names for v in z[name]]], dtype=torch.float64)
    top = pa[2] + 3 * CUBE + CUBE / 2  # the tower's top (cube D's top face)
    held: list[tuple[float, float]] = []
    with BatchedScene(1, spec.geometry_cfg, spec.sim, robot=spec.robot) as scene:
        ie = scene.object_index("cube_e")

        def watch(_: object) -> None:
            if bool(scene.holds("cube_e")[0]):
                e = scene.object_poses()[0, ie, :3].tolist()
                held.append((math.dist(e[:2], pa[:2]), e[2] - CUBE / 2 - top))

        scene.add_step_hook(watch)
        res = PlanRealizer(task, scene, spec.rollout, seed=spec.seed,
                           start=SceneState(base=(bx - CARRY_BACK, by, yaw), objects=stack)).rollout(Z)
        poses = scene.object_poses()[0]
    tower = [poses[g.object_index(n), :3].tolist() for n in ("cube_a", "cube_b", "cube_c", "cube_d")]
    return TowerCarry(res, held, tower, poses[ie, :3].tolist(), tuple(pa))
