"""Replay, video and validation replicas of a run's best plan, rebuilt from its run directory.

What it does:
  * ``load_run`` reads ``result.json`` of a run directory (the resolved ``config``, ``best_z``,
    ``best_cost``, ``columns``); ``build_replay_spec`` turns that config back into a ``RunSpec``
    with ``realize.run_config.build_run_spec`` (the simulator backend forced, CPU by default);
  * ``replay`` re-simulates the best plan in ONE copy (N = 1) with the run's task, geometry,
    physics, controllers and seed, checks that it reaches the goal and compares its cost with
    the saved ``best_cost``; with ``video=...`` it renders every k-th control step to an MP4;
  * ``validate`` re-simulates the best plan K times at once (N = K copies of one batched scene)
    under small perturbations: the task's reset randomization (cube xy and yaw on table 1, robot
    start xy; see ``envs/pick_place.py``) and the cube's friction scaled by a random factor per
    copy. It reports the success share and the failure reasons, and writes them into
    ``result.json`` under ``validation`` (read, add the key, write back atomically).
How it hooks into the rollout without copying it: ``HookedScene`` is a ``BatchedScene`` whose
``reset``/``step`` call a callback after the physics (the video writer renders there) and whose
``reset`` can force the task's randomization; ``PlanRealizer.rollout`` runs on it unchanged.
Env options that ``BatchedScene`` does not expose (render camera size/pose, reset noise
amplitudes) are passed to ``gym.make`` through the task's registered kwargs for the time of the
construction only (``env_overrides``).
A top-k run (``task.planner.top_k > 1``) replays its leading candidate (the winner once
decided): ``best_z`` belongs to that candidate's plan and parameters.
What it doesn't: search (``realize.app``), change the run's other files, or perturb anything
but the start state and the cube friction. Friction is set per copy through the SAPIEN PhysX
components on the CPU backend: SAPIEN has no batched material API there (a loop over K shapes,
once per validation, not per step); PhysX GPU fixes materials when the GPU scene is built, so a
friction range on the GPU backend is refused.

A replay on CPU of a run made on CPU uses the same seed and initial state, but the run
simulated its winning sample in one of N tiled copies (world xy offset by metres): float32
rounding then differs from copy 0 at the origin and the cost can differ by a step or two (a
16-copy run replayed identically, an 8-copy run 1 step lower). ``cost_diff`` reports it rather
than asserting equality. For the same reason the K validation replicas are not bit-identical
even without perturbations.
"""

from __future__ import annotations

import contextlib
import json
import math
import time
from collections import Counter
from collections.abc import Callable, Iterator, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import torch

from realize.results import RESULT_FILE, atomic_write_json
from realize.run_config import RunSpec, build_run_spec
from realize.scene import BatchedScene, SimSettings

__all__ = [
    "ReplayError",
    "SavedRun",
    "HookedScene",
    "VideoRecorder",
    "VideoReport",
    "ReplayReport",
    "ValidationReport",
    "load_run",
    "build_replay_spec",
    "camera_overrides",
    "video_camera",
    "env_overrides",
    "set_cube_friction",
    "cube_friction",
    "replay",
    "validate",
    "write_validation",
]

ENV_ID = "RealizePickPlace-v1"


class ReplayError(ValueError):
    """A run directory cannot be replayed; the message names the directory or file."""


# --------------------------------------------------------------------------------------------
# run directory
# --------------------------------------------------------------------------------------------


@dataclass
class SavedRun:
    """What a replay needs from ``result.json``."""

    run_dir: Path
    config: dict[str, Any]
    best_z: list[float]
    columns: list[str]
    best_cost: float | None
    feasible: bool
    n_envs_scene: int | None
    backend: str | None
    status: str | None
    doc: dict[str, Any] = field(repr=False, default_factory=dict)


def load_run(run_dir: str | Path) -> SavedRun:
    """Read ``RUN_DIR/result.json``; raises ``ReplayError`` if it holds no best plan."""
    run_dir = Path(run_dir)
    path = run_dir / RESULT_FILE
    if not path.is_file():
        raise ReplayError(f"{path}: not found (is {run_dir} a run directory written by `realize`?)")
    try:
        doc = json.loads(path.read_text())
    except (OSError, json.JSONDecodeError) as e:
        raise ReplayError(f"{path}: cannot read: {e}") from None
    if not isinstance(doc, dict) or not isinstance(doc.get("config"), dict):
        raise ReplayError(f"{path}: no resolved `config` mapping")
    z = doc.get("best_z")
    if not isinstance(z, list) or not z or not all(isinstance(v, (int, float)) and v is not None for v in z):
        raise ReplayError(f"{path}: no `best_z` (the run found no plan to replay)")
    cost = doc.get("best_cost")
    n_scene = doc.get("n_envs_scene")
    if n_scene is None:
        n_scene = (doc["config"].get("ce") or {}).get("n_envs")
    return SavedRun(
        run_dir=run_dir,
        config=doc["config"],
        best_z=[float(v) for v in z],
        columns=list(doc.get("columns") or []),
        best_cost=float(cost) if isinstance(cost, (int, float)) else None,
        feasible=bool(doc.get("feasible", False)),
        n_envs_scene=int(n_scene) if isinstance(n_scene, (int, float)) else None,
        backend=doc.get("backend"),
        status=doc.get("status"),
        doc=doc,
    )


def build_replay_spec(run: SavedRun, backend: str = "cpu") -> RunSpec:
    """The run's ``RunSpec`` with the simulator backend forced to ``backend`` (cpu | gpu | auto)."""
    if backend not in ("cpu", "gpu", "auto"):
        raise ReplayError(f"backend = {backend!r} is invalid: allowed 'cpu', 'gpu', 'auto'")
    cfg = json.loads(json.dumps(run.config))  # deep copy of plain data
    cfg["sim"] = dict(cfg.get("sim") or {}, backend=backend)
    cfg["device"] = {"cpu": "cpu", "gpu": "cuda"}.get(backend, "auto")
    cfg["resume"] = None
    spec = build_run_spec(cfg)
    lead = run.doc.get("leader") if isinstance(run.doc, dict) else None
    if spec.halving and isinstance(lead, dict):  # a top-k run: best_z belongs to the leading candidate
        i = lead.get("index")
        if not isinstance(i, int) or not 0 <= i < len(spec.candidates) or spec.candidates[i].describe() != lead.get("plan"):
            raise ReplayError(
                f"{run.run_dir / RESULT_FILE}: its leading candidate {lead.get('plan')!r} is not among the plans "
                f"the planner returns now ({[t.describe() for t in spec.candidates]})"
            )
        spec.task = spec.candidates[i]
    if len(run.best_z) != spec.task.layout.dim:
        raise ReplayError(
            f"{run.run_dir / RESULT_FILE}: best_z has {len(run.best_z)} values, the task's parameters "
            f"{spec.task.layout.dim}"
        )
    return spec


# --------------------------------------------------------------------------------------------
# scene hooks
# --------------------------------------------------------------------------------------------


@contextlib.contextmanager
def env_overrides(**kwargs: Any) -> Iterator[None]:
    """Extra ``gym.make`` kwargs for the task while the block builds scenes (restored after).

    ``BatchedScene`` builds its env with fixed kwargs; the ones it does not set (e.g.
    ``human_render_camera_configs``, ``cube_xy_noise``, ``robot_xy_noise``) reach the env
    through the registered spec's default kwargs, which ``gym.make`` merges in.
    """
    import gymnasium as gym

    import envs  # noqa: F401  (registers the task)

    spec = gym.spec(ENV_ID)
    saved = dict(spec.kwargs)
    spec.kwargs.update({k: v for k, v in kwargs.items() if v is not None})
    try:
        yield
    finally:
        spec.kwargs.clear()
        spec.kwargs.update(saved)


def camera_overrides(width: int | None = None, height: int | None = None,
                     eye: Sequence[float] | None = None, target: Sequence[float] | None = None) -> dict | None:
    """``human_render_camera_configs`` for the task's render camera (None: keep the task's)."""
    cam: dict[str, Any] = {}
    if width is not None:
        cam["width"] = int(width)
    if height is not None:
        cam["height"] = int(height)
    if eye is not None or target is not None:
        if eye is None or target is None:
            raise ReplayError("a camera pose needs both eye and target")
        from mani_skill.utils import sapien_utils

        cam["pose"] = sapien_utils.look_at(eye=list(map(float, eye)), target=list(map(float, target)))
    return {"render_camera": cam} if cam else None


def video_camera(geometry: Any) -> tuple[list[float], list[float]]:
    """A camera (eye, target) that keeps the whole task in view at 4:3: from the -y side, high,
    centred on the world bounds, so the start, both tables and the exit all stay in the frame
    (the task's own render camera is a far diagonal view in which the robot is small)."""
    cx = (geometry.bounds_low[0] + geometry.bounds_high[0]) / 2
    cy = (geometry.bounds_low[1] + geometry.bounds_high[1]) / 2
    return [cx + 0.2, cy - 3.6, 3.5], [cx + 0.2, cy + 0.1, 0.3]


class HookedScene(BatchedScene):
    """A ``BatchedScene`` that reports each control step and can force the reset randomization.

    Args (besides ``BatchedScene``'s):
        on_step: called as ``on_step(step)`` after ``reset`` (step 0) and after every ``every``-th
            control step since the last reset (the physics of that step already simulated).
        every: call period in control steps (>= 1).
        randomize: every ``reset`` applies the task's randomization (cube xy/yaw, robot start xy),
            whatever the caller asks (``PlanRealizer.rollout`` resets without it).

    On the CPU backend it also applies ``sim.torch_threads_cpu`` for any N (``BatchedScene`` does
    only with PhysX workers, N >= 8): with torch's default pool a 4-copy rollout took 20-29 s
    on a 2-core machine, 3.8 s single-threaded.
    """

    def __init__(self, n: int, geometry: Any = None, sim: SimSettings | None = None, *,
                 on_step: Callable[[int], None] | None = None, every: int = 1, randomize: bool = False):
        if every < 1:
            raise ValueError(f"every = {every} must be >= 1")
        self.on_step = on_step
        self.every = every
        self.randomize = randomize
        self.step_count = 0
        super().__init__(n, geometry, sim)
        if self.backend == "cpu" and self.sim.torch_threads_cpu is not None:
            torch.set_num_threads(self.sim.torch_threads_cpu)

    def reset(self, seed: int = 0, randomize: bool = False) -> None:
        super().reset(seed=seed, randomize=randomize or self.randomize)
        self.step_count = 0
        if self.on_step is not None:
            self.on_step(0)

    def step(self) -> None:
        super().step()
        self.step_count += 1
        if self.on_step is not None and self.step_count % self.every == 0:
            self.on_step(self.step_count)


def _cube_shapes(scene: BatchedScene) -> list[Any]:
    """The PhysX collision shape of each copy's cube (CPU backend)."""
    if scene.backend != "cpu":
        raise ReplayError("per-copy cube friction is set on the CPU backend only (PhysX GPU fixes materials at build)")
    shapes = []
    for cube in scene.u.cubes:
        body = cube._bodies[0]
        (shape,) = body.get_collision_shapes()
        shapes.append(shape)
    return shapes


def cube_friction(scene: BatchedScene) -> np.ndarray:
    """(N, 2) static and dynamic friction of each copy's cube (CPU backend)."""
    mats = [s.get_physical_material() for s in _cube_shapes(scene)]
    return np.array([[m.static_friction, m.dynamic_friction] for m in mats], dtype=np.float64)


def set_cube_friction(scene: BatchedScene, factors: np.ndarray | Sequence[float]) -> np.ndarray:
    """Scale each copy's cube friction (static and dynamic) by ``factors`` (N,) from the scene's
    configured value ``geometry.cube_friction``; returns the (N,) friction now set.

    One loop over the copies: SAPIEN has no batched material API on CPU. Each copy gets its own
    material. PhysX combines the friction of two touching shapes by averaging (its default), so
    the friction of a cube-finger or cube-table contact moves by half the cube's change.
    """
    import sapien

    f = np.asarray(factors, dtype=np.float64).reshape(-1)
    shapes = _cube_shapes(scene)
    if len(f) != len(shapes):
        raise ValueError(f"{len(f)} friction factors for {len(shapes)} copies")
    if not np.all(np.isfinite(f)) or np.any(f <= 0):
        raise ValueError(f"friction factors must be finite and > 0, got {f}")
    base = float(scene.geometry.cube_friction)
    values = base * f
    for shape, mu in zip(shapes, values):
        old = shape.get_physical_material()
        shape.set_physical_material(sapien.physx.PhysxMaterial(float(mu), float(mu), float(old.restitution)))
    return values


# --------------------------------------------------------------------------------------------
# video
# --------------------------------------------------------------------------------------------


@dataclass
class VideoReport:
    path: str
    frames: int
    fps: float
    every: int
    seconds: float  # video length
    bytes: int
    width: int
    height: int
    first_render_s: float  # the first frame (on lavapipe it compiles the shaders)
    render_s_per_frame: float  # mean over the other frames
    hold_s: float


class VideoRecorder:
    """Renders copy 0 of a scene into an MP4 (H.264 through imageio's ffmpeg), frame by frame.

    Use as ``HookedScene(on_step=recorder)`` then ``recorder.attach(scene)``; frames are written
    as they are rendered (nothing is kept in memory).
    """

    def __init__(self, path: str | Path, fps: float = 20.0, every: int = 1, quality: int = 7):
        import imageio.v2 as imageio

        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self.fps, self.every = float(fps), int(every)
        self._writer = imageio.get_writer(str(self.path), format="FFMPEG", mode="I", fps=self.fps, codec="libx264",
                                          quality=quality, pixelformat="yuv420p", macro_block_size=1)
        self.scene: BatchedScene | None = None
        self.frames = 0
        self.render_times: list[float] = []
        self.last: np.ndarray | None = None
        self.shape: tuple[int, int] = (0, 0)

    def attach(self, scene: BatchedScene) -> None:
        self.scene = scene

    def __call__(self, step: int) -> None:
        if self.scene is None:  # reset inside the scene's own constructor: nothing to render yet
            return
        t0 = time.perf_counter()
        frame = np.ascontiguousarray(self.scene.render()[..., :3]).astype(np.uint8, copy=False)
        self.render_times.append(time.perf_counter() - t0)
        self._writer.append_data(frame)
        self.frames += 1
        self.last = frame
        self.shape = frame.shape[:2]

    def close(self, hold_s: float = 0.0) -> VideoReport:
        """Repeat the last frame for ``hold_s`` seconds, finish the file and report."""
        held = 0
        if self.last is not None:
            held = int(round(hold_s * self.fps))
            for _ in range(held):
                self._writer.append_data(self.last)
        self._writer.close()
        rt = self.render_times
        return VideoReport(
            path=str(self.path), frames=self.frames + held, fps=self.fps, every=self.every,
            seconds=(self.frames + held) / self.fps, bytes=self.path.stat().st_size if self.path.exists() else 0,
            width=int(self.shape[1]), height=int(self.shape[0]), first_render_s=rt[0] if rt else math.nan,
            render_s_per_frame=float(np.mean(rt[1:])) if len(rt) > 1 else math.nan, hold_s=held / self.fps,
        )


# --------------------------------------------------------------------------------------------
# replay
# --------------------------------------------------------------------------------------------


@dataclass
class ReplayReport:
    run_dir: str
    feasible: bool
    cost: float
    saved_cost: float | None
    cost_diff: float | None  # cost - saved_cost
    matches: bool | None  # cost == saved_cost (None: nothing saved)
    failure: str
    steps: int
    n_envs_run: int | None  # copies of the run's scene (its winning sample may sit in another tile)
    backend: str
    wall_time_s: float
    video: VideoReport | None = None

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)


def _z(run: SavedRun, k: int = 1) -> torch.Tensor:
    return torch.tensor([run.best_z], dtype=torch.float64).repeat(k, 1)


def replay(run_dir: str | Path, video: str | Path | None = None, *, fps: float = 20.0, every: int = 2,
           width: int | None = 640, height: int | None = 480, eye: Sequence[float] | None = None,
           target: Sequence[float] | None = None, task_camera: bool = False, backend: str = "cpu",
           hold_s: float = 1.0) -> ReplayReport:
    """Re-simulate the run's best plan in one copy; with ``video`` write an MP4 of it.

    The video shows every ``every``-th control step at ``fps`` frames per second (the control
    rate is ``sim.control_freq``: at 20 Hz, ``every=2, fps=20`` plays at twice real time), then
    holds the last frame for ``hold_s`` seconds. ``width``/``height`` set the frame size (None:
    the task camera's); the camera sits at ``eye`` looking at ``target``, by default at
    ``video_camera(geometry)``, or where the task's render camera is with ``task_camera``.
    """
    from realize.realization.rollout import PlanRealizer

    t0 = time.perf_counter()
    run = load_run(run_dir)
    spec = build_replay_spec(run, backend)
    overrides: dict[str, Any] = {}
    if video is not None:
        if eye is None and target is None and not task_camera:
            eye, target = video_camera(spec.geometry)
        overrides["human_render_camera_configs"] = camera_overrides(width, height, eye, target)
    recorder = VideoRecorder(video, fps=fps, every=every) if video is not None else None
    try:
        with env_overrides(**overrides):
            scene = HookedScene(1, spec.geometry_cfg, spec.sim, on_step=recorder, every=every)
        with scene:
            if recorder is not None:
                recorder.attach(scene)
            realizer = PlanRealizer(spec.task, scene, spec.rollout, seed=spec.seed)
            res = realizer.rollout(_z(run))
            vid = recorder.close(hold_s) if recorder is not None else None
            recorder = None
    finally:
        if recorder is not None:  # an error mid-rollout: still close the file
            recorder.close()
    cost = float(res.cost[0])
    diff = None if run.best_cost is None else cost - run.best_cost
    return ReplayReport(
        run_dir=str(run.run_dir), feasible=bool(res.feasible[0]), cost=cost, saved_cost=run.best_cost,
        cost_diff=diff, matches=None if diff is None else diff == 0.0, failure=res.failure[0],
        steps=int(res.steps[0]), n_envs_run=run.n_envs_scene, backend=scene.backend,
        wall_time_s=time.perf_counter() - t0, video=vid,
    )


# --------------------------------------------------------------------------------------------
# validation replicas
# --------------------------------------------------------------------------------------------


@dataclass
class ValidationReport:
    replicas: int
    success_share: float
    failures: dict[str, int]  # failure reason ("<action>:<template>:<reason>") -> count
    seed: int
    friction_range: list[float] | None
    friction: list[float]  # the cube friction of each replica
    randomize: bool
    cube_xy_noise: float | None
    robot_xy_noise: float | None
    cost_mean: float | None  # over the successful replicas
    cost_std: float | None
    saved_cost: float | None
    backend: str
    wall_time_s: float

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)


def validate(run_dir: str | Path, replicas: int = 16, seed: int = 0, *,
             friction_range: tuple[float, float] | None = (0.8, 1.2), randomize: bool = True,
             cube_xy_noise: float | None = None, robot_xy_noise: float | None = None,
             backend: str = "cpu", write: bool = True) -> ValidationReport:
    """Re-simulate the best plan ``replicas`` times at once under perturbations; report the share
    that reaches the goal and (``write``) store it in ``result.json`` under ``validation``.

    Perturbations: the task's reset randomization with ``seed`` (noise amplitudes: the task's
    defaults unless given) and, per replica, the cube friction times U(friction_range) drawn
    from ``numpy.random.default_rng(seed)`` (None: friction unchanged).
    """
    from realize.realization.rollout import PlanRealizer

    if isinstance(replicas, bool) or not isinstance(replicas, int) or replicas < 1:
        raise ReplayError(f"replicas = {replicas!r} must be an integer >= 1")
    if friction_range is not None:
        lo, hi = map(float, friction_range)
        if not (0 < lo <= hi and math.isfinite(hi)):
            raise ReplayError(f"friction range {friction_range} must satisfy 0 < low <= high")
    t0 = time.perf_counter()
    run = load_run(run_dir)
    spec = build_replay_spec(run, backend)
    with env_overrides(cube_xy_noise=cube_xy_noise, robot_xy_noise=robot_xy_noise):
        scene = HookedScene(replicas, spec.geometry_cfg, spec.sim, randomize=randomize)
    with scene:
        if friction_range is not None:
            factors = np.random.default_rng(seed).uniform(lo, hi, size=replicas)
            friction = set_cube_friction(scene, factors)
        else:
            friction = np.full(replicas, float(scene.geometry.cube_friction))
        realizer = PlanRealizer(spec.task, scene, spec.rollout, seed=seed)
        res = realizer.rollout(_z(run, replicas))
        noise = (scene.u.cube_xy_noise, scene.u.robot_xy_noise)
        used_backend = scene.backend
    ok = res.feasible.numpy()
    costs = res.cost.numpy().astype(np.float64)[ok]
    report = ValidationReport(
        replicas=replicas, success_share=float(ok.mean()),
        failures=dict(sorted(Counter(f for f in res.failure if f).items())), seed=int(seed),
        friction_range=None if friction_range is None else [lo, hi], friction=[float(v) for v in friction],
        randomize=randomize, cube_xy_noise=float(noise[0]) if randomize else None,
        robot_xy_noise=float(noise[1]) if randomize else None,
        cost_mean=float(costs.mean()) if len(costs) else None, cost_std=float(costs.std()) if len(costs) else None,
        saved_cost=run.best_cost, backend=used_backend, wall_time_s=time.perf_counter() - t0,
    )
    if write:
        write_validation(run.run_dir, report)
    return report


def write_validation(run_dir: str | Path, report: ValidationReport) -> None:
    """Add ``validation`` to ``RUN_DIR/result.json`` (re-read just before, written atomically)."""
    path = Path(run_dir) / RESULT_FILE
    doc = json.loads(path.read_text())
    doc["validation"] = report.to_dict()
    atomic_write_json(path, doc)
