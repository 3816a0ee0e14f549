"""Batched A* on a 2D occupancy grid, in torch (CPU and CUDA, one code path): the entry points.

What it does
------------
``astar`` runs N independent A* searches at once, one per (start, goal) cell pair, on one shared
grid (H, W) or on one grid per plan (N, H, W): it validates and snaps the start / goal cells,
labels connected components (``realize.controllers.grid_cells``), runs the batched search loop
(``realize.controllers.astar_search``, where the open list, the pops per iteration and the
optimality argument are described) and walks the parent pointers back into cell paths.
``astar_world`` takes world (x, y) points instead of cells.

Graph (the test oracle builds exactly this graph for networkx):
  * nodes: free cells; 8-connected; orthogonal step cost 1, diagonal step cost sqrt(2), in cells
    (multiply by ``GridSpec.resolution`` for metres);
  * corner rule: **a diagonal move is allowed only if both orthogonally adjacent cells it passes
    between are free** (no squeezing between two diagonal obstacles, no clipping a corner);
  * heuristic: octile distance ``max(dr, dc) + (sqrt(2) - 1) * min(dr, dc)``, admissible and
    consistent for this graph.
Before searching, a goal in another connected component than the start is reported UNREACHABLE
without a search (otherwise A* would exhaust the start's component).

Determinism: the same call gives the same result. Among several optimal paths (equal cost), the one
returned may depend on the batch it ran in (``topk`` tie order after buffer compaction); cost,
status, snapping and path length do not. ``planner="field"`` (``realize.controllers.astar_field``)
replaces the search loop by cached per-start Dijkstra fields: same costs, statuses and snapping,
paths independent of the batch but in general other cells than A* picks among equal-cost paths.
What the static map alone determines (components, move table) is built once per grid content
(``realize.controllers.grid_cache``).

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
no dynamic obstacles, no waypoints (``realize.controllers.waypoints.path_to_waypoints`` turns
cell paths into world waypoints).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from enum import IntEnum

import torch
from torch import Tensor

from realize.controllers.astar_field import field_search
from realize.controllers.settings import PLANNERS
from realize.controllers.astar_search import run_search
from realize.controllers.grid_cache import grid_cached
from realize.controllers.grid_cells import as_cells, components, nearest_free
from realize.controllers.occupancy import GridSpec, cell_in_grid, world_to_cell

__all__ = ["PLANNERS", "AStarStatus", "AStarResult", "astar", "astar_world"]



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
    expansions: (N,) int64 number of node expansions (re-expansions counted; planner="field": cells
        reached by the Dijkstra fields computed in the call).
    iterations: number of batched iterations the search loop ran (0 for planner="field").
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


def astar(
    occupied: Tensor,
    start: Tensor,
    goal: Tensor,
    *,
    snap: bool = True,
    expansions_per_step: int | None = None,
    max_iterations: int | None = None,
    dtype: torch.dtype = torch.float64,
    planner: str = "astar",
) -> AStarResult:
    """Batched A* from ``start[i]`` to ``goal[i]`` for every plan i.

    occupied: (H, W) bool grid shared by all plans, or (N, H, W) one grid per plan (True = blocked).
    start, goal: (N, 2) cells as (row, col); integer tensors, or float tensors (floored; NaN / inf
        rows are flagged NONFINITE_INPUT).
    snap: move an occupied start / goal to the nearest free cell (flagged) instead of failing.
    expansions_per_step: open entries each search pops per batched iteration (>= 1; 1 = textbook
        A*; None = adaptive, the default; the cost is optimal for any value, see
        ``realize.controllers.astar_search``).
    max_iterations: cap on batched iterations (None: run until every search ends); searches cut
        off get ITERATION_LIMIT.
    dtype: float dtype of g / f (float64 keeps sums of many sqrt(2) steps exact enough to compare).
    planner: "astar" (the batched search loop) or "field" (cached Dijkstra fields per start cell,
        ``realize.controllers.astar_field``; per-plan grids get one uncached field each; ignores
        expansions_per_step and max_iterations). Both return optimal costs; among equal-cost paths they pick differently.

    Runs on the device of ``occupied``; start / goal are moved there.
    """
    if occupied.ndim not in (2, 3):
        raise ValueError(f"occupied must be (H, W) or (N, H, W); got {tuple(occupied.shape)}")
    if expansions_per_step is not None and (
            isinstance(expansions_per_step, bool) or not isinstance(expansions_per_step, int)
            or expansions_per_step < 1):
        raise ValueError(f"expansions_per_step must be None or an int >= 1, got {expansions_per_step!r}")
    if planner not in PLANNERS:
        raise ValueError(f"planner must be one of {PLANNERS}, got {planner!r}")
    if max_iterations is not None and max_iterations < 0:
        raise ValueError(f"max_iterations must be >= 0 or None, got {max_iterations}")
    device = occupied.device
    start_c, s_fin = as_cells(start.to(device), "start", None)
    n = start_c.shape[0]
    goal_c, g_fin = as_cells(goal.to(device), "goal", n)
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
        best, anyfree = nearest_free(free_flat[grid_row[rows]], start_c[rows], w)
        s_idx = s_idx.index_put((rows,), torch.where(anyfree, best, s_idx[rows]))
        bad_free = bad_free.index_put((rows,), ~anyfree)
    # connected components (4-connectivity == 8-connectivity under the corner rule)
    comp = grid_cached("components", free, components) if shared else components(free)  # (B, HW)
    s_comp = comp[grid_row, s_idx]
    g_comp = comp[grid_row, g_idx]
    if snap and bool(goal_snapped.any()):
        rows = (goal_snapped & ~bad_free).nonzero().squeeze(1)
        if rows.numel():
            # nearest free cell in the (possibly snapped) start's component: the robot can get there
            same = comp[grid_row[rows]] == s_comp[rows, None]
            best, anyfree = nearest_free(same, goal_c[rows], w)
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

    if planner == "field":
        out = field_search(free, searching, s_idx, g_idx, dtype=dtype)
    else:
        out = run_search(free, shared, searching, s_idx, g_idx, expansions_per_step=expansions_per_step,
                         max_iterations=max_iterations, dtype=dtype)
    cost, reached, limited, expansions = out.cost, out.reached, out.limited, out.expansions

    found = reached & ok
    status = torch.where(ok & limited, torch.full_like(status, AStarStatus.ITERATION_LIMIT), status)
    status = torch.where(ok & ~limited & ~found, torch.full_like(status, AStarStatus.UNREACHABLE), status)
    cost = torch.where(found, cost, torch.full_like(cost, math.inf))
    path, lengths = _trace_paths(out.parent, searching, found, s_idx, g_idx, w, hw)

    return AStarResult(
        cost=cost, found=found, status=status, path=path, lengths=lengths,
        start=start_c, goal=goal_c, start_snapped=start_snapped, goal_snapped=goal_snapped,
        expansions=expansions, iterations=out.iterations,
    )


def _trace_paths(
    out_parent: Tensor | None, searching: Tensor, found: Tensor, s_idx: Tensor, g_idx: Tensor, w: int,
    hw: int,
) -> tuple[Tensor, Tensor]:
    """Walk parents back from the goal (a loop over path length only): paths (N, L, 2) padded
    with -1, lengths (N,)."""
    n = searching.shape[0]
    device = searching.device
    i64 = torch.int64
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
    return path, lengths


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
