"""``CrossEntropyOptimizer``: ask/tell cross-entropy search over a ``ParamLayout`` (Algorithm 1).

What it does: generic over any batched evaluator (cost, feasibility and a progress score per
row), so it runs and is tested without a simulator; it implements ``realize.search.protocol.Searcher``.

* Iteration 0 samples each parameter uniformly over its region (``ParamLayout.sample_uniform``),
  or, warm-started (``warm``: a ``WarmDistribution``), from a given distribution with a share
  of uniform samples.
* Later iterations sample an independent normal per column of Z (or a mixture of ``n_modes``
  of them, ``realize.search.ce.mixture``) refit from the elite set of the previous iteration and
  ``project`` the draws back into the regions. Optionally a share of each batch is drawn
  uniformly again (``uniform_share``).
* Elites are the ``n_elite`` best rows (``realize.search.ce.ranking``); the refit is the (optionally
  rank-weighted) elite mean and population std, floored at ``min_std`` and optionally smoothed
  with ``alpha`` (1 = paper, no smoothing).
* With ``keep_elites`` the last refit's feasible elites are ranked with the batch
  (``realize.search.ce.elite_memory``).
* It stops after ``iterations`` or, if ``converge_std`` is set, once every std is below it, or,
  with ``patience``, once the elites have stopped improving and a feasible best is in hand.

The defaults of the multimodal/robust options take exactly the code paths and random draws of
the single-Gaussian search, bit for bit. Bookkeeping (sampling, ranking, refits) runs on the
CPU in ``CEConfig.dtype`` with one ``torch.Generator`` seeded from the config, so the same seed
gives bit-identical samples on any machine; only the Z handed out by ``ask`` is moved to the
caller's device. The state round-trips through plain JSON (``state_dict``) for resuming.
Angles (a hemisphere yaw column) are plain reals: the Gaussian does not wrap, ``project``
wraps/clamps its draws; keep yaw ranges away from the +-pi seam if that matters.

What it doesn't: simulate, know plans, log or write files; full-covariance normals; mixtures
whose number of modes changes during a run.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Mapping
from typing import Any

import torch
from torch import Tensor

from realize.search.ce.config import CEConfig
from realize.search.ce.elite_memory import pooled, remembered
from realize.search.ce.mixture import Mixture, fit_mixture
from realize.search.ce.sampling import draw_rows, row_sources, screened_draw
from realize.search.ce.ranking import (choose_elites, elite_weights, fit_normal, rank_samples, robust_cost,
                                       robust_order, sort_key)
from realize.search.ce.state import CEResult, CEState, IterationRecord, WarmDistribution
from realize.tasks.param_layout import ParamLayout
from realize.search.protocol import Batch, EvalResult, SearchReport

__all__ = ["CrossEntropyOptimizer", "optimize", "Evaluator", "IterationCallback"]

Evaluator = Callable[[Tensor], EvalResult]
IterationCallback = Callable[[IterationRecord, CEState], "bool | None"]


class CrossEntropyOptimizer:
    """Ask/tell cross-entropy optimizer over a ``ParamLayout``.

    ``ask()`` returns the current ``Batch`` (``Z (N, D)`` on ``device``; ``None`` once done);
    ``tell(result)`` ranks it, refits the distribution and returns the ``IterationRecord``;
    ``run(evaluate)`` loops until done. Pass ``state`` (or call ``load_state_dict``) to resume:
    the continued run draws exactly the samples the uninterrupted one would have.
    """

    def __init__(self, layout: ParamLayout, config: CEConfig, device: torch.device | str | None = None,
                 state: CEState | None = None, warm: WarmDistribution | None = None,
                 screen: Callable[[Tensor], Tensor] | None = None) -> None:
        if not isinstance(layout, ParamLayout):
            raise TypeError(f"layout must be a ParamLayout, got {type(layout).__name__}")
        self.layout = layout
        self.config = config
        self.device = torch.device(device) if device is not None else torch.device("cpu")
        self.dtype = config.torch_dtype
        self._gen = torch.Generator(device="cpu")
        self._gen.manual_seed(config.seed)
        self._warm_share: float | None = None
        if state is None and warm is not None:
            self._state = self._check_state(CEState(iteration=0, rng_state=self._gen.get_state(), mean=warm.mean,
                                                    std=warm.std, weights=warm.weights))
            self._warm_share = warm.uniform_share
        elif state is None:
            self._state = CEState(iteration=0, rng_state=self._gen.get_state())
        else:
            self._state = self._check_state(state.copy())
            self._gen.set_state(self._state.rng_state)
        self._pending: tuple[Batch, float] | None = None
        self._given = False  # the pending batch came from ``give``
        # ce.screen: (N, D) -> (N,) bool, the samples physics would fail for certain; they are
        # drawn again (at most ce.screen_tries times) and kept apart, not simulated
        self._screen = screen if config.screen else None
        # ce.keep_elites, where a sample's score is its own (not a robust or kNN-ranked search)
        self._keeps = config.keep_elites and config.replicas == 1 and config.knn_robust == 0
        self._screened: Tensor | None = None
        # normalised space for clustering and kNN: each column over its region's bounding box
        low, high = layout.bounds()
        width = high - low
        self._norm_low = low.to(self.dtype)
        self._norm_scale = torch.where(width > 0, width, torch.ones_like(width)).to(self.dtype)

    def normalize(self, Z: Tensor) -> Tensor:
        """``(N, D)`` rows mapped to the normalised space (each column's region box -> [0, 1])."""
        return (Z - self._norm_low) / self._norm_scale

    def _check_state(self, s: CEState) -> CEState:
        D, k = self.layout.dim, self.config.n_modes
        for name in ("mean", "std", "init_mean", "init_std", "best_z", "weights"):
            v = getattr(s, name)
            if v is not None:
                want = (k,) if name == "weights" else (k, D) if name in ("mean", "std") and k > 1 else (D,)
                if v.shape != want:
                    raise ValueError(
                        f"state.{name}: expected shape {want} for this layout and ce.n_modes = {k}, "
                        f"got {tuple(v.shape)}"
                    )
                setattr(s, name, v.to(dtype=self.dtype, device="cpu"))
        if (s.mean is None) != (s.std is None):
            raise ValueError("state: mean and std must both be set or both be null")
        if k == 1 and s.weights is not None:
            raise ValueError("state.weights: only a mixture (ce.n_modes > 1) has weights")
        if k > 1 and (s.mean is None) != (s.weights is None):
            raise ValueError(f"state: a mixture (ce.n_modes = {k}) needs mean, std and weights together")
        if s.iteration < 0:
            raise ValueError(f"state.iteration must be >= 0, got {s.iteration}")
        return s

    # ---- the Searcher protocol -------------------------------------------------------------

    @property
    def state(self) -> CEState:
        """A copy of the current state (safe to serialise/keep)."""
        return self._state.copy()

    @property
    def iteration(self) -> int:
        return self._state.iteration

    @property
    def iterations_done(self) -> int:
        return self._state.iteration

    @property
    def done(self) -> bool:
        s = self._state
        return s.iteration >= self.config.iterations or s.converged or not self.config.within_budget(s.iteration)

    def ask(self) -> Batch | None:
        """The batch of the current iteration (``Z`` on ``self.device``), ``None`` once done.

        Calling it again before ``tell`` returns the same batch."""
        if self.done:
            return None
        if self._pending is None:
            t0 = time.perf_counter()
            s = self._state
            Z = self._sample(self.config.samples_at(s.iteration))
            if self._screen is not None:
                Z = self._screened_draw(Z)
            drawn = Batch(Z, None, _clone(s.mean), _clone(s.std), _clone(s.weights))
            self._pending = (drawn, t0)
        b = self._pending[0]
        # the evaluator may not alter our copy
        return Batch(b.Z.to(self.device, copy=True), None, b.mean, b.std, b.weights)

    def give(self, Z: Tensor) -> None:
        """Make ``Z (N, D)`` the current iteration's batch instead of a draw: rows chosen elsewhere
        (a stitched search's plans, confirmed whole: ``realize.search.chain``). ``tell`` ranks
        and refits from them as from drawn rows; the record says ``sampled_from = "given"``."""
        if self.done:
            raise RuntimeError("give() after the search is done")
        if Z.ndim != 2 or Z.shape[1] != self.layout.dim:
            raise ValueError(f"give(): expected rows of {self.layout.dim} parameters, got {tuple(Z.shape)}")
        s = self._state
        self._pending = (Batch(Z.detach().to("cpu", self.dtype).clone(), None, _clone(s.mean), _clone(s.std),
                               _clone(s.weights)), time.perf_counter())
        self._given = True

    def tell(self, result: EvalResult, eval_time: float = math.nan) -> IterationRecord:
        """Score the pending batch, update the distribution and the best, return the record
        (``eval_time``: the seconds the caller spent evaluating, kept in the record)."""
        if self._pending is None:
            raise RuntimeError("tell() called without a pending batch; call ask() first")
        batch, t0 = self._pending
        Z = batch.Z
        source = "given" if self._given else "uniform" if batch.mean is None else \
            "warm" if self._warm_first else "gaussian"
        cfg, s = self.config, self._state
        n = Z.shape[0]
        r = result.to_cpu(n, self.dtype)
        best_order = rank_samples(r.cost, r.feasible, r.progress, r.distance, r.share)  # the batch's best first
        n_feas = int(r.feasible.sum())
        Zr, rr = pooled(Z, r, s.memory_z, s.memory_cost) if self._keeps else (Z, r)  # + remembered elites
        order = best_order if rr is r else rank_samples(rr.cost, rr.feasible, rr.progress, rr.distance)
        robust = None
        if cfg.knn_robust > 0:
            robust = robust_cost(self.normalize(Z), r, cfg)
            order = robust_order(order, robust, r.feasible)

        elite, refit = choose_elites(order, int(rr.feasible.sum()), cfg)
        if source == "uniform" or (source == "given" and s.init_mean is None):  # (what a first refit smooths from)
            s.init_mean = Z.mean(0)
            s.init_std = Z.std(0, correction=0)
        if refit != "kept":
            self._refit(Zr[elite])
        if self._keeps:
            s.memory_z, s.memory_cost = remembered(Zr, rr, elite)

        self._update_best(Z, r, int(best_order[0]))
        feas_cost = r.cost[r.feasible]
        elite_feas = rr.cost[elite][rr.feasible[elite]]
        s.elite_costs.append(float(elite_feas.mean()) if refit == "elite" else math.nan)
        if cfg.patience is not None and self._settled():
            s.converged = True
        rec = IterationRecord(
            iteration=s.iteration,
            n_envs=n,
            Z=Z.clone() if cfg.keep_samples else None,
            cost=r.cost,
            feasible=r.feasible,
            progress=r.progress,
            distance=r.distance,
            elite_idx=elite[elite < n].clone(),
            sampled_from=source,
            refit=refit,
            mean=_clone(s.mean),
            std=_clone(s.std),
            n_feasible=n_feas,
            success_share=n_feas / n if r.share is None else float(r.share.mean()),
            best_cost=s.best_cost if s.best_feasible else math.inf,
            iteration_best_cost=float(feas_cost.min()) if n_feas else math.inf,
            elite_cost_min=float(elite_feas.min()) if elite_feas.numel() else math.nan,
            elite_cost_mean=float(elite_feas.mean()) if elite_feas.numel() else math.nan,
            elite_cost_max=float(elite_feas.max()) if elite_feas.numel() else math.nan,
            eval_time=eval_time,
            wall_time=time.perf_counter() - t0,
            converged=s.converged,
            weights=_clone(s.weights),
            best_idx=int(best_order[0]),
            robust_cost=robust,
            share=None if r.share is None else r.share.clone(),
            n_stopped=None if r.stopped is None else int(r.stopped.sum()),
            n_screened=None if self._screened is None else int(self._screened.shape[0]),
            screened_Z=self._screened if cfg.keep_samples else None,
            n_remembered=int((elite >= n).sum()) if self._keeps else None,
        )
        self._screened, self._given = None, False
        s.iteration += 1
        s.rng_state = self._gen.get_state()
        self._pending = None
        return rec

    def report(self) -> SearchReport:
        return SearchReport(lead=None, state=self.state)

    def state_dict(self) -> dict[str, Any]:
        """The whole state as plain JSON data (``CEState.to_dict``)."""
        return self._state.to_dict()

    def load_state_dict(self, d: Mapping[str, Any]) -> None:
        """Continue from ``state_dict()`` output; ``ValueError`` if it does not fit this search."""
        try:
            state = CEState.from_dict(d, dtype=self.dtype)
        except (KeyError, TypeError, ValueError) as e:
            raise ValueError(f"malformed CE state ({type(e).__name__}: {e})") from None
        self._state = self._check_state(state)
        self._gen.set_state(self._state.rng_state)
        self._pending, self._given = None, False

    # ---- convenience -----------------------------------------------------------------------

    def run(self, evaluate: Evaluator, on_iteration: IterationCallback | None = None) -> CEResult:
        """Iterate ask -> evaluate -> tell until done. ``on_iteration(record, state)`` is called
        after each iteration (state is a copy, ready to serialise); returning ``True`` stops."""
        history: list[IterationRecord] = []
        while (batch := self.ask()) is not None:
            t0 = time.perf_counter()
            res = evaluate(batch.Z)
            rec = self.tell(res, eval_time=time.perf_counter() - t0)
            history.append(rec)
            if on_iteration is not None and on_iteration(rec, self.state):
                break
        return self.result(history)

    def result(self, history: list[IterationRecord] | None = None) -> CEResult:
        s = self._state
        if s.best_z is None:
            raise RuntimeError("no iteration has been evaluated yet")
        return CEResult(
            best_z=s.best_z.clone(),
            best_params={k: v.clone() for k, v in self.layout.split(s.best_z[None]).items()},
            best_cost=s.best_cost,
            best_feasible=s.best_feasible,
            best_iteration=s.best_iteration,
            mean=_clone(s.mean),
            std=_clone(s.std),
            converged=s.converged,
            history=history or [],
            state=self.state,
            weights=_clone(s.weights),
        )

    # ---- internals ---------------------------------------------------------------------

    @property
    def _warm_first(self) -> bool:
        """Whether the current iteration is the first of a warm-started search."""
        return self._warm_share is not None and self._state.iteration == 0

    def _sample(self, n: int) -> Tensor:
        return self._draw(self._sources(n))

    def _sources(self, n: int) -> Tensor:
        share = self._warm_share if self._warm_first else self.config.uniform_share
        return row_sources(self._state, n, share)

    def _draw(self, source: Tensor) -> Tensor:
        return draw_rows(self.layout, self._state, source, self._gen, self.dtype)

    def _screened_draw(self, Z: Tensor) -> Tensor:
        """``ce.screen``: the rejected rows drawn again (``screened_draw``); the rejected draws
        are kept for the iteration's record (``screened_Z``), not simulated."""
        assert self._screen is not None
        Z, self._screened = screened_draw(Z, self._sources(Z.shape[0]), self._screen, self.config.screen_tries,
                                          self._draw)
        return Z

    def _refit(self, Ze: Tensor) -> None:
        """Refit the distribution from the elite rows (best first); updates the state."""
        cfg, s = self.config, self._state
        w = elite_weights(Ze.shape[0], cfg.rank_weighted, self.dtype)
        if cfg.n_modes > 1:
            k, D = cfg.n_modes, self.layout.dim
            if s.mean is None:  # first refit: every mode's predecessor is the uniform batch
                assert s.init_mean is not None and s.init_std is not None
                old = Mixture(s.init_mean.expand(k, D).clone(), s.init_std.expand(k, D).clone(),
                              torch.full((k,), 1.0 / k, dtype=self.dtype))
            else:
                assert s.std is not None and s.weights is not None
                old = Mixture(s.mean, s.std, s.weights)
            mix = fit_mixture(Ze, w, old, s.mean is None, self._gen, self.normalize, cfg.alpha, cfg.min_std)
            s.mean, s.std, s.weights = mix.mean, mix.std, mix.weights
            if cfg.converge_std is not None:
                live = s.weights > 0
                if float(s.std[live].max()) < cfg.converge_std:
                    s.converged = True
            return
        new_mean, new_std = fit_normal(Ze, w)
        a = cfg.alpha
        if a < 1.0:
            old_mean = s.mean if s.mean is not None else s.init_mean
            old_std = s.std if s.std is not None else s.init_std
            assert old_mean is not None and old_std is not None
            new_mean = a * new_mean + (1 - a) * old_mean
            new_std = a * new_std + (1 - a) * old_std
        s.mean, s.std = new_mean, new_std.clamp_min(cfg.min_std)
        if cfg.converge_std is not None and float(s.std.max()) < cfg.converge_std:
            s.converged = True

    def _settled(self) -> bool:
        """The stopping rule (``CEConfig.patience``): a feasible best in hand, and the elites'
        mean cost fell by less than ``min_improvement`` (relative) over the last ``patience``
        iterations (both ends full elite sets of feasible samples)."""
        s, p = self._state, self.config.patience
        assert p is not None
        if not s.best_feasible or len(s.elite_costs) <= p:
            return False
        old, new = s.elite_costs[-1 - p], s.elite_costs[-1]
        return math.isfinite(old) and math.isfinite(new) and old - new <= self.config.min_improvement * old

    def _update_best(self, Z: Tensor, r: EvalResult, top: int) -> None:
        """Keep the batch's best single sample if it beats the best of all iterations."""
        s = self._state
        share = 1.0 if r.share is None else float(r.share[top])
        cand = sort_key(bool(r.feasible[top]), float(r.cost[top]),
                        math.nan if r.progress is None else float(r.progress[top]),
                        math.nan if r.distance is None else float(r.distance[top]), share)
        best = sort_key(s.best_feasible, s.best_cost, s.best_progress, s.best_distance, s.best_share)
        if s.best_z is None or cand < best:
            s.best_z = Z[top].clone()
            s.best_cost = float(r.cost[top])
            s.best_feasible = bool(r.feasible[top])
            s.best_progress = math.nan if r.progress is None else float(r.progress[top])
            s.best_distance = math.nan if r.distance is None else float(r.distance[top])
            s.best_iteration = s.iteration
            s.best_share = share


def _clone(v: Tensor | None) -> Tensor | None:
    return None if v is None else v.clone()


def optimize(layout: ParamLayout, evaluate: Evaluator, config: CEConfig, device: torch.device | str | None = None,
             on_iteration: IterationCallback | None = None, state: CEState | None = None) -> CEResult:
    """Run Algorithm 1: ``CrossEntropyOptimizer(layout, config, device, state).run(...)``."""
    return CrossEntropyOptimizer(layout, config, device=device, state=state).run(evaluate, on_iteration)
