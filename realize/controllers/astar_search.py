"""The batched A* search loop: N searches on an 8-connected grid, vectorised across plans.

What it does
------------
:func:`run_search` runs the searches of the plans marked ``searching`` (start and goal already
validated, snapped and known to be in one connected component, see ``realize.controllers.astar``)
and returns their costs, expansion counts and parent pointers. g-values, current keys and parent
pointers are dense (K, H*W) tensors, and every iteration each still-running search pops its k
lowest-key open entries, closes them and relaxes their 8 neighbours with gather / scatter-min
ops. There is no Python loop over plans; the loop is over iterations, and finished searches are
compacted away (whenever half of the rows in the working set are done) so the slowest plan does
not drag the whole batch through the full-size tensors.

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
iteration's cost is mostly fixed op overhead when few searches run.

What it doesn't: validate inputs, snap cells, label components or walk parents back into paths
(``realize.controllers.astar``); the graph (moves, costs, corner rule) is the one described there.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import torch
from torch import Tensor

from realize.controllers.grid_cache import grid_cached

__all__ = ["SQRT2", "SearchOutcome", "octile", "run_search"]

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


@dataclass
class SearchOutcome:
    """What the search loop found, per plan (N rows; plans not searched keep the initial values).

    cost: (N,) g of the goal (inf when not reached); reached: (N,) bool; limited: (N,) bool, cut
    off by ``max_iterations``; expansions: (N,) int64; iterations: batched iterations run;
    parent: (K, H*W + 1) int32 parent pointers of the K searched plans, in the order of
    ``searching.nonzero()`` (-1 where none), or None when no plan was searched.
    """

    cost: Tensor
    reached: Tensor
    limited: Tensor
    expansions: Tensor
    iterations: int
    parent: Tensor | None


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


def _move_table(free: Tensor) -> Tensor:
    """free (1, H, W) -> (H*W + 1, 8) int64: flat index reached by each move, H*W (a dummy row and
    column never read back) where the move is not allowed."""
    h, w = free.shape[-2:]
    hw = h * w
    device = free.device
    shifts = torch.arange(8, dtype=torch.uint8, device=device)
    dflat = torch.tensor([dr * w + dc for dr, dc in zip(_DR, _DC)], dtype=torch.int64, device=device)
    allowed = ((_move_bits(free)[0, :, None] >> shifts) & 1).bool()  # (HW, 8)
    table = torch.where(allowed, torch.arange(hw, device=device)[:, None] + dflat, hw)
    return torch.cat([table, torch.full((1, 8), hw, dtype=torch.int64, device=device)], dim=0)


def _heuristic(gw: Tensor, h: int, w: int, dtype: torch.dtype) -> Tensor:
    """(K,) flat goal cells -> (K, H*W + 1) keys' heuristic part (1 + _TIE) * octile(cell, goal).

    Looked up in a table over (|d_row|, |d_col|) built with the same float ops as a direct
    evaluation, so the values are bit-identical to it; column H*W (the dummy cell) is read as
    row H, column 0, as ``flat // w``, ``flat % w`` give."""
    device = gw.device
    rr = torch.arange(h + 1, device=device, dtype=dtype)
    cc = torch.arange(w, device=device, dtype=dtype)
    # key = g + (1 + tie) h: among equal f, pop the node nearer the goal
    tab = (octile(rr[:, None], cc[None]) * (1.0 + _TIE)).reshape(-1)
    dr = (torch.arange(h + 1, device=device)[None] - (gw // w)[:, None]).abs()  # (K, H + 1)
    dc = (torch.arange(w, device=device)[None] - (gw % w)[:, None]).abs()  # (K, W)
    idx = (dr[:, :, None] * w + dc[:, None, :]).reshape(gw.shape[0], -1)[:, : h * w + 1]
    return tab[idx]


def run_search(
    free: Tensor,
    shared: bool,
    searching: Tensor,
    s_idx: Tensor,
    g_idx: Tensor,
    *,
    expansions_per_step: int | None,
    max_iterations: int | None,
    dtype: torch.dtype,
) -> SearchOutcome:
    """Search from flat cell ``s_idx[i]`` to ``g_idx[i]`` for every plan i with ``searching[i]``.

    free: (1, H, W) bool grid shared by all plans (``shared``) or (N, H, W) one per plan.
    s_idx, g_idx: (N,) int64 flat cell indices (free, in one component where ``searching``).
    expansions_per_step, max_iterations, dtype: as ``realize.controllers.astar.astar`` takes them.
    """
    device = free.device
    n = searching.shape[0]
    h, w = free.shape[-2:]
    hw = h * w
    i64 = torch.int64
    cost = torch.full((n,), math.inf, dtype=dtype, device=device)
    expansions = torch.zeros(n, dtype=i64, device=device)
    reached = torch.zeros(n, dtype=torch.bool, device=device)
    limited = torch.zeros(n, dtype=torch.bool, device=device)
    iterations = 0

    orig = searching.nonzero().squeeze(1)  # working row -> plan index
    k_rows = int(orig.numel())
    out_parent = None
    if k_rows == 0:
        return SearchOutcome(cost, reached, limited, expansions, iterations, out_parent)
    inf = math.inf
    eps = 1e-9
    # neighbour table: flat index of the cell reached by each of the 8 moves, hw (a dummy
    # column that is never read back) where the move is not allowed
    shifts = torch.arange(8, dtype=torch.uint8, device=device)
    dflat = torch.tensor([dr * w + dc for dr, dc in zip(_DR, _DC)], dtype=i64, device=device)
    step = torch.tensor(_COST, dtype=dtype, device=device)
    if shared:  # the static map of a run: built once (realize.controllers.grid_cache)
        table = grid_cached("astar_moves", free, _move_table)
    else:
        bits = _move_bits(free)  # (B, HW) uint8
        bits = torch.cat([bits, torch.zeros_like(bits[:, :1])], dim=1)
    out_parent = torch.full((k_rows, hw + 1), -1, dtype=torch.int32, device=device)
    out_row = torch.arange(k_rows, device=device)  # working row -> row of out_parent
    # dense per-node state: g, key of the node if open (inf if closed / unseen), parent
    g = torch.full((k_rows, hw + 1), inf, dtype=dtype, device=device)
    f_cur = torch.full_like(g, inf)
    parent = torch.full((k_rows, hw + 1), -1, dtype=torch.int32, device=device)
    sw, gw = s_idx[orig], g_idx[orig]
    hh = _heuristic(gw, h, w, dtype)
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
    return SearchOutcome(cost, reached, limited, expansions, iterations, out_parent)
