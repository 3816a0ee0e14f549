"""Batched A* and occupancy grids, checked against networkx on the same graph.

Oracle graph: free cells, 8-connected, orthogonal cost 1, diagonal cost sqrt(2), a diagonal edge
only where both orthogonally adjacent cells are free (the planner's corner rule).
"""

from __future__ import annotations

import math

import networkx as nx
import pytest
import torch

from helpers import assert_path_valid
from realize.controllers.astar import AStarStatus, astar, astar_world
from realize.controllers.astar_search import SQRT2
from realize.controllers.grid_cells import components
from realize.controllers.waypoints import path_to_waypoints
from realize.controllers.occupancy import (
    GridSpec,
    cell_in_grid,
    cell_to_world,
    grid_from_bounds,
    occupancy_from_boxes,
    world_to_cell,
)


# ----------------------------------------------------------------------------- helpers
def oracle_graph(occ: torch.Tensor) -> "nx.Graph":
    h, w = occ.shape
    o = occ.tolist()
    g = nx.Graph()
    for r in range(h):
        for c in range(w):
            if o[r][c]:
                continue
            g.add_node((r, c))
            for dr, dc in ((0, 1), (1, 0), (1, 1), (1, -1)):
                rr, cc = r + dr, c + dc
                if not (0 <= rr < h and 0 <= cc < w) or o[rr][cc]:
                    continue
                if dr and dc and (o[r + dr][c] or o[r][c + dc]):
                    continue
                g.add_edge((r, c), (rr, cc), weight=SQRT2 if (dr and dc) else 1.0)
    return g


def octile_h(u, v) -> float:
    a, b = abs(u[0] - v[0]), abs(u[1] - v[1])
    return max(a, b) + (SQRT2 - 1.0) * min(a, b)


def oracle_cost(g, s, t) -> float:
    try:
        return nx.astar_path_length(g, s, t, heuristic=octile_h, weight="weight")
    except nx.NetworkXNoPath:
        return math.inf


def random_pairs(gen, n, h, w):
    s = torch.stack([torch.randint(0, h, (n,), generator=gen), torch.randint(0, w, (n,), generator=gen)], 1)
    t = torch.stack([torch.randint(0, h, (n,), generator=gen), torch.randint(0, w, (n,), generator=gen)], 1)
    return s, t


# ----------------------------------------------------------------------------- A* vs oracle
def test_costs_match_networkx_on_240_random_grids():
    """240 seeded grids of random size and density, 8 pairs each, all searched in ONE call with
    per-plan grids (grids padded to 16x16 with blocked cells); costs equal networkx's."""
    gen = torch.Generator().manual_seed(1234)
    n_grids, per, side = 240, 8, 16
    grids, starts, goals, sizes = [], [], [], []
    for i in range(n_grids):
        h, w = torch.randint(1, side + 1, (2,), generator=gen).tolist()
        density = [0.0, 0.15, 0.3, 0.45][i % 4]
        occ = torch.rand(h, w, generator=gen) < density
        free = (~occ).nonzero()
        if free.shape[0] == 0:
            occ[0, 0] = False
            free = (~occ).nonzero()
        # pick endpoints among free cells (snapping is tested separately)
        si = torch.randint(0, free.shape[0], (per,), generator=gen)
        gi = torch.randint(0, free.shape[0], (per,), generator=gen)
        s, t = free[si], free[gi].clone()
        t[0] = s[0]  # start == goal in every grid
        padded = torch.ones(side, side, dtype=torch.bool)
        padded[:h, :w] = occ
        grids.append(padded.expand(per, side, side))
        starts.append(s)
        goals.append(t)
        sizes.append((h, w, occ))
    occ_all = torch.cat(grids)
    res = astar(occ_all, torch.cat(starts), torch.cat(goals))
    n_unreach = n_zero = 0
    for i, (h, w, occ) in enumerate(sizes):
        g = oracle_graph(occ)
        for k in range(per):
            p = i * per + k
            s = tuple(starts[i][k].tolist())
            t = tuple(goals[i][k].tolist())
            ref = oracle_cost(g, s, t)
            got = float(res.cost[p])
            assert not bool(res.start_snapped[p]) and not bool(res.goal_snapped[p])
            if math.isinf(ref):
                n_unreach += 1
                assert math.isinf(got) and not bool(res.found[p])
                assert int(res.status[p]) == AStarStatus.UNREACHABLE and int(res.lengths[p]) == 0
            else:
                assert got == pytest.approx(ref, abs=1e-9), (i, k, s, t)
                assert bool(res.found[p]) and int(res.status[p]) == AStarStatus.OK
                assert_path_valid(occ, res.path[p], int(res.lengths[p]), s, t, got)
                if s == t:
                    n_zero += 1
                    assert got == 0.0 and int(res.lengths[p]) == 1
    assert n_unreach >= 20 and n_zero >= n_grids


@pytest.mark.parametrize("k", [1, 3, 16, None])
def test_shared_grid_all_pop_sizes_match_networkx(k):
    gen = torch.Generator().manual_seed(7)
    occ = torch.rand(30, 40, generator=gen) < 0.3
    s, t = random_pairs(gen, 40, 30, 40)
    res = astar(occ, s, t, expansions_per_step=k, snap=False)
    g = oracle_graph(occ)
    for i in range(40):
        if bool(occ[s[i, 0], s[i, 1]]) or bool(occ[t[i, 0], t[i, 1]]):
            expected = AStarStatus.START_OCCUPIED if bool(occ[s[i, 0], s[i, 1]]) else AStarStatus.GOAL_OCCUPIED
            assert int(res.status[i]) == expected and not bool(res.found[i])
            continue
        ref = oracle_cost(g, tuple(s[i].tolist()), tuple(t[i].tolist()))
        assert float(res.cost[i]) == pytest.approx(ref, abs=1e-9) if math.isfinite(ref) else math.isinf(float(res.cost[i]))
        if math.isfinite(ref):
            assert_path_valid(occ, res.path[i], int(res.lengths[i]), s[i].tolist(), t[i].tolist(), float(res.cost[i]))


def test_batched_equals_per_sample():
    gen = torch.Generator().manual_seed(3)
    occ = torch.rand(25, 35, generator=gen) < 0.25
    s, t = random_pairs(gen, 24, 25, 35)
    t[5] = torch.tensor([40, 1])  # off the grid: must not disturb the others
    batched = astar(occ, s, t, expansions_per_step=4)
    per_plan = astar(occ.expand(24, 25, 35), s, t, expansions_per_step=4)
    for i in range(24):
        single = astar(occ, s[i:i + 1], t[i:i + 1], expansions_per_step=4)
        for r in (batched, per_plan):
            assert int(r.status[i]) == int(single.status[0])
            assert float(r.cost[i]) == float(single.cost[0]) or (
                math.isinf(float(r.cost[i])) and math.isinf(float(single.cost[0])))
            ln = int(single.lengths[0])
            # equal cost a + b sqrt(2) means equal step counts; among several optimal paths the
            # one returned may differ with the batch (tie order in topk); each must be valid
            assert int(r.lengths[i]) == ln
            if ln:
                assert_path_valid(occ, r.path[i], ln, single.start[0].tolist(),
                                  single.goal[0].tolist(), float(single.cost[0]))
            assert bool(r.start_snapped[i]) == bool(single.start_snapped[0])
            assert bool(r.goal_snapped[i]) == bool(single.goal_snapped[0])


def test_same_call_is_deterministic():
    gen = torch.Generator().manual_seed(5)
    occ = torch.rand(30, 30, generator=gen) < 0.3
    s, t = random_pairs(gen, 50, 30, 30)
    a, b = astar(occ, s, t), astar(occ, s, t)
    assert torch.equal(a.path, b.path) and torch.equal(a.cost, b.cost) and torch.equal(a.status, b.status)


def test_open_floor_expands_about_path_length():
    occ = torch.zeros(40, 60, dtype=torch.bool)
    res = astar(occ, torch.tensor([[5, 5]]), torch.tensor([[35, 55]]), expansions_per_step=1)
    assert float(res.cost[0]) == pytest.approx(30 * SQRT2 + 20)
    assert int(res.expansions[0]) <= int(res.lengths[0]) + 2


# ----------------------------------------------------------------------------- snapping
def test_goal_and_start_snapping():
    occ = torch.zeros(20, 20, dtype=torch.bool)
    occ[5:10, 5:10] = True  # block
    occ[15:20, 15:20] = True
    occ[17, 17] = False  # a sealed free pocket inside the second block
    s = torch.tensor([[7, 7], [0, 0], [0, 0], [7, 6]])
    t = torch.tensor([[0, 0], [7, 8], [18, 18], [7, 6]])
    res = astar(occ, s, t)
    assert res.found.all(), [res.reason(i) for i in range(4)]
    assert res.start_snapped.tolist() == [True, False, False, True]
    assert res.goal_snapped.tolist() == [False, True, True, True]
    comp = components(~occ[None])[0]
    for i in range(4):
        for which, cell in (("start", res.start[i]), ("goal", res.goal[i])):
            assert not bool(occ[cell[0], cell[1]])
        # snapped start: nearest free cell (Euclidean); snapped goal: nearest free cell in the
        # start's component (so the sealed pocket at (17, 17) is never chosen)
        if bool(res.start_snapped[i]):
            free = (~occ).nonzero()
            d2 = ((free - s[i]) ** 2).sum(-1)
            assert int(((res.start[i] - s[i]) ** 2).sum()) == int(d2.min())
        if bool(res.goal_snapped[i]):
            sc = comp[res.start[i, 0] * 20 + res.start[i, 1]]
            free = (comp.reshape(20, 20) == sc).nonzero()
            d2 = ((free - t[i]) ** 2).sum(-1)
            assert int(((res.goal[i] - t[i]) ** 2).sum()) == int(d2.min())
        assert_path_valid(occ, res.path[i], int(res.lengths[i]), res.start[i].tolist(),
                          res.goal[i].tolist(), float(res.cost[i]))
    assert res.goal[2].tolist() != [17, 17]


def test_robot_parked_inside_table_padding_plans_away():
    """After a grasp the base sits within the 20 cm padding of the table: start must snap."""
    spec = grid_from_bounds((0.0, 0.0, 6.0, 4.0), 0.05)
    centers = torch.tensor([[2.0, 2.0], [4.5, 1.0]])
    half = torch.tensor([[0.4, 0.6], [0.3, 0.3]])
    occ = occupancy_from_boxes(spec, centers, half, torch.tensor([0.0, 0.4]), padding=0.2)
    start = torch.tensor([[2.5, 2.0], [2.0, 2.7], [4.5, 1.5]])  # 10 cm from table edges
    goal = torch.tensor([[5.5, 3.5], [0.5, 0.5], [2.6, 2.0]])  # last goal inside padding too
    res = astar_world(occ, spec, start, goal)
    assert res.found.all() and res.start_snapped.all()
    assert res.goal_snapped.tolist() == [False, False, True]
    wp = path_to_waypoints(res, spec, start_xy=start, goal_xy=goal)
    # snapped start: the first waypoint is the snapped free cell, close to the robot
    first = wp.points[:, 0]
    assert ((first - start).norm(dim=-1) < 0.2 + 2 * spec.resolution).all()
    # goal not snapped: final waypoint is the exact requested point
    last = wp.points.gather(1, (wp.lengths - 1)[:, None, None].expand(-1, 1, 2))[:, 0]
    assert torch.allclose(last[:2], goal[:2])


# ----------------------------------------------------------------------------- bad inputs
def test_bad_inputs_are_flagged_per_plan():
    occ = torch.zeros(10, 12, dtype=torch.bool)
    s = torch.tensor([[1.0, 1.0], [1.0, 1.0], [-1.0, 3.0], [1.0, 1.0], [2.0, 2.0]])
    t = torch.tensor([[8.0, 10.0], [10.0, 3.0], [3.0, 3.0], [float("nan"), 2.0], [2.0, 2.0]])
    res = astar(occ, s, t)
    assert [res.reason(i) for i in range(5)] == [
        "OK", "GOAL_OUT_OF_GRID", "START_OUT_OF_GRID", "NONFINITE_INPUT", "OK"]
    assert res.found.tolist() == [True, False, False, False, True]
    assert torch.isinf(res.cost[1:4]).all() and (res.lengths[1:4] == 0).all()
    assert float(res.cost[4]) == 0.0

    full = torch.ones(4, 4, dtype=torch.bool)
    r2 = astar(full, torch.tensor([[0, 0]]), torch.tensor([[3, 3]]))
    assert r2.reason(0) == "NO_FREE_CELL" and not bool(r2.found[0])

    spec = grid_from_bounds((0, 0, 1.2, 1.0), 0.1)
    r3 = astar_world(occ, spec, torch.tensor([[0.15, 0.15], [0.15, 0.15]]),
                     torch.tensor([[5.0, 0.5], [float("inf"), 0.5]]))
    assert [r3.reason(i) for i in range(2)] == ["GOAL_OUT_OF_GRID", "NONFINITE_INPUT"]


def test_bad_arguments_raise_clear_errors():
    occ = torch.zeros(5, 5, dtype=torch.bool)
    s = torch.tensor([[0, 0]])
    with pytest.raises(ValueError, match="expansions_per_step"):
        astar(occ, s, s, expansions_per_step=0)
    with pytest.raises(ValueError, match="goal"):
        astar(occ, s, torch.tensor([[0, 0], [1, 1]]))
    with pytest.raises(ValueError, match="start"):
        astar(occ, torch.tensor([0, 0]), s)
    with pytest.raises(ValueError, match="occupied"):
        astar(torch.zeros(5, dtype=torch.bool), s, s)
    with pytest.raises(ValueError, match="padding"):
        occupancy_from_boxes(GridSpec((0, 0), 0.1, (5, 5)), torch.zeros(1, 2), torch.ones(1, 2), padding=-0.1)
    with pytest.raises(ValueError, match="resolution"):
        GridSpec((0, 0), 0.0, (5, 5))


# ----------------------------------------------------------------------------- occupancy
def test_padded_box_covers_expected_cells():
    spec = GridSpec(origin=(-1.0, -2.0), resolution=0.1, shape=(40, 30))
    c, he, pad = (0.52, -0.31), (0.3, 0.2), 0.25
    occ = occupancy_from_boxes(spec, torch.tensor([c]), torch.tensor([he]), padding=pad, pad_bounds=False)
    for r in range(40):
        for col in range(30):
            x = -1.0 + (col + 0.5) * 0.1
            y = -2.0 + (r + 0.5) * 0.1
            ex = max(abs(x - c[0]) - he[0], 0.0)
            ey = max(abs(y - c[1]) - he[1], 0.0)
            d = math.hypot(ex, ey)
            if abs(d - pad) > 1e-6:
                assert bool(occ[r, col]) == (d <= pad), (r, col, d)
    # the box itself (unpadded) is inside; the rounded corners are not blocked as a square would be
    corner = world_to_cell(spec, torch.tensor([c[0] + he[0] + 0.2, c[1] + he[1] + 0.2]))
    assert not bool(occ[corner[0], corner[1]])


def test_yawed_boxes_batched_bounds_and_mask():
    spec = grid_from_bounds((0.0, 0.0, 4.0, 3.0), 0.05)
    c = torch.tensor([[1.0, 1.5], [3.0, 1.0]])
    he = torch.tensor([[0.5, 0.2], [0.2, 0.5]])
    rot = occupancy_from_boxes(spec, c[:1], he[:1], torch.tensor([math.pi / 2]), padding=0.1, pad_bounds=False)
    swapped = occupancy_from_boxes(spec, c[:1], he[:1].flip(-1), None, padding=0.1, pad_bounds=False)
    assert (rot != swapped).sum() <= 4  # equal up to cells exactly on the boundary
    # batched: one grid per plan equals per-sample grids
    cb = torch.stack([c, c + 0.3, c - 0.2])
    yb = torch.tensor([[0.0, 0.3], [0.5, -0.2], [1.0, 0.0]])
    valid = torch.tensor([[True, True], [True, False], [False, False]])
    ob = occupancy_from_boxes(spec, cb, he.expand(3, 2, 2), yb, padding=0.2, valid=valid)
    assert ob.shape == (3, spec.height, spec.width)
    for i in range(3):
        keep = valid[i]
        oi = occupancy_from_boxes(spec, cb[i][keep], he[keep], yb[i][keep], padding=0.2)
        assert torch.equal(ob[i], oi)
    # no boxes: only the border band (cells whose centre is within the padding of the bounds)
    border = ob[2]
    assert border[0].all() and border[-1].all() and border[:, 0].all() and not border[10, 10]
    assert not occupancy_from_boxes(spec, cb[2][:0], he[:0], padding=0.2, pad_bounds=False).any()


def test_world_cell_roundtrip():
    spec = GridSpec(origin=(-2.0, 1.0), resolution=0.1, shape=(30, 50))
    cells = torch.tensor([[0, 0], [29, 49], [10, 3]])
    xy = cell_to_world(spec, cells)
    assert torch.equal(world_to_cell(spec, xy), cells)
    assert cell_in_grid(spec, world_to_cell(spec, torch.tensor([[-2.05, 1.5], [0.0, 4.01], [0.0, 2.0]]))).tolist() == [
        False, False, True]


# ----------------------------------------------------------------------------- waypoints
def test_waypoints_thin_and_shortcut_stay_free():
    spec = grid_from_bounds((0.0, 0.0, 6.0, 4.0), 0.1)
    occ = occupancy_from_boxes(spec, torch.tensor([[3.0, 1.5]]), torch.tensor([[0.1, 1.5]]), padding=0.3)
    start = torch.tensor([[1.0, 1.0], [1.0, 3.5]])
    goal = torch.tensor([[5.0, 1.0], [5.0, 3.5]])
    res = astar_world(occ, spec, start, goal)
    assert res.found.all()
    full = path_to_waypoints(res, spec, thin=False)
    thin = path_to_waypoints(res, spec)
    short = path_to_waypoints(res, spec, occupied=occ, start_xy=start, goal_xy=goal)
    assert torch.equal(full.lengths, res.lengths)
    assert (thin.lengths < full.lengths).all() and (short.lengths <= thin.lengths).all()
    assert torch.allclose(short.points[1, 0], goal[1])  # straight line above the wall: one waypoint
    for i in range(2):
        pts = torch.cat([start[i:i + 1], short.points[i, : int(short.lengths[i])]])
        for a, b in zip(pts[:-1], pts[1:]):
            tt = torch.linspace(0, 1, 200)[:, None]
            cells = world_to_cell(spec, a + tt * (b - a))
            assert not occ[cells[:, 0], cells[:, 1]].any()


@pytest.mark.gpu
@pytest.mark.skipif(not torch.cuda.is_available(), reason="needs CUDA")
def test_cuda_matches_cpu():
    gen = torch.Generator().manual_seed(11)
    occ = torch.rand(40, 50, generator=gen) < 0.25
    s, t = random_pairs(gen, 64, 40, 50)
    cpu = astar(occ, s, t)
    gpu = astar(occ.cuda(), s.cuda(), t.cuda())
    assert torch.equal(cpu.status, gpu.status.cpu())
    assert torch.allclose(cpu.cost, gpu.cost.cpu(), atol=1e-9)
