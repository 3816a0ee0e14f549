"""A chain of stitched segments (``realize.search.chain``) on analytic problems: no simulator.

* Three segments of separable bowls (the whole plan's cost the segments' summed) find the
  analytic optimum, stitched cost == confirmed; the same problem cut once (two segments) and
  cut twice returns the same plan (to the searches' precision). Elsewhere a segment also
  pays a term of where it starts, so the starts handed out must be the right end states.
* Credit: a suffix that fails from every start of the prefix's cheaper mode moves the prefix's
  distribution to its other mode (without credit it stays), and the same one segment back in a
  chain of three; a dead entry's parent loses its win.
* A paused chain goes on from its ``state_dict`` as if never paused; bad input is refused.
"""

from __future__ import annotations

import json
import math
from collections.abc import Sequence

import pytest
import torch

from realize.search.ce.config import CEConfig
from realize.search.chain import ChainSearch
from realize.search.chain_pool import Pool
from realize.search.protocol import EvalResult
from realize.search.segments import StitchConfig, chain_names
from realize.tasks.param_layout import ParamLayout
from realize.tasks.regions import Box

CENTRES = [torch.tensor([0.5, -1.0]), torch.tensor([1.2]), torch.tensor([-2.0, 1.5, 0.25])]
BASE = [100.0, 150.0, 200.0]


def _box(d: int) -> Box:
    return Box([-3.0] * d, [3.0] * d)


def _chain_layouts(groups: Sequence[Sequence[int]]) -> tuple[ParamLayout, list[ParamLayout], list[list[int]]]:
    """The whole layout of the three parameters P0, P1, P2 and the segments' layouts for
    ``groups`` (the parameters of each segment, in order), with their columns."""
    names = [f"P{i}" for i in range(3)]
    full = ParamLayout({n: _box(len(c)) for n, c in zip(names, CENTRES)})
    segs = [ParamLayout({names[i]: _box(len(CENTRES[i])) for i in g}) for g in groups]
    cols = [[c for i in g for c in range(full.slices[names[i]].start, full.slices[names[i]].stop)] for g in groups]
    return full, segs, cols


def _cost(i: int, z: torch.Tensor, start: torch.Tensor | None, w: float) -> torch.Tensor:
    """Parameter i's bowl, plus w |start| summed where it starts from a state."""
    c = BASE[i] + 20.0 * ((z - CENTRES[i]) ** 2).sum(1)
    return c if start is None else c + w * start.abs().sum(1)


class Bowls:
    """Segments of the bowls over ``groups``: a segment's cost is its parameters' bowls (the
    first one's plus ``w`` |start|, the state a tuple of every column so far); its end state those
    columns. The whole plan's cost is the segments' summed from the real states, so a stitched
    cost equals its confirmed cost. ``fail_if(start)`` (optional): the rows of the last segment
    that fail from a start. Every start handed out must be an end state handed out before."""

    def __init__(self, groups: Sequence[Sequence[int]], names: dict[int | None, str], fail_if=None,
                 w: float = 5.0) -> None:
        self.groups, self.fail_if, self.w = [list(g) for g in groups], fail_if, w
        self.ends: set[tuple[float, ...]] = set()
        self.seg = {n: k - 1 for k, n in names.items() if k is not None}
        self.calls: list[tuple[str, int]] = []

    def _segment(self, j: int, Z: torch.Tensor, start: torch.Tensor | None) -> torch.Tensor:
        out, at, prev = torch.zeros(Z.shape[0], dtype=torch.float64), 0, start
        for i in self.groups[j]:
            d = len(CENTRES[i])
            out = out + _cost(i, Z[:, at:at + d], prev, self.w)
            prev, at = None, at + d
        return out

    def __call__(self, segment: str, Z: torch.Tensor, starts):
        Z = Z.double()
        self.calls.append((segment, Z.shape[0]))
        ok = torch.ones(Z.shape[0], dtype=torch.bool)
        if segment == "full":
            cost, at, prev = torch.zeros(Z.shape[0], dtype=torch.float64), 0, None
            for j, g in enumerate(self.groups):
                d = sum(len(CENTRES[i]) for i in g)
                cost = cost + self._segment(j, Z[:, at:at + d], prev)
                prev, at = Z[:, :at + d], at + d
            if self.fail_if is not None:
                last = sum(len(CENTRES[i]) for i in self.groups[-1])
                ok = ~self.fail_if(Z[:, :Z.shape[1] - last])
            return EvalResult(cost, ok), None
        j = self.seg[segment]
        assert (starts is None) == (j == 0) and (starts is None or all(tuple(s) in self.ends for s in starts))
        start = None if starts is None else torch.tensor([list(s) for s in starts], dtype=torch.float64)
        cost = self._segment(j, Z, start)
        if j == len(self.groups) - 1:
            if self.fail_if is not None:
                ok = ~self.fail_if(start)
            return EvalResult(cost, ok, ok.double()), None
        ends = [tuple(z) for z in (Z if start is None else torch.cat([start, Z], 1)).tolist()]
        self.ends.update(ends)
        return EvalResult(cost, ok), ends


def _ce(n: int, iterations: int, seed: int = 0, n_elite: int = 5, **kw) -> CEConfig:
    return CEConfig(n_envs=n, n_elite=n_elite, iterations=iterations, seed=seed, **kw)


# ---- three segments ----------------------------------------------------------------------------

# separable (no start terms, w = 0): the optimum is every bowl's centre
ARGMIN, OPTIMUM = torch.cat(CENTRES).double(), sum(BASE)


def _three(cfg: StitchConfig, seed: int = 0, fail_if=None, w: float = 5.0, n_elite: int = 5) -> tuple[ChainSearch, Bowls]:
    groups = [[0], [1], [2]]
    full, segs, cols = _chain_layouts(groups)
    return ChainSearch(full, segs, cols, _ce(cfg.n_suffix, cfg.iterations, seed, n_elite), cfg), \
        Bowls(groups, chain_names(3), fail_if, w)


def test_three_segments_find_the_analytic_optimum_and_confirm_their_cost() -> None:
    cfg = StitchConfig(n_prefix=60, n_suffix=60, iterations=12, pool=5, confirm=4, splits=(1, 2))
    search, ev = _three(cfg, w=0.0)
    res = search.run(ev)
    assert res.feasible and OPTIMUM <= res.cost < OPTIMUM + 3.0
    assert float((res.z - ARGMIN).abs().max()) < 0.1
    for stitched, confirmed, ok in res.confirmed:
        assert ok and math.isclose(stitched, confirmed, rel_tol=1e-9)
    # round r: segment 0, then segment 1 from round 1 on, segment 2 from round 2 on; then the confirmation
    names = chain_names(3)
    expected = [(names[1], 60)] + [(names[1], 60), (names[2], 60)] + \
        [(names[1], 60), (names[2], 60), (names[3], 60)] * (cfg.iterations - 2) + [("full", cfg.confirm)]
    assert ev.calls == expected and len(expected) == cfg.batches
    assert res.samples == sum(n for _, n in expected) and len(res.history) == cfg.iterations
    assert all(s >= 0.0 for s in res.segment_s) and len(res.segment_s) == 3


def test_one_cut_and_two_cuts_return_the_same_plan() -> None:
    """The same bowls cut once (P0 | P1 P2) and twice (P0 | P1 | P2): both return the analytic
    optimum's plan, so each other's, to the searches' precision."""
    full, segs, cols = _chain_layouts([[0], [1, 2]])
    one = ChainSearch(full, segs, cols, _ce(60, 16, n_elite=10),
                      StitchConfig(n_prefix=60, n_suffix=60, iterations=16, pool=5, confirm=4)).run(
        Bowls([[0], [1, 2]], chain_names(2), w=0.0))
    two, ev = _three(StitchConfig(n_prefix=60, n_suffix=60, iterations=16, pool=5, confirm=4, splits=(1, 2)), w=0.0,
                     n_elite=10)
    res = two.run(ev)
    assert one.feasible and res.feasible
    assert float((one.z - ARGMIN).abs().max()) < 0.1 and float((res.z - ARGMIN).abs().max()) < 0.1
    assert float((one.z - res.z).abs().max()) < 0.15 and abs(one.cost - res.cost) < 3.0


# ---- credit ------------------------------------------------------------------------------------

def _bimodal(credit: int, seed: int = 0) -> tuple[ChainSearch, object]:
    """A prefix of one column x whose cost has two valleys, x = -0.6 (cost 0) and x = +0.6
    (cost 0.4); the suffix fails from every start with x < 0."""
    full = ParamLayout({"X": Box([-1.0], [1.0]), "Y": Box([-1.0], [1.0])})
    pre, suf = ParamLayout({"X": Box([-1.0], [1.0])}), ParamLayout({"Y": Box([-1.0], [1.0])})
    cfg = StitchConfig(n_prefix=30, n_suffix=30, iterations=8, pool=5, confirm=3, credit=credit, credit_radius=0.15)
    ce = CEConfig(n_envs=30, n_elite=5, iterations=8, seed=seed, uniform_share=0.2)

    def prefix_cost(x: torch.Tensor) -> torch.Tensor:
        return 10.0 * torch.minimum((x + 0.6) ** 2, (x - 0.6) ** 2 + 0.04)

    def evaluate(segment, Z, starts):
        Z = Z.double()
        if segment == "prefix":
            return EvalResult(prefix_cost(Z[:, 0]), torch.ones(len(Z), dtype=torch.bool)), [(float(z),) for z in Z[:, 0]]
        x = Z[:, 0] if segment == "full" else torch.tensor([s[0] for s in starts], dtype=torch.float64)
        y = Z[:, -1]
        cost = 10.0 * y ** 2 + (prefix_cost(x) if segment == "full" else 0.0)
        ok = x > 0
        return EvalResult(cost, ok, ok.double()), None

    return ChainSearch(full, [pre, suf], [[0], [1]], ce, cfg), evaluate


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_a_suffix_failing_from_one_mode_moves_the_prefix_to_the_other(seed: int) -> None:
    plain, ev = _bimodal(credit=0, seed=seed)
    base = plain.run(ev)
    credited, ev = _bimodal(credit=2, seed=seed)
    res = credited.run(ev)
    assert float(plain.opts[0].state.mean[0]) < 0  # without credit the prefix stays in its cheaper valley
    assert float(credited.opts[0].state.mean[0]) > 0.3  # with it, in the one the suffix succeeds from
    assert res.feasible and float(res.z[0]) > 0
    assert sum(h.dead for h in res.history) > 0 and not base.history[-1].dead
    # the rows of the cheaper valley were ranked after the others: the refit left it
    assert credited.known[0] and any(dead for _, dead in credited.known[0].values())


def test_the_last_segment_failing_from_one_mode_moves_the_middle_one() -> None:
    """Three segments: the middle one's column has two valleys (-0.6: cost 0, +0.6: cost 0.4),
    the last fails from every start whose middle column is negative. With credit the middle
    segment's distribution ends in the valley the last succeeds from; without, in the cheaper."""
    box = Box([-1.0], [1.0])
    full = ParamLayout({"X": box, "Y": box, "W": box})
    segs = [ParamLayout({n: box}) for n in ("X", "Y", "W")]

    def valleys(y: torch.Tensor) -> torch.Tensor:
        return 10.0 * torch.minimum((y + 0.6) ** 2, (y - 0.6) ** 2 + 0.04)

    def evaluate(segment, Z, starts):
        Z = Z.double()
        ones = torch.ones(len(Z), dtype=torch.bool)
        if segment == "segment1":
            return EvalResult(Z[:, 0] ** 2, ones), [(float(x),) for x in Z[:, 0]]
        if segment == "segment2":
            return EvalResult(valleys(Z[:, 0]), ones), [(s[0], float(y)) for s, y in zip(starts, Z[:, 0])]
        y = torch.tensor([s[1] for s in starts], dtype=torch.float64) if segment == "segment3" else Z[:, 1]
        cost = Z[:, -1] ** 2 + (Z[:, 0] ** 2 + valleys(Z[:, 1]) if segment == "full" else 0.0)
        return EvalResult(cost, y > 0, (y > 0).double()), None

    means = []
    for credit in (0, 2):
        cfg = StitchConfig(n_prefix=30, n_suffix=30, iterations=10, pool=5, confirm=3, splits=(1, 2), credit=credit,
                           credit_radius=0.15)
        s = ChainSearch(full, segs, [[0], [1], [2]], CEConfig(n_envs=30, n_elite=5, iterations=10, seed=0,
                                                             uniform_share=0.2), cfg)
        res = s.run(evaluate)
        means.append(float(s.opts[1].state.mean[0]))
    assert means[0] < 0 < 0.3 < means[1]
    assert res.feasible and float(res.z[1]) > 0 and sum(h.dead for h in res.history) > 0


def _pool(ids: list[int], parent: list[int], cost: list[float]) -> Pool:
    n = len(ids)
    return Pool(torch.zeros(n, 1, dtype=torch.float64), torch.tensor(cost, dtype=torch.float64), [None] * n,
                torch.tensor(ids), torch.tensor(parent), torch.zeros(n, dtype=torch.bool))


def test_a_dead_entry_takes_its_win_back_from_its_parent() -> None:
    """Pool 1's entry 11 is pool 0's entry 1's only feasible child; once it is dead (two rows
    from it, none feasible), entry 1 has no win left and dies too; entry 0 keeps its own."""
    cfg = StitchConfig(n_prefix=4, n_suffix=4, iterations=3, pool=5, confirm=1, credit=2, splits=(1, 2))
    s, _ = _three(cfg, n_elite=2)
    s.pools[0] = _pool([0, 1], [-1, -1], [1.0, 2.0])
    s.pools[0].z = torch.zeros(2, 2, dtype=torch.float64)
    s.pools[0].tries, s.pools[0].wins = torch.tensor([3, 2]), torch.tensor([1, 1])
    s.pools[1] = _pool([10, 11], [0, 1], [3.0, 4.0])
    s.pools[1].z = torch.zeros(2, 3, dtype=torch.float64)
    s._credit(1, torch.tensor([0, 1, 1, 0]), torch.tensor([True, False, False, True]))
    assert s.pools[1].ids.tolist() == [10] and s.pools[0].ids.tolist() == [0]
    assert s.dead_total == 2 and s.known[1][11][1] and s.known[0][1][1] and not s.known[0][0][1]
    # a row of segment 0 where the dead entry was is doomed; one far from it is not
    near, far = torch.zeros(1, 2, dtype=torch.float64), torch.full((1, 2), 2.5, dtype=torch.float64)
    s.known[0] = {1: (s.opts[0].normalize(near)[0].tolist(), True)}
    assert s._doomed(0, torch.cat([near, far])).tolist() == [True, False]


def test_the_pool_ranks_doomed_entries_last_then_by_cost() -> None:
    a, b = _pool([0, 1], [-1, -1], [3.0, 1.0]), _pool([2, 3], [-1, -1], [0.5, 2.0])
    b.doomed = torch.tensor([True, False])
    assert a.merged(b, 3).ids.tolist() == [1, 3, 0]
    assert a.merged(a.take(torch.zeros(0, dtype=torch.long)), 5).ids.tolist() == [1, 0]


# ---- state and input ---------------------------------------------------------------------------

@pytest.mark.parametrize("pause_after", [1, 3, 6])
def test_a_paused_chain_goes_on_from_its_state_dict_as_if_never_paused(pause_after: int) -> None:
    cfg = StitchConfig(n_prefix=12, n_suffix=12, iterations=4, pool=3, confirm=2, splits=(1, 2), credit=2)
    whole, ev = _three(cfg, fail_if=lambda s: s[:, 0] > 1.5)
    whole_res = whole.run(ev)
    first, ev = _three(cfg, fail_if=lambda s: s[:, 0] > 1.5)
    names = chain_names(3)
    for _ in range(pause_after):
        b = first.ask()
        r, ends = ev(names[b.candidate], b.Z, b.starts)
        r.end_states = ends
        first.tell(r)
    saved = json.loads(json.dumps(first.state_dict()))  # as a checkpoint holds it
    second, _ = _three(cfg, fail_if=lambda s: s[:, 0] > 1.5)
    second.read_state = tuple  # the analytic states are tuples; JSON gives lists
    second.load_state_dict(saved)
    assert second.iterations_done == pause_after
    rest = second.run(ev)
    assert torch.equal(rest.z, whole_res.z) and rest.cost == whole_res.cost and rest.confirmed == whole_res.confirmed


def test_bad_chains_are_refused() -> None:
    full, segs, cols = _chain_layouts([[0], [1], [2]])
    with pytest.raises(ValueError, match="needs at least 3 rounds"):
        ChainSearch(full, segs, cols, _ce(10, 2), StitchConfig(iterations=2, splits=(1, 2)))
    with pytest.raises(ValueError, match="must split the plan's 6 columns"):
        ChainSearch(full, segs, [cols[0], cols[1], cols[1]], _ce(10, 3), StitchConfig(iterations=3))
    with pytest.raises(ValueError, match="stitch.credit = -1"):
        StitchConfig(credit=-1)
    with pytest.raises(ValueError, match="stitch.splits"):
        StitchConfig(splits=(2, 1))
    with pytest.raises(ValueError, match="not a stitched chain's state"):
        ChainSearch(full, segs, cols, _ce(10, 3), StitchConfig(iterations=3)).load_state_dict({"kind": "stitched"})
    assert StitchConfig(iterations=5, splits=(1, 2)).batches == 3 * 5 - 3 + 1
    assert StitchConfig(iterations=5, split=2).batches == 10 and not StitchConfig(split=2).chain
