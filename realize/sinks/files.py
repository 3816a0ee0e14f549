"""The run's own files as sinks: history + checkpoint (the commit point) and ``result.json``.

What it does:
  * ``CheckpointSink`` (critical): after every iteration appends it to its plan's ``History``
    and writes ``history.npz`` (``history_c{i}.npz`` per candidate of a top-k run), then
    ``checkpoint.json`` (the search's ``state_dict``, the config, every ``IterationSummary``,
    the wall time, the segment count): the iteration is committed once that file is replaced;
  * ``ResultSink`` (critical): ``result.json`` with status ``running`` when opened and after
    every iteration, and with the run's final status on close. What it writes is what it has
    seen: an iteration interrupted before the sinks saw it is not in the document.
  * ``RunClock``: the run's wall time over all its segments.
Every write is atomic (``realize.run_dir``).
What it doesn't: build the result document (``realize.run_dir.build``; the caller passes a
``make_doc``), or decide the order of sinks (``realize.run.assembly``: checkpoint, then result).
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

from realize.run_dir.checkpoint import Checkpoint
from realize.run_dir.directory import RunDir
from realize.run_dir.history import History
from realize.run_dir.result_doc import ResultDoc
from realize.run_dir.summaries import IterationSummary
from realize.search.protocol import SearchReport
from realize.sinks.base import Iteration

__all__ = ["RunClock", "CheckpointSink", "ResultSink", "MakeDoc"]

# (status, error, the search's standing, every IterationSummary so far) -> result document
MakeDoc = Callable[[str, "str | None", SearchReport, Sequence[IterationSummary]], ResultDoc]


@dataclass
class RunClock:
    """Wall time of a run: ``before`` seconds of earlier segments plus this one's."""

    before: float = 0.0
    started: float = field(default_factory=time.perf_counter)

    def wall(self) -> float:
        return self.before + (time.perf_counter() - self.started)


class CheckpointSink:
    """History files and ``checkpoint.json`` (see the module docstring). ``histories`` maps a
    batch's candidate (``None`` for a single plan) to its ``History`` (restored ones included);
    ``records`` are the summaries already committed (a resumed run's)."""

    name = "checkpoint"
    critical = True
    wants_trajectories = False

    def __init__(self, run_dir: RunDir, histories: Mapping[int | None, History], records: Sequence[IterationSummary],
                 config: dict[str, Any], clock: RunClock, segments: int) -> None:
        self.rd, self.histories, self.records = run_dir, dict(histories), list(records)
        self.config, self.clock, self.segments = config, clock, segments

    def open(self) -> None:
        pass

    def on_iteration(self, it: Iteration) -> None:
        rec, res, c = it.record, it.rollout, it.batch.candidate
        h = self.histories[c]
        h.append(
            {
                "Z": rec.Z,
                "cost": rec.cost,
                "feasible": rec.feasible,
                "progress": rec.progress,
                "distance": rec.distance,
                "elite_idx": rec.elite_idx,
                "action_success": res.action_success,
                "goal": res.goal,
                "steps": res.steps,
                "share": rec.share,  # robust search only (None values are not stored)
                "screened_Z": rec.screened_Z,  # ce.screen only: draws rejected before simulation
                "world_cost": res.world_cost,
                "world_feasible": res.world_feasible,
            },
            n_envs=rec.n_envs,
            success_share=rec.success_share,
            best_cost=rec.best_cost,
            mean=rec.mean,
            std=rec.std,
            weights=rec.weights,
        )
        records = self.records + [it.summary]
        self.rd.write_history(h, candidate=c)
        # the commit point of the iteration
        self.rd.write_checkpoint(Checkpoint(len(records), it.state, self.config, records, self.clock.wall(),
                                            self.segments))
        self.records = records

    def close(self, status: str | None, error: str | None) -> None:
        pass


class ResultSink:
    """``result.json`` (see the module docstring); ``make_doc`` builds the document from what
    this sink has seen: the last ``SearchReport`` and every summary (``records``: a resumed
    run's committed ones first)."""

    name = "result file"
    critical = True
    wants_trajectories = False

    def __init__(self, run_dir: RunDir, make_doc: MakeDoc, report: SearchReport,
                 records: Sequence[IterationSummary]) -> None:
        self.rd, self.make_doc = run_dir, make_doc
        self.report, self.records = report, list(records)

    def write(self, status: str, error: str | None = None) -> None:
        self.rd.write_result(self.make_doc(status, error, self.report, self.records))

    def open(self) -> None:
        self.write("running")

    def on_iteration(self, it: Iteration) -> None:
        self.records.append(it.summary)
        self.report = it.report
        self.write("running")

    def close(self, status: str | None, error: str | None) -> None:
        if status is not None:
            self.write(status, error)
