"""The mixture of ``k`` diagonal normals (``ce.n_modes = k > 1``): k-means and the refit.

What it does: the refit clusters the elites by k-means (k-means++ seeds drawn from the CE
generator) in the normalised parameter space (each column divided by its region's
bounding-box width), fits one normal per cluster and sets the weights to the clusters'
(rank-weighted) shares. New clusters are matched to the previous modes by the smallest total
distance of their means, so ``alpha`` smooths each mode with its predecessor. A mode whose
cluster is empty (fewer distinct elites than modes) keeps its parameters with weight 0.
Sampling gives mode ``j`` ``round(weights[j] * N)`` rows (``mode_counts``, largest remainder).
Batch-first torch on the CPU, deterministic given the generator.
What it doesn't: rank samples or keep state (``realize.search.ce.ranking``, ``realize.search.ce.optimizer``).
"""

from __future__ import annotations

import itertools
from collections.abc import Callable
from dataclasses import dataclass

import torch
from torch import Tensor

__all__ = ["kmeans", "mode_counts", "match_modes", "Mixture", "fit_mixture"]


def _sq_dist(X: Tensor, C: Tensor) -> Tensor:
    """``(m, c)`` exact squared Euclidean distances (no matmul shortcut: ties stay ties)."""
    return ((X[:, None, :] - C[None, :, :]) ** 2).sum(-1)


def kmeans(X: Tensor, k: int, generator: torch.Generator, max_iter: int = 100) -> tuple[Tensor, int]:
    """Cluster the rows of ``X (m, D)`` into at most ``k`` groups; returns ``(labels (m,), c)``.

    k-means++ seeding draws from ``generator`` (the first centre uniformly, each further one with
    probability proportional to the squared distance to the nearest centre), then Lloyd steps
    until the labels stop changing. Seeding stops early when every row coincides with a centre
    (fewer distinct rows than ``k``), so ``c <= min(k, m)`` and labels lie in ``[0, c)``. A
    centre that loses all its rows stays where it was. Ties go to the lower centre index.
    """
    m = X.shape[0]
    if m == 0:
        return torch.zeros(0, dtype=torch.long), 0
    first = int(torch.randint(m, (1,), generator=generator))
    centers = [X[first]]
    d2 = _sq_dist(X, X[first][None])[:, 0]
    while len(centers) < k:
        total = float(d2.sum())
        if not total > 0.0:
            break
        u = torch.rand(1, generator=generator, dtype=X.dtype) * total
        i = int(torch.searchsorted(torch.cumsum(d2, 0), u, right=True).clamp(max=m - 1))
        if not float(d2[i]) > 0.0:  # rounding at the very end of the cumulative sum
            i = int(torch.nonzero(d2 > 0).flatten()[-1])
        centers.append(X[i])
        d2 = torch.minimum(d2, _sq_dist(X, X[i][None])[:, 0])
    C = torch.stack(centers)
    c = C.shape[0]
    labels = _sq_dist(X, C).argmin(1)
    for _ in range(max_iter):
        onehot = torch.nn.functional.one_hot(labels, c).to(X.dtype)  # (m, c)
        count = onehot.sum(0)
        sums = onehot.T @ X
        C = torch.where(count[:, None] > 0, sums / count.clamp_min(1.0)[:, None], C)
        new = _sq_dist(X, C).argmin(1)
        if torch.equal(new, labels):
            break
        labels = new
    return labels, c


def mode_counts(weights: Tensor, n: int) -> Tensor:
    """``(k,)`` long, summing to ``n``: ``floor(w * n)`` per mode plus one row for each of the
    largest remainders (ties to the lower index). ``weights`` need not be normalised."""
    w = weights.clamp_min(0.0)
    w = w / w.sum() if float(w.sum()) > 0 else torch.full_like(w, 1.0 / w.numel())
    exact = w * n
    counts = torch.floor(exact).to(torch.long)
    rest = n - int(counts.sum())
    if rest > 0:
        frac = exact - counts.to(exact.dtype)
        order = torch.sort(-frac, stable=True).indices
        counts[order[:rest]] += 1
    return counts


def match_modes(new: Tensor, old: Tensor) -> list[int]:
    """For each row of ``new (c, D)`` a distinct row of ``old (k, D)``, c <= k, minimising the
    summed distance: exhaustive for k <= 6, else greedy by increasing pair distance."""
    c, k = new.shape[0], old.shape[0]
    d = torch.cdist(new, old)
    if k <= 6:
        best: tuple[float, tuple[int, ...]] | None = None
        for perm in itertools.permutations(range(k), c):
            tot = float(sum(d[i, j] for i, j in enumerate(perm)))
            if best is None or tot < best[0]:
                best = (tot, perm)
        assert best is not None
        return list(best[1])
    out = [-1] * c
    used: set[int] = set()
    for flat in torch.sort(d.flatten(), stable=True).indices.tolist():
        i, j = divmod(flat, k)
        if out[i] < 0 and j not in used:
            out[i] = j
            used.add(j)
    return out


@dataclass
class Mixture:
    """``mean``/``std`` ``(k, D)`` and ``weights`` ``(k,)`` (normalised)."""

    mean: Tensor
    std: Tensor
    weights: Tensor


def fit_mixture(
    Ze: Tensor,
    w: Tensor,
    old: Mixture,
    first: bool,
    generator: torch.Generator,
    normalize: Callable[[Tensor], Tensor],
    alpha: float,
    min_std: float,
) -> Mixture:
    """Refit the k-mode mixture from the elite rows ``Ze (m, D)`` (best first, weights ``w``).

    ``old`` is the previous mixture (``first``: the moments of the uniform batch in every
    mode, uniform weights: no matching then, clusters take the modes in label order)."""
    k = old.weights.numel()
    dtype = Ze.dtype
    old_mean, old_std, old_w = old.mean, old.std, old.weights
    X = normalize(Ze)
    labels, c = kmeans(X, k, generator)
    onehot = torch.nn.functional.one_hot(labels, c).to(dtype) * w[:, None]  # (m, c)
    mass = onehot.sum(0)
    keep = torch.nonzero(mass > 0).flatten()  # clusters with elites, in label order
    onehot, mass = onehot[:, keep], mass[keep]
    c_mean = (onehot.T @ Ze) / mass[:, None]
    c_var = (onehot[:, :, None] * (Ze[:, None, :] - c_mean[None]) ** 2).sum(0) / mass[:, None]  # (c, D)
    if first:
        slot = list(range(keep.numel()))
    else:
        slot = match_modes(normalize(c_mean), normalize(old_mean))
    new_mean, new_std, new_w = old_mean.clone(), old_std.clone(), torch.zeros(k, dtype=dtype)
    for ci, j in enumerate(slot):
        new_mean[j], new_std[j], new_w[j] = c_mean[ci], c_var[ci].sqrt(), mass[ci]
    a = alpha
    if a < 1.0:
        new_mean = a * new_mean + (1 - a) * old_mean
        new_std = a * new_std + (1 - a) * old_std
        new_w = a * new_w + (1 - a) * old_w
    return Mixture(new_mean, new_std.clamp_min(min_std), new_w / new_w.sum())
