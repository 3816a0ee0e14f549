"""The stitched search at one cut (``realize.search.chain.ChainSearch`` of two segments, a
prefix and a suffix) on an analytic problem: no simulator. The prefix's cost is a quadratic
bowl, its end state the point it reached; the suffix's cost a bowl plus a term of where it
starts; the whole plan's cost the two summed, so the stitched cost of a plan must equal its
confirmed cost, and the search must find the bowls' joint minimum. A paused search goes on from
its state as if never paused, from a state of the one-cut search the chain replaced too."""

from __future__ import annotations

import math

import pytest
import torch

from realize.search.ce.config import CEConfig
from realize.search.chain import ChainSearch
from realize.search.protocol import EvalResult
from realize.search.segments import StitchConfig, chain_names
from realize.tasks.param_layout import ParamLayout
from realize.tasks.regions import Box

A = torch.tensor([0.5, -1.0])  # the prefix's best point
B = torch.tensor([-2.0, 1.5, 0.25])  # the suffix's best point


def _layouts() -> tuple[ParamLayout, ParamLayout, ParamLayout]:
    p, s = Box([-3.0, -3.0], [3.0, 3.0]), Box([-3.0, -3.0, -3.0], [3.0, 3.0, 3.0])
    return ParamLayout({"P": p, "S": s}), ParamLayout({"P": p}), ParamLayout({"S": s})


def _prefix_cost(zp: torch.Tensor) -> torch.Tensor:
    return 100.0 + 20.0 * ((zp - A) ** 2).sum(1)


def _suffix_cost(zs: torch.Tensor, start: torch.Tensor) -> torch.Tensor:
    return 200.0 + 20.0 * ((zs - B) ** 2).sum(1) + 5.0 * start.abs().sum(1)


class Evaluator:
    """The three segments' costs, and the checks that the search hands each what it should."""

    def __init__(self) -> None:
        self.calls: list[tuple[str, int]] = []
        self.ends: list[tuple[float, ...]] = []  # every end state the prefix handed out

    def __call__(self, segment, Z, starts):
        Z = Z.double()
        self.calls.append((segment, Z.shape[0]))
        if segment == "prefix":
            assert starts is None
            feasible = Z[:, 0] > -1.0  # a third of the region fails "the grasp"
            ends = [tuple(z.tolist()) if ok else None for z, ok in zip(Z, feasible.tolist())]
            self.ends += [e for e in ends if e is not None]
            return EvalResult(_prefix_cost(Z), feasible, feasible.double(), torch.zeros(len(Z))), ends
        if segment == "suffix":
            assert starts is not None and len(starts) == Z.shape[0]
            assert all(s in self.ends for s in starts), "a suffix row started from a state no prefix ended in"
            start = torch.tensor(starts, dtype=torch.float64)
            return EvalResult(_suffix_cost(Z, start), torch.ones(len(Z), dtype=torch.bool)), None
        assert segment == "full" and starts is None
        zp, zs = Z[:, :2], Z[:, 2:]
        cost = _prefix_cost(zp) + _suffix_cost(zs, zp)
        return EvalResult(cost, zp[:, 0] > -1.0), None


def _search(cfg: StitchConfig, seed: int = 0) -> ChainSearch:
    full, pre, suf = _layouts()
    ce = CEConfig(n_envs=cfg.n_prefix, n_elite=5, iterations=cfg.iterations, seed=seed)
    return ChainSearch(full, [pre, suf], [[0, 1], [2, 3, 4]], ce, cfg)


def test_stitched_search_finds_the_joint_minimum_and_confirms_its_cost() -> None:
    ev = Evaluator()
    cfg = StitchConfig(n_prefix=60, n_suffix=60, iterations=12, pool=5, confirm=4)
    res = _search(cfg).run(ev)
    assert res.feasible
    # the whole plan's minimum: the prefix at A, the suffix at B, the prefix's end (A) paid by the suffix
    best = 100.0 + 200.0 + 5.0 * float(A.abs().sum())
    assert best <= res.cost < best + 3.0
    # the analytic suffix cost depends on the real start only: stitched == confirmed, plan for plan
    for stitched, confirmed, ok in res.confirmed:
        assert ok and math.isclose(stitched, confirmed, rel_tol=1e-9)
    # each round a prefix, then (from round 1 on) a suffix from the pool of the rounds before;
    # the confirmation realizes cfg.confirm whole plans at the end
    assert ev.calls == [("prefix", 60)] + [("prefix", 60), ("suffix", 60)] * (cfg.iterations - 1) + \
        [("full", cfg.confirm)]
    assert res.samples == 60 * cfg.iterations + 60 * (cfg.iterations - 1) + cfg.confirm
    assert [h.pools for h in res.history] == [[5]] * cfg.iterations


def test_stitched_search_is_deterministic() -> None:
    cfg = StitchConfig(n_prefix=20, n_suffix=20, iterations=3, pool=3, confirm=2)
    a, b = _search(cfg).run(Evaluator()), _search(cfg).run(Evaluator())
    assert torch.equal(a.z, b.z) and a.confirmed == b.confirmed


def test_the_pool_keeps_the_cheapest_feasible_prefixes_with_their_states() -> None:
    s, ev = _search(StitchConfig(n_prefix=6, n_suffix=6, iterations=2, pool=3, confirm=1)), Evaluator()
    Z = torch.tensor([[0.0, 0.0], [-2.0, 0.0], [0.5, -1.0], [1.0, 1.0], [0.4, -1.0], [2.0, 2.0]], dtype=torch.float64)
    s.opts[0].give(Z)  # round 0's prefix rows (the second fails "the grasp")
    b = s.ask()
    r, ends = ev("prefix", b.Z, b.starts)
    r.end_states = ends
    s.tell(r)  # round 0 has no suffix: its prefixes join the pool at once
    assert s.pools[0].z.tolist() == [[0.5, -1.0], [0.4, -1.0], [0.0, 0.0]]
    assert s.pools[0].states == [tuple(z) for z in s.pools[0].z.tolist()]


def test_a_split_that_does_not_cover_the_columns_is_refused() -> None:
    full, pre, suf = _layouts()
    with pytest.raises(ValueError, match="split the plan's 5 columns"):
        ChainSearch(full, [pre, suf], [[0, 1], [1, 2, 3]], CEConfig(n_envs=10, n_elite=2), StitchConfig())
    with pytest.raises(ValueError, match="stitch.iterations must be >= 2"):
        StitchConfig(iterations=1)
    with pytest.raises(ValueError, match="stitch.pool = 0"):
        StitchConfig(pool=0)


def _paused(cfg: StitchConfig, pause_after: int):
    """The whole search's result, and an evaluator and a search that ran its first ``pause_after`` batches."""
    whole = _search(cfg).run(Evaluator())
    ev, first = Evaluator(), _search(cfg)
    for _ in range(pause_after):
        b = first.ask()
        r, ends = ev(chain_names(2)[b.candidate], b.Z, b.starts)
        r.end_states = ends
        first.tell(r)
    return whole, ev, first


@pytest.mark.parametrize("pause_after", [1, 2, 3])  # round 0, a prefix whose rows wait for the suffix, a round
def test_a_paused_search_goes_on_from_its_state_dict_as_if_never_paused(pause_after: int) -> None:
    import json

    cfg = StitchConfig(n_prefix=20, n_suffix=20, iterations=3, pool=3, confirm=2)
    whole, ev, first = _paused(cfg, pause_after)
    saved = json.loads(json.dumps(first.state_dict()))  # as a checkpoint holds it
    second = _search(cfg)
    second.read_state = tuple  # the analytic states are tuples; JSON gives lists
    second.load_state_dict(saved)
    assert second.iterations_done == pause_after and second.pools[0].states == first.pools[0].states
    assert second.fresh[0].states == first.fresh[0].states  # (after 2: a prefix's rows wait for the suffix)
    rest = second.run(ev)
    assert torch.equal(rest.z, whole.z) and rest.cost == whole.cost and rest.confirmed == whole.confirmed


def _as_stitched(d: dict) -> dict:
    """The chain's ``state_dict`` in the form a one-cut run checkpointed before the chain ran it
    (kind "stitched": the prefix's, suffix's and confirmation's searches, the pool and the
    waiting prefixes without ids, each stitched plan as its prefix's and its suffix's columns)."""
    def rows(p: dict) -> dict:
        return {k: p[k] for k in ("z", "cost", "states")}

    return {"kind": "stitched", "round": d["round"], "phase": {0: "prefix", 1: "suffix"}.get(d["phase"], d["phase"]),
            "batches": d["batches"], "prefix": d["segments"][0], "suffix": d["segments"][1], "full": d["full"],
            "pool": rows(d["pools"][0]), "fresh": rows(d["fresh"][0]),
            "stitched": [[c, z[:2], z[2:]] for c, z in d["stitched"]]}


@pytest.mark.parametrize("pause_after", [1, 2, 3, 5])  # ... and before the confirmation
def test_a_one_cut_run_checkpointed_before_the_chain_ran_it_goes_on(pause_after: int) -> None:
    """An interrupted one-cut run's checkpoint from before the chain was its search resumes as if
    never paused (``realize.search.segments.stitched_as_chain``); a malformed one is refused."""
    import json

    cfg = StitchConfig(n_prefix=20, n_suffix=20, iterations=3, pool=3, confirm=2)
    whole, ev, first = _paused(cfg, pause_after)
    second = _search(cfg)
    second.read_state = tuple
    second.load_state_dict(json.loads(json.dumps(_as_stitched(first.state_dict()))))
    assert second.iterations_done == pause_after and second.phase == first.phase
    rest = second.run(ev)
    assert torch.equal(rest.z, whole.z) and rest.cost == whole.cost and rest.confirmed == whole.confirmed
    with pytest.raises(ValueError, match="malformed stitched state"):
        _search(cfg).load_state_dict({"kind": "stitched", "round": 0})


def test_the_confirmation_is_a_given_batch_whose_best_is_the_searchs() -> None:
    s = _search(StitchConfig(n_prefix=20, n_suffix=20, iterations=2, pool=3, confirm=3))
    res = s.run(Evaluator())
    assert s.done and s.ask() is None and s.iterations_done == 4
    st = s.report().state
    assert st.best_feasible and st.best_cost == res.cost == min(c for _, c, ok in res.confirmed if ok)
    with pytest.raises(RuntimeError, match="after the stitched search is done"):
        s.tell(EvalResult(torch.zeros(3), torch.ones(3, dtype=torch.bool)))


def test_a_smoothed_search_confirms_too() -> None:
    """``ce.alpha < 1`` smooths each refit towards the last distribution; the confirmation's
    search has none before its given batch, so it smooths towards that batch's own spread."""
    full, pre, suf = _layouts()
    cfg = StitchConfig(n_prefix=20, n_suffix=20, iterations=3, pool=3, confirm=3)
    ce = CEConfig(n_envs=20, n_elite=5, iterations=3, seed=0, alpha=0.7)
    res = ChainSearch(full, [pre, suf], [[0, 1], [2, 3, 4]], ce, cfg).run(Evaluator())
    assert res.feasible and res.confirmed
