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
    thinks; the pause is counted) and the plan repaired with ``realize.run.planner.Planner``:
    **re-parameterize** (``Planner.replan``: the remaining actions from that state, in the world
    as observed, warm-started, small budget) where the remaining plan can still start from the
    state, else **re-sequence** (``realize.repair.resequence``: the symbolic state read off the
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
import time
from dataclasses import asdict
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from realize.repair.records import ExecutionSummary, ReplanRecord, WorldLog
from realize.repair.executor import EXECUTION_BACKEND, Executor
from realize.config import ConfigError
from realize.execution.disturbances import draw, read_disturbances
from realize.execution.export import DEFAULT_ACCELERATION_LIMIT, ExportOptions, export_formats, export_world
from realize.execution.settings import ExecuteSettings

__all__ = ["execute", "execute_world", "judge_replans", "ExecutionSummary", "WorldLog", "ReplanRecord", "EXECUTION_DIR"]

log = logging.getLogger("realize")

EXECUTION_DIR = "execution"
SEED_STRIDE = 1000  # world k of a study with seed S draws its world and disturbances with seed S * 1000 + k


def execute_world(run_dir: str | Path, settings: ExecuteSettings, k: int, *, closed_loop: bool = True,
                  planner: Any = None, out: Path | None = None, budget: Any = None, recorder: Any = None,
                  trajectory: str | Path | None = None, video: str | Path | None = None) -> WorldLog:
    """World ``k`` of the study ``settings`` of the run at ``run_dir`` (see ``execute``); the
    executed trajectory is saved to ``trajectory`` (an ``.npz``) and an MP4 to ``video``
    where given."""
    from realize.validation.replay import build_replay_spec, returned_z, saved_plan

    run = saved_plan(run_dir)
    choice = returned_z(run)
    spec = build_replay_spec(dataclasses.replace(run, best_z=choice.z), EXECUTION_BACKEND, judged=True)
    disturbances = read_disturbances(settings.disturbances, spec.geometry, [str(a) for a in spec.task.plan])
    seed = settings.seed * SEED_STRIDE + k
    scheduled = draw(disturbances, np.random.default_rng([settings.seed, k]))
    out = Path(out) if out is not None else Path(run_dir) / EXECUTION_DIR / "default"
    ex = Executor(run, spec, settings, scheduled, seed, k, closed_loop, out, planner, recorder, video, budget)
    try:
        wl = ex.run_world(choice.z)
        if trajectory is not None:
            ex.traj.save(trajectory)
        return wl
    finally:
        ex.close()


def execute(run_dir: str | Path, settings: ExecuteSettings, *, name: str | None = None, worlds: int | None = None,
            open_loop: bool = True, closed_loop: bool = True, out: str | Path | None = None, budget: Any = None,
            rerun: bool = True, progress: bool = True, video: bool = False, export: str | Sequence[str] = (),
            export_acceleration: float = DEFAULT_ACCELERATION_LIMIT) -> ExecutionSummary:
    """The study of module docstring: ``worlds`` (default ``settings.worlds``) worlds, each open
    loop and/or closed loop, into ``out`` (default ``<run>/execution/<name>``). Every world's
    files are written as it ends (a killed study keeps what it has); ``summary.json`` after
    each world. Bad disturbances are refused before anything is simulated. ``export``: formats
    (``ros2``, ``lerobot``: ``realize.execution.export``) each world is also written in, after its
    files, with ``export_acceleration`` the arm's acceleration limit; bad names are refused first.
    ``budget``: the replans' search, in place of ``settings.budget``."""
    from realize.run.planner import Planner
    from realize.validation.replay import build_replay_spec, saved_plan

    t0 = time.perf_counter()
    run = saved_plan(run_dir)
    spec = build_replay_spec(run, EXECUTION_BACKEND, judged=True)
    read_disturbances(settings.disturbances, spec.geometry, [str(a) for a in spec.task.plan])  # before simulating
    formats = export_formats(export)
    export_options = ExportOptions.for_robot(spec.robot, export_acceleration) if formats else None
    if not (open_loop or closed_loop):
        raise ConfigError("execute: neither open nor closed loop asked for")
    n = settings.worlds if worlds is None else int(worlds)
    if n < 1:
        raise ConfigError(f"execute: worlds = {n} is invalid: must be >= 1")
    label = name or "default"
    where = Path(out) if out is not None else Path(run_dir) / EXECUTION_DIR / label
    where.mkdir(parents=True, exist_ok=True)
    if budget is not None:  # (summary.json's settings say the budget the replans ran on)
        settings = dataclasses.replace(settings, budget=budget)
    budget = settings.budget
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
                judge_replans(wl, next((o for o in logs["open"] if o.world == k), None))
                (where / f"{stem}.json").write_text(json.dumps(wl.to_dict(), indent=2, default=str) + "\n")
                files += [f"{stem}.json", f"{stem}.npz"] + ([f"{stem}.mp4"] if video else [])
                if rec is not None:
                    files.append(f"{stem}.rrd")
                if formats:
                    exported = export_world(where / f"{stem}.npz", where / f"{stem}.json", where, formats, spec.robot,
                                            options=export_options, observations=wl.observed or None)
                    files += [f for f in exported.files if f not in files]
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


def judge_replans(closed: WorldLog, opened: WorldLog | None) -> None:
    """Each replan's verdict once the world has played out both ways (``ReplanRecord.verdict``):
    ``needless`` where the open loop reached the goal in the same world, ``harmful`` where it
    did and the closed loop did not, else ``needed``. Nothing without an open-loop run."""
    if opened is None or closed.mode != "closed":
        return
    for r in closed.replans:
        r.verdict = ("harmful" if not closed.success else "needless") if opened.success else "needed"


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
        pause_s=[w.pause_s for w in closed], wall_time_s=wall,
        needless_replans=sum(r.verdict in ("needless", "harmful") for w in closed for r in w.replans) if opened else None,
        harmful_replans=sum(r.verdict == "harmful" for w in closed for r in w.replans) if opened else None,
        checks=sum(len(w.checks) for w in closed), checks_gone_on=sum(c["go_on"] for w in closed for c in w.checks),
        hold_s=[w.hold_s for w in closed], settings=asdict(settings), files=list(files))
