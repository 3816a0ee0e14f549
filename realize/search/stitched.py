"""Stitched segments (issue 35, lever 3): a plan searched as two segments realized side by side.

The seed paper's "next step": break a plan into smaller action sequences that are simulated
in parallel and stitched together. Here a plan is cut before action ``split`` (for the seed
task after the grasp): the prefix (actions ``0 .. split - 1``) and the suffix (``split ..``).

What it does: ``StitchedSearch.run(evaluate)``, per iteration,
  * draws ``n_prefix`` prefix samples from the prefix's own cross-entropy search
    (``CrossEntropyOptimizer`` over the prefix's columns, ranked by the prefix's cost) and
    realizes them from the task's start; each feasible one's end state joins a pool of the
    ``pool`` cheapest prefixes found so far (its columns, its cost, its state);
  * from iteration 1 on (the pool is empty before), draws ``n_suffix`` suffix samples from the
    suffix's search and realizes sample i from pool entry ``i mod len(pool)``'s end state; the
    suffix's search ranks them by the suffix's own cost (so pruning a suffix row by its own cost
    is exact), and every feasible suffix row is a stitched plan of cost prefix + suffix;
  * at the end, the ``confirm`` cheapest stitched plans are realized whole, from the task's start
    (``"full"``), and the cheapest confirmed one is returned: a stitched cost is a guess (a
    restored state starts at rest, its contacts made anew), the confirmed cost is the plan's.
``evaluate(segment, Z, starts)`` (``segment``: "prefix" | "suffix" | "full"; ``starts``: one
start state per row, or None) returns an ``EvalResult`` and, for the prefix, the rows' end
states (None where infeasible); the states are opaque here.

What it doesn't: simulate or capture states (``realize.app.stitched``), pick the split, keep a
checkpoint, or rank a prefix by the suffixes it allows (a cheaper grasp that makes the place
dearer still wins its pool place; the confirmation sees the sum).
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import torch
from torch import Tensor

from realize.search.ce.config import CEConfig
from realize.search.ce.optimizer import CrossEntropyOptimizer
from realize.search.protocol import EvalResult
from realize.tasks.param_layout import ParamLayout

__all__ = ["StitchConfig", "StitchedIteration", "StitchedResult", "StitchedSearch", "SegmentEvaluator"]

# (segment, Z, starts) -> (result, end states of the rows or None)
SegmentEvaluator = Callable[[str, Tensor, "Sequence[Any] | None"], "tuple[EvalResult, list[Any] | None]"]


@dataclass(frozen=True)
class StitchConfig:
    """The stitched search's budget: samples per segment and iteration, the prefix pool, and how
    many stitched plans are confirmed whole."""

    n_prefix: int = 100
    n_suffix: int = 100
    iterations: int = 10
    pool: int = 10
    confirm: int = 10

    def __post_init__(self) -> None:
        for name in ("n_prefix", "n_suffix", "iterations", "pool", "confirm"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int) or v < 1:
                raise ValueError(f"stitch.{name} = {v!r} is invalid: expected an integer >= 1")
        if self.iterations < 2:
            raise ValueError("stitch.iterations must be >= 2: the suffix starts from the prefixes of iteration 0")


@dataclass
class StitchedIteration:
    """One iteration: rows and feasible rows per segment, the pool's size, the cheapest
    stitched cost so far, and the seconds spent realizing each segment."""

    iteration: int
    prefix_rows: int
    prefix_feasible: int
    suffix_rows: int
    suffix_feasible: int
    pool: int
    best_stitched: float
    prefix_s: float
    suffix_s: float


@dataclass
class StitchedResult:
    """The returned plan (``z``, full layout; None if no stitched plan confirmed feasible), its
    confirmed cost, the stitched cost it was chosen by, every confirmed plan's costs, the history
    and the seconds of the search (``search_s``, confirmation included) and of the confirmation."""

    z: Tensor | None
    cost: float
    stitched_cost: float
    confirmed: list[tuple[float, float, bool]] = field(default_factory=list)  # (stitched, confirmed, feasible)
    candidates: Tensor | None = None  # (len(confirmed), D) the confirmed plans, in ``confirmed``'s order
    history: list[StitchedIteration] = field(default_factory=list)
    search_s: float = 0.0
    confirm_s: float = 0.0
    samples: int = 0
    row_steps: int = 0  # control steps summed over every simulated row (filled by the caller that simulates)
    batch_steps: int = 0  # and over every call, of the call's longest row (each worker's shards end to end)

    @property
    def feasible(self) -> bool:
        return self.z is not None


class StitchedSearch:
    """Cross-entropy search over a plan cut into a prefix and a suffix (module docstring).

    ``prefix_cols`` and ``suffix_cols``: the full layout's columns of the prefix's and the
    suffix's layouts, in their order (disjoint; together every column of ``layout``)."""

    def __init__(self, layout: ParamLayout, prefix: ParamLayout, suffix: ParamLayout, prefix_cols: Sequence[int],
                 suffix_cols: Sequence[int], ce: CEConfig, cfg: StitchConfig) -> None:
        cols = list(prefix_cols) + list(suffix_cols)
        if sorted(cols) != list(range(layout.dim)) or len(prefix_cols) != prefix.dim or len(suffix_cols) != suffix.dim:
            raise ValueError(f"prefix columns {list(prefix_cols)} and suffix columns {list(suffix_cols)} must split "
                             f"the plan's {layout.dim} columns between its two segments")
        self.layout, self.cfg = layout, cfg
        self.prefix_cols, self.suffix_cols = torch.tensor(prefix_cols), torch.tensor(suffix_cols)
        one = dict(keep_elites=False, patience=None, screen=False, schedule="constant", n_envs_end=None)
        self.pre = CrossEntropyOptimizer(prefix, dataclasses.replace(ce, n_envs=cfg.n_prefix, iterations=cfg.iterations,
                                                                     **one))
        self.suf = CrossEntropyOptimizer(suffix, dataclasses.replace(ce, n_envs=cfg.n_suffix, seed=ce.seed + 1,
                                                                     iterations=cfg.iterations - 1, **one))
        self.pool_z = torch.zeros(0, prefix.dim, dtype=ce.torch_dtype)
        self.pool_cost = torch.zeros(0, dtype=ce.torch_dtype)
        self.pool_state: list[Any] = []
        # every feasible stitched plan: (stitched cost, prefix columns, suffix columns)
        self.stitched: list[tuple[float, Tensor, Tensor]] = []

    def _join(self, zp: Tensor, zs: Tensor) -> Tensor:
        z = torch.empty(zp.shape[0], self.layout.dim, dtype=zp.dtype)
        z[:, self.prefix_cols] = zp
        z[:, self.suffix_cols] = zs.to(zp.dtype)
        return z

    def _add_to_pool(self, Z: Tensor, r: EvalResult, ends: list[Any] | None) -> None:
        """The ``pool`` cheapest feasible prefixes so far (ties: the older first, then row order)."""
        ok = torch.nonzero(r.feasible).flatten()
        if ends is None and len(ok):
            raise ValueError("the prefix's evaluation returned no end states")
        z = torch.cat([self.pool_z, Z[ok].to(self.pool_z.dtype)])
        cost = torch.cat([self.pool_cost, r.cost[ok].to(self.pool_cost.dtype)])
        states = self.pool_state + [ends[i] for i in ok.tolist()] if len(ok) else self.pool_state
        keep = torch.sort(cost, stable=True).indices[:self.cfg.pool]
        self.pool_z, self.pool_cost = z[keep], cost[keep]
        self.pool_state = [states[i] for i in keep.tolist()]

    def _suffix_step(self, evaluate: SegmentEvaluator) -> tuple[int, int, float]:
        batch = self.suf.ask()
        assert batch is not None
        n = batch.Z.shape[0]
        src = torch.arange(n) % len(self.pool_state)
        t0 = time.perf_counter()
        r, _ = evaluate("suffix", batch.Z, [self.pool_state[i] for i in src.tolist()])
        dt = time.perf_counter() - t0
        r = r.to_cpu(n, self.pool_cost.dtype)
        self.suf.tell(r, eval_time=dt)
        total = r.cost + self.pool_cost[src]
        for i in torch.nonzero(r.feasible).flatten().tolist():
            self.stitched.append((float(total[i]), self.pool_z[src[i]].clone(), batch.Z[i].detach().cpu().clone()))
        return n, int(r.feasible.sum()), dt

    def run(self, evaluate: SegmentEvaluator,
            on_iteration: Callable[[StitchedIteration], None] | None = None) -> StitchedResult:
        """Search, then confirm the cheapest stitched plans whole (module docstring)."""
        t_start = time.perf_counter()
        history: list[StitchedIteration] = []
        samples = 0
        for it in range(self.cfg.iterations):
            batch = self.pre.ask()
            assert batch is not None
            t0 = time.perf_counter()
            r, ends = evaluate("prefix", batch.Z, None)
            dt_p = time.perf_counter() - t0
            r = r.to_cpu(batch.Z.shape[0], self.pool_cost.dtype)
            self.pre.tell(r, eval_time=dt_p)
            n_s = f_s = 0
            dt_s = 0.0
            if self.pool_state and not self.suf.done:  # the suffix starts from earlier iterations' prefixes
                n_s, f_s, dt_s = self._suffix_step(evaluate)
            self._add_to_pool(batch.Z.detach().cpu(), r, ends)
            samples += batch.Z.shape[0] + n_s
            best = min((c for c, _, _ in self.stitched), default=math.inf)
            rec = StitchedIteration(it, batch.Z.shape[0], int(r.feasible.sum()), n_s, f_s, len(self.pool_state),
                                    best, dt_p, dt_s)
            history.append(rec)
            if on_iteration is not None:
                on_iteration(rec)
        out = self.confirm(evaluate)
        out.history, out.samples = history, samples + len(out.confirmed)
        out.search_s = time.perf_counter() - t_start
        return out

    def confirm(self, evaluate: SegmentEvaluator) -> StitchedResult:
        """Realize the ``confirm`` cheapest stitched plans whole; the cheapest feasible one wins
        (ties: the cheaper stitched cost, then the order found)."""
        ranked = sorted(range(len(self.stitched)), key=lambda i: (self.stitched[i][0], i))[:self.cfg.confirm]
        if not ranked:
            return StitchedResult(None, math.inf, math.inf)
        Z = torch.cat([self._join(self.stitched[i][1][None], self.stitched[i][2][None]) for i in ranked])
        t0 = time.perf_counter()
        r, _ = evaluate("full", Z, None)
        dt = time.perf_counter() - t0
        r = r.to_cpu(Z.shape[0], Z.dtype)
        confirmed = [(self.stitched[i][0], float(r.cost[k]), bool(r.feasible[k])) for k, i in enumerate(ranked)]
        ok = [k for k in range(len(ranked)) if confirmed[k][2]]
        if not ok:
            return StitchedResult(None, math.inf, math.inf, confirmed, Z, confirm_s=dt)
        k = min(ok, key=lambda k: (confirmed[k][1], confirmed[k][0], k))
        return StitchedResult(Z[k].clone(), confirmed[k][1], confirmed[k][0], confirmed, Z, confirm_s=dt)
