"""Shortest paths from cached distance fields: the ``planner="field"`` alternative to the batched
A* loop of ``realize.controllers.astar_search``, on one shared static grid (or one grid per plan).

What it does
------------
:func:`field_search` answers N (start, goal) queries on the same graph as the A* search (free
cells, 8-connected, step cost 1 / sqrt(2), corner rule; ``realize.controllers.astar``) with one
Dijkstra field per *distinct start cell*: distances and a shortest-path tree from that cell to
every free cell, computed by ``scipy.sparse.csgraph.dijkstra`` (compiled) on a sparse graph built
once per grid. Fields are kept across calls, keyed by grid content and start cell (the static
map is the same for every plan, action and CE iteration of a run; every plan of a run's first
``move_to`` starts from the same cell), at most ``_MAX_FIELDS`` per grid (least recently used dropped first). The result has the
``SearchOutcome`` layout, so ``astar`` walks the tree's parent pointers into cell paths as it
does for A*.

Costs are optimal, like A*'s (up to float rounding of the sums). The path among several optimal
ones is the one in the start cell's Dijkstra tree: it depends only on the grid, the start and the
goal, not on the batch (A*'s choice may depend on the batch), but it is in general NOT the cell
path A* picks, so waypoints and rollouts differ from ``planner="astar"``.

Per-plan grids (``free`` (N, H, W), e.g. a base path that must keep a held arm off a wall,
``realize.controllers.carry_footprint``): one field per searching plan on its own graph, not
cached (such a grid is met once); a plan's path still depends only on its grid, start and goal.
The loop is over those plans, each a compiled Dijkstra call.

What it doesn't: iteration limits (a field is computed whole), or run on an accelerator: the
fields are computed on the CPU and the parent rows moved to the grid's device.
"""

from __future__ import annotations

import math

import numpy as np
import torch
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import dijkstra
from torch import Tensor

from realize.controllers.astar_search import _COST, SearchOutcome, _move_table
from realize.controllers.grid_cache import grid_cached

__all__ = ["field_search"]

_MAX_FIELDS = 256  # fields kept per grid (each: H*W float64 + int32, ~180 kB at 120 x 124)


class _Fields:
    """Per-grid state: the sparse move graph and the fields computed so far (oldest first)."""

    def __init__(self, free: Tensor):
        hw = free.shape[-2] * free.shape[-1]
        table = _move_table(free)[:hw].cpu().numpy()  # (HW, 8), hw where not allowed
        src = np.repeat(np.arange(hw), 8)
        dst = table.reshape(-1)
        cost = np.tile(np.asarray(_COST, dtype=np.float64), hw)
        ok = dst < hw
        self.graph = csr_matrix((cost[ok], (src[ok], dst[ok])), shape=(hw, hw))
        self.hw = hw
        self.dist: dict[int, np.ndarray] = {}
        self.parent: dict[int, np.ndarray] = {}

    def get(self, starts: list[int]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(dist (S, HW) float64, parent (S, HW + 1) int32 with -1 where none, settled (S,) int64:
        cells the field reaches where it was computed in this call, 0 where it was cached) for the
        given distinct start cells."""
        new = [s for s in starts if s not in self.dist]
        fresh: dict[int, int] = {}
        if new:
            d, p = dijkstra(self.graph, directed=True, indices=np.asarray(new), return_predecessors=True)
            p = np.where(p < 0, -1, p).astype(np.int32)
            p = np.concatenate([p, np.full((len(new), 1), -1, dtype=np.int32)], axis=1)
            for i, s in enumerate(new):
                self.dist[s], self.parent[s] = d[i], p[i]
                fresh[s] = int(np.isfinite(d[i]).sum())
        out = (np.stack([self.dist[s] for s in starts]), np.stack([self.parent[s] for s in starts]),
               np.asarray([fresh.get(s, 0) for s in starts], dtype=np.int64))
        for s in starts:  # least recently used first
            self.dist[s] = self.dist.pop(s)
            self.parent[s] = self.parent.pop(s)
        for s in list(self.dist)[: max(0, len(self.dist) - _MAX_FIELDS)]:
            del self.dist[s], self.parent[s]
        return out


def field_search(free: Tensor, searching: Tensor, s_idx: Tensor, g_idx: Tensor, *,
                 dtype: torch.dtype) -> SearchOutcome:
    """Shortest paths for the plans with ``searching[i]``, from flat cell ``s_idx[i]`` to ``g_idx[i]``.

    free: (1, H, W) bool grid shared by all plans, or (N, H, W) one grid per plan. Returns the ``SearchOutcome`` of
    ``realize.controllers.astar_search.run_search``; ``expansions`` counts the cells reached by
    each field computed in this call, on the first plan using it (0 elsewhere, and where the field
    was cached); ``iterations`` is 0.
    """
    device = free.device
    n = searching.shape[0]
    cost = torch.full((n,), math.inf, dtype=dtype, device=device)
    expansions = torch.zeros(n, dtype=torch.int64, device=device)
    reached = torch.zeros(n, dtype=torch.bool, device=device)
    limited = torch.zeros(n, dtype=torch.bool, device=device)
    rows = searching.nonzero().squeeze(1)
    if rows.numel() == 0:
        return SearchOutcome(cost, reached, limited, expansions, 0, None)
    sw = s_idx[rows].cpu()
    if free.shape[0] > 1:  # one grid per plan: one uncached field each
        per = [_Fields(free[r : r + 1]).get([s]) for r, s in zip(rows.tolist(), sw.tolist())]
        dist, parent, settled = (np.concatenate(parts) for parts in zip(*per))
        inv = torch.arange(rows.numel())
        uniq = inv
    else:
        fields = grid_cached("astar_fields", free, _Fields)
        uniq, inv = torch.unique(sw, return_inverse=True)
        dist, parent, settled = fields.get(uniq.tolist())
    dist_t = torch.from_numpy(dist)
    c = dist_t[inv, g_idx[rows].cpu()].to(device=device, dtype=dtype)
    cost[rows] = c
    reached[rows] = torch.isfinite(c)
    # each field's fresh work is counted once, on the first plan that uses it
    first = torch.zeros(uniq.numel(), dtype=torch.int64).scatter_reduce(
        0, inv, torch.arange(inv.numel()), reduce="amin", include_self=False)
    exp = torch.zeros(rows.numel(), dtype=torch.int64)
    exp[first] = torch.from_numpy(settled)
    expansions[rows] = exp.to(device)
    out_parent = torch.from_numpy(parent)[inv].to(device)
    return SearchOutcome(cost, reached, limited, expansions, 0, out_parent)
