"""Replay and video of a run's best plan, rebuilt from its run directory.

What it does:
  * ``saved_plan`` reads the run's best plan through ``realize.run_dir.directory.RunDir``
    (the resolved ``config``, ``best_z``, ``best_cost``, ``columns``, the top-k leader);
    ``build_replay_spec`` turns that config back into a ``RunSpec`` with
    ``realize.spec.run_spec.build_run_spec`` (the run's simulator backend, or one forced);
    ``replay_spec`` makes a run's spec (rebuilt, or the one in memory) a replay's;
  * ``replay`` re-simulates the best plan in ONE copy (N = 1) with the run's task, geometry,
    physics, controllers and seed, checks that it reaches the goal and compares its cost with
    the saved ``best_cost``; with ``video=...`` it renders every k-th control step to an MP4.
How it hooks into the rollout without copying it: the video writer is a step hook of the
``BatchedScene`` (``add_step_hook``) and the render camera an ``EnvOptions`` of it, so
``PlanRealizer.rollout`` runs unchanged, for every scene variant (the scene picks its task).
A top-k run (``task.planner.top_k > 1``) replays its leading candidate (the winner once
decided): ``best_z`` belongs to that candidate's plan and parameters.

Which parameters: a run whose ``result.json`` holds a candidate validation (``validation`` with
``candidates`` and ``returned``, ``realize.validation.candidates``) returns the plan
``validation.candidates[returned].z``, and ``replay`` runs that one (``returned_z``; its saved
cost is that candidate's nominal cost; in a top-k run the candidates come from the leader's
history, so they share ``best_z``'s plan). ``nominal=True`` replays the search's nominal
``best_z`` instead, as does a run without that block (or with a single-plan ``validation``).
``ReplayReport.plan`` and ``.candidate`` say which ran; ``best_z_rows(run)`` stays ``best_z``.
What it doesn't: search (``realize.run.one_run``), perturb anything (``realize.validation.returned_plan``), or write
to the run directory.

The task, scene and every setting come from the run's own config (``result.json``), never from
the live files: a run started with ``task_file`` keeps the file's content (``realize.spec.run_spec``),
and ``notes`` says when that file has changed since.

A replay on CPU of a run made on CPU uses the same seed and initial state, but the run
simulated its winning sample beside other samples in one PhysX scene (a shard of its copies),
which does not keep copies apart bit for bit: replayed alone, the cost can differ by a step or
two. ``exact=True`` re-runs that shard with that iteration's samples (``realize.validation.replay_shard``)
and gets the run's cost bit for bit; ``cost_diff`` reports either.
"""

from __future__ import annotations

import dataclasses
import json
import math
import time
from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch

from realize.world.geometry import SceneGeometry
from realize.run_dir.directory import BestPlan, RunDir, RunDirError
from realize.run_dir.names import RESULT_FILE
from realize.validation.replay_shard import ShardReplay, ShardReplayError, replay_shard
from realize.spec.run_spec import RunSpec, build_run_spec
from realize.spec.task_plans import TaskOrigin
from realize.validation.video import Caption, FollowCamera, VideoRecorder, VideoReport, focus_points
from realize.scene import Camera, EnvOptions
from realize.world.state import SceneState, save_state

__all__ = [
    "ReplayError", "VideoRecorder", "VideoReport", "ReplayReport", "PlanChoice",
    "saved_plan", "returned_z", "build_replay_spec", "replay_spec", "video_camera", "best_z_rows", "replay",
]

NOMINAL = "best_z"  # PlanChoice.source of the search's nominal best
RETURNED = "validation.returned"  # PlanChoice.source of the plan the candidate validation returns


class ReplayError(ValueError):
    """A run directory cannot be replayed; the message names the directory or file."""


# --------------------------------------------------------------------------------------------
# run directory
# --------------------------------------------------------------------------------------------


def saved_plan(run_dir: str | Path) -> BestPlan:
    """The run's best plan as ``RunDir.best_plan`` reads it; ``ReplayError`` (naming the file)
    if the directory holds none."""
    try:
        return RunDir(run_dir).best_plan()
    except RunDirError as e:
        raise ReplayError(str(e)) from None


@dataclass(frozen=True)
class PlanChoice:
    """The parameter vector a replay runs: ``source`` is ``"validation.returned"`` (``candidate``
    indexes ``validation.candidates``) or ``"best_z"``; ``cost`` is the search's cost of it, and
    ``why`` one line on the choice."""

    z: list[float]
    cost: float
    source: str
    candidate: int | None
    why: str


def returned_z(run: BestPlan, nominal: bool = False) -> PlanChoice:
    """The plan the run returns: ``validation.candidates[validation.returned]`` of its
    ``result.json`` when it holds a candidate validation, else (or with ``nominal``) ``best_z``.
    ``ReplayError`` (naming the file; ``nominal=True`` goes around it) if that block is malformed."""
    best = PlanChoice(list(run.best_z), run.best_cost, NOMINAL, None, "")
    if nominal:
        return dataclasses.replace(best, why="the search's nominal best_z, as asked")
    d = RunDir(run.run_dir).result_json() or {}
    v = d.get("validation")
    if not isinstance(v, Mapping) or "returned" not in v or "candidates" not in v:
        what = "no validation" if not isinstance(v, Mapping) else "a single-plan validation (no returned)"
        return dataclasses.replace(best, why=f"the search's nominal best_z (result.json holds {what})")
    where = f"{run.run_dir / RESULT_FILE}: validation"
    cands, i = v["candidates"], v["returned"]
    if not isinstance(cands, list) or isinstance(i, bool) or not isinstance(i, int) or not 0 <= i < len(cands):
        n = len(cands) if isinstance(cands, list) else 0
        raise ReplayError(f"{where}: returned = {i!r} does not index its {n} candidates "
                          "(nominal=True / --nominal replays best_z)")
    c = cands[i]
    z = c.get("z") if isinstance(c, Mapping) else None
    if (not isinstance(z, list) or not all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in z)
            or len(z) != len(run.best_z)):
        raise ReplayError(f"{where}: candidates[{i}].z is not {len(run.best_z)} numbers like best_z "
                          "(nominal=True / --nominal replays best_z)")
    cost = c.get("cost")
    cost = float(cost) if isinstance(cost, (int, float)) and not isinstance(cost, bool) else math.inf
    share = c.get("success_share")
    tail = f", success {share:.2f}" if isinstance(share, (int, float)) else ""
    return PlanChoice([float(x) for x in z], cost, RETURNED, i,
                      f"validation candidate {i} of {len(cands)} (nominal cost {cost:.0f}{tail}; "
                      f"{v.get('reason', '?')})")


def build_replay_spec(run: BestPlan, backend: str | None = None, judged: bool = False) -> RunSpec:
    """The run's ``RunSpec``, rebuilt from its saved config, on the simulator backend the run's
    config names (``sim.backend`` and ``device``, as the run resolved them), or with ``backend``
    (cpu | gpu | auto) forced; made a replay's by ``replay_spec`` (``judged``: see there)."""
    if backend not in (None, "cpu", "gpu", "auto"):
        raise ReplayError(f"backend = {backend!r} is invalid: allowed 'cpu', 'gpu', 'auto' (None: the run's own)")
    cfg = json.loads(json.dumps(run.config))  # deep copy of plain data
    if backend is not None:
        cfg["sim"] = dict(cfg.get("sim") or {}, backend=backend)
        cfg["device"] = {"cpu": "cpu", "gpu": "cuda"}.get(backend, "auto")
    cfg["resume"] = None
    try:
        spec = build_run_spec(cfg)
    except ValueError as e:
        raise ReplayError(f"{run.run_dir / RESULT_FILE}: its config: {e}") from None
    return replay_spec(spec, run, judged)


def replay_spec(spec: RunSpec, run: BestPlan, judged: bool = False) -> RunSpec:
    """``spec`` (the run's, in memory or rebuilt) made a replay's, as a new spec: a top-k run's
    leading candidate as the task (``best_z`` belongs to it), and every row realized to its end.
    ``judged``: the goal as validation and execution judge it, without the search's
    ``goal.margin`` (``GoalSpec.judged``); a replay of the run keeps it (the run's own outcome)."""
    task = spec.task
    lead = run.leader
    if spec.halving and lead is not None:
        i = lead.index
        if not isinstance(i, int) or not 0 <= i < len(spec.candidates) or spec.candidates[i].describe() != lead.plan:
            raise ReplayError(
                f"{run.run_dir / RESULT_FILE}: its leading candidate {lead.plan!r} is not among the plans "
                f"the planner returns now ({[t.describe() for t in spec.candidates]})"
            )
        task = spec.candidates[i]
    if len(run.best_z) != task.layout.dim:
        raise ReplayError(
            f"{run.run_dir / RESULT_FILE}: best_z has {len(run.best_z)} values, the task's parameters "
            f"{task.layout.dim}"
        )
    candidates = spec.candidates
    if judged:
        task = dataclasses.replace(task, goal=task.goal.judged())
        candidates = [dataclasses.replace(c, goal=c.goal.judged()) for c in candidates]
    return dataclasses.replace(spec, task=task, candidates=candidates, ce=dataclasses.replace(spec.ce, prune=False))


def best_z_rows(run: BestPlan, k: int = 1) -> torch.Tensor:
    """(k, D) the run's best parameter vector, repeated."""
    return torch.tensor([run.best_z], dtype=torch.float64).repeat(k, 1)


# --------------------------------------------------------------------------------------------
# video
# --------------------------------------------------------------------------------------------


def video_camera(geometry: SceneGeometry) -> tuple[list[float], list[float]]:
    """A camera (eye, target) that keeps the whole task in view at 4:3: from the -y side, high,
    centred on the world bounds, so the start, both tables and the exit all stay in the frame
    (the task's own render camera is a far diagonal view in which the robot is small)."""
    cx = (geometry.bounds_low[0] + geometry.bounds_high[0]) / 2
    cy = (geometry.bounds_low[1] + geometry.bounds_high[1]) / 2
    return [cx + 0.2, cy - 3.6, 3.5], [cx + 0.2, cy + 0.1, 0.3]


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
    state_at: int | None = None  # the action whose starting state was captured (0-based)
    state_out: str | None = None  # where that state was written
    exact: ShardReplay | None = None  # the best sample re-run in its shard (cost, feasible, failure are its)
    notes: list[str] | None = None  # e.g. the run's task file has changed since (its own copy was used)
    plan: str = NOMINAL  # which z ran: "validation.returned" or "best_z" (PlanChoice.source)
    candidate: int | None = None  # its index into validation.candidates
    plan_note: str = ""  # PlanChoice.why

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)


def replay(run_dir: str | Path, video: str | Path | None = None, *, fps: float = 20.0, every: int = 2,
           width: int | None = 960, height: int | None = 720, eye: Sequence[float] | None = None,
           target: Sequence[float] | None = None, task_camera: bool = False, backend: str | None = None,
           hold_s: float = 1.0, state_at: int | None = None, state_out: str | Path | None = None,
           exact: bool = False, overview: bool = False, nominal: bool = False) -> ReplayReport:
    """Re-simulate the run's plan in one copy; with ``video`` write an MP4 of it.

    The plan is the one the run returns (``returned_z``: its validation's returned candidate
    if it has one, else ``best_z``); ``nominal=True`` replays ``best_z``. The report's
    ``saved_cost`` is the search's cost of the plan that ran.

    The video shows every ``every``-th control step at ``fps`` frames per second (the control
    rate is ``sim.control_freq``: at 20 Hz, ``every=2, fps=20`` plays at twice real time), then
    holds the last frame for ``hold_s`` seconds (captioned with the outcome). ``width``/``height``
    set the frame size (None: the task camera's). By default the camera follows the robot and
    what the current action works on (``realize.validation.video.FollowCamera``); with ``eye`` and
    ``target`` it stays there, with ``task_camera`` where the task's render camera is
    (``overview``: ``video_camera(geometry)``, a fixed view of the whole world). Every frame is labelled with
    the current action and the control step (``realize.validation.video.Caption``).

    With ``state_at=K`` and ``state_out``, the scene's state at the moment action K (0-based)
    begins, right after action K-1 succeeded, is written there as a
    ``realize.world.state.SceneState`` JSON (``ReplayError`` if the replay never gets there).

    With ``exact`` the best sample is also re-run in the shard the run simulated it in (module
    docstring); the report's cost, feasibility and failure are then that rollout's. Without a
    video or a state to capture, that is the only rollout.
    """
    from realize.workers.realizers import open_realization

    t0 = time.perf_counter()
    run = saved_plan(run_dir)
    choice = returned_z(run, nominal)
    run = dataclasses.replace(run, best_z=choice.z, best_cost=choice.cost)  # the plan to run, everywhere below
    spec = build_replay_spec(run, backend)
    if (state_at is None) != (state_out is None):
        raise ReplayError("state_at and state_out go together: the action to capture and the file to write")
    n_actions = spec.task.n_actions
    if state_at is not None and (isinstance(state_at, bool) or not isinstance(state_at, int)
                                 or not 0 <= state_at < n_actions):
        raise ReplayError(f"state_at = {state_at!r} is invalid: the plan {spec.task.describe()} has {n_actions} "
                          "actions, numbered from 0")
    origin = TaskOrigin.from_json(spec.config.get("task_origin"))
    notes = [n for n in [None if origin is None else origin.note()] if n is not None]
    if run.config.get("task_file") is not None:  # a run from before run directories kept their task
        notes.append(f"the run's result.json names task_file {run.config['task_file']!r} but keeps no copy of it; "
                     "its task was read from that file as it is now")
    shard = None
    if exact:
        try:
            shard = replay_shard(run, spec)
        except ShardReplayError as e:
            raise ReplayError(str(e)) from None
        if video is None and state_at is None:
            return _report(run, spec, shard.cost, shard.feasible, shard.failure, shard.steps, spec.placement.backend,
                           t0, shard=shard, notes=notes, choice=choice)
    captured: list[SceneState] = []
    options = EnvOptions()
    recorder = None
    if video is not None:
        follow = None
        if overview and eye is None and target is None:
            eye, target = video_camera(spec.geometry)
        elif eye is None and target is None and not task_camera:  # the camera follows the action
            follow = FollowCamera(focus_points(spec.task, np.asarray(run.best_z)),
                                  objects=[a.obj for a in spec.task.plan])
            eye, target = video_camera(spec.geometry)  # the pose it starts from (moved before each frame)
        cam = Camera(width=width, height=height, eye=None if eye is None else tuple(map(float, eye)),
                     target=None if target is None else tuple(map(float, target)))
        options = EnvOptions(camera=cam)
        caption = Caption([str(a) for a in spec.task.plan], spec.sim.control_freq, height or 512)
        recorder = VideoRecorder(video, fps=fps, every=every, follow=follow, caption=caption)
    try:
        scene, (realizer,) = open_realization(spec, n_envs=1, env=options)
        with scene:
            if recorder is not None:
                recorder.attach(scene)
            where = "" if state_at is None else (f"replay of {run.run_dir} at the start of action {state_at} "
                                                 f"({spec.task.plan[state_at]})")

            def on_action(a: int, rows: torch.Tensor) -> None:
                if recorder is not None and recorder.caption is not None:
                    recorder.caption.on_action(a, rows)
                if a == state_at and bool((rows == 0).any()):
                    captured.append(scene.capture_state(0, source=where))

            realizer.action_hook = on_action
            res = realizer.rollout(best_z_rows(run))
            outcome = (f"reaches the goal, cost {float(res.cost[0]):.0f}" if bool(res.feasible[0])
                       else f"fails: {res.failure[0]}")
            vid = recorder.close(hold_s, final_text=f"end: {outcome}") if recorder is not None else None
            recorder = None
    finally:
        if recorder is not None:  # an error mid-rollout: still close the file
            recorder.close()
    if state_at is not None:
        if not captured:
            raise ReplayError(f"the replay of {run.run_dir} never began action {state_at} (it failed: "
                              f"{res.failure[0]}); no state written")
        assert state_out is not None
        save_state(captured[0], state_out)
    if shard is not None:
        return _report(run, spec, shard.cost, shard.feasible, shard.failure, shard.steps, scene.backend, t0,
                       video=vid, state_at=state_at, state_out=state_out, shard=shard, notes=notes, choice=choice)
    return _report(run, spec, float(res.cost[0]), bool(res.feasible[0]), res.failure[0], int(res.steps[0]),
                   scene.backend, t0, video=vid, state_at=state_at, state_out=state_out, notes=notes, choice=choice)


def _report(run: BestPlan, spec: RunSpec, cost: float, feasible: bool, failure: str, steps: int, backend: str,
            t0: float, *, video: VideoReport | None = None, state_at: int | None = None,
            state_out: str | Path | None = None, shard: ShardReplay | None = None,
            notes: list[str] | None = None, choice: PlanChoice | None = None) -> ReplayReport:
    saved = run.best_cost if math.isfinite(run.best_cost) else None
    diff = None if saved is None else cost - saved
    return ReplayReport(
        run_dir=str(run.run_dir), feasible=feasible, cost=cost, saved_cost=saved,
        cost_diff=diff, matches=None if diff is None else diff == 0.0, failure=failure,
        steps=steps, n_envs_run=run.n_envs, backend=backend,
        wall_time_s=time.perf_counter() - t0, video=video, state_at=state_at,
        state_out=None if state_out is None else str(state_out), exact=shard, notes=notes or None,
        plan=NOMINAL if choice is None else choice.source, candidate=None if choice is None else choice.candidate,
        plan_note="" if choice is None else choice.why,
    )
