"""The one search loop: ask a batch, realize it in the scene, tell the result, hand it to the sinks.

What it does: ``search_loop`` drives any ``realize.search.protocol.Searcher`` (one CE search, or
successive halving over candidate plans; it does not know which) to its end:

    open the sinks -> open the rollout workers -> while searcher.ask() gives a batch:
    rollout on the batch's plan -> searcher.tell -> sinks.on_iteration -> after_iteration hook

inside a ``realize.run.guard.RunGuard`` (signals -> interrupted status, failures -> error.txt, the
sinks' final ``close`` shielded from a second Ctrl-C, then the workers closed). It returns the
guard (``status``, ``exit_code``) and the count of iterations every sink has seen.
What it doesn't: choose the searcher, the sinks or the files (``realize.run.assembly``), or sample,
rank and simulate itself.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from realize.run.guard import RunGuard, RunSignals
from realize.search.protocol import Searcher
from realize.sinks.base import Iteration, SinkSet

__all__ = ["search_loop", "LoopEnd"]

# () -> the run's rollout workers (realize.workers.pool.RolloutPool): rollout(candidate, Z, record), close()
OpenPool = Callable[[], Any]


class LoopEnd:
    """How the loop ended: ``status`` (done | interrupted), ``exit_code`` (0, 130, 143) and
    ``iterations`` (the run's complete iterations, a resumed run's earlier ones included)."""

    def __init__(self, status: str, exit_code: int, iterations: int, stopped: bool = False) -> None:
        self.status, self.exit_code, self.iterations = status, exit_code, iterations
        self.stopped = stopped  # ended by ``until`` before the searcher was done


def search_loop(searcher: Searcher, sinks: SinkSet, open_pool: OpenPool, *, error_file: Path | None = None,
                after_iteration: Callable[[int], None] | None = None, keep_pool: bool = False,
                until: Callable[[Iteration], bool] | None = None) -> LoopEnd:
    """Run ``searcher`` to its end (see the module docstring). ``after_iteration(i)`` is called
    once iteration ``i`` (counted over the whole run) has passed every sink; a failure other
    than an interrupt is re-raised after the sinks closed with status ``failed``. ``until(it)``
    true after an iteration ends the search there (a replan that has its plan: ``LoopEnd.stopped``).
    With ``keep_pool`` the workers stay open for the caller (``realize.run.planner``, which
    closes them), else the loop closes them."""
    done = [searcher.iterations_done]
    stopped = [False]
    pools: list[Any] = []

    def close_pool() -> None:
        for p in pools:
            try:
                p.close()
            except Exception:  # pragma: no cover
                pass

    guard = RunGuard(lambda: done[0], sinks.close, close_pool, error_file)
    with guard:
        with RunSignals():
            sinks.open()
            pool = open_pool()
            if not keep_pool:
                pools.append(pool)
            record = sinks.wants_trajectories
            while (batch := searcher.ask()) is not None:
                t0 = time.perf_counter()
                segment = {} if batch.starts is None and not batch.capture_end else \
                    {"starts": batch.starts, "capture_end": batch.capture_end}  # a stitched search's segment
                res = pool.rollout(batch.candidate, batch.Z, record=record, **segment)
                t_eval = time.perf_counter() - t0
                rec = searcher.tell(res.to_eval(), eval_time=t_eval)
                it = Iteration(done[0], batch, rec, res, rec.summary(batch.candidate), searcher.report(),
                               searcher.state_dict())
                sinks.on_iteration(it)
                done[0] += 1
                if after_iteration is not None:
                    after_iteration(it.index)
                if until is not None and not searcher.done and until(it):
                    stopped[0] = True
                    break
    return LoopEnd(guard.status, guard.exit_code, done[0], stopped[0])
