"""The fast paths of the base planner, against the implementations they replace and oracles.

* Bit-identical rewrites (numbers must not move): the octile heuristic read from a table equals
  the direct formula bit for bit; the waypoint shortcut loop (restricted to the plans a position
  concerns, stopped at the longest thinned path) equals the original loop, kept here as the
  reference, on the seed and wall scenes.
* ``planner="field"`` (cached Dijkstra fields): the same found / status / snapping / endpoints and
  costs as batched A* over many random pairs on the seed and wall scenes, and as networkx on random
  grids; valid paths; a plan's path does not depend on its batch; the caches follow the map's
  content (another scene, an in-place edit) instead of going stale.
"""

from __future__ import annotations

import math

import networkx as nx
import pytest
import torch

from helpers import assert_path_valid
from realize.controllers import astar_field, grid_cache
from realize.controllers.astar import AStarStatus, astar, astar_world
from realize.controllers.astar_search import SQRT2, _heuristic, _TIE, octile
from realize.controllers.grid_cache import clear_grid_cache, grid_cached
from realize.controllers.occupancy import cell_in_grid, cell_to_world, grid_from_bounds, occupancy_from_boxes, world_to_cell
from realize.controllers.waypoints import _compact, path_to_waypoints
from realize.world.geometry import GeometryCfg, WallCfg, build_geometry
from realize.robot.spec import DEFAULT_ROBOT, load_robot_spec

FOOTPRINT = load_robot_spec(DEFAULT_ROBOT).base.footprint_radius  # the default robot's (A* pads by it)


def scene_grid(variant: str):
    # wider than configs/scene/ (y +-2.5), so that the test's routes behind the tables exist
    geo = build_geometry(GeometryCfg(variant=variant, walls=[WallCfg()] if variant == "wall" else [],
                                     bounds_low=(-3.0, -3.0), bounds_high=(3.2, 3.0)))
    spec = grid_from_bounds((geo.bounds_low[0], geo.bounds_low[1], geo.bounds_high[0], geo.bounds_high[1]), 0.05)
    obs = geo.obstacles
    occ = occupancy_from_boxes(spec, torch.tensor([b.center[:2] for b in obs]),
                               torch.tensor([b.footprint_half_size() for b in obs]),
                               torch.tensor([b.yaw for b in obs]), padding=0.2 + FOOTPRINT)
    return spec, occ


def random_world_pairs(spec, n: int, seed: int):
    gen = torch.Generator().manual_seed(seed)
    lo = torch.tensor(spec.origin)
    span = torch.tensor([spec.width, spec.height], dtype=torch.float32) * spec.resolution
    return lo + span * torch.rand(n, 2, generator=gen), lo + span * torch.rand(n, 2, generator=gen)


# ------------------------------------------------------------------ bit-identical rewrites
@pytest.mark.parametrize("dtype", [torch.float64, torch.float32])
def test_heuristic_table_is_bit_identical_to_direct_octile(dtype):
    gen = torch.Generator().manual_seed(0)
    for h, w in ((1, 1), (7, 3), (120, 124), (33, 90)):
        hw = h * w
        gw = torch.randint(0, hw, (17,), generator=gen)
        cells = torch.arange(hw + 1)
        direct = octile((cells[None] // w - (gw // w)[:, None]).to(dtype),
                        (cells[None] % w - (gw % w)[:, None]).to(dtype)) * (1.0 + _TIE)
        assert torch.equal(_heuristic(gw, h, w, dtype), direct)


def reference_waypoints(result, spec, occupied, start_xy, goal_xy, dtype=torch.float32):
    """path_to_waypoints as it was before the fast shortcut loop (thin=True)."""
    n, l = result.path.shape[:2]
    j = torch.arange(l)[None]
    ln = result.lengths
    pts = cell_to_world(spec, result.path.clamp(min=0), dtype=dtype)
    keep = j < ln[:, None]
    if l > 2:
        d = result.path[:, 1:] - result.path[:, :-1]
        same = (d[:, 1:] == d[:, :-1]).all(dim=-1)
        drop = torch.zeros_like(keep)
        drop[:, 1:-1] = same & (j[:, 1:-1] < (ln[:, None] - 1))
        keep = keep & ~drop
    pts, ln2 = _compact(pts, keep)
    l2 = pts.shape[1]
    if l2 > 2:
        free = ~occupied.bool().reshape(-1, spec.height, spec.width)
        keep = torch.zeros(n, l2, dtype=torch.bool)
        keep[:, 0] = ln2 > 0
        anchor = pts[:, 0]
        for jj in range(2, l2):
            a, b = anchor, pts[:, jj]
            n_s = int(torch.ceil((b - a).norm(dim=-1).max() / (0.25 * spec.resolution)).item()) + 2
            t = torch.linspace(0.0, 1.0, n_s, dtype=a.dtype)
            cells = world_to_cell(spec, a[:, None] + t[None, :, None] * (b - a)[:, None])
            inside = cell_in_grid(spec, cells)
            fr = free[0][cells[..., 0].clamp(0, spec.height - 1), cells[..., 1].clamp(0, spec.width - 1)]
            brk = (jj < ln2) & ~(fr & inside).all(dim=1)
            keep[:, jj - 1] = keep[:, jj - 1] | brk
            anchor = torch.where(brk[:, None], pts[:, jj - 1], anchor)
        last = (ln2 - 1).clamp(min=0)
        keep = keep | ((torch.arange(l2)[None] == last[:, None]) & (ln2[:, None] > 0))
        pts, ln2 = _compact(pts, keep)
        l2 = pts.shape[1]
    rep = result.found & ~result.goal_snapped
    is_last = torch.arange(l2)[None] >= (ln2 - 1).clamp(min=0)[:, None]
    pts = torch.where((rep[:, None] & is_last)[..., None], goal_xy.to(dtype)[:, None], pts)
    drop_first = result.found & ~result.start_snapped & (ln2 > 1)
    idx = (torch.arange(l2)[None] + drop_first[:, None].to(torch.int64)).clamp(max=l2 - 1)
    pts = pts.gather(1, idx[..., None].expand(-1, -1, 2))
    ln2 = ln2 - drop_first.to(torch.int64)
    fill = pts.gather(1, (ln2 - 1).clamp(min=0)[:, None, None].expand(-1, 1, 2))
    pts = torch.where((torch.arange(l2)[None] < ln2[:, None])[..., None], pts, fill)
    pts = torch.where((ln2 == 0)[:, None, None], torch.zeros_like(pts), pts)
    return pts, ln2


@pytest.mark.parametrize("variant", ["plain", "wall"])
@pytest.mark.parametrize("planner", ["astar", "field"])
def test_waypoints_equal_the_original_shortcut_loop(variant, planner):
    spec, occ = scene_grid(variant)
    for seed, n in ((0, 200), (1, 7), (2, 1)):
        s, g = random_world_pairs(spec, n, seed)
        res = astar_world(occ, spec, s, g, planner=planner)
        wps = path_to_waypoints(res, spec, occupied=occ, start_xy=s, goal_xy=g)
        pts, ln = reference_waypoints(res, spec, occ, s, g)
        assert torch.equal(wps.points, pts) and torch.equal(wps.lengths, ln)


# ------------------------------------------------------------------ field planner
@pytest.mark.parametrize("variant", ["plain", "wall"])
def test_field_matches_astar_on_scenes(variant):
    """Random pairs anywhere on the map (many start or end inside padding and get snapped, some
    goals are unreachable): everything but the choice among equal-cost paths agrees with A*."""
    spec, occ = scene_grid(variant)
    s, g = random_world_pairs(spec, 300, 10)
    s[:100] = s[0]  # a common start, as at a run's first move_to
    ref = astar_world(occ, spec, s, g)
    clear_grid_cache()
    for _ in range(2):  # cold, then from the cached fields
        got = astar_world(occ, spec, s, g, planner="field")
        for f in ("found", "status", "start", "goal", "start_snapped", "goal_snapped"):
            assert torch.equal(getattr(got, f), getattr(ref, f)), f
        fin = ref.found
        assert torch.allclose(got.cost[fin], ref.cost[fin], rtol=0, atol=1e-9)
        assert torch.isinf(got.cost[~fin]).all() and (got.lengths[~fin] == 0).all()
        for i in fin.nonzero().flatten().tolist():
            assert_path_valid(occ, got.path[i], int(got.lengths[i]), got.start[i].tolist(), got.goal[i].tolist(),
                              float(got.cost[i]))
    assert int(fin.sum()) >= 100 and bool(ref.start_snapped.any()) and bool(ref.goal_snapped.any())


def test_field_costs_match_networkx_on_random_grids():
    gen = torch.Generator().manual_seed(21)
    for _ in range(6):
        occ = torch.rand(20, 27, generator=gen) < 0.3
        free_cells = (~occ).nonzero()
        pick = torch.randint(0, free_cells.shape[0], (2, 25), generator=gen)
        s, t = free_cells[pick[0]], free_cells[pick[1]]
        g = nx.Graph()
        for r in range(20):
            for c in range(27):
                for dr, dc in ((0, 1), (1, 0), (1, 1), (1, -1)):
                    rr, cc = r + dr, c + dc
                    if occ[r, c] or not (0 <= rr < 20 and 0 <= cc < 27) or occ[rr, cc]:
                        continue
                    if dr and dc and (occ[r + dr, c] or occ[r, c + dc]):
                        continue
                    g.add_edge((r, c), (rr, cc), weight=SQRT2 if (dr and dc) else 1.0)
        res = astar(occ, s, t, planner="field")
        for i in range(25):
            a, b = tuple(s[i].tolist()), tuple(t[i].tolist())
            try:
                ref = 0.0 if a == b else nx.dijkstra_path_length(g, a, b)
            except (nx.NetworkXNoPath, nx.NodeNotFound):
                ref = math.inf
            if math.isinf(ref):
                assert not bool(res.found[i]) and int(res.status[i]) == AStarStatus.UNREACHABLE
            else:
                assert float(res.cost[i]) == pytest.approx(ref, abs=1e-9)
                assert_path_valid(occ, res.path[i], int(res.lengths[i]), a, b, float(res.cost[i]))


def test_field_paths_do_not_depend_on_the_batch():
    spec, occ = scene_grid("wall")
    s, g = random_world_pairs(spec, 40, 3)
    batch = astar_world(occ, spec, s, g, planner="field")
    for i in range(0, 40, 3):
        one = astar_world(occ, spec, s[i:i + 1], g[i:i + 1], planner="field")
        ln = int(one.lengths[0])
        assert ln == int(batch.lengths[i]) and torch.equal(one.path[0, :ln], batch.path[i, :ln])


def test_common_start_computes_one_field_and_reuses_it():
    spec, occ = scene_grid("plain")
    clear_grid_cache()
    _, g = random_world_pairs(spec, 200, 4)
    s = torch.tensor([[-2.0, 0.0]]).expand(200, 2)
    first = astar_world(occ, spec, s, g, planner="field")
    assert int((first.expansions > 0).sum()) == 1  # one field for 200 plans
    again = astar_world(occ, spec, s, g.flip(0), planner="field")
    assert int(again.expansions.sum()) == 0  # from the cache


def test_caches_follow_the_map_content():
    spec, plain = scene_grid("plain")
    _, wall = scene_grid("wall")
    assert not torch.equal(plain, wall)
    clear_grid_cache()
    s = torch.tensor([[0.0, -2.4], [-2.0, 0.0]]).repeat(10, 1)
    g = torch.tensor([[0.0, 2.4], [2.4, 0.0]]).repeat(10, 1)
    costs = {}
    for name, occ in (("plain", plain), ("wall", wall), ("plain", plain)):
        got = astar_world(occ, spec, s, g, planner="field")
        ref = astar_world(occ, spec, s, g)
        assert torch.allclose(got.cost, ref.cost, rtol=0, atol=1e-9)
        costs.setdefault(name, got.cost)
    assert not torch.allclose(costs["plain"], costs["wall"])  # the wall lengthens some routes
    # an in-place edit of the same tensor is a new map: block a row across the whole grid
    occ = plain.clone()
    before = astar_world(occ, spec, s, g, planner="field")
    assert bool(before.found.all())
    occ[spec.height // 2] = True
    after = astar_world(occ, spec, s, g, planner="field")
    assert torch.equal(after.found, astar_world(occ, spec, s, g).found) and not bool(after.found.all())
    # the grid cache keeps a bounded number of maps, most recent first
    calls = []
    for k in range(grid_cache._MAX_GRIDS + 2):
        grid_cached("probe", torch.full((3, 3), k), lambda f: calls.append(1) or f.sum())
    assert len(grid_cache._ENTRIES) == grid_cache._MAX_GRIDS
    grid_cached("probe", torch.full((3, 3), grid_cache._MAX_GRIDS + 1), lambda f: calls.append(1))
    assert len(calls) == grid_cache._MAX_GRIDS + 2  # the latest map was a hit


def test_field_cache_is_bounded(monkeypatch):
    monkeypatch.setattr(astar_field, "_MAX_FIELDS", 5)
    spec, occ = scene_grid("plain")
    clear_grid_cache()
    s, g = random_world_pairs(spec, 12, 5)
    for i in range(12):
        astar_world(occ, spec, s[i:i + 1], g[i:i + 1], planner="field")
    fields = grid_cached("astar_fields", ~occ[None], lambda f: None)
    assert len(fields.dist) == 5
    # a call with more distinct starts than the cache holds, mixing cached and new ones
    res = astar_world(occ, spec, s, g, planner="field")
    assert torch.allclose(res.cost, astar_world(occ, spec, s, g).cost, rtol=0, atol=1e-9, equal_nan=True)
    assert len(fields.dist) == 5


def test_field_planner_on_per_plan_grids_matches_the_shared_grid_and_astar():
    # plan i on its own grid (the wall world, plus a random block of cells for odd i): the same
    # cost as A* on that grid, and the same path as the field on that grid alone (no batch effect)
    spec, occ = scene_grid("wall")
    s, g = random_world_pairs(spec, 12, 7)
    grids = occ.expand(12, -1, -1).clone()
    gen = torch.Generator().manual_seed(3)
    for i in range(1, 12, 2):
        r, c = (int(torch.randint(10, spec.height - 20, (1,), generator=gen)),
                int(torch.randint(10, spec.width - 20, (1,), generator=gen)))
        grids[i, r:r + 12, c:c + 4] = True
    got = astar_world(grids, spec, s, g, planner="field")
    ref = astar_world(grids, spec, s, g)
    assert torch.equal(got.found, ref.found) and torch.equal(got.status, ref.status)
    assert torch.allclose(got.cost, ref.cost, rtol=0, atol=1e-9, equal_nan=True)
    for i in range(12):
        one = astar_world(grids[i], spec, s[i:i + 1], g[i:i + 1], planner="field")
        ln = int(one.lengths[0])
        assert ln == int(got.lengths[i]) and torch.equal(one.path[0, :ln], got.path[i, :ln])
        if ln:
            assert_path_valid(grids[i], got.path[i], ln, got.start[i], got.goal[i], float(got.cost[i]))


def test_unknown_planner_is_refused():
    occ = torch.zeros(5, 5, dtype=torch.bool)
    cells = torch.zeros(2, 2, dtype=torch.int64)
    with pytest.raises(ValueError, match="planner"):
        astar(occ, cells, cells, planner="dijkstra")
