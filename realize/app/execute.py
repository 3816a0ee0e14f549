"""Carry a returned plan out in a world that changes, watch it, and repair it.

What it does: ``execute(run_dir, settings)`` takes a run's returned plan and, for each of
``settings.worlds`` worlds, carries it out action by action in a separate one-copy world
(``realize.execution.world.ExecutionWorld``: its own scene, drawn from the task's perturbation
model with the world's own seed, plus the scheduled disturbances of ``settings``), with the
same controllers the search simulated (``PlanRealizer`` on that one copy, planning in what the
robot believes of its world). Closed loop (``closed_loop=True``):
  * every ``monitor_every`` control steps and at each action's end the observed world is
    compared with what the plan expects (``realize.execution.monitor``: the grasp holds, the
    objects the next actions act on lie where assumed, the tables stand where assumed, no new
    box in the map, the base arrived); an action that fails counts as a deviation too;
  * on a deviation the world's state is captured (the robot holds still while the planner
    thinks; the pause is counted) and the plan repaired with ``realize.app.planner.Planner``:
    **re-parameterize** (``Planner.replan``: the remaining actions from that state, in the world
    as observed, warm-started, small budget) where the remaining plan can still start from the
    state, else **re-sequence** (``realize.app.resequence``: the symbolic state read off the
    world, a new PDDL plan from it, realized from the state);
  * it goes on with the new plan, and stops at the goal, after ``max_replans`` repairs, or at
    ``time_limit_s`` (control time plus planning time).
Open loop (``closed_loop=False``): the same world and disturbances, the plan carried out
to its end without repairs (objects tracked, as the search's controllers do).

What an execution leaves (``<run>/execution/<label>/``): ``summary.json`` (worlds,
closed/open-loop success, replans per world, every replan's wall time), one
``world-<k>-<mode>.json`` per world (each action planned and as executed, every deviation,
disturbance and replan with its kind, time and cost), ``world-<k>-<mode>.npz`` (the executed
trajectory a robot's driver can follow: ``realize.execution.trajectory``, format in
``docs/execution_format.md``), ``world-<k>-<mode>.rrd`` (the executed world on the control-step
timeline, replans as events) and with ``video`` an MP4 per world; the replans' run
directories go under ``replans/``.
What it doesn't: search itself (the planner does), or know any robot or object by name.
"""

from __future__ import annotations

import dataclasses
import json
import logging
import math
import time
from collections.abc import Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import torch

from realize.config import ConfigError
from realize.execution.disturbances import Schedule, Scheduled, draw, read_disturbances
from realize.execution.monitor import Deviation, check, expectation
from realize.execution.settings import ExecuteSettings
from realize.execution.world import ExecutionWorld, Observation, geometry_changes

__all__ = ["execute", "execute_world", "ExecutionSummary", "WorldLog", "ReplanRecord", "EXECUTION_DIR"]

log = logging.getLogger("realize")

EXECUTION_DIR = "execution"
SEED_STRIDE = 1000  # world k of a study with seed S draws its world and disturbances with seed S * 1000 + k


@dataclass
class ReplanRecord:
    """One repair: ``kind`` re-parameterize | re-sequence, at control step ``step`` (of the
    world's timeline), from action ``from_action`` (of the plan it repaired), why, its wall
    time, what it found and where it ran."""

    kind: str
    step: int
    from_action: int
    reason: list[str]
    wall_s: float
    feasible: bool
    cost: float | None
    plan: str
    run_dir: str
    scene: str  # built | kept: the planner's workers
    changes: list[str]
    timings: dict[str, float] = field(default_factory=dict)


@dataclass
class ActionRecord:
    """An action as planned (its parameters) and as executed (steps, outcome)."""

    index: int  # in the plan that was running
    text: str
    params: dict[str, list[float]]
    begin_step: int
    end_step: int | None = None
    outcome: str = "running"  # done | failed: ... | interrupted: <deviation> | cut


@dataclass
class WorldLog:
    """One world's execution (written as ``world-<k>-<mode>.json``)."""

    world: int
    seed: int
    mode: str  # closed | open
    success: bool = False
    failure: str = ""
    steps: int = 0
    control_time_s: float = 0.0
    pause_s: float = 0.0  # the robot held still while the planner thought
    wall_s: float = 0.0
    plan: str = ""  # the plan it started with
    final_plan: str = ""  # the plan it ended with
    disturbances: list[dict[str, Any]] = field(default_factory=list)
    deviations: list[dict[str, Any]] = field(default_factory=list)
    actions: list[ActionRecord] = field(default_factory=list)
    replans: list[ReplanRecord] = field(default_factory=list)

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)


@dataclass
class ExecutionSummary:
    """A study's ``summary.json``."""

    run_dir: str
    label: str
    worlds: int
    seed: int
    closed_loop_success: float | None
    open_loop_success: float | None
    closed_successes: int | None
    open_successes: int | None
    replans: list[int]  # per closed-loop world
    replan_s: list[float]  # every replan's wall time
    replan_kinds: list[str]
    replans_with_open_success: list[int]  # replans in worlds that open loop got right (a control's check)
    pause_s: list[float]
    wall_time_s: float
    settings: dict[str, Any]
    files: list[str]
    planner_start_s: float = 0.0  # opening the replans' workers, before the first world

    def to_dict(self) -> dict[str, Any]:
        d = asdict(self)
        s = sorted(self.replan_s)
        d["replan_s_median"] = float(np.median(s)) if s else None
        d["replan_s_p95"] = float(np.percentile(s, 95)) if s else None
        return d


class _Stop(Exception):
    """Raised from a step hook: the world deviated from the plan; the segment ends here."""

    def __init__(self, deviations: list[Deviation], obs: Observation) -> None:
        super().__init__("; ".join(map(str, deviations)))
        self.deviations, self.obs = deviations, obs


def _params_of(task: Any, z: Sequence[float], a: int) -> dict[str, list[float]]:
    zz = torch.tensor([list(z)], dtype=torch.float64)
    split = task.layout.split(zz)
    return {p: [float(v) for v in split[p][0].tolist()] for p in task.plan[a].params if p in split}


class _Segment:
    """One stretch of execution: a plan (``task``, ``z``) run from ``start`` in the world, with
    the disturbances due and (closed loop) the monitor; ``offset``: the original plan's index of
    the task's action 0 (None: a re-sequenced plan, whose actions the triggers do not name)."""

    def __init__(self, task: Any, z: Sequence[float], start: Any, belief: Any, offset: int | None) -> None:
        self.task, self.z, self.start, self.belief, self.offset = task, list(z), start, belief, offset
        self.action = 0


class _Executor:
    def __init__(self, run: Any, spec: Any, settings: ExecuteSettings, scheduled: list[Scheduled], world_seed: int,
                 k: int, closed: bool, out: Path, planner: Any, recorder: Any = None,
                 video: str | Path | None = None) -> None:
        self.run, self.spec, self.settings, self.closed = run, spec, settings, closed
        self.out, self.planner, self.k = out, planner, k
        env, self.video = None, None
        if video is not None:  # the existing video code: a render camera over the whole world, a step hook
            from realize.app.replay import video_camera
            from realize.app.video import VideoRecorder
            from realize.scene import Camera, EnvOptions

            eye, target = video_camera(spec.geometry)
            env = EnvOptions(camera=Camera(width=640, height=480, eye=tuple(eye), target=tuple(target)))
            self.video = VideoRecorder(video, fps=20.0, every=2)
        self.world = ExecutionWorld(spec, world_seed, disturbances=scheduled, env=env)
        if self.video is not None:
            self.video.attach(self.world.scene)
        self.schedule = Schedule(scheduled, self.world.scene.control_dt)
        self.log = WorldLog(world=k, seed=world_seed, mode="closed" if closed else "open", plan=spec.task.describe())
        self.base_step = 0  # world timeline steps before the current segment
        self.seg: _Segment | None = None
        self.recorder = recorder
        from realize.execution.trajectory import TrajectoryLog

        self.traj = TrajectoryLog(spec.sim.control_freq)  # what a robot's driver would follow
        self.world.scene.add_step_hook(self._on_step)

    # ------------------------------------------------------------------ hooks
    def _now(self) -> int:
        return self.base_step + self.world.scene.step_count

    def _on_action(self, a: int, rows: torch.Tensor) -> None:
        if not bool((rows == 0).any()) or self.seg is None:
            return
        seg, now = self.seg, self._now()
        if self.log.actions and self.log.actions[-1].outcome == "running":
            self.log.actions[-1].outcome, self.log.actions[-1].end_step = "done", now
        seg.action = a
        self.log.actions.append(ActionRecord(a, str(seg.task.plan[a]), _params_of(seg.task, seg.z, a), now))
        if seg.offset is not None:
            self.schedule.action_began(seg.offset + a, now)
        if self.closed and a > 0:  # the end of action a - 1
            self._monitor(done_action=a - 1)

    def _on_step(self, step: int) -> None:
        if self.seg is None or step == 0:
            return
        scene, now = self.world.scene, self._now()
        self._record()
        for s in self.schedule.due(now, held=self.world.held()):
            text = self.world.apply(s)
            self.log.disturbances.append({"step": now, "index": s.index, "effect": type(s.effect).__name__,
                                          "what": text, **_plain(s.effect)})
            log.info("world %d (%s): step %d: %s", self.k, self.log.mode, now, text)
            if self.recorder is not None:
                self.recorder.event(now, f"disturbance: {text}")
        if self.recorder is not None:
            self.recorder.step(now, scene)
        if self.closed and step % self.settings.monitor_every == 0:
            self._monitor()

    def _record(self) -> None:
        scene, seg = self.world.scene, self.seg
        assert seg is not None
        base, arm, grip = scene.commanded_targets()
        a = seg.action
        text = str(seg.task.plan[a]) if a < len(seg.task.plan) else ""
        self.traj.append(self._now(), len(self.log.actions) - 1, text, dict(zip(scene.robot.upper.joints, arm[0].tolist())),
                         base[0].tolist(), bool(grip[0]))

    def _monitor(self, done_action: int | None = None) -> None:
        seg = self.seg
        assert seg is not None
        obs = self.world.observe()
        a = seg.action if done_action is None else done_action
        start_held = None if seg.start is None else seg.start.held
        objects_at = None if seg.start is None else {n: tuple(p.position[:2]) for n, p in seg.start.objects.items()}
        exp = expectation(seg.task, seg.belief, a, done=done_action is not None, start_held=start_held,
                          objects_at=objects_at)
        devs = check(obs, exp, self.settings.tolerance)
        if devs:
            raise _Stop(devs, obs)

    # ------------------------------------------------------------------ the loop
    def run_world(self, z: Sequence[float]) -> WorldLog:
        from realize.realization.rollout import PlanRealizer

        t0 = time.perf_counter()
        spec, s = self.spec, self.settings
        seg = _Segment(spec.task, z, None, spec.geometry, 0)
        source: Any = self.run.run_dir
        while True:
            self.seg = seg
            realizer = PlanRealizer(seg.task, self.world.scene, spec.rollout, seed=spec.seed, start=seg.start,
                                    geometry=seg.belief)
            realizer.action_hook = self._on_action
            stop: _Stop | None = None
            res = None
            try:
                res = realizer.rollout(torch.tensor([seg.z], dtype=torch.float64))
            except _Stop as e:
                stop = e
            now = self._now()
            self.base_step = now
            last = self.log.actions[-1] if self.log.actions else None
            if stop is None:
                assert res is not None
                if last is not None and last.outcome == "running":
                    last.end_step = now
                    last.outcome = "done" if bool(res.action_success[0, last.index]) else f"failed: {res.failure[0]}"
                done = bool(res.action_success[0].all())
                if done and self._goal_holds(seg):
                    self.log.success = True
                    break
                failure = str(res.failure[0]) or "goal not reached (in the world as it is)"
                reasons = [f"action_failed: {failure}"]
                obs = self.world.observe()
                a_fail = _failed_action(failure, seg.action)
            else:
                reasons = [str(d) for d in stop.deviations]
                obs = stop.obs
                a_fail = seg.action
                if last is not None and last.outcome == "running":
                    last.end_step, last.outcome = now, "interrupted: " + reasons[0]
            self.log.deviations.append({"step": now, "action": a_fail, "what": reasons})
            elapsed = now * self.world.scene.control_dt + self.log.pause_s
            if not self.closed:
                self.log.failure = reasons[0]
                break
            if len(self.log.replans) >= s.max_replans:
                self.log.failure = f"{reasons[0]} (after {s.max_replans} replans, the most allowed)"
                break
            if elapsed >= s.time_limit_s:
                self.log.failure = f"{reasons[0]} (time limit {s.time_limit_s:g} s reached)"
                break
            rec, seg_new = self._repair(seg, source, obs, a_fail, reasons)
            self.log.replans.append(rec)
            self.log.pause_s += rec.wall_s
            if self.recorder is not None:
                self.recorder.event(now, f"replan ({rec.kind}) from action {rec.from_action}: {rec.plan} "
                                         f"cost {rec.cost}, {rec.wall_s:.1f} s")
            if seg_new is None:
                self.log.failure = f"{reasons[0]}; the {rec.kind} found no plan"
                break
            seg, source = seg_new, Path(rec.run_dir)
        self.log.steps = self.base_step
        self.log.control_time_s = self.base_step * self.world.scene.control_dt
        self.log.final_plan = seg.task.describe()
        self.log.wall_s = time.perf_counter() - t0
        return self.log

    def _goal_holds(self, seg: _Segment) -> bool:
        """The task's goal in the world as it is (a moved table where it stands now), whatever
        the robot believed: the executor's verdict."""
        from realize.tasks.goals import goal_reached

        scene = self.world.scene
        objects = scene.object_poses()[:, :, :3]
        speeds = scene.object_velocities()[:, :, :3].norm(dim=-1)
        ok, _ = goal_reached(seg.task.goal, self.world.geometry_now(), seg.task.layout.regions, objects, speeds,
                             scene.base_pose()[:, :2], self.spec.rollout.rest_speed)
        return bool(ok[0])

    def _repair(self, seg: _Segment, source: Any, obs: Observation, a: int, reasons: list[str]
                ) -> tuple[ReplanRecord, _Segment | None]:
        """Re-parameterize (the remaining actions from the state) or re-sequence (a new plan)."""
        from realize.app.replay import build_replay_spec, saved_plan
        from realize.app.resequence import resequence_task
        from realize.tasks.suffix import check_suffix_start, task_suffix

        t0 = time.perf_counter()
        state = obs.state
        changes = geometry_changes(obs, self.spec.geometry_cfg)
        remaining = task_suffix(seg.task, a)
        kind = "re-parameterize"
        try:
            check_suffix_start(remaining, state)
        except ConfigError:
            kind = "re-sequence"
        rdir = self.out / "replans" / f"world-{self.k}-replan-{len(self.log.replans)}"
        try:
            if kind == "re-parameterize":
                src_cfg = saved_plan(source).config
                base_k = 0 if src_cfg.get("replan") is None or src_cfg.get("replan_from") is None else \
                    int(src_cfg["replan"]["action"] or 0)
                res = self.planner.replan(state, base_k + a, changes, source=source, run_dir=rdir,
                                          budget=self.budget, seed=self.spec.seed)
            else:
                from realize.execution.world import apply_geometry_updates, geometry_updates
                from realize.world.geometry import build_geometry

                now_geo = build_geometry(apply_geometry_updates(self.spec.geometry_cfg,
                                                                geometry_updates(obs, self.spec.geometry_cfg)))
                task_cfg = resequence_task(saved_plan(source).config["task"], now_geo, state, rdir)
                res = self.planner.resequence(task_cfg, state, changes, source=source, run_dir=rdir,
                                              budget=self.budget, seed=self.spec.seed)
        except ConfigError as e:
            wall = time.perf_counter() - t0
            return ReplanRecord(kind, self._now(), a, reasons + [f"refused: {e}"], wall, False, None, "", str(rdir),
                                "", changes), None
        wall = time.perf_counter() - t0
        rec = ReplanRecord(kind, self._now(), res.from_action, reasons, wall, res.feasible,
                           res.cost if res.feasible else None, res.plan, str(res.run_dir), res.scene, changes,
                           res.timings.to_dict())
        log.info("world %d: %s from action %d in %.1f s: %s (cost %s)", self.k, kind, res.from_action, wall, res.plan,
                 f"{res.cost:.0f}" if res.feasible else "none")
        if not res.feasible:
            return rec, None
        rspec = build_replay_spec(saved_plan(res.run_dir))
        whole = self.spec.task.describe()
        offset = res.from_action if rspec.config.get("task", {}).get("plan") == self.run.config["task"].get("plan") \
            and whole.endswith(rspec.task.describe()) else None
        return rec, _Segment(rspec.task, res.z, rspec.start, rspec.geometry, offset)

    budget: Any = None

    def close(self) -> None:
        if self.video is not None:
            self.video.close(hold_s=1.0)
        self.world.close()


def _failed_action(failure: str, default: int) -> int:
    """The action index of a ``"K:template:reason"`` failure (else ``default``)."""
    head = failure.split(":", 1)[0]
    return int(head) if head.isdigit() else default


def _plain(effect: Any) -> dict[str, Any]:
    try:
        return {k: (list(v) if isinstance(v, tuple) else v) for k, v in dataclasses.asdict(effect).items()}
    except TypeError:  # pragma: no cover
        return {}


def execute_world(run_dir: str | Path, settings: ExecuteSettings, k: int, *, closed_loop: bool = True,
                  planner: Any = None, out: Path | None = None, budget: Any = None, recorder: Any = None,
                  trajectory: str | Path | None = None, video: str | Path | None = None) -> WorldLog:
    """World ``k`` of the study ``settings`` of the run at ``run_dir`` (see ``execute``); the
    executed trajectory is saved to ``trajectory`` (an ``.npz``) and an MP4 to ``video``
    where given."""
    from realize.app.replay import build_replay_spec, returned_z, saved_plan

    run = saved_plan(run_dir)
    choice = returned_z(run)
    spec = build_replay_spec(dataclasses.replace(run, best_z=choice.z))
    disturbances = read_disturbances(settings.disturbances, spec.geometry, [str(a) for a in spec.task.plan])
    seed = settings.seed * SEED_STRIDE + k
    scheduled = draw(disturbances, np.random.default_rng([settings.seed, k]))
    out = Path(out) if out is not None else Path(run_dir) / EXECUTION_DIR / "default"
    ex = _Executor(run, spec, settings, scheduled, seed, k, closed_loop, out, planner, recorder, video)
    ex.budget = budget
    try:
        wl = ex.run_world(choice.z)
        if trajectory is not None:
            ex.traj.save(trajectory)
        return wl
    finally:
        ex.close()


def _label(settings_name: str | None, closed: bool | None = None) -> str:
    return settings_name or "default"


def execute(run_dir: str | Path, settings: ExecuteSettings, *, name: str | None = None, worlds: int | None = None,
            open_loop: bool = True, closed_loop: bool = True, out: str | Path | None = None, budget: Any = None,
            rerun: bool = True, progress: bool = True, video: bool = False) -> ExecutionSummary:
    """The study of module docstring: ``worlds`` (default ``settings.worlds``) worlds, each open
    loop and/or closed loop, into ``out`` (default ``<run>/execution/<name>``). Every world's
    files are written as it ends (a killed study keeps what it has); ``summary.json`` after
    each world. Bad disturbances are refused before anything is simulated."""
    from realize.app.planner import Planner, ReplanBudget
    from realize.app.replay import build_replay_spec, saved_plan

    t0 = time.perf_counter()
    run = saved_plan(run_dir)
    spec = build_replay_spec(run)
    read_disturbances(settings.disturbances, spec.geometry, [str(a) for a in spec.task.plan])  # before simulating
    if not (open_loop or closed_loop):
        raise ConfigError("execute: neither open nor closed loop asked for")
    n = settings.worlds if worlds is None else int(worlds)
    if n < 1:
        raise ConfigError(f"execute: worlds = {n} is invalid: must be >= 1")
    label = name or "default"
    where = Path(out) if out is not None else Path(run_dir) / EXECUTION_DIR / label
    where.mkdir(parents=True, exist_ok=True)
    budget = budget or ReplanBudget()
    logs: dict[str, list[WorldLog]] = {"open": [], "closed": []}
    files: list[str] = []
    planner = Planner.from_run(run_dir) if closed_loop else None
    warm_s = planner.warm_up(budget) if planner is not None else 0.0  # the planner is up before the robot moves
    modes = [m for m, on in (("open", open_loop), ("closed", closed_loop)) if on]
    bar = None
    if progress:
        from tqdm import tqdm

        bar = tqdm(total=n * len(modes), desc=f"execute {label}", unit="world")
    try:
        for k in range(n):
            for mode in modes:
                rec = None
                stem = f"world-{k}-{mode}"
                if rerun:
                    from realize.recording.execution_log import ExecutionRecorder

                    rec = ExecutionRecorder(where / f"{stem}.rrd", spec, stem)
                try:
                    wl = execute_world(run_dir, settings, k, closed_loop=mode == "closed", planner=planner, out=where,
                                       budget=budget, recorder=rec, trajectory=where / f"{stem}.npz",
                                       video=where / f"{stem}.mp4" if video else None)
                finally:
                    if rec is not None:
                        rec.close()
                logs[mode].append(wl)
                (where / f"{stem}.json").write_text(json.dumps(wl.to_dict(), indent=2, default=str) + "\n")
                files += [f"{stem}.json", f"{stem}.npz"] + ([f"{stem}.mp4"] if video else [])
                if rec is not None:
                    files.append(f"{stem}.rrd")
                summary = _summary(run_dir, label, settings, n, logs, files, time.perf_counter() - t0)
                (where / "summary.json").write_text(json.dumps(summary.to_dict(), indent=2) + "\n")
                if bar is not None:
                    bar.update(1)
                    bar.set_postfix_str(f"{mode}: {'goal' if wl.success else 'failed'}, {len(wl.replans)} replan(s)")
    finally:
        if bar is not None:
            bar.close()
        if planner is not None:
            planner.close()
    out_summary = _summary(run_dir, label, settings, n, logs, files, time.perf_counter() - t0)
    out_summary.planner_start_s = warm_s
    (where / "summary.json").write_text(json.dumps(out_summary.to_dict(), indent=2) + "\n")
    return out_summary


def _summary(run_dir: Any, label: str, settings: ExecuteSettings, n: int, logs: dict[str, list[WorldLog]],
             files: list[str], wall: float) -> ExecutionSummary:
    closed, opened = logs["closed"], logs["open"]
    open_ok = {w.world for w in opened if w.success}
    return ExecutionSummary(
        run_dir=str(run_dir), label=label, worlds=n, seed=settings.seed,
        closed_loop_success=(sum(w.success for w in closed) / len(closed)) if closed else None,
        open_loop_success=(sum(w.success for w in opened) / len(opened)) if opened else None,
        closed_successes=sum(w.success for w in closed) if closed else None,
        open_successes=sum(w.success for w in opened) if opened else None,
        replans=[len(w.replans) for w in closed],
        replan_s=[r.wall_s for w in closed for r in w.replans],
        replan_kinds=[r.kind for w in closed for r in w.replans],
        replans_with_open_success=[len(w.replans) for w in closed if w.world in open_ok],
        pause_s=[w.pause_s for w in closed], wall_time_s=wall, settings=asdict(settings), files=list(files))
