"""One world's execution: the plan carried out segment by segment in an ``ExecutionWorld``,
watched at the monitor rate and repaired through the planner (``realize.app.execute`` runs a study
of such worlds; its docstring says what the loop does).

What it does: ``Executor(run, spec, settings, scheduled, seed, k, closed, out, planner)`` builds the
world (and its video, recording and trajectory log), ``run_world(z)`` executes the plan ``z``: each
segment a ``PlanRealizer`` rollout of the plan being run from its start state in the robot's belief
geometry, with step and action hooks that apply due disturbances, record the commands, and stop
the segment on a deviation; then ``_repair`` re-parameterizes or re-sequences and the next segment
runs the new plan from the captured state.
What it doesn't: choose worlds, write files or summarize a study (``realize.app.execute``).
"""

from __future__ import annotations

import dataclasses
import logging
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import torch

from realize.app.execution_records import ActionRecord, ReplanRecord, WorldLog
from realize.config import ConfigError
from realize.execution.disturbances import Scheduled
from realize.execution.monitor import Deviation, check, expectation
from realize.execution.schedule import Schedule
from realize.execution.settings import ExecuteSettings
from realize.execution.world import ExecutionWorld, Observation, geometry_changes

__all__ = ["Executor", "EXECUTION_BACKEND"]

# an executed world is one copy restored and disturbed through the CPU backend's setters (the GPU
# backend's restore has never run), whatever backend the run searched on
EXECUTION_BACKEND = "cpu"

log = logging.getLogger("realize")


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


class Executor:
    def __init__(self, run: Any, spec: Any, settings: ExecuteSettings, scheduled: list[Scheduled], world_seed: int,
                 k: int, closed: bool, out: Path, planner: Any, recorder: Any = None,
                 video: str | Path | None = None, budget: Any = None) -> None:
        self.run, self.spec, self.settings, self.closed = run, spec, settings, closed
        self.budget = budget  # the replans' ReplanBudget (None: the planner's default)
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
                             scene.base_pose()[:, :2], self.spec.rollout.rest_speed, seg.task.frames)
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
        kind = "re-parameterize"
        if a >= seg.task.n_actions:  # every action done but the goal does not hold: a new sequence from here
            kind = "re-sequence"
        else:
            try:
                check_suffix_start(task_suffix(seg.task, a), state)
            except ConfigError:
                kind = "re-sequence"
        rdir = self.out / "replans" / f"world-{self.k}-replan-{len(self.log.replans)}"
        try:
            task_cfg = None
            if kind == "re-sequence":
                from realize.execution.world import apply_geometry_updates, geometry_updates
                from realize.world.geometry import build_geometry

                now_geo = build_geometry(apply_geometry_updates(self.spec.geometry_cfg,
                                                                geometry_updates(obs, self.spec.geometry_cfg)))
                task_cfg = resequence_task(saved_plan(source).config["task"], now_geo, state, rdir)
                if not task_cfg["plan"] and a >= seg.task.n_actions:
                    # symbolically done, geometrically not (the base just outside the exit): the last action again
                    kind, a, task_cfg = "re-parameterize", seg.task.n_actions - 1, None
            if task_cfg is None:
                src_cfg = saved_plan(source).config
                base_k = 0 if src_cfg.get("replan") is None or src_cfg.get("replan_from") is None else \
                    int(src_cfg["replan"]["action"] or 0)
                res = self.planner.replan(state, base_k + a, changes, source=source, run_dir=rdir,
                                          budget=self.budget, seed=self.spec.seed)
            else:
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
        rspec = build_replay_spec(saved_plan(res.run_dir), EXECUTION_BACKEND)
        whole = self.spec.task.describe()
        offset = res.from_action if rspec.config.get("task", {}).get("plan") == self.run.config["task"].get("plan") \
            and whole.endswith(rspec.task.describe()) else None
        return rec, _Segment(rspec.task, res.z, rspec.start, rspec.geometry, offset)

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
