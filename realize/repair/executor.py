"""One world's execution: the plan carried out segment by segment in an ``ExecutionWorld``,
watched at the monitor rate and repaired through the planner (``realize.repair.study`` runs a study
of such worlds; its docstring says what the loop does).

What it does: ``Executor(run, spec, settings, scheduled, seed, k, closed, out, planner)`` builds the
world (and its video, recording and trajectory log), ``run_world(z)`` executes the plan ``z``: each
segment a ``PlanRealizer`` rollout of the plan being run from its start state in the robot's belief
geometry (with perception on, its controllers act on the belief: objects and the base where it has
them), with step and action hooks that apply due disturbances, record the commands, and stop
the segment on a deviation; then ``_repair`` re-parameterizes or re-sequences and the next segment
runs the new plan from the captured state.
What it doesn't: choose worlds, write files or summarize a study (``realize.repair.study``).
"""

from __future__ import annotations

import dataclasses
import logging
import math
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import torch

from realize.repair.records import ActionRecord, WorldLog
from realize.repair.on_deviation import EXECUTION_BACKEND, Segment, go_on, repair, why_no_plan
from realize.execution.disturbances import Scheduled
from realize.execution.monitor import Deviation, check, expectation
from realize.execution.in_hand import firm_grip
from realize.execution.layout_updates import apply_geometry_updates, geometry_updates
from realize.execution.precheck import Precheck
from realize.execution.robot_view import RobotView
from realize.execution.schedule import Schedule
from realize.execution.settings import ExecuteSettings
from realize.execution.world import ExecutionWorld, Observation
from realize.robot.layout import BASE, UPPER

__all__ = ["Executor", "EXECUTION_BACKEND", "waits_for_rest"]

HOLD_TEXT = "hold"  # the trajectory's action text while the robot holds for the planner
WAIT_FOR_REST_S = 3.0  # s of control time at most a dropped or knocked object is waited for to land before deciding

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


class Executor:
    def __init__(self, run: Any, spec: Any, settings: ExecuteSettings, scheduled: list[Scheduled], world_seed: int,
                 k: int, closed: bool, out: Path, planner: Any, recorder: Any = None,
                 video: str | Path | None = None, budget: Any = None) -> None:
        self.run, self.spec, self.settings, self.closed = run, spec, settings, closed
        self.budget = budget  # the replans' ReplanBudget (None: the planner's default)
        self.out, self.planner, self.k = out, planner, k
        env, self.video = None, None
        if video is not None:  # the existing video code: a render camera over the whole world, a step hook
            from realize.validation.replay import video_camera
            from realize.validation.video import VideoRecorder
            from realize.scene import Camera, EnvOptions

            eye, target = video_camera(spec.geometry)
            env = EnvOptions(camera=Camera(width=640, height=480, eye=tuple(eye), target=tuple(target)))
            self.video = VideoRecorder(video, fps=20.0, every=2)
        self.world = ExecutionWorld(spec, world_seed, disturbances=scheduled, env=env)
        if self.video is not None:
            self.video.attach(self.world.scene)
        self.schedule = Schedule(scheduled, self.world.scene.control_dt)
        self.log = WorldLog(world=k, seed=world_seed, mode="closed" if closed else "open", plan=spec.task.describe())
        self.seg: Segment | None = None
        self.recorder = recorder
        from realize.execution.trajectory import TrajectoryLog

        self.traj = TrajectoryLog(spec.sim.control_freq)  # what a robot's driver would follow
        self.clock = 0  # control steps of the world's timeline (segments and holds)
        self.holding = False  # the robot holds while the planner thinks: no monitor
        self.tries = 0  # replans in a row that found no plan (the next one searches longer)
        # the robot perceives the same way open loop or closed: its controllers act on what it sees either way
        self.view = RobotView(self.world, settings.noise, world_seed)
        self.belief = self.view.belief
        self.precheck = Precheck(spec, settings.precheck, world_seed) if closed else None
        self.world.scene.add_step_hook(self._on_step)

    # ------------------------------------------------------------------ hooks
    def now(self) -> int:
        """The world's control step (segments and holds)."""
        return self.clock

    def _observe(self) -> Observation:
        """What the robot decides from: the world itself (no noise) or its filtered belief."""
        return self.view.observe(self.now())

    def _on_action(self, a: int, rows: torch.Tensor) -> None:
        if not bool((rows == 0).any()) or self.seg is None:
            return
        seg, now = self.seg, self.now()
        if self.log.actions and self.log.actions[-1].outcome == "running":
            self.log.actions[-1].outcome, self.log.actions[-1].end_step = "done", now
        seg.action = a
        self.log.actions.append(ActionRecord(a, str(seg.task.plan[a]), _params_of(seg.task, seg.z, a), now))
        if seg.offset is not None:
            self.schedule.action_began(seg.offset + a, now)
        if self.closed and a > 0:  # the end of action a - 1
            self._monitor(done_action=a - 1)

    def _on_step(self, step: int) -> None:
        if self.seg is None:
            return
        if step == 0:
            self.view.sense(self.now(), first=True)
            return
        self.clock += 1
        scene, now = self.world.scene, self.now()
        self.view.sense(self.now())
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
        if self.closed and not self.holding and step % self.settings.monitor_every == 0:
            self._monitor()

    def _record(self) -> None:
        scene, seg = self.world.scene, self.seg
        assert seg is not None
        base, arm, grip = scene.commanded_targets()
        a = seg.action
        text = HOLD_TEXT if self.holding else str(seg.task.plan[a]) if a < len(seg.task.plan) else ""
        q = scene.whole_body_q()[0]  # what the encoders and the localizer read (the belief's base where it drifts)
        drift = self.view.base_error()[0].double() if scene.robot.base.joints else torch.zeros(3, dtype=torch.float64)
        x, y, yaw = (q[BASE].double() + drift).tolist()
        self.traj.append(self.now(), len(self.log.actions) - 1, text, dict(zip(scene.robot.upper.joints, arm[0].tolist())),
                         base[0].tolist(), bool(grip[0]), q[UPPER].tolist() + [x, y, yaw])

    def _monitor(self, done_action: int | None = None) -> None:
        seg = self.seg
        assert seg is not None
        obs = self._observe()
        self._keep(obs)
        devs = self._deviations(seg, obs, seg.action if done_action is None else done_action, done_action is not None)
        if devs:
            raise _Stop(devs, obs)

    def _keep(self, obs: Observation) -> None:
        """What the monitor decided from, for the world's exports (``WorldLog.observed``): the
        base (x, y, 0 and its heading), every object and table as poses (x, y, z, qw, qx, qy, qz)."""
        s = obs.state
        poses: dict[str, list[float]] = {"base": [s.base[0], s.base[1], 0.0, math.cos(s.base[2] / 2), 0.0, 0.0,
                                                  math.sin(s.base[2] / 2)]}
        poses.update({n: [*p.position, *p.quaternion] for n, p in s.objects.items()})
        poses.update({n: [t.x, t.y, 0.0, math.cos(t.yaw / 2), 0.0, 0.0, math.sin(t.yaw / 2)] for n, t in obs.tables.items()})
        self.log.observed.append((self.now() * self.world.scene.control_dt, poses))

    def _deviations(self, seg: Segment, obs: Observation, a: int, done: bool) -> list[Deviation]:
        """The monitor's checks of ``obs`` against what ``seg``'s plan expects during action
        ``a`` (``done``: at its end)."""
        start_held = None if seg.start is None else seg.start.held
        objects_at = None if seg.start is None else {n: tuple(p.position) for n, p in seg.start.objects.items()}
        exp = expectation(seg.task, seg.belief, a, done=done, start_held=start_held, objects_at=objects_at)
        return check(obs, exp, self.settings.tolerance)

    # ------------------------------------------------------------------ the loop
    def run_world(self, z: Sequence[float]) -> WorldLog:
        from realize.realization.rollout import PlanRealizer

        t0 = time.perf_counter()
        spec, s = self.spec, self.settings
        dt = self.world.scene.control_dt
        seg = Segment(spec.task, z, None, spec.geometry, 0)
        source: Any = self.run.run_dir
        resume = False  # a repaired plan takes over from the world as it is (no restore)
        pending: tuple[list[str], Observation, int] | None = None  # a deviation found at a hand-over
        while True:
            self.seg = seg
            if pending is None:
                realizer = PlanRealizer(seg.task, self.world.scene, seg.rollout or spec.rollout, seed=spec.seed,
                                        geometry=seg.belief)
                realizer.action_hook = self._on_action
                if self.belief is not None:  # the controllers act on the belief: objects and base where it has them
                    realizer.seen_objects = lambda: self.view.seen_objects(self.now())
                    if self.world.scene.robot.base.joints:
                        realizer.base_error = self.view.base_error
                reasons, obs, a_fail, done = self._segment(seg, realizer, resume)
                if done:
                    self.log.success = True
                    break
            else:
                reasons, obs, a_fail = pending
                pending = None
            now = self.now()
            self.log.deviations.append({"step": now, "action": a_fail, "what": reasons})
            elapsed = now * dt + (self.log.pause_s if s.think == "frozen" else 0.0)
            if not self.closed:
                self.log.failure = reasons[0]
                break
            if len(self.log.replans) >= s.max_replans:
                self.log.failure = f"{reasons[0]} (after {s.max_replans} replans, the most allowed)"
                break
            if elapsed >= s.time_limit_s:
                self.log.failure = f"{reasons[0]} (time limit {s.time_limit_s:g} s reached)"
                break
            if waits_for_rest(reasons):  # see where it lands first
                held = self._hold_steps(int(round(WAIT_FOR_REST_S / self.world.scene.control_dt)), until_rest=True)
                obs = self._observe() if held else obs
            obs = self._firm_grip(obs)
            seg_new, think_s = go_on(self, seg, obs, a_fail, reasons)
            if seg_new is None:
                rec, seg_new = repair(self, seg, source, obs, a_fail, reasons)
                rec.wall_s += think_s  # the check was thinking too
                self.log.replans.append(rec)
                think_s = rec.wall_s
                if self.recorder is not None:
                    self.recorder.event(now, f"replan ({rec.kind}) from action {rec.from_action}: {rec.plan} "
                                             f"cost {rec.cost}, {rec.wall_s:.1f} s")
                if seg_new is None:
                    self.log.pause_s += think_s
                    rec.hold_steps = self._hold(think_s)
                    refused = any(r.startswith("refused:") for r in rec.reason)
                    if not refused and len(self.log.replans) < s.max_replans:  # again, with more iterations
                        self.tries += 1
                        pending = (reasons, self._observe(), a_fail)
                        continue
                    self.log.failure = f"{reasons[0]}; the {rec.kind} found no plan: {why_no_plan(rec, obs.state)}"
                    break
                self.tries = 0
                source = Path(rec.run_dir)
                rec.hold_steps = self._hold(think_s)
            else:
                self.log.checks[-1]["hold_steps"] = self._hold(think_s)
            self.log.pause_s += think_s
            seg = seg_new
            resume = True
            # the plan takes over from the world as it is now: what it assumed may be stale
            self.seg = seg
            obs = self._observe()
            devs = self._deviations(seg, obs, 0, False)
            if devs:
                pending = ([f"at hand-over: {d}" for d in devs], obs, 0)
        self.log.steps = self.now()
        self.log.control_time_s = self.now() * dt
        self.log.hold_s = self.log.hold_steps * dt
        self.log.final_plan = seg.task.describe()
        self.log.wall_s = time.perf_counter() - t0
        return self.log

    def _segment(self, seg: Segment, realizer: Any, resume: bool) -> tuple[list[str], Observation, int, bool]:
        """Run ``seg`` until it ends or deviates, from the world's start or (``resume``) from the
        world as it is: (reasons, what the robot saw, the action to repair from, reached the goal)."""
        stop: _Stop | None = None
        res = None
        try:
            res = realizer.rollout(torch.tensor([seg.z], dtype=torch.float64), resume=resume)
        except _Stop as e:
            stop = e
        now = self.now()
        last = self.log.actions[-1] if self.log.actions else None
        if stop is None:
            assert res is not None
            if last is not None and last.outcome == "running":
                last.end_step = now
                last.outcome = "done" if bool(res.action_success[0, last.index]) else f"failed: {res.failure[0]}"
            if bool(res.action_success[0].all()) and self._goal_holds(seg):
                return [], self._observe(), seg.action, True
            failure = str(res.failure[0]) or "goal not reached (in the world as it is)"
            return [f"action_failed: {failure}"], self._observe(), _failed_action(failure, seg.action), False
        reasons = [str(d) for d in stop.deviations]
        if last is not None and last.outcome == "running":
            last.end_step, last.outcome = now, "interrupted: " + reasons[0]
        return reasons, stop.obs, seg.action, False

    def _hold(self, think_s: float) -> int:
        """The world while the planner thinks ``think_s`` (``settings.think``): the robot holds
        for that many control steps (``_hold_steps``); returns them."""
        t = self.settings.think
        n = 0 if t == "frozen" else int(math.ceil(think_s / self.world.scene.control_dt)) if t == "measured" else int(t)
        return self._hold_steps(n)

    def _hold_steps(self, most: int, until_rest: bool = False) -> int:
        """The robot holds (base stopped, arm where it is, gripper as it was) for ``most`` control
        steps, or (``until_rest``) until every object is at rest (``controller.rest_speed``) if
        sooner, while the world goes on (disturbances fire, the sensor reads, no monitor);
        returns the steps held (world time lost, counted in ``hold_steps``)."""
        scene, rest = self.world.scene, self.spec.rollout.rest_speed
        n = 0
        self.holding = True
        try:
            with torch.inference_mode():
                scene.hold_still()
                while n < most and not (until_rest and float(scene.object_velocities()[0, :, :3].norm(dim=-1).max())
                                        <= rest):
                    scene.step()
                    n += 1
        finally:
            self.holding = False
        self.log.hold_steps += n
        return n

    def _firm_grip(self, obs: Observation) -> Observation:
        """The state the planner starts from, with a grip its restore keeps: where the object in
        the hand, restored as observed, falls out of the fingers at rest or on a short drive (a
        grip askew or off the pads' middle, ``Precheck.grip_holds``), it is squared with the hand
        and centred between the pads, as deep as a restore of it still holds
        (``realize.execution.in_hand.firm_grip``); a grip that holds is left as observed."""
        s = obs.state
        if s.held is None or obs.hand is None or self.precheck is None:
            return obs
        layout = self.layout(obs)
        if self.precheck.grip_holds(s, layout):
            return obs
        squared = firm_grip(s, obs.hand, self.spec.geometry.object(s.held), self.spec.robot.tcp.approach_axis,
                            lambda st: self.precheck.grip_holds(st, layout))
        log.info("world %d: the grip of %s as observed slips in a restore: the planner assumes it square", self.k,
                 s.held)
        return dataclasses.replace(obs, state=squared)

    def replan_budget(self) -> Any:
        """The next replan's budget: the study's, its iterations doubled for every try in a row
        that found no plan."""
        from realize.run.planner import ReplanBudget

        b = self.budget or ReplanBudget()
        return dataclasses.replace(b, iterations=b.iterations * 2 ** self.tries) if self.tries else b

    def moved_m(self) -> float | None:
        """How far a believed table must be from the config to count as moved (None: exact)."""
        return None if self.belief is None else self.settings.tolerance.table_m

    def layout(self, obs: Observation) -> Any:
        """The run's scene config with the world as ``obs`` shows it (moved tables, new boxes)."""
        cfg = self.spec.geometry_cfg
        return apply_geometry_updates(cfg, geometry_updates(obs, cfg, self.moved_m()))

    def _goal_holds(self, seg: Segment) -> bool:
        """The task's goal in the world as it is (a moved table where it stands now), whatever
        the robot believed: the executor's verdict."""
        from realize.execution.layout_updates import geometry_now
        from realize.tasks.goals import goal_reached

        scene = self.world.scene
        objects = scene.object_poses()[:, :, :3]
        speeds = scene.object_velocities()[:, :, :3].norm(dim=-1)
        ok, _ = goal_reached(seg.task.goal, geometry_now(self.world), seg.task.layout.regions, objects, speeds,
                             scene.base_pose()[:, :2], self.spec.rollout.rest_speed, seg.task.frames)
        return bool(ok[0])

    def close(self) -> None:
        if self.precheck is not None:
            self.precheck.close()
        if self.video is not None:
            self.video.close(hold_s=1.0)
        self.world.close()


def waits_for_rest(reasons: Sequence[str]) -> bool:
    """Whether a deviation's ``reasons`` let an object fall: a grasp lost, a support moved, or an
    action that failed with the object dropped (a place that knocked it out of the hand, read at
    once still falling: grasp_slip world 15 at seed 0 read cube C 1 cm above cube B, on nothing the
    blocks domain can say). The executor then holds until every object is at rest (at most
    ``WAIT_FOR_REST_S``) before it reads the state to repair from."""
    return any(r.startswith(("grasp_lost", "support_moved")) or r.endswith(":object_dropped") for r in reasons)


def _failed_action(failure: str, default: int) -> int:
    """The action index of a ``"K:template:reason"`` failure (else ``default``)."""
    head = failure.split(":", 1)[0]
    return int(head) if head.isdigit() else default


def _plain(effect: Any) -> dict[str, Any]:
    try:
        return {k: (list(v) if isinstance(v, tuple) else v) for k, v in dataclasses.asdict(effect).items()}
    except TypeError:  # pragma: no cover
        return {}
