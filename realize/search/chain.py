"""Stitched segments (issues 35, 57): a plan cut into K >= 2 segments, each with its own CE search.

What it does: ``ChainSearch`` is the ask/tell ``realize.search.protocol.Searcher`` of every
stitched search (``realize.search.segments.StitchConfig``): one cut is its two-segment case (a
prefix and a suffix), more cuts a longer chain. Segment j (0-based) has its own
``CrossEntropyOptimizer`` over its columns (``n_prefix`` rows for segment 0, ``n_suffix`` for
each later one; seed ``ce.seed + j``; ``iterations - j`` rounds). Each round r:
  * segment 0's batch, realized from the task's start, the rows' end states captured;
  * then, in order, each later segment j whose start pool is not empty: row i starts from entry
    ``i mod len(pool)`` of pool j-1 (``Batch.starts``), ranked by its own cost (so pruning a row
    by its own cost is exact); a segment before the last has its rows' end states captured too;
  * then the round's feasible rows join their segment's pool: the ``pool`` cheapest feasible
    partial plans through that segment so far, by cumulative cost (their columns, costs, end
    states; ties to the older, then row order). Segment j of round r thus starts from rows of
    rounds before r; it first runs in round j, so a chain needs ``iterations >= K``. The last
    round's first batch feeds no later segment and is kept (docs/results.md, "Dropping the
    last prefix batch").
Every feasible row of the last segment is a stitched plan (cost: its segments' costs summed);
the ``confirm`` cheapest are realized whole from the task's start at the end (a
``CrossEntropyOptimizer`` over the whole layout, seed ``ce.seed + K``, ranks them:
``CrossEntropyOptimizer.give``); its best is the search's (``report().state``). A stitched cost
is a guess (a restored state starts at rest, its contacts made anew), the confirmed cost the plan's.
A search of two segments without credit draws, ranks and returns bit for bit what the one-cut
search before the chain did (the golden run ``seed_paper_default``, ``tests/golden_runs.py``).

Credit (``credit = c > 0``): a later segment's failures reach the earlier segment's elites.
  * A pool entry counts the rows started from it (tries) and those that ended feasible (wins);
    once a feasible child is itself dropped as dead, its win is taken back from its parent.
  * An entry with at least ``c`` tries and no win is dead: it leaves the pool (no more rows
    start from it), and its own columns are remembered with that verdict (an entry with ``c``
    tries and a win is remembered as alive).
  * A new row of that segment whose nearest remembered entry (in the segment's normalized
    columns, each region's box -> [0, 1]) is dead and no farther than ``credit_radius`` is
    doomed: its segment's CE ranks it after every feasible row that is not
    (``EvalResult.share`` 0 against 1), and the pool ranks it after every entry that is not.
So a segment whose successors keep failing from one mode of it refits on its other rows. A
doomed row is still realized, kept and tried downstream: the verdict is a guess from neighbours.
``run(evaluate)`` drives the same ask/tell without a run directory (the analytic tests).
``state_dict`` holds the segments' and the confirmation's searches, the pools and the round's
rows waiting to join them (states through their ``to_json``; a ``read_state`` given to the
constructor reads them back), the credit's verdicts and the stitched plans kept; a one-cut
run's state from before the chain ran it loads too (``realize.search.segments.stitched_as_chain``).

What it doesn't: simulate or capture states (``realize.run.stitched_run``), choose the cuts
(``realize.tasks.split``), rank a row by the later segments it allows (without credit, a
cheaper grasp that makes the place dearer still wins its pool place; the confirmation sees the
sum), or let a segment's rows depend on the predecessor's columns: each segment's CE is one
distribution over its own columns, whatever row its start came from. The segments' searches
run a constant schedule without elite memory, screen or patience.
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
from realize.search.chain_pool import Pool
from realize.search.protocol import Batch, EvalResult, SearchReport
from realize.search.segments import CHAIN_KIND, STITCHED_KIND, SegmentEvaluator, StitchConfig, chain_names, \
    stitched_as_chain
from realize.tasks.param_layout import ParamLayout

__all__ = ["ChainSearch", "ChainIteration", "ChainResult", "CHAIN_KIND"]


@dataclass
class ChainIteration:
    """One round: per segment its rows, feasible rows and seconds (0 where it did not run), the
    pools' sizes after the round, the entries dropped as dead in it, the cheapest stitched cost
    so far."""

    iteration: int
    rows: list[int]
    feasible: list[int]
    seconds: list[float]
    pools: list[int]
    dead: int
    best_stitched: float


@dataclass
class ChainResult:
    """The returned plan (``z``, full layout; None if no stitched plan confirmed feasible), its
    confirmed cost, the stitched cost it was chosen by, every confirmed plan's costs and the
    plans, the rounds, and the seconds of the search (confirmation included), of the
    confirmation and of each segment's batches (``segment_s``)."""

    z: Tensor | None
    cost: float
    stitched_cost: float
    confirmed: list[tuple[float, float, bool]] = field(default_factory=list)  # (stitched, confirmed, feasible)
    candidates: Tensor | None = None  # (len(confirmed), D) the confirmed plans, in ``confirmed``'s order
    history: list[ChainIteration] = field(default_factory=list)
    search_s: float = 0.0
    confirm_s: float = 0.0
    segment_s: list[float] = field(default_factory=list)
    samples: int = 0

    @property
    def feasible(self) -> bool:
        return self.z is not None


class ChainSearch:
    """Cross-entropy search over a plan cut into ``len(segments)`` segments (module docstring).

    ``cols[j]``: the full layout's columns of segment j's layout, in its order (disjoint;
    together every column of ``layout``)."""

    def __init__(self, layout: ParamLayout, segments: Sequence[ParamLayout], cols: Sequence[Sequence[int]],
                 ce: CEConfig, cfg: StitchConfig, device: torch.device | str | None = None,
                 read_state: Callable[[Any], Any] = lambda d: d) -> None:
        k = len(segments)
        flat = [c for cs in cols for c in cs]
        if k < 2 or len(cols) != k or sorted(flat) != list(range(layout.dim)) or \
                any(len(c) != s.dim for c, s in zip(cols, segments)):
            raise ValueError(f"segment columns {[list(c) for c in cols]} must split the plan's {layout.dim} columns "
                             "between its (at least two) segments")
        if cfg.iterations < k:
            raise ValueError(f"ce.iterations = {cfg.iterations}: a chain of {k} segments needs at least {k} rounds "
                             "(segment j first runs in round j)")
        self.layout, self.cfg, self.read_state, self.k = layout, cfg, read_state, k
        self.order = torch.tensor(flat)  # chain order (segment 0's columns, then segment 1's, ...) -> layout
        dims = [s.dim for s in segments]
        self.offsets = [sum(dims[:j]) for j in range(k + 1)]
        one = dict(keep_elites=False, patience=None, screen=False, schedule="constant", n_envs_end=None)

        def opt(lay: ParamLayout, n: int, seed: int, iterations: int) -> CrossEntropyOptimizer:
            c = dataclasses.replace(ce, n_envs=n, n_elite=min(ce.n_elite, n), seed=seed, iterations=iterations, **one)
            return CrossEntropyOptimizer(lay, c, device=device)

        self.opts = [opt(s, cfg.n_prefix if j == 0 else cfg.n_suffix, ce.seed + j, cfg.iterations - j)
                     for j, s in enumerate(segments)]
        self.full = opt(layout, cfg.confirm, ce.seed + k, 1)
        self.dtype = ce.torch_dtype
        # pools[j] / fresh[j]: feasible partial plans through segment j (j < K - 1), kept / of this round
        self.pools = [Pool.empty(self.offsets[j + 1], self.dtype) for j in range(k - 1)]
        self.fresh = [Pool.empty(self.offsets[j + 1], self.dtype) for j in range(k - 1)]
        # credit's verdicts per segment (j < K - 1): entry id -> (its own columns, normalized; dead)
        self.known: list[dict[int, tuple[list[float], bool]]] = [{} for _ in range(k - 1)]
        self.next_id = 0
        self.dead_total = 0
        # the ``confirm`` cheapest feasible stitched plans so far: (stitched cost, columns in chain order)
        self.stitched: list[tuple[float, Tensor]] = []
        self.round, self.phase, self.batches = 0, 0, 0  # phase: a segment index, "confirm" or "done"
        self._src: Tensor | None = None  # the pending batch's start pool entries
        self._Z: Tensor | None = None  # the pending batch's samples (CPU)

    # ---- the Searcher protocol -------------------------------------------------------------

    @property
    def done(self) -> bool:
        return self.phase == "done"

    @property
    def iterations_done(self) -> int:
        return self.batches

    def ask(self) -> Batch | None:
        """The next batch (``candidate``: segment j's is j + 1; None for the confirmation)."""
        if isinstance(self.phase, int):
            j = self.phase
            b = self.opts[j].ask()
            assert b is not None
            b.candidate, b.capture_end = j + 1, j < self.k - 1
            if j > 0:
                pool = self.pools[j - 1]
                self._src = torch.arange(b.Z.shape[0]) % len(pool)
                b.starts = [pool.states[i] for i in self._src.tolist()]
        elif self.phase == "confirm":
            self.full.give(self._join(torch.stack([z for _, z in self.stitched])))
            b = self.full.ask()
            assert b is not None
        else:
            return None
        self._Z = b.Z.detach().cpu()
        return b

    def tell(self, result: EvalResult, eval_time: float = math.nan) -> IterationRecord:
        """The evaluation of the last ``ask``'s batch (with ``end_states`` before the last segment)."""
        if self.phase == "done":
            raise RuntimeError("tell() after the stitched search is done")
        if self.phase == "confirm":
            rec = self.full.tell(result, eval_time=eval_time)
            self.phase = "done"
        else:
            if self._Z is None:
                raise RuntimeError("tell() called without a pending batch; call ask() first")
            j = int(self.phase)
            Z = self._Z.to(self.dtype)
            r = result.to_cpu(Z.shape[0], self.dtype)
            doomed = self._doomed(j, Z)
            if bool(doomed.any()):  # credit: ranked after the rows that are not (module docstring)
                r.share = (r.feasible & ~doomed).to(self.dtype)
            rec = self.opts[j].tell(r, eval_time=eval_time)
            rec.success_share = rec.n_feasible / rec.n_envs  # (the record's, not the share credit ranked by)
            src = self._src
            base_z, base_cost, parent = (Z[:, :0], torch.zeros_like(r.cost), torch.full((Z.shape[0],), -1)) \
                if src is None else (self.pools[j - 1].z[src], self.pools[j - 1].cost[src], self.pools[j - 1].ids[src])
            total = r.cost + base_cost
            if j < self.k - 1:
                self._fresh(j, torch.cat([base_z, Z], 1), total, r.feasible, result.end_states, parent, doomed)
            else:
                self._keep(torch.cat([base_z, Z], 1), total, r.feasible)
            if src is not None:
                self._credit(j - 1, src, r.feasible)
            self._src = None
            self.phase = self._next(j)
        self.batches += 1
        self._Z = None
        return rec

    def report(self) -> SearchReport:
        """The confirmation's standing, with the segments' distributions side by side as its
        ``mean``/``std`` once each has one (one normal each): what a warm start starts from."""
        state, parts = self.full.state, [o.state for o in self.opts]
        if all(p.mean is not None and p.std is not None and p.mean.ndim == 1 for p in parts):
            state.mean = self._join(torch.cat([p.mean for p in parts])[None])[0]  # type: ignore[misc]
            state.std = self._join(torch.cat([p.std for p in parts])[None])[0]  # type: ignore[misc]
            state.weights = None
        return SearchReport(lead=None, state=state)

    def state_dict(self) -> dict[str, Any]:
        return {
            "kind": CHAIN_KIND, "round": self.round, "phase": self.phase, "batches": self.batches,
            "segments": [o.state_dict() for o in self.opts], "full": self.full.state_dict(),
            "pools": [p.to_json() for p in self.pools], "fresh": [p.to_json() for p in self.fresh],
            "known": [[[i, z, d] for i, (z, d) in kn.items()] for kn in self.known],
            "next_id": self.next_id, "dead_total": self.dead_total,
            "stitched": [[c, z.tolist()] for c, z in self.stitched],
        }

    def load_state_dict(self, d: Mapping[str, Any]) -> None:
        """Continue from ``state_dict()`` output (or, with two segments, a one-cut run's older state:
        ``stitched_as_chain``); ``ValueError`` if it is not this chain's state."""
        if d.get("kind") == STITCHED_KIND and self.k == 2:
            d = stitched_as_chain(d)
        if d.get("kind") != CHAIN_KIND:
            raise ValueError(f"not a stitched chain's state (kind {d.get('kind')!r})")
        try:
            if len(d["segments"]) != self.k or len(d["pools"]) != self.k - 1:
                raise ValueError(f"{len(d['segments'])} segments, expected {self.k}")
            for o, s in zip(self.opts, d["segments"]):
                o.load_state_dict(s)
            self.full.load_state_dict(d["full"])
            self.pools = [Pool.from_json(p, self.offsets[j + 1], self.dtype, self.read_state)
                          for j, p in enumerate(d["pools"])]
            self.fresh = [Pool.from_json(p, self.offsets[j + 1], self.dtype, self.read_state)
                          for j, p in enumerate(d["fresh"])]
            self.known = [{int(i): ([float(v) for v in z], bool(x)) for i, z, x in kn} for kn in d["known"]]
            self.stitched = [(float(c), torch.tensor(z, dtype=self.dtype)) for c, z in d["stitched"]]
            self.next_id, self.dead_total = int(d["next_id"]), int(d["dead_total"])
            self.round, self.batches = int(d["round"]), int(d["batches"])
            phase = d["phase"]
            self.phase = phase if phase in ("confirm", "done") else int(phase)
        except (KeyError, TypeError, ValueError, RuntimeError) as e:
            raise ValueError(f"malformed stitched chain state ({type(e).__name__}: {e})") from None
        if isinstance(self.phase, int) and not 0 <= self.phase < self.k:
            raise ValueError(f"malformed stitched chain state (phase {self.phase})")
        self._src = None

    # ---- without a run directory -----------------------------------------------------------

    def run(self, evaluate: SegmentEvaluator,
            on_iteration: Callable[[ChainIteration], None] | None = None) -> ChainResult:
        """Ask/tell to the end with ``evaluate(segment, Z, starts)`` (segment: ``chain_names``)."""
        names = chain_names(self.k)
        t_start = time.perf_counter()
        out = ChainResult(None, math.inf, math.inf, segment_s=[0.0] * self.k)
        rows, feas, secs = [0] * self.k, [0] * self.k, [0.0] * self.k
        dead0, best = self.dead_total, 0
        while (batch := self.ask()) is not None:
            rnd = self.round
            t0 = time.perf_counter()
            r, ends = evaluate(names[batch.candidate], batch.Z, batch.starts)
            dt = time.perf_counter() - t0
            r.end_states = ends
            rec = self.tell(r, eval_time=dt)
            out.samples += rec.n_envs
            if batch.candidate is None:
                out.candidates, out.confirm_s, best = batch.Z.detach().cpu().clone(), dt, rec.best_idx
                out.confirmed = [(c, float(rec.cost[i]), bool(rec.feasible[i])) for i, (c, _) in enumerate(self.stitched)]
                continue
            j = batch.candidate - 1
            rows[j], feas[j], secs[j] = rec.n_envs, rec.n_feasible, dt
            out.segment_s[j] += dt
            if self.round != rnd or self.done:  # the round ended
                cheapest = self.stitched[0][0] if self.stitched else math.inf
                out.history.append(ChainIteration(rnd, rows, feas, secs, [len(p) for p in self.pools],
                                                  self.dead_total - dead0, cheapest))
                if on_iteration is not None:
                    on_iteration(out.history[-1])
                rows, feas, secs, dead0 = [0] * self.k, [0] * self.k, [0.0] * self.k, self.dead_total
        if out.candidates is not None and out.confirmed[best][2]:
            out.z, out.cost, out.stitched_cost = out.candidates[best].clone(), out.confirmed[best][1], \
                out.confirmed[best][0]
        out.search_s = time.perf_counter() - t_start
        return out

    # ---- internals ---------------------------------------------------------------------------

    def _next(self, j: int) -> int | str:
        """The next segment of this round that can run (its start pool not empty, rounds left),
        else the round ends: the fresh rows join the pools and the next round (or the end) begins."""
        for i in range(j + 1, self.k):
            if len(self.pools[i - 1]) and not self.opts[i].done:
                return i
        for i in range(self.k - 1):
            self.pools[i] = self.pools[i].merged(self.fresh[i], self.cfg.pool)
            self.fresh[i] = self.fresh[i].take(torch.zeros(0, dtype=torch.long))
        self.round += 1
        if self.round < self.cfg.iterations:
            return 0
        return "confirm" if self.stitched else "done"

    def _join(self, z: Tensor) -> Tensor:
        """Rows in chain order -> rows of the full layout."""
        out = torch.empty(z.shape[0], self.layout.dim, dtype=self.dtype)
        out[:, self.order] = z.to(self.dtype)
        return out

    def _own(self, j: int, z: Tensor) -> Tensor:
        """Segment j's own columns of rows in chain order through segment j (or later)."""
        return z[:, self.offsets[j]:self.offsets[j + 1]]

    def _fresh(self, j: int, z: Tensor, total: Tensor, feasible: Tensor, ends: Sequence[Any] | None,
               parent: Tensor, doomed: Tensor) -> None:
        """This round's feasible rows of segment j: their columns so far, cumulative costs, end states."""
        ok = torch.nonzero(feasible).flatten()
        if ends is None and len(ok):
            raise ValueError(f"segment {j}'s evaluation returned no end states")
        ids = torch.arange(self.next_id, self.next_id + len(ok))
        self.next_id += len(ok)
        states = [ends[i] for i in ok.tolist()] if ends is not None else []
        self.fresh[j] = Pool(z[ok], total[ok], states, ids, parent[ok], doomed[ok])

    def _keep(self, z: Tensor, total: Tensor, feasible: Tensor) -> None:
        """Keep the ``confirm`` cheapest stitched plans: the kept ones and the last segment's
        feasible rows (stitched cost ``total``), ties to the one found first."""
        ok = torch.nonzero(feasible).flatten()
        ok = ok[torch.sort(total[ok], stable=True).indices[:self.cfg.confirm]]  # only these can be kept
        new = [(float(total[i]), z[i].clone()) for i in ok.tolist()]
        self.stitched = sorted(self.stitched + new, key=lambda p: p[0])[:self.cfg.confirm]

    def _doomed(self, j: int, Z: Tensor) -> Tensor:
        """(N,) bool: segment j's rows whose nearest remembered entry is dead, within ``credit_radius``."""
        out = torch.zeros(Z.shape[0], dtype=torch.bool)
        if self.cfg.credit == 0 or j == self.k - 1 or not any(d for _, d in self.known[j].values()):
            return out
        known = list(self.known[j].values())
        kz = torch.tensor([z for z, _ in known], dtype=self.dtype)
        dead = torch.tensor([d for _, d in known])
        dist, idx = torch.cdist(self.opts[j].normalize(Z), kz).min(1)
        return dead[idx] & (dist <= self.cfg.credit_radius)

    def _credit(self, j: int, src: Tensor, feasible: Tensor) -> None:
        """Pool j's entries count the rows just started from them and the feasible ones; with
        ``credit``, settle them (``_settle``)."""
        pool = self.pools[j]
        pool.tries += torch.bincount(src, minlength=len(pool))
        pool.wins += torch.bincount(src[feasible], minlength=len(pool))
        if self.cfg.credit > 0:
            self._settle(j)

    def _settle(self, j: int) -> None:
        """Remember the verdict of pool j's entries tried ``credit`` times; drop the dead ones and
        take their wins back from their parents in pool j - 1 (which may die in turn)."""
        pool = self.pools[j]
        tried = pool.tries >= self.cfg.credit
        if not bool(tried.any()):
            return
        norm = self.opts[j].normalize(self._own(j, pool.z))
        dead = tried & (pool.wins <= 0)
        for i in torch.nonzero(tried).flatten().tolist():
            self.known[j][int(pool.ids[i])] = (norm[i].tolist(), bool(dead[i]))
        if not bool(dead.any()):
            return
        parents = pool.parent[dead]
        self.dead_total += int(dead.sum())
        self.pools[j] = pool.take(torch.nonzero(~dead).flatten())
        if j > 0:
            up = self.pools[j - 1]
            lost = (up.ids[:, None] == parents[None, :]).sum(1)  # (entries,) children of each just dropped
            if bool(lost.any()):
                up.wins -= lost
                self._settle(j - 1)
