"""Batched A* on a 2D occupancy grid, in torch (CPU and CUDA, one code path).

What it does
------------
``astar`` runs N independent A* searches at once, one per (start, goal) cell pair, on one shared
grid (H, W) or on one grid per plan (N, H, W). The searches are vectorised across N: g-values,
current keys and parent pointers are dense (N, H*W) tensors, and every iteration each
still-running search pops its k lowest-key open entries, closes them and relaxes their 8
neighbours with gather / scatter-min ops. There is no Python loop over plans; the loop is over
iterations, and finished searches are compacted away (whenever half of the rows in the working set
are done) so the slowest plan does not drag the whole batch through the full-size tensors.

Graph (the test oracle builds exactly this graph for networkx):
  * nodes: free cells; 8-connected; orthogonal step cost 1, diagonal step cost sqrt(2), in cells
    (multiply by ``GridSpec.resolution`` for metres);
  * corner rule: **a diagonal move is allowed only if both orthogonally adjacent cells it passes
    between are free** (no squeezing between two diagonal obstacles, no clipping a corner);
  * heuristic: octile distance ``max(dr, dc) + (sqrt(2) - 1) * min(dr, dc)``, admissible and
    consistent for this graph.

Open list: a per-search buffer of (key, node) entries with lazy deletion (an improved node gets a
new entry, its old one goes stale and is skipped when popped), so a pop is a ``topk`` over the
buffer, not over the whole grid. Keys are ``g + (1 + 1e-10) h``: f-order with ties going to the
node nearer the goal (see ``_TIE``).

Optimality: with ``expansions_per_step == 1`` this is textbook A* (pop the min-key node). With
k > 1 it pops the k best entries per step; a closed node whose g later improves is re-opened, and
a search stops only when ``g(goal) <= min key over the open set`` (or the open set is empty), so
the returned cost is still optimal (some node of an optimal path is always open with its optimal
g). k > 1 trades extra expansions for far fewer iterations. The default (``None``) adapts k to the
number of running searches (about ``_POP_BUDGET`` pops per iteration in all, 4..64 each), since an
iteration's cost is mostly fixed op overhead when few searches run. Before searching, connected
components of the free cells are labelled; a goal in another component than the start is reported
UNREACHABLE without a search (otherwise A* would exhaust the start's component).

Determinism: the same call gives the same result. Among several optimal paths (equal cost), the one
returned may depend on the batch it ran in (``topk`` tie order after buffer compaction); cost,
status, snapping and path length do not.

Special cases, all per plan, never an exception for the batch:
  * start == goal: cost 0, path = [start], found True.
  * start inside an occupied cell: snapped to the nearest free cell (Euclidean distance in cells,
    ties -> lowest row-major index), flagged in ``start_snapped``. A robot parked beside a table
    after a grasp sits inside the table's inflated padding: its start moves to the closest free
    cell and the path begins there.
  * goal inside an occupied cell: snapped to the nearest free cell *in the (snapped) start's
    connected component*, i.e. the nearest free cell the robot can actually reach, flagged in
    ``goal_snapped``. Search, cost and path use the snapped cells (``start`` / ``goal`` fields).
    ``snap=False`` reports START_OCCUPIED / GOAL_OCCUPIED instead.
  * start / goal outside the grid: START_OUT_OF_GRID / GOAL_OUT_OF_GRID; non-finite coordinates
    (NaN / inf, for float inputs or world inputs): NONFINITE_INPUT; grid with no free cell at all
    when a snap is needed: NO_FREE_CELL; unreachable goal: UNREACHABLE. In all failure cases
    found=False, cost=inf, length 0.

What it does not do: no any-angle (theta*) search, no robot footprint beyond the grid's inflation,
no dynamic obstacles. ``path_to_waypoints`` turns cell paths into world waypoints, dropping
collinear cells and, optionally, shortcutting along sampled line-of-sight segments.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from enum import IntEnum

import torch
from torch import Tensor

from realize.controllers.occupancy import GridSpec, cell_in_grid, cell_to_world, world_to_cell

__all__ = [
    "AStarStatus",
    "AStarResult",
    "Waypoints",
    "astar",
    "astar_world",
    "path_to_waypoints",
    "octile",
    "components",
    "SQRT2",
]

SQRT2 = math.sqrt(2.0)

# 8 moves: 4 orthogonal then 4 diagonal, as (d_row, d_col)
_DR = (-1, 1, 0, 0, -1, -1, 1, 1)
_DC = (0, 0, -1, 1, -1, 1, -1, 1)
_COST = (1.0, 1.0, 1.0, 1.0, SQRT2, SQRT2, SQRT2, SQRT2)
# Tie-break weight: open nodes are ordered by key = g + (1 + _TIE) * h, i.e. by f with ties going
# to the node nearer the goal (on open floor this cuts expansions from the whole f-tie band to about
# the path length). It makes the search weighted A* with weight 1 + 1e-10, so the returned cost is
# at most (1 + 1e-10) C*; distinct path costs a + b sqrt(2) on grids up to thousands of cells a side
# differ by far more than 1e-10 C*, so the cost is exactly optimal there.
_TIE = 1e-10
# adaptive pops per iteration (expansions_per_step=None): aim for about _POP_BUDGET pops per
# batched iteration over all running searches, between _K_MIN and _K_MAX per search. Per-iteration
# cost is mostly fixed op overhead when few searches run, so the last, longest searches pop many.
_POP_BUDGET = 1024
_K_MIN = 4
_K_MAX = 64


class AStarStatus(IntEnum):
    """Per-plan outcome code (``AStarResult.status``)."""

    OK = 0
    UNREACHABLE = 1
    START_OUT_OF_GRID = 2
    GOAL_OUT_OF_GRID = 3
    NONFINITE_INPUT = 4
    NO_FREE_CELL = 5
    START_OCCUPIED = 6
    GOAL_OCCUPIED = 7
    ITERATION_LIMIT = 8


@dataclass
class AStarResult:
    """Batched A* output. All tensors lead with N (one row per plan).

    cost: (N,) path cost in cells (orthogonal 1, diagonal sqrt 2); inf when not found.
    found: (N,) bool.
    status: (N,) int64 ``AStarStatus`` codes; ``reason(i)`` gives the name.
    path: (N, L, 2) int64 (row, col) cells from start to goal, padded with -1 beyond ``lengths``.
    lengths: (N,) int64 number of cells on the path (1 when start == goal, 0 when not found).
    start, goal: (N, 2) int64 cells actually searched (after snapping; input cells otherwise,
        -1 where the input was invalid).
    start_snapped, goal_snapped: (N,) bool, True where the input cell was occupied and moved.
    expansions: (N,) int64 number of node expansions (re-expansions counted).
    iterations: number of batched iterations the search loop ran.
    """

    cost: Tensor
    found: Tensor
    status: Tensor
    path: Tensor
    lengths: Tensor
    start: Tensor
    goal: Tensor
    start_snapped: Tensor
    goal_snapped: Tensor
    expansions: Tensor
    iterations: int = 0

    def reason(self, i: int) -> str:
        """Human-readable status of plan ``i``."""
        return AStarStatus(int(self.status[i])).name

    def cost_m(self, spec: GridSpec) -> Tensor:
        """Cost in metres."""
        return self.cost * spec.resolution


@dataclass
class Waypoints:
    """World waypoints per plan: points (N, L, 2) (x, y), padded by repeating the last valid point
    (zeros for an empty plan); lengths (N,) int64 (0 when no path was found)."""

    points: Tensor
    lengths: Tensor


def octile(dr: Tensor, dc: Tensor) -> Tensor:
    """Octile distance for cell offsets (consistent heuristic for the 8-connected sqrt-2 graph)."""
    a, b = dr.abs(), dc.abs()
    return torch.maximum(a, b) + (SQRT2 - 1.0) * torch.minimum(a, b)


def _move_bits(free: Tensor) -> Tensor:
    """free (B, H, W) bool -> (B, H*W) uint8, bit d set when move d from that cell is allowed
    (target in grid and free; for diagonals both orthogonal side cells free too)."""
    b, h, w = free.shape
    fp = torch.zeros(b, h + 2, w + 2, dtype=torch.bool, device=free.device)
    fp[:, 1:-1, 1:-1] = free

    def shifted(dr: int, dc: int) -> Tensor:
        return fp[:, 1 + dr:1 + dr + h, 1 + dc:1 + dc + w]

    bits = torch.zeros(b, h, w, dtype=torch.uint8, device=free.device)
    for d, (dr, dc) in enumerate(zip(_DR, _DC)):
        ok = free & shifted(dr, dc)
        if dr != 0 and dc != 0:
            ok = ok & shifted(dr, 0) & shifted(0, dc)
        bits = bits | (ok.to(torch.uint8) << d)
    return bits.reshape(b, h * w)


def _as_cells(x: Tensor, name: str, n: int | None) -> tuple[Tensor, Tensor]:
    """Validate a (N, 2) cell tensor; returns (int64 cells with -1 where non-finite, finite mask)."""
    if x.ndim != 2 or x.shape[-1] != 2:
        raise ValueError(f"{name} must have shape (N, 2) as (row, col); got {tuple(x.shape)}")
    if n is not None and x.shape[0] != n:
        raise ValueError(f"{name} has {x.shape[0]} rows, expected {n}")
    if x.dtype.is_floating_point:
        finite = torch.isfinite(x).all(dim=-1)
        big = float(2 ** 30)
        xi = torch.floor(torch.nan_to_num(x, nan=-1.0).clamp(-big, big)).to(torch.int64)
        xi = torch.where(finite[:, None], xi, torch.full_like(xi, -1))
        return xi, finite
    if x.dtype == torch.bool or x.is_complex():
        raise ValueError(f"{name} must be an integer or float tensor, got {x.dtype}")
    return x.to(torch.int64), torch.ones(x.shape[0], dtype=torch.bool, device=x.device)


def components(free: Tensor) -> Tensor:
    """Connected-component labels of free cells, (B, H, W) bool -> (B, H*W) int64.

    Under the corner rule a diagonal move needs both orthogonal side cells free, so 8-connectivity
    reduces to 4-connectivity. Every free cell gets the flat index of one cell of its component
    (the same for the whole component); blocked cells get -1. Hook-and-shortcut label
    propagation (each round: hook every label's root to the smallest neighbouring label, then
    pointer-jump), a loop over rounds (about log of the component diameter), not over plans.
    """
    b, h, w = free.shape
    hw = h * w
    freef = free.reshape(b, hw)
    ar = torch.arange(hw, device=free.device).expand(b, hw)
    # column hw is a blocked sentinel whose label is itself
    lab = torch.cat([torch.where(freef, ar, hw), torch.full((b, 1), hw, device=free.device)], dim=1)
    big = torch.full((b, h, w), hw, dtype=lab.dtype, device=free.device)
    while True:
        grid = lab[:, :hw].reshape(b, h, w)
        m = grid.clone()
        m[:, 1:] = torch.minimum(m[:, 1:], grid[:, :-1])
        m[:, :-1] = torch.minimum(m[:, :-1], grid[:, 1:])
        m[:, :, 1:] = torch.minimum(m[:, :, 1:], grid[:, :, :-1])
        m[:, :, :-1] = torch.minimum(m[:, :, :-1], grid[:, :, 1:])
        m = torch.where(free, m, big).reshape(b, hw)
        m = torch.cat([m, torch.full((b, 1), hw, dtype=m.dtype, device=m.device)], dim=1)
        new = lab.scatter_reduce(1, lab, m, reduce="amin")  # hook roots
        new = torch.minimum(new, m)
        while True:  # shortcut: point every cell at its label's label until flat
            nxt = new.gather(1, new)
            if torch.equal(nxt, new):
                break
            new = nxt
        if torch.equal(new, lab):
            break
        lab = new
    return torch.where(freef, lab[:, :hw], -1)


def _nearest_free(free_rows: Tensor, cells: Tensor, w: int) -> tuple[Tensor, Tensor]:
    """free_rows (K, HW) bool, cells (K, 2) -> (flat index of nearest free cell (K,), any free (K,))."""
    hw = free_rows.shape[1]
    idx = torch.arange(hw, device=cells.device)
    rr, cc = idx // w, idx % w
    dr_, dc_ = rr[None] - cells[:, :1], cc[None] - cells[:, 1:]
    d2 = dr_ * dr_ + dc_ * dc_
    d2 = torch.where(free_rows, d2, torch.full_like(d2, torch.iinfo(torch.int64).max))
    best = torch.argmin(d2, dim=1)  # first minimum -> lowest row-major index on ties
    return best, free_rows.any(dim=1)


def astar(
    occupied: Tensor,
    start: Tensor,
    goal: Tensor,
    *,
    snap: bool = True,
    expansions_per_step: int | None = None,
    max_iterations: int | None = None,
    dtype: torch.dtype = torch.float64,
) -> AStarResult:
    """Batched A* from ``start[i]`` to ``goal[i]`` for every plan i.

    occupied: (H, W) bool grid shared by all plans, or (N, H, W) one grid per plan (True = blocked).
    start, goal: (N, 2) cells as (row, col); integer tensors, or float tensors (floored; NaN / inf
        rows are flagged NONFINITE_INPUT).
    snap: move an occupied start / goal to the nearest free cell (flagged) instead of failing.
    expansions_per_step: open entries each search pops per batched iteration (>= 1; 1 = textbook
        A*; None = adaptive, the default; the cost is optimal for any value, see module docstring).
    max_iterations: cap on batched iterations (None: run until every search ends); searches cut
        off get ITERATION_LIMIT.
    dtype: float dtype of g / f (float64 keeps sums of many sqrt(2) steps exact enough to compare).

    Runs on the device of ``occupied``; start / goal are moved there.
    """
    if occupied.ndim not in (2, 3):
        raise ValueError(f"occupied must be (H, W) or (N, H, W); got {tuple(occupied.shape)}")
    if expansions_per_step is not None and (
            isinstance(expansions_per_step, bool) or not isinstance(expansions_per_step, int)
            or expansions_per_step < 1):
        raise ValueError(f"expansions_per_step must be None or an int >= 1, got {expansions_per_step!r}")
    if max_iterations is not None and max_iterations < 0:
        raise ValueError(f"max_iterations must be >= 0 or None, got {max_iterations}")
    device = occupied.device
    start_c, s_fin = _as_cells(start.to(device), "start", None)
    n = start_c.shape[0]
    goal_c, g_fin = _as_cells(goal.to(device), "goal", n)
    shared = occupied.ndim == 2
    if not shared and occupied.shape[0] != n:
        raise ValueError(f"per-plan occupied has {occupied.shape[0]} grids for {n} plans")
    h, w = occupied.shape[-2:]
    hw = h * w
    spec = GridSpec(origin=(0.0, 0.0), resolution=1.0, shape=(h, w))
    free = ~(occupied.bool().reshape(-1, h, w))  # (B, H, W), B = 1 or N
    free_flat = free.reshape(-1, hw)

    i64 = torch.int64
    status = torch.zeros(n, dtype=i64, device=device)
    status = torch.where(~(s_fin & g_fin), torch.full_like(status, AStarStatus.NONFINITE_INPUT), status)
    s_in = cell_in_grid(spec, start_c)
    g_in = cell_in_grid(spec, goal_c)
    status = torch.where((status == 0) & ~s_in, torch.full_like(status, AStarStatus.START_OUT_OF_GRID), status)
    status = torch.where((status == 0) & ~g_in, torch.full_like(status, AStarStatus.GOAL_OUT_OF_GRID), status)
    ok = status == 0
    start_c = torch.where(ok[:, None], start_c, torch.full_like(start_c, -1))
    goal_c = torch.where(ok[:, None], goal_c, torch.full_like(goal_c, -1))
    s_idx = torch.where(ok, start_c[:, 0] * w + start_c[:, 1], torch.zeros_like(status))
    g_idx = torch.where(ok, goal_c[:, 0] * w + goal_c[:, 1], torch.zeros_like(status))
    rows_all = torch.arange(n, device=device)
    grid_row = torch.zeros_like(rows_all) if shared else rows_all
    s_free = free_flat[grid_row, s_idx]
    g_free = free_flat[grid_row, g_idx]
    start_snapped = ok & ~s_free
    goal_snapped = ok & ~g_free

    bad_free = torch.zeros(n, dtype=torch.bool, device=device)
    if snap and bool(start_snapped.any()):
        rows = start_snapped.nonzero().squeeze(1)
        best, anyfree = _nearest_free(free_flat[grid_row[rows]], start_c[rows], w)
        s_idx = s_idx.index_put((rows,), torch.where(anyfree, best, s_idx[rows]))
        bad_free = bad_free.index_put((rows,), ~anyfree)
    # connected components (4-connectivity == 8-connectivity under the corner rule)
    comp = components(free)  # (B, HW)
    s_comp = comp[grid_row, s_idx]
    g_comp = comp[grid_row, g_idx]
    if snap and bool(goal_snapped.any()):
        rows = (goal_snapped & ~bad_free).nonzero().squeeze(1)
        if rows.numel():
            # nearest free cell in the (possibly snapped) start's component: the robot can get there
            same = comp[grid_row[rows]] == s_comp[rows, None]
            best, anyfree = _nearest_free(same, goal_c[rows], w)
            g_idx = g_idx.index_put((rows,), torch.where(anyfree, best, g_idx[rows]))
            g_comp = comp[grid_row, g_idx]
    if snap:
        status = torch.where(bad_free & (status == 0), torch.full_like(status, AStarStatus.NO_FREE_CELL), status)
        start_snapped = start_snapped & (status == 0)
        goal_snapped = goal_snapped & (status == 0)
    else:
        status = torch.where((status == 0) & start_snapped, torch.full_like(status, AStarStatus.START_OCCUPIED), status)
        status = torch.where((status == 0) & goal_snapped, torch.full_like(status, AStarStatus.GOAL_OCCUPIED), status)
        start_snapped = torch.zeros_like(start_snapped)
        goal_snapped = torch.zeros_like(goal_snapped)
    ok = status == 0
    start_c = torch.where(ok[:, None], torch.stack([s_idx // w, s_idx % w], -1), start_c)
    goal_c = torch.where(ok[:, None], torch.stack([g_idx // w, g_idx % w], -1), goal_c)
    # different components: unreachable without searching (A* would exhaust the start's component)
    searching = ok & (s_comp == g_comp) & (s_comp >= 0)

    cost = torch.full((n,), math.inf, dtype=dtype, device=device)
    expansions = torch.zeros(n, dtype=i64, device=device)
    reached = torch.zeros(n, dtype=torch.bool, device=device)
    limited = torch.zeros(n, dtype=torch.bool, device=device)
    iterations = 0

    orig = searching.nonzero().squeeze(1)  # working row -> plan index
    k_rows = int(orig.numel())
    out_parent = None
    if k_rows > 0:
        inf = math.inf
        eps = 1e-9
        # neighbour table: flat index of the cell reached by each of the 8 moves, hw (a dummy
        # column that is never read back) where the move is not allowed
        bits = _move_bits(free)  # (B, HW) uint8
        shifts = torch.arange(8, dtype=torch.uint8, device=device)
        dflat = torch.tensor([dr * w + dc for dr, dc in zip(_DR, _DC)], dtype=i64, device=device)
        step = torch.tensor(_COST, dtype=dtype, device=device)
        if shared:
            allowed = ((bits[0, :, None] >> shifts) & 1).bool()  # (HW, 8)
            table = torch.where(allowed, torch.arange(hw, device=device)[:, None] + dflat, hw)
            table = torch.cat([table, torch.full((1, 8), hw, dtype=i64, device=device)], dim=0)
        else:
            bits = torch.cat([bits, torch.zeros_like(bits[:, :1])], dim=1)
        out_parent = torch.full((k_rows, hw + 1), -1, dtype=torch.int32, device=device)
        out_row = torch.arange(k_rows, device=device)  # working row -> row of out_parent
        # dense per-node state: g, key of the node if open (inf if closed / unseen), parent
        g = torch.full((k_rows, hw + 1), inf, dtype=dtype, device=device)
        f_cur = torch.full_like(g, inf)
        parent = torch.full((k_rows, hw + 1), -1, dtype=torch.int32, device=device)
        sw, gw = s_idx[orig], g_idx[orig]
        cells = torch.arange(hw + 1, device=device)
        hh = octile((cells[None] // w - (gw // w)[:, None]).to(dtype),
                    (cells[None] % w - (gw % w)[:, None]).to(dtype))
        hh = hh * (1.0 + _TIE)  # key = g + (1 + tie) h: among equal f, pop the node nearer the goal
        ar = torch.arange(k_rows, device=device)
        g[ar, sw] = 0.0
        f_cur[ar, sw] = hh[ar, sw]
        # open list: per-row buffer of (key, node) entries with lazy deletion. An entry is live
        # when its key equals f_cur of its node; a node whose g improves gets a new entry and
        # its old one goes stale. Column `cap` is a write-only trash slot.
        if expansions_per_step is None:  # adaptive: about _POP_BUDGET pops per iteration in all
            k_max = min(_K_MAX, hw)
            kk = max(1, min(k_max, _POP_BUDGET // max(k_rows, 1), hw))
            kk = max(kk, min(_K_MIN, k_max))
        else:
            k_max = kk = min(expansions_per_step, hw)
        cap = max(64, 16 * kk)
        buf_key = torch.full((k_rows, cap + 1), inf, dtype=dtype, device=device)
        buf_node = torch.full((k_rows, cap + 1), hw, dtype=i64, device=device)
        buf_key[:, 0] = f_cur[ar, sw]
        buf_node[:, 0] = sw
        ptr = torch.ones(k_rows, dtype=i64, device=device)  # next free slot per row
        alive = torch.ones(k_rows, dtype=torch.bool, device=device)
        exp_w = torch.zeros(k_rows, dtype=i64, device=device)
        scratch = torch.zeros(k_rows, hw + 1, dtype=i64, device=device) if k_max > 1 else None
        jcol = torch.arange(8 * k_max, device=device)[None]

        def retire(mask: Tensor) -> None:
            """Copy parents of working rows in ``mask`` out (each row is retired exactly once)."""
            rows = mask.nonzero().squeeze(1)
            out_parent.index_copy_(0, out_row[rows], parent[rows])
            expansions.index_put_((orig[rows],), exp_w[rows])

        while True:
            if kk == 1:
                vals, pos = torch.min(buf_key, dim=1, keepdim=True)
            else:
                vals, pos = torch.topk(buf_key, kk, dim=1, largest=False, sorted=True)
            fmin = vals[:, 0]  # <= min key over the open set (stale entries only lower it)
            g_goal = g.gather(1, gw[:, None])[:, 0]
            # done: no open node's key is below the goal's g (inf <= inf covers an empty open set)
            fin = alive & (g_goal <= fmin * (1.0 + 1e-13))
            if bool(fin.any()):
                rows = fin.nonzero().squeeze(1)
                cost.index_put_((orig[rows],), g_goal[rows])
                reached.index_put_((orig[rows],), torch.isfinite(g_goal[rows]))
                alive = alive & ~fin
                # freeze finished searches: with no open entry and g = inf every later pop of
                # theirs relaxes nothing, so their parent pointers stay as they are
                buf_key.index_fill_(0, rows, inf)
                g.index_fill_(0, rows, inf)
                vals = vals.index_fill(0, rows, inf)
                n_alive = int(alive.sum())
                if n_alive == 0:
                    break
                rows_now = alive.shape[0]
                if n_alive <= rows_now // 2 and rows_now >= 8:
                    retire(~alive)
                    keep = alive.nonzero().squeeze(1)
                    g, f_cur, parent, hh = g[keep], f_cur[keep], parent[keep], hh[keep]
                    if scratch is not None:
                        scratch = scratch[keep]
                    buf_key, buf_node, ptr = buf_key[keep], buf_node[keep], ptr[keep]
                    orig, out_row, exp_w = orig[keep], out_row[keep], exp_w[keep]
                    gw, vals, pos, alive = gw[keep], vals[keep], pos[keep], alive[keep]
                    if expansions_per_step is None:
                        kk_new = min(k_max, max(kk, _POP_BUDGET // keep.numel()), cap)
                        if kk_new != kk:  # pop more per iteration from now on
                            kk = kk_new
                            vals, pos = torch.topk(buf_key, kk, dim=1, largest=False, sorted=True)
            if max_iterations is not None and iterations >= max_iterations:
                limited.index_put_((orig[alive],), torch.ones((), dtype=torch.bool, device=device))
                break
            iterations += 1
            node = buf_node.gather(1, pos)  # (K, k)
            buf_key.scatter_(1, pos, inf)  # entries are consumed whether live or stale
            live = (vals == f_cur.gather(1, node)) & (vals < inf)
            node = torch.where(live, node, hw)
            exp_w = exp_w + live.sum(dim=1)
            f_cur.scatter_(1, node, inf)  # close
            gi = g.gather(1, node)
            if shared:
                nb = table[node]  # (K, k, 8)
            else:
                b = bits[orig[:, None], node]
                mv = ((b[..., None] >> shifts) & 1).bool()
                nb = torch.where(mv, node[..., None] + dflat, hw)
            cand = (gi[..., None] + step).flatten(1)  # (K, 8k)
            nb = nb.flatten(1)
            src = node.to(torch.int32)[..., None].expand(-1, -1, 8).reshape(node.shape[0], -1)
            g_old = g.gather(1, nb)
            g.scatter_reduce_(1, nb, cand, reduce="amin")
            g_new = g.gather(1, nb)
            imp = (cand < g_old - eps) & (cand <= g_new) & (nb < hw)
            nb_w = torch.where(imp, nb, hw)
            if kk > 1:
                # several popped nodes may give a neighbour the same best g: push it once
                scratch.scatter_reduce_(1, nb_w, jcol[:, : nb_w.shape[1]].expand_as(nb_w),
                                        reduce="amax", include_self=False)
                imp = imp & (scratch.gather(1, nb_w) == jcol[:, : nb_w.shape[1]])
                nb_w = torch.where(imp, nb, hw)
            parent.scatter_(1, nb_w, src)
            key = cand + hh.gather(1, nb)
            f_cur.scatter_(1, nb_w, key)
            # push the improved nodes (re-opening closed ones) into the open buffer
            csum = torch.cumsum(imp, dim=1)
            cnt = csum[:, -1]
            need = int((ptr + cnt).max())
            if need > cap:
                # drop consumed / stale entries, pack live ones to the front, grow if still tight
                stale = buf_key != f_cur.gather(1, buf_node)
                bk = torch.where(stale, inf, buf_key)[:, :cap]
                bk, order = torch.sort(bk, dim=1, stable=True)
                bn = buf_node[:, :cap].gather(1, order)
                ptr = torch.isfinite(bk).sum(dim=1)
                new_cap = cap
                while int((ptr + cnt).max()) > new_cap // 2:
                    new_cap *= 2
                buf_key = torch.full((bk.shape[0], new_cap + 1), inf, dtype=dtype, device=device)
                buf_node = torch.full((bk.shape[0], new_cap + 1), hw, dtype=i64, device=device)
                buf_key[:, :cap] = bk
                buf_node[:, :cap] = bn
                cap = new_cap
            slot = torch.where(imp, ptr[:, None] + csum - 1, cap)
            buf_key.scatter_(1, slot, key)
            buf_node.scatter_(1, slot, nb)
            buf_key[:, cap] = inf
            ptr = ptr + cnt
        retire(torch.ones_like(alive))

    found = reached & ok
    status = torch.where(ok & limited, torch.full_like(status, AStarStatus.ITERATION_LIMIT), status)
    status = torch.where(ok & ~limited & ~found, torch.full_like(status, AStarStatus.UNREACHABLE), status)
    cost = torch.where(found, cost, torch.full_like(cost, math.inf))

    # ---- path reconstruction: walk parents back from the goal, loop over path length only ----
    lengths = torch.zeros(n, dtype=i64, device=device)
    path = torch.full((n, 1, 2), -1, dtype=i64, device=device)
    if out_parent is not None and bool(found.any()):
        srch = searching.nonzero().squeeze(1)
        fo = found[srch]  # found, in out_parent row order
        par = out_parent[fo].to(i64)
        plans = srch[fo]
        cur, s_end = g_idx[plans], s_idx[plans]
        ar = torch.arange(par.shape[0], device=device)
        rev = [cur]
        done = cur == s_end
        while not bool(done.all()):
            nxt = par[ar, cur]
            cur = torch.where(done, cur, nxt)
            rev.append(cur)
            done = done | (cur == s_end)
            if len(rev) > hw + 1:  # cannot happen with a consistent parent tree; guard anyway
                raise RuntimeError("A* parent pointers form a cycle")
        rev_t = torch.stack(rev, dim=1)  # (F, Lmax)
        lmax = rev_t.shape[1]
        # length = first position where the start appears, + 1
        is_s = rev_t == s_end[:, None]
        ln = torch.argmax(is_s.to(torch.int8), dim=1) + 1
        j = torch.arange(lmax, device=device)[None]
        src_j = (ln[:, None] - 1 - j).clamp(min=0)
        fwd = rev_t.gather(1, src_j)
        fwd_valid = j < ln[:, None]
        cells = torch.stack([fwd // w, fwd % w], dim=-1)
        cells = torch.where(fwd_valid[..., None], cells, torch.full_like(cells, -1))
        path = torch.full((n, lmax, 2), -1, dtype=i64, device=device)
        path[plans] = cells
        lengths[plans] = ln

    return AStarResult(
        cost=cost, found=found, status=status, path=path, lengths=lengths,
        start=start_c, goal=goal_c, start_snapped=start_snapped, goal_snapped=goal_snapped,
        expansions=expansions, iterations=iterations,
    )


def astar_world(
    occupied: Tensor,
    spec: GridSpec,
    start_xy: Tensor,
    goal_xy: Tensor,
    **kwargs,
) -> AStarResult:
    """``astar`` with world (x, y) start / goal points (N, 2); converts with ``world_to_cell``.

    Non-finite points are flagged NONFINITE_INPUT, points off the grid START/GOAL_OUT_OF_GRID.
    ``kwargs`` go to ``astar``. Costs are in cells (``result.cost_m(spec)`` for metres).
    """
    if tuple(occupied.shape[-2:]) != tuple(spec.shape):
        raise ValueError(f"occupied grid {tuple(occupied.shape[-2:])} does not match spec.shape {spec.shape}")
    for name, p in (("start_xy", start_xy), ("goal_xy", goal_xy)):
        if p.ndim != 2 or p.shape[-1] != 2:
            raise ValueError(f"{name} must be (N, 2); got {tuple(p.shape)}")
    dev = occupied.device
    s = world_to_cell(spec, start_xy.to(dev)).to(torch.float64)
    g = world_to_cell(spec, goal_xy.to(dev)).to(torch.float64)
    s = torch.where(torch.isfinite(start_xy.to(dev)).all(-1, keepdim=True), s, torch.full_like(s, math.nan))
    g = torch.where(torch.isfinite(goal_xy.to(dev)).all(-1, keepdim=True), g, torch.full_like(g, math.nan))
    return astar(occupied, s, g, **kwargs)


def _compact(points: Tensor, keep: Tensor) -> tuple[Tensor, Tensor]:
    """Keep points[i, j] where keep[i, j], packed to the front; pad by repeating the last kept point."""
    n, l = keep.shape
    pos = torch.cumsum(keep.to(torch.int64), dim=1) - 1
    lengths = keep.sum(dim=1)
    tgt = torch.where(keep, pos, torch.full_like(pos, l))  # column l = trash
    out = torch.zeros(n, l + 1, points.shape[-1], dtype=points.dtype, device=points.device)
    out = out.scatter(1, tgt[..., None].expand(-1, -1, points.shape[-1]), points)[:, :l]
    j = torch.arange(l, device=points.device)[None]
    last = (lengths - 1).clamp(min=0)
    fill = out.gather(1, last[:, None, None].expand(-1, 1, points.shape[-1]))
    out = torch.where((j < lengths[:, None])[..., None], out, fill)
    return out, lengths


def _line_free(free: Tensor, shared: bool, spec: GridSpec, a: Tensor, b: Tensor, rows: Tensor) -> Tensor:
    """Line of sight between world points a, b (K, 2): samples every quarter cell stay in free cells."""
    seg = (b - a).norm(dim=-1)
    n_s = int(torch.ceil(seg.max() / (0.25 * spec.resolution)).item()) + 2 if seg.numel() else 2
    t = torch.linspace(0.0, 1.0, n_s, device=a.device, dtype=a.dtype)
    pts = a[:, None] + t[None, :, None] * (b - a)[:, None]
    cells = world_to_cell(spec, pts)
    inside = cell_in_grid(spec, cells)
    r = cells[..., 0].clamp(0, spec.height - 1)
    c = cells[..., 1].clamp(0, spec.width - 1)
    if shared:
        fr = free[0][r, c]
    else:
        fr = free[rows[:, None], r, c]
    return (fr & inside).all(dim=1)


def path_to_waypoints(
    result: AStarResult,
    spec: GridSpec,
    *,
    thin: bool = True,
    occupied: Tensor | None = None,
    start_xy: Tensor | None = None,
    goal_xy: Tensor | None = None,
    dtype: torch.dtype = torch.float32,
) -> Waypoints:
    """Cell paths -> world waypoints (cell centres).

    thin: drop cells where the path keeps its direction (only corners remain, plus both ends).
    occupied: if given ((H, W) or (N, H, W)), also shortcut greedily: from each anchor, skip to the
        farthest later waypoint reachable in a straight line whose samples (every quarter cell) all
        lie in free cells. A sampled check, not an exact supercover; the grid's padding absorbs the
        difference.
    start_xy: (N, 2) current base positions; where the start was not snapped, the first waypoint
        (the start cell's centre, where the robot already is) is dropped if more remain.
    goal_xy: (N, 2) requested goals; where the goal was not snapped, the last waypoint becomes the
        exact goal point instead of its cell centre.
    Plans without a path get length 0.
    """
    n, l = result.path.shape[:2]
    dev = result.path.device
    j = torch.arange(l, device=dev)[None]
    ln = result.lengths
    valid = j < ln[:, None]
    pts = cell_to_world(spec, result.path.clamp(min=0), dtype=dtype)
    keep = valid.clone()
    if thin and l > 2:
        d = result.path[:, 1:] - result.path[:, :-1]  # (N, L-1, 2)
        same = (d[:, 1:] == d[:, :-1]).all(dim=-1)  # point j+1 is interior and straight
        interior = (j[:, 1:-1] < (ln[:, None] - 1))
        drop = torch.zeros_like(keep)
        drop[:, 1:-1] = same & interior
        keep = keep & ~drop
    pts, ln2 = _compact(pts, keep)
    l2 = pts.shape[1]

    if occupied is not None and l2 > 2:
        free = ~occupied.bool().reshape(-1, spec.height, spec.width)
        shared = free.shape[0] == 1
        rows = torch.arange(n, device=dev)
        keep = torch.zeros(n, l2, dtype=torch.bool, device=dev)
        keep[:, 0] = ln2 > 0
        anchor = pts[:, 0]
        for jj in range(2, l2):
            inpath = jj < ln2
            los = _line_free(free, shared, spec, anchor, pts[:, jj], rows)
            brk = inpath & ~los  # need to keep the previous point
            keep[:, jj - 1] = keep[:, jj - 1] | brk
            anchor = torch.where(brk[:, None], pts[:, jj - 1], anchor)
        last = (ln2 - 1).clamp(min=0)
        keep = keep | ((torch.arange(l2, device=dev)[None] == last[:, None]) & (ln2[:, None] > 0))
        pts, ln2 = _compact(pts, keep)
        l2 = pts.shape[1]

    if goal_xy is not None:
        rep = result.found & ~result.goal_snapped
        last = (ln2 - 1).clamp(min=0)
        is_last = torch.arange(l2, device=dev)[None] >= last[:, None]
        pts = torch.where((rep[:, None] & is_last)[..., None], goal_xy.to(dev, dtype)[:, None], pts)
    if start_xy is not None:
        drop_first = result.found & ~result.start_snapped & (ln2 > 1)
        idx = (torch.arange(l2, device=dev)[None] + drop_first[:, None].to(torch.int64)).clamp(max=l2 - 1)
        pts = pts.gather(1, idx[..., None].expand(-1, -1, 2))
        ln2 = ln2 - drop_first.to(torch.int64)
        # re-pad by repeating the last valid point
        last = (ln2 - 1).clamp(min=0)
        fill = pts.gather(1, last[:, None, None].expand(-1, 1, 2))
        pts = torch.where((torch.arange(l2, device=dev)[None] < ln2[:, None])[..., None], pts, fill)
    empty = ln2 == 0
    pts = torch.where(empty[:, None, None], torch.zeros_like(pts), pts)
    return Waypoints(points=pts, lengths=ln2)
