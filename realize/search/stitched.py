"""Stitched segments (issue 35, lever 3): a plan searched as two segments realized side by side.

The seed paper's "next step": break a plan into smaller action sequences that are simulated
in parallel and stitched together. Here a plan is cut before action ``split`` (for the seed
task after the grasp): the prefix (actions ``0 .. split - 1``) and the suffix (``split ..``).

What it does: ``StitchedSearch`` is an ask/tell ``realize.search.protocol.Searcher`` whose
batches are segments (``Batch.candidate``: ``PREFIX``, ``SUFFIX``, or ``None`` for the whole
plan). Each of ``iterations`` rounds:
  * a prefix batch: ``n_prefix`` samples of the prefix's own cross-entropy search
    (``CrossEntropyOptimizer`` over the prefix's columns, ranked by the prefix's cost), realized
    from the task's start with ``capture_end``;
  * from round 1 on, a suffix batch: ``n_suffix`` samples of the suffix's search, row i realized
    from pool entry ``i mod len(pool)``'s end state (``Batch.starts``), ranked by the suffix's own
    cost (so pruning a suffix row by its own cost is exact); every feasible suffix row is a
    stitched plan of cost prefix + suffix;
  * then the round's feasible prefixes join the pool of the ``pool`` cheapest prefixes found so
    far (their columns, costs and end states). The suffix of round r thus starts from rounds
    0 .. r - 1's prefixes. The last round's prefix batch feeds no suffix, and it is kept:
    dropping it (each round's suffix before its prefix, none in the last round) draws the same
    samples and pools for about 2 % fewer batch steps; measured while restores still depended on
    the scene's history, that moved their noise and seed 1 ended at 481, +11.6 %
    (docs/results.md, "Dropping the last prefix batch"). Restores are history-free now.
Then one confirmation batch: the ``confirm`` cheapest stitched plans realized whole from the
task's start (a third ``CrossEntropyOptimizer``, over the whole layout, ranks them:
``CrossEntropyOptimizer.give``); its best is the search's (``report().state``). A stitched cost is
a guess (a restored state starts at rest, its contacts made anew), the confirmed cost the plan's.
``run(evaluate)`` drives the same ask/tell without a run directory (the analytic tests).
``state_dict`` holds the three searches, the pool and the round's prefixes waiting to join it
(states through their ``to_json``; a ``read_state`` given to the constructor reads them back)
and the stitched plans kept.

Its budget is ``realize.search.segments.StitchConfig``.

What it doesn't: simulate or capture states (``realize.run.stitched_run``, ``realize.run.loop``),
pick the split, or rank a prefix by the suffixes it allows (a cheaper grasp that makes the place
dearer still wins its pool place; the confirmation sees the sum). The segments' searches run a
constant schedule without elite memory, screen or patience.
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import torch
from torch import Tensor

from realize.search.ce.config import CEConfig
from realize.search.ce.optimizer import CrossEntropyOptimizer
from realize.search.ce.state import IterationRecord
from realize.search.protocol import Batch, EvalResult, SearchReport
from realize.search.segments import SegmentEvaluator, StitchConfig
from realize.tasks.param_layout import ParamLayout

__all__ = ["StitchedIteration", "StitchedResult", "StitchedSearch", "PREFIX", "SUFFIX", "SEGMENT_NAMES",
           "STITCHED_KIND"]

PREFIX, SUFFIX = 1, 2  # a batch's candidate: the task index in the run's workers and the history key
SEGMENT_NAMES: dict[int | None, str] = {None: "full", PREFIX: "prefix", SUFFIX: "suffix"}
STITCHED_KIND = "stitched"  # the "kind" of its state_dict (a checkpoint's ce_state)

@dataclass
class StitchedIteration:
    """One round: rows and feasible rows per segment, the pool's size, the cheapest stitched
    cost so far, and the seconds spent realizing each segment."""

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

    @property
    def feasible(self) -> bool:
        return self.z is not None


def _state_json(s: Any) -> Any:
    return s.to_json() if hasattr(s, "to_json") else s


class StitchedSearch:
    """Cross-entropy search over a plan cut into a prefix and a suffix (module docstring).

    ``prefix_cols`` and ``suffix_cols``: the full layout's columns of the prefix's and the
    suffix's layouts, in their order (disjoint; together every column of ``layout``)."""

    def __init__(self, layout: ParamLayout, prefix: ParamLayout, suffix: ParamLayout, prefix_cols: Sequence[int],
                 suffix_cols: Sequence[int], ce: CEConfig, cfg: StitchConfig, device: torch.device | str | None = None,
                 read_state: Callable[[Any], Any] = lambda d: d) -> None:
        cols = list(prefix_cols) + list(suffix_cols)
        if sorted(cols) != list(range(layout.dim)) or len(prefix_cols) != prefix.dim or len(suffix_cols) != suffix.dim:
            raise ValueError(f"prefix columns {list(prefix_cols)} and suffix columns {list(suffix_cols)} must split "
                             f"the plan's {layout.dim} columns between its two segments")
        self.layout, self.cfg, self.read_state = layout, cfg, read_state
        self.prefix_cols, self.suffix_cols = torch.tensor(prefix_cols), torch.tensor(suffix_cols)
        one = dict(keep_elites=False, patience=None, screen=False, schedule="constant", n_envs_end=None,
                   iterations=cfg.iterations)

        def opt(lay: ParamLayout, n: int, seed: int, **kw: Any) -> CrossEntropyOptimizer:
            c = dataclasses.replace(ce, n_envs=n, n_elite=min(ce.n_elite, n), seed=seed, **{**one, **kw})
            return CrossEntropyOptimizer(lay, c, device=device)

        self.pre = opt(prefix, cfg.n_prefix, ce.seed)
        self.suf = opt(suffix, cfg.n_suffix, ce.seed + 1, iterations=cfg.iterations - 1)
        self.full = opt(layout, cfg.confirm, ce.seed + 2, iterations=1)
        self.dtype = ce.torch_dtype
        self.pool_z = torch.zeros(0, prefix.dim, dtype=self.dtype)
        self.pool_cost = torch.zeros(0, dtype=self.dtype)
        self.pool_state: list[Any] = []
        # the ``confirm`` cheapest feasible stitched plans so far: (stitched cost, prefix columns, suffix columns)
        self.stitched: list[tuple[float, Tensor, Tensor]] = []
        self.round, self.phase, self.batches = 0, "prefix", 0  # phase: prefix | suffix | confirm | done
        self._src: Tensor | None = None  # the pending suffix batch's pool entries
        self._Z: Tensor | None = None  # the pending batch's samples (CPU)
        # this round's feasible prefixes, which join the pool once the round's suffix has run
        self.fresh_z, self.fresh_cost, self.fresh_state = self.pool_z[:0], self.pool_cost[:0], []

    # ---- the Searcher protocol -------------------------------------------------------------

    @property
    def done(self) -> bool:
        return self.phase == "done"

    @property
    def iterations_done(self) -> int:
        return self.batches

    def ask(self) -> Batch | None:
        """The next segment's batch (``candidate``: PREFIX, SUFFIX or None for the confirmation)."""
        if self.phase == "prefix":
            b = self.pre.ask()
            assert b is not None
            b.candidate, b.capture_end = PREFIX, True
        elif self.phase == "suffix":
            b = self.suf.ask()
            assert b is not None
            self._src = torch.arange(b.Z.shape[0]) % len(self.pool_state)
            b.candidate, b.starts = SUFFIX, [self.pool_state[i] for i in self._src.tolist()]
        elif self.phase == "confirm":
            Z = torch.cat([self._join(zp[None], zs[None]) for _, zp, zs in self.stitched])
            self.full.give(Z)
            b = self.full.ask()
            assert b is not None
        else:
            return None
        self._Z = b.Z.detach().cpu()
        return b

    def tell(self, result: EvalResult, eval_time: float = math.nan) -> IterationRecord:
        """The evaluation of the last ``ask``'s batch (a prefix's with its ``end_states``)."""
        if self.phase in ("prefix", "suffix") and self._Z is None:
            raise RuntimeError("tell() called without a pending batch; call ask() first")
        if self.phase == "prefix":
            assert self._Z is not None
            rec = self.pre.tell(result, eval_time=eval_time)
            self._fresh(self._Z, result)
            if self.pool_state and not self.suf.done:  # the suffix starts from earlier rounds' prefixes
                self.phase = "suffix"
            else:
                self._join_fresh()
                self.phase = self._next_round()
        elif self.phase == "suffix":
            assert self._src is not None
            n = self._src.shape[0]
            r = result.to_cpu(n, self.dtype)
            rec = self.suf.tell(r, eval_time=eval_time)
            self._keep(r.cost + self.pool_cost[self._src], r.feasible)
            self._src = None
            self._join_fresh()
            self.phase = self._next_round()
        elif self.phase == "confirm":
            rec = self.full.tell(result, eval_time=eval_time)
            self.phase = "done"
        else:
            raise RuntimeError("tell() after the stitched search is done")
        self.batches += 1
        self._Z = None
        return rec

    def report(self) -> SearchReport:
        """The confirmation's standing (no best plan before the stitched plans are confirmed),
        with the two segments' distributions side by side as its ``mean``/``std`` once both have
        one (one normal each, ``ce.n_modes = 1``): what a warm start or a replan of the run
        starts from."""
        state, pre, suf = self.full.state, self.pre.state, self.suf.state
        if pre.mean is not None and suf.mean is not None and pre.mean.ndim == suf.mean.ndim == 1:
            assert pre.std is not None and suf.std is not None
            state.mean = self._join(pre.mean[None], suf.mean[None])[0]
            state.std = self._join(pre.std[None], suf.std[None])[0]
            state.weights = None
        return SearchReport(lead=None, state=state)

    def state_dict(self) -> dict[str, Any]:
        return {
            "kind": STITCHED_KIND, "round": self.round, "phase": self.phase, "batches": self.batches,
            "prefix": self.pre.state_dict(), "suffix": self.suf.state_dict(), "full": self.full.state_dict(),
            "pool": {"z": self.pool_z.tolist(), "cost": self.pool_cost.tolist(),
                     "states": [_state_json(s) for s in self.pool_state]},
            "fresh": {"z": self.fresh_z.tolist(), "cost": self.fresh_cost.tolist(),
                      "states": [_state_json(s) for s in self.fresh_state]},
            "stitched": [[c, zp.tolist(), zs.tolist()] for c, zp, zs in self.stitched],
        }

    def load_state_dict(self, d: Mapping[str, Any]) -> None:
        """Continue from ``state_dict()`` output; ``ValueError`` if it is not a stitched search's."""
        if d.get("kind") != STITCHED_KIND:
            raise ValueError(f"not a stitched search's state (kind {d.get('kind')!r})")
        try:
            self.pre.load_state_dict(d["prefix"])
            self.suf.load_state_dict(d["suffix"])
            self.full.load_state_dict(d["full"])
            self.pool_z, self.pool_cost, self.pool_state = self._prefix_rows(d["pool"])
            self.fresh_z, self.fresh_cost, self.fresh_state = self._prefix_rows(d["fresh"])
            self.stitched = [(float(c), torch.tensor(zp, dtype=self.dtype), torch.tensor(zs, dtype=self.dtype))
                             for c, zp, zs in d["stitched"]]
            self.round, self.phase, self.batches = int(d["round"]), str(d["phase"]), int(d["batches"])
        except (KeyError, TypeError, ValueError, RuntimeError) as e:
            raise ValueError(f"malformed stitched state ({type(e).__name__}: {e})") from None
        if self.phase not in ("prefix", "suffix", "confirm", "done") or not (
                len(self.pool_state) == len(self.pool_cost) == self.pool_z.shape[0]
                and len(self.fresh_state) == len(self.fresh_cost) == self.fresh_z.shape[0]):
            raise ValueError("malformed stitched state (phase / pool)")
        self._src = None

    def _prefix_rows(self, p: Mapping[str, Any]) -> tuple[Tensor, Tensor, list[Any]]:
        """A ``state_dict``'s pool (or waiting prefixes) back as columns, costs and states."""
        z = torch.tensor(p["z"], dtype=self.dtype).reshape(-1, self.pool_z.shape[1])
        return z, torch.tensor(p["cost"], dtype=self.dtype).reshape(-1), [self.read_state(x) for x in p["states"]]

    # ---- without a run directory -----------------------------------------------------------

    def run(self, evaluate: SegmentEvaluator,
            on_iteration: Callable[[StitchedIteration], None] | None = None) -> StitchedResult:
        """Ask/tell to the end with ``evaluate(segment, Z, starts)``; the confirmed plans and the
        rounds' history (module docstring)."""
        t_start = time.perf_counter()
        history: list[StitchedIteration] = []
        row: dict[str, Any] = {}
        samples, confirm_s = 0, 0.0
        confirmed: list[tuple[float, float, bool]] = []
        Zc: Tensor | None = None
        best = 0
        while (batch := self.ask()) is not None:
            seg, rnd = SEGMENT_NAMES[batch.candidate], self.round
            t0 = time.perf_counter()
            r, ends = evaluate(seg, batch.Z, batch.starts)
            dt = time.perf_counter() - t0
            r.end_states = ends
            rec = self.tell(r, eval_time=dt)
            samples += rec.n_envs
            if seg == "full":
                Zc, confirm_s, best = batch.Z.detach().cpu().clone(), dt, rec.best_idx
                confirmed = [(c, float(rec.cost[k]), bool(rec.feasible[k])) for k, (c, _, _) in enumerate(self.stitched)]
                continue
            row[seg] = (rec.n_envs, rec.n_feasible, dt)
            if self.round != rnd or self.done:  # the round ended
                (np_, fp, tp), (ns, fs, ts) = (row.get(k, (0, 0, 0.0)) for k in ("prefix", "suffix"))
                best = self.stitched[0][0] if self.stitched else math.inf
                history.append(StitchedIteration(rnd, np_, fp, ns, fs, len(self.pool_state), best, tp, ts))
                if on_iteration is not None:
                    on_iteration(history[-1])
                row = {}
        out = StitchedResult(None, math.inf, math.inf, confirmed, Zc, history, confirm_s=confirm_s, samples=samples)
        if Zc is not None and confirmed[best][2]:  # the confirmation's best row (its search's best_z)
            out.z, out.cost, out.stitched_cost = Zc[best].clone(), confirmed[best][1], confirmed[best][0]
        out.search_s = time.perf_counter() - t_start
        return out

    # ---- internals ---------------------------------------------------------------------------

    def _next_round(self) -> str:
        self.round += 1
        if self.round < self.cfg.iterations:
            return "prefix"
        return "confirm" if self.stitched else "done"

    def _join(self, zp: Tensor, zs: Tensor) -> Tensor:
        z = torch.empty(zp.shape[0], self.layout.dim, dtype=self.dtype)
        z[:, self.prefix_cols] = zp.to(self.dtype)
        z[:, self.suffix_cols] = zs.to(self.dtype)
        return z

    def _keep(self, total: Tensor, feasible: Tensor) -> None:
        """Keep the ``confirm`` cheapest stitched plans: the kept ones and the suffix batch's
        feasible rows (stitched cost ``total``), ties to the one found first."""
        assert self._Z is not None and self._src is not None
        ok = torch.nonzero(feasible).flatten()
        ok = ok[torch.sort(total[ok], stable=True).indices[:self.cfg.confirm]]  # only these can be kept
        new = [(float(total[i]), self.pool_z[self._src[i]].clone(), self._Z[i].to(self.dtype).clone())
               for i in ok.tolist()]
        self.stitched = sorted(self.stitched + new, key=lambda p: p[0])[:self.cfg.confirm]

    def _fresh(self, Z: Tensor, result: EvalResult) -> None:
        """This round's feasible prefixes: their columns, costs and end states."""
        r = result.to_cpu(Z.shape[0], self.dtype)
        ok = torch.nonzero(r.feasible).flatten()
        ends = result.end_states
        if ends is None and len(ok):
            raise ValueError("the prefix's evaluation returned no end states")
        self.fresh_z, self.fresh_cost = Z[ok].to(self.dtype), r.cost[ok]
        self.fresh_state = [ends[i] for i in ok.tolist()] if ends is not None else []

    def _join_fresh(self) -> None:
        """The ``pool`` cheapest feasible prefixes so far (ties: the older first, then row order)."""
        z, cost = torch.cat([self.pool_z, self.fresh_z]), torch.cat([self.pool_cost, self.fresh_cost])
        states = self.pool_state + self.fresh_state
        keep = torch.sort(cost, stable=True).indices[:self.cfg.pool]
        self.pool_z, self.pool_cost = z[keep], cost[keep]
        self.pool_state = [states[i] for i in keep.tolist()]
        self.fresh_z, self.fresh_cost, self.fresh_state = self.fresh_z[:0], self.fresh_cost[:0], []
