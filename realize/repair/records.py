"""What an execution writes: one world's log (actions, deviations, disturbances, replans) and a
study's summary, as dataclasses (``world-K-<mode>.json``, ``summary.json``).

What it does: ``ReplanRecord``, ``ActionRecord``, ``WorldLog``, ``ExecutionSummary`` (its
``to_dict`` adds the replans' median and p95 wall time).
What it doesn't: execute anything (``realize.repair.executor``, ``realize.repair.study``).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np

__all__ = ["ReplanRecord", "ActionRecord", "WorldLog", "ExecutionSummary"]


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
    hold_steps: int = 0  # control steps the world ran on while the robot held for it (execute.think)
    # after the world played out: needless (the open loop reached the goal in this world) or
    # needed; harmful too where the open loop reached it and the closed loop did not ("": no open loop run)
    verdict: str = ""


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
    pause_s: float = 0.0  # wall time the planner thought (checks and replans)
    hold_steps: int = 0  # control steps the world ran on while the robot held for the planner
    hold_s: float = 0.0  # the same in control time: world time lost to thinking
    wall_s: float = 0.0
    plan: str = ""  # the plan it started with
    final_plan: str = ""  # the plan it ended with
    disturbances: list[dict[str, Any]] = field(default_factory=list)
    deviations: list[dict[str, Any]] = field(default_factory=list)
    actions: list[ActionRecord] = field(default_factory=list)
    replans: list[ReplanRecord] = field(default_factory=list)
    checks: list[dict[str, Any]] = field(default_factory=list)  # checks before a repair (realize.execution.precheck)
    # what the monitor decided from, each check: (control time s, name -> x, y, z, qw, qx, qy, qz); the exports
    # write it (a ROS 2 bag's observed poses), the JSON leaves it out
    observed: list[tuple[float, dict[str, list[float]]]] = field(default_factory=list)

    def to_dict(self) -> dict[str, Any]:
        d = asdict(self)
        d.pop("observed")
        return d


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
    pause_s: list[float]  # per closed-loop world: the planner's thinking (wall time)
    wall_time_s: float
    settings: dict[str, Any]
    files: list[str]
    planner_start_s: float = 0.0  # opening the replans' workers, before the first world
    # replans whose world the open loop got right (needless), and those of them after which the closed loop
    # failed (harmful): ReplanRecord.verdict; None where no open loop ran
    needless_replans: int | None = None
    harmful_replans: int | None = None
    checks: int = 0  # checks before a repair (execute.precheck)
    checks_gone_on: int = 0  # of them, how many let the plan go on unchanged
    hold_s: list[float] = field(default_factory=list)  # per closed-loop world: world time lost to thinking

    def to_dict(self) -> dict[str, Any]:
        d = asdict(self)
        s = sorted(self.replan_s)
        d["replan_s_median"] = float(np.median(s)) if s else None
        d["replan_s_p95"] = float(np.percentile(s, 95)) if s else None
        return d
