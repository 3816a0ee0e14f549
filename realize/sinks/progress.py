"""The progress bar as a sink: one tqdm step per iteration, with its success share and best cost.

What it does: ``ProgressSink`` shows ``iterations done / planned`` on stderr; the postfix says
the iteration's success share (with ``ce.prune``, how many rows were stopped as they could not be
an elite: they count as not succeeded) and the best feasible cost so far of the plan searched (for
a top-k run also which candidate ran, in which halving round; for a stitched run which segment).
Off with ``logging.progress=false``.
Not critical.
What it doesn't: log anything else (``logging`` does).
"""

from __future__ import annotations

import math
import sys
from collections.abc import Mapping
from typing import Any

from realize.sinks.base import Iteration

__all__ = ["ProgressSink"]


class ProgressSink:
    """A tqdm bar of ``total`` iterations starting at ``initial`` (see the module docstring)."""

    name = "progress bar"
    critical = False
    wants_trajectories = False

    def __init__(self, total: int, initial: int = 0, desc: str = "CE", enabled: bool = True,
                 labels: Mapping[int | None, str] | None = None) -> None:
        self.total, self.initial, self.desc, self.enabled = total, initial, desc, enabled
        self.labels = labels  # a stitched search's: each batch's segment by its candidate key
        self.bar: Any = None

    def open(self) -> None:
        from tqdm import tqdm

        self.bar = tqdm(total=self.total, initial=self.initial, desc=self.desc, unit="it", dynamic_ncols=True,
                        disable=not self.enabled, file=sys.stderr)

    def on_iteration(self, it: Iteration) -> None:
        rec = it.record
        c = it.batch.candidate
        if self.labels:
            where = f"{self.labels[c]}, "
        else:
            where = "" if c is None else f"candidate {c} (round {it.report.round}), "
        cost = f"{rec.best_cost:.0f}" if math.isfinite(rec.best_cost) else "-"
        stopped = ""
        if rec.n_stopped:  # ce.prune: the share among the rows that finished too
            finished = rec.n_envs - rec.n_stopped
            share = f" of all, {rec.n_feasible / finished:.0%} of the {finished} that finished" if finished else ""
            stopped = f"{share} ({rec.n_stopped} stopped: could not be an elite)"
        screened = f", {rec.n_screened} screened out" if rec.n_screened else ""
        self.bar.set_postfix_str(f"{where}success {rec.success_share:.0%}{stopped}{screened}, best cost {cost}")
        self.bar.update(1)

    def close(self, status: str | None, error: str | None) -> None:
        if self.bar is not None:
            self.bar.close()
            self.bar = None
