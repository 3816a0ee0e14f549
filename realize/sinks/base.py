"""The sink protocol, the event a sink receives, and the one place where a failing sink is handled.

What it does:
  * ``Iteration``: one finished iteration as the sinks see it: the batch (samples, candidate,
    the distribution they were drawn from), the search's record, the rollout result, the
    iteration's ``IterationSummary``, the search's standing (``SearchReport``) and its
    ``state_dict()``, all taken right after ``tell``;
  * ``Sink``: ``open()`` before the scene is built, ``on_iteration(it)`` after every iteration,
    ``close(status, error)`` at the end (``status`` is the run's final one: done | interrupted |
    failed; ``None`` when the sink is dropped mid-run). ``name`` names it in messages;
    ``critical`` sinks (result file, checkpoint) fail the run when they fail; the others are
    logged, dropped, and the search goes on. ``wants_trajectories``: the rollout records
    trajectories only if a sink wants them;
  * ``SinkSet``: calls the sinks in order and applies that rule, in one place.
What it doesn't: know any file or format (the sink modules), or drive the search (``realize.run.loop``).
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any, Protocol

from realize.search.ce.state import IterationRecord
from realize.run_dir.summaries import IterationSummary
from realize.search.protocol import Batch, SearchReport

__all__ = ["Iteration", "Sink", "SinkSet", "SinkError"]

log = logging.getLogger("realize")


@dataclass
class Iteration:
    """One finished iteration (see the module docstring). ``index`` counts the run's iterations
    (all candidates, from 0; resumed runs go on counting); ``rollout`` is the evaluator's full
    result (``realize.realization.result.RolloutResult``)."""

    index: int
    batch: Batch
    record: IterationRecord
    rollout: Any
    summary: IterationSummary
    report: SearchReport
    state: dict[str, Any]


class Sink(Protocol):
    """What the loop calls (see the module docstring)."""

    name: str
    critical: bool
    wants_trajectories: bool

    def open(self) -> None: ...

    def on_iteration(self, it: Iteration) -> None: ...

    def close(self, status: str | None, error: str | None) -> None: ...


class SinkError(RuntimeError):
    """A critical sink (result file, checkpoint) failed: the run fails with this message."""


class SinkSet:
    """The run's sinks, called in order. A critical sink's exception becomes a ``SinkError``
    (the run fails); any other sink's is logged as a warning and that sink is closed and dropped.
    ``KeyboardInterrupt`` always goes through."""

    def __init__(self, sinks: Sequence[Sink]) -> None:
        self.active: list[Sink] = list(sinks)

    @property
    def wants_trajectories(self) -> bool:
        return any(getattr(s, "wants_trajectories", False) for s in self.active)

    def _call(self, sink: Sink, what: str, fn: Callable[[], None]) -> None:
        try:
            fn()
        except Exception as e:
            if sink.critical:
                raise SinkError(f"the {sink.name} failed {what} ({type(e).__name__}: {e})") from e
            log.warning("the %s failed %s (%s: %s); it stops, the search goes on", sink.name, what,
                        type(e).__name__, e)
            self.active.remove(sink)
            try:
                sink.close(None, None)
            except Exception:
                pass

    def open(self) -> None:
        for s in list(self.active):
            self._call(s, "to open", s.open)

    def on_iteration(self, it: Iteration) -> None:
        for s in list(self.active):
            self._call(s, f"at iteration {it.index}", lambda s=s: s.on_iteration(it))

    def close(self, status: str, error: str | None = None) -> None:
        """The end of the run: every sink's ``close`` (the result file's final write among them),
        all of them even if a critical one fails (its ``SinkError`` is raised afterwards)."""
        failed: SinkError | None = None
        for s in list(self.active):
            try:
                self._call(s, "to close", lambda s=s: s.close(status, error))
            except SinkError as e:
                failed = failed or e
        if failed is not None:
            raise failed
