"""Cross-entropy search over plan parameters (Algorithm 1 of the paper; Botev et al. 2013).

Generic over any batched evaluator ``evaluate(Z (N, D)) -> EvalResult`` (cost, feasibility and
a progress score per row), so it runs and is tested without a simulator.

* Iteration 0 samples each parameter uniformly over its region (``ParamLayout.sample_uniform``).
* Later iterations sample an independent normal per column of Z (mean/std refit from the elite
  set of the previous iteration) and ``project`` the draws back into the regions. Optionally a
  share of each batch is drawn uniformly again (``uniform_share``).
* Elites are the ``n_elite`` best rows: feasible rows by ascending cost first. When fewer than
  ``n_elite`` rows are feasible, ``fallback`` decides (see ``CEConfig``).
* The refit is the (optionally rank-weighted) elite mean and population std, floored at
  ``min_std`` and optionally smoothed with ``alpha`` (1 = paper, no smoothing).
* It stops after ``iterations`` or, if ``converge_std`` is set, once every std is below it.

Two multimodal/robust options, both off by default (the defaults take exactly the code paths
and random draws of the single-Gaussian search, bit for bit):

* ``n_modes = k > 1``: the distribution is a mixture of ``k`` diagonal normals (``mean``/``std``
  ``(k, D)``, ``weights`` ``(k,)``). The refit clusters the elites by k-means (k-means++ seeds
  drawn from the CE generator) in the normalised parameter space (each column divided by its
  region's bounding-box width), fits one normal per cluster and sets the weights to the
  clusters' (rank-weighted) shares. New clusters are matched to the previous modes by the
  smallest total distance of their means, so ``alpha`` smooths each mode with its predecessor.
  A mode whose cluster is empty (fewer distinct elites than modes) keeps its parameters with
  weight 0. Each batch gives mode ``j`` ``round(weights[j] * N)`` rows (largest remainder).
* ``knn_robust = k > 0``: feasible samples are ranked for the elite set by the mean cost of
  their ``k`` nearest samples of the batch (normalised space, the sample itself included), an
  infeasible neighbour counting as ``failure_cost`` (``CEConfig.failure_cost``, else
  ``EvalResult.failure_cost``: the rollout's horizon cost). Infeasible samples keep the
  progress order of the fallback. The reported best sample is still the best single sample.

Bookkeeping (sampling, ranking, refits, history) runs on the CPU in ``CEConfig.dtype`` with one
``torch.Generator`` seeded from the config, so the same seed gives bit-identical samples on any
machine; only the Z handed to ``evaluate`` is moved to the caller's device. The whole optimizer
state (``CEState``) round-trips through plain JSON (``to_dict``/``from_dict``) for resuming.

Angles (a hemisphere yaw column) are treated as plain reals: the Gaussian does not wrap, and
``project`` wraps/clamps its draws; keep yaw ranges away from the +-pi seam if that matters.

Not here: simulation, plan semantics, logging backends, full-covariance normals, mixtures whose
number of modes changes during a run.
"""

from __future__ import annotations

import itertools
import math
import time
from collections.abc import Callable, Mapping
from dataclasses import asdict, dataclass, field, fields
from typing import Any

import torch
from torch import Tensor

from realize.param_layout import ParamLayout

__all__ = [
    "CEConfig",
    "EvalResult",
    "CEState",
    "IterationRecord",
    "CEResult",
    "CrossEntropyOptimizer",
    "optimize",
    "rank_samples",
    "kmeans",
    "knn_mean",
    "mode_counts",
    "FALLBACKS",
    "SCHEDULES",
]

FALLBACKS = ("progress", "feasible_only", "keep")
SCHEDULES = ("constant", "linear")
_DTYPES = {"float32": torch.float32, "float64": torch.float64}


# --------------------------------------------------------------------------------------------
# config
# --------------------------------------------------------------------------------------------


@dataclass
class CEConfig:
    """Cross-entropy settings. Defaults follow the seed paper (200 samples, 10 elites, 10 its).

    Fallback when fewer than ``n_elite`` samples are feasible (``fallback``):

    * ``"progress"`` (default): fill the elite set with the best infeasible samples, ranked by
      ``progress`` descending (e.g. number of actions completed), ties broken by ``distance``
      ascending (a distance-to-success proxy), then by cost ascending. Feasible samples always
      come first. Without progress/distance scores this ranks infeasible samples by cost.
    * ``"feasible_only"``: refit from the feasible samples alone if there are at least
      ``min_feasible_refit`` of them, otherwise keep the current distribution (at iteration 0
      that means sampling uniformly again).
    * ``"keep"``: keep the current distribution.

    Sample counts: ``schedule="constant"`` uses ``n_samples`` every iteration; ``"linear"`` goes
    from ``n_samples`` at iteration 0 to ``n_samples_end`` at iteration ``iterations - 1``
    (rounded), as the journal version's 3000 -> 300.

    Multimodal / robust options (off by default, see the module docstring): ``n_modes`` (>= 1,
    <= ``n_elite``) normals in a mixture; ``knn_robust`` (0 = off, else the neighbourhood size,
    <= the samples of every iteration) ranks feasible elites by their neighbourhood's mean cost;
    ``failure_cost`` (null or a number) is what an infeasible neighbour costs there (null: the
    evaluator's ``EvalResult.failure_cost``, e.g. the rollout's horizon in control steps).
    """

    n_samples: int = 200
    n_elite: int = 10
    iterations: int = 10
    schedule: str = "constant"
    n_samples_end: int | None = None
    min_std: float = 1e-3
    alpha: float = 1.0
    fallback: str = "progress"
    min_feasible_refit: int = 2
    converge_std: float | None = None
    seed: int = 0
    uniform_share: float = 0.0
    rank_weighted: bool = False
    n_modes: int = 1
    knn_robust: int = 0
    failure_cost: float | None = None
    dtype: str = "float64"
    keep_samples: bool = True

    def __post_init__(self) -> None:
        self.validate()

    def validate(self, prefix: str = "ce") -> None:
        """Raise ``ValueError`` naming the offending key (``<prefix>.<key>``)."""

        def is_int(v: Any) -> bool:
            return isinstance(v, int) and not isinstance(v, bool)

        def is_num(v: Any) -> bool:
            return isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)

        for key in ("n_samples", "n_elite", "iterations", "min_feasible_refit", "n_modes", "knn_robust", "seed"):
            if not is_int(getattr(self, key)):
                raise ValueError(f"{prefix}.{key} must be an integer, got {getattr(self, key)!r}")
        if self.iterations < 1:
            raise ValueError(f"{prefix}.iterations must be >= 1, got {self.iterations}")
        if self.n_samples < 1:
            raise ValueError(f"{prefix}.n_samples must be >= 1, got {self.n_samples}")
        if self.n_elite < 1:
            raise ValueError(f"{prefix}.n_elite must be >= 1, got {self.n_elite}")
        if self.schedule not in SCHEDULES:
            raise ValueError(f"{prefix}.schedule must be one of {list(SCHEDULES)}, got {self.schedule!r}")
        if self.schedule == "linear":
            if self.n_samples_end is None or not is_int(self.n_samples_end) or self.n_samples_end < 1:
                raise ValueError(
                    f"{prefix}.n_samples_end must be an integer >= 1 with schedule 'linear', got {self.n_samples_end!r}"
                )
        elif self.n_samples_end is not None and self.n_samples_end != self.n_samples:
            raise ValueError(
                f"{prefix}.n_samples_end ({self.n_samples_end}) is only used with schedule 'linear' "
                f"(schedule is {self.schedule!r}); remove it or set {prefix}.schedule=linear"
            )
        n_min, i_min = min((self.n_samples_at(i), i) for i in range(self.iterations))
        if self.n_elite > n_min:
            raise ValueError(
                f"{prefix}.n_elite ({self.n_elite}) must be <= the number of samples at every iteration "
                f"(only {n_min} at iteration {i_min})"
            )
        if not is_num(self.min_std) or self.min_std < 0:
            raise ValueError(f"{prefix}.min_std must be a finite number >= 0, got {self.min_std!r}")
        if not is_num(self.alpha) or not 0.0 < self.alpha <= 1.0:
            raise ValueError(f"{prefix}.alpha must be in (0, 1], got {self.alpha!r}")
        if self.fallback not in FALLBACKS:
            raise ValueError(f"{prefix}.fallback must be one of {list(FALLBACKS)}, got {self.fallback!r}")
        if self.min_feasible_refit < 1:
            raise ValueError(f"{prefix}.min_feasible_refit must be >= 1, got {self.min_feasible_refit}")
        if self.converge_std is not None:
            if not is_num(self.converge_std) or self.converge_std <= 0:
                raise ValueError(f"{prefix}.converge_std must be a number > 0 or null, got {self.converge_std!r}")
            if self.converge_std <= self.min_std:
                raise ValueError(
                    f"{prefix}.converge_std ({self.converge_std}) must be > {prefix}.min_std ({self.min_std}), "
                    "else it can never be reached"
                )
        if not is_num(self.uniform_share) or not 0.0 <= self.uniform_share < 1.0:
            raise ValueError(f"{prefix}.uniform_share must be in [0, 1), got {self.uniform_share!r}")
        if not isinstance(self.rank_weighted, bool):
            raise ValueError(f"{prefix}.rank_weighted must be true or false, got {self.rank_weighted!r}")
        if not isinstance(self.keep_samples, bool):
            raise ValueError(f"{prefix}.keep_samples must be true or false, got {self.keep_samples!r}")
        if self.n_modes < 1:
            raise ValueError(f"{prefix}.n_modes must be >= 1 (1 = a single Gaussian), got {self.n_modes}")
        if self.n_modes > self.n_elite:
            raise ValueError(
                f"{prefix}.n_modes ({self.n_modes}) must be <= {prefix}.n_elite ({self.n_elite}): "
                "each mode is fitted to a cluster of elites"
            )
        if self.knn_robust < 0:
            raise ValueError(f"{prefix}.knn_robust must be >= 0 (0 = off), got {self.knn_robust}")
        if self.knn_robust > n_min:
            raise ValueError(
                f"{prefix}.knn_robust ({self.knn_robust}) must be <= the number of samples at every iteration "
                f"(only {n_min} at iteration {i_min})"
            )
        if self.failure_cost is not None and not is_num(self.failure_cost):
            raise ValueError(f"{prefix}.failure_cost must be a finite number or null, got {self.failure_cost!r}")
        if self.dtype not in _DTYPES:
            raise ValueError(f"{prefix}.dtype must be one of {list(_DTYPES)}, got {self.dtype!r}")

    def n_samples_at(self, iteration: int) -> int:
        """Number of samples drawn at ``iteration`` (0-based) under the schedule."""
        if self.schedule == "constant" or self.iterations == 1:
            return self.n_samples
        assert self.n_samples_end is not None
        t = min(max(iteration, 0), self.iterations - 1) / (self.iterations - 1)
        return int(round(self.n_samples + (self.n_samples_end - self.n_samples) * t))

    @property
    def torch_dtype(self) -> torch.dtype:
        return _DTYPES[self.dtype]

    @classmethod
    def from_dict(cls, d: Mapping[str, Any], where: str = "ce") -> CEConfig:
        """Build from a mapping (e.g. a Hydra ``ce`` group); unknown keys are an error."""
        if not isinstance(d, Mapping):
            raise ValueError(f"{where}: expected a mapping, got {type(d).__name__}")
        names = [f.name for f in fields(cls)]
        unknown = sorted(str(k) for k in d if k not in names)
        if unknown:
            raise ValueError(f"{where}: unknown key(s) {unknown} (allowed: {names})")
        obj = cls.__new__(cls)
        for f in fields(cls):
            default = f.default
            setattr(obj, f.name, d.get(f.name, default))
        # YAML may give floats for integer keys (1e3): accept exact integers
        for key in ("n_samples", "n_elite", "iterations", "n_samples_end", "min_feasible_refit", "seed",
                    "n_modes", "knn_robust"):
            v = getattr(obj, key)
            if isinstance(v, float) and v.is_integer():
                setattr(obj, key, int(v))
        obj.validate(where)
        return obj

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)


# --------------------------------------------------------------------------------------------
# evaluation result and ranking
# --------------------------------------------------------------------------------------------


@dataclass
class EvalResult:
    """What an evaluator returns for ``N`` samples.

    ``cost`` (N,) float, lower is better (NaN is treated as +inf); ``feasible`` (N,) bool;
    ``progress`` (N,) float, higher is closer to success (e.g. actions completed); ``distance``
    (N,) float, lower is closer to success (tie-break for equal progress). ``progress`` and
    ``distance`` are only used to rank infeasible samples and may be ``None``.
    ``failure_cost`` is what an infeasible sample costs for robust kNN scoring (e.g. the
    rollout's horizon); only read with ``knn_robust > 0`` and no ``CEConfig.failure_cost``.
    """

    cost: Tensor
    feasible: Tensor
    progress: Tensor | None = None
    distance: Tensor | None = None
    failure_cost: float | None = None

    def to_cpu(self, n: int, dtype: torch.dtype) -> EvalResult:
        """Validate shapes against ``n`` and return a CPU copy in ``dtype`` (bool feasibility)."""

        def vec(t: Any, name: str, kind: torch.dtype) -> Tensor:
            if not isinstance(t, Tensor):
                t = torch.as_tensor(t)
            t = t.detach().to("cpu")
            if t.shape != (n,):
                raise ValueError(f"EvalResult.{name}: expected shape ({n},), got {tuple(t.shape)}")
            return t.to(kind)

        return EvalResult(
            cost=vec(self.cost, "cost", dtype),
            feasible=vec(self.feasible, "feasible", torch.bool),
            progress=None if self.progress is None else vec(self.progress, "progress", dtype),
            distance=None if self.distance is None else vec(self.distance, "distance", dtype),
            failure_cost=self.failure_cost,
        )


def _stable_argsort(key: Tensor, order: Tensor) -> Tensor:
    return order[torch.sort(key[order], stable=True).indices]


def rank_samples(
    cost: Tensor, feasible: Tensor, progress: Tensor | None = None, distance: Tensor | None = None
) -> Tensor:
    """Indices ``(N,)`` best first: feasible rows by cost, then infeasible rows by
    (progress desc, distance asc, cost asc). Ties keep the original order (stable)."""
    n = cost.shape[0]
    c = torch.nan_to_num(cost, nan=math.inf)
    zero = torch.zeros_like(c)
    p = zero if progress is None else torch.where(feasible, zero, -torch.nan_to_num(progress, nan=-math.inf))
    d = zero if distance is None else torch.where(feasible, zero, torch.nan_to_num(distance, nan=math.inf))
    order = torch.arange(n)
    for key in (c, d, p, (~feasible).to(torch.int8)):  # least significant first
        order = _stable_argsort(key, order)
    return order


def _sort_key(feasible: bool, cost: float, progress: float, distance: float) -> tuple[float, ...]:
    """Scalar lexicographic key matching ``rank_samples`` (smaller is better)."""
    c = math.inf if math.isnan(cost) else cost
    if feasible:
        return (0.0, 0.0, 0.0, c)
    p = -math.inf if math.isnan(progress) else progress
    d = math.inf if math.isnan(distance) else distance
    return (1.0, -p, d, c)


# --------------------------------------------------------------------------------------------
# multimodal and robust helpers (batch-first, CPU, deterministic given the generator)
# --------------------------------------------------------------------------------------------


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


def knn_mean(X: Tensor, values: Tensor, k: int) -> Tensor:
    """``(N,)``: the mean of ``values`` over each row's ``k`` nearest rows of ``X (N, D)``,
    the row itself always included (its own distance is set below every other)."""
    n = X.shape[0]
    k = min(k, n)
    d = torch.cdist(X, X)
    d.diagonal().fill_(-1.0)
    idx = torch.topk(d, k, dim=1, largest=False, sorted=True).indices  # (N, k)
    return values[idx].mean(1)


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


def _match_modes(new: Tensor, old: Tensor) -> list[int]:
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


# --------------------------------------------------------------------------------------------
# state, records, result
# --------------------------------------------------------------------------------------------


def _t2l(t: Tensor | None) -> list | None:
    return None if t is None else t.detach().cpu().tolist()


def _f2j(x: float) -> float | str:
    """JSON has no inf/nan: encode them as strings."""
    return x if math.isfinite(x) else str(x)


def _j2f(x: float | str) -> float:
    return float(x)


@dataclass
class CEState:
    """Everything needed to continue a run: the distribution, the best so far and the RNG.

    ``iteration`` counts completed iterations (the next one to run). ``mean``/``std`` are
    ``None`` while the distribution is still the uniform one over the regions. ``best_*`` is the
    best sample of all completed iterations (feasible first; see ``rank_samples``).
    ``init_mean``/``init_std`` are the moments of the last uniform batch (the "previous"
    distribution for the first smoothed refit). With ``n_modes = k > 1`` ``mean``/``std`` are
    ``(k, D)`` and ``weights`` ``(k,)`` holds the mixture weights; it is ``None`` otherwise (and
    left out of ``to_dict``, so single-mode checkpoints read as before).
    """

    iteration: int
    rng_state: Tensor
    mean: Tensor | None = None
    std: Tensor | None = None
    init_mean: Tensor | None = None
    init_std: Tensor | None = None
    best_z: Tensor | None = None
    best_cost: float = math.inf
    best_feasible: bool = False
    best_progress: float = -math.inf
    best_distance: float = math.inf
    best_iteration: int = -1
    converged: bool = False
    weights: Tensor | None = None

    def to_dict(self) -> dict[str, Any]:
        """Plain-JSON form (lists, numbers, strings for inf/nan; the RNG state as a byte list)."""
        d = {
            "iteration": self.iteration,
            "rng_state": self.rng_state.to(torch.uint8).tolist(),
            "mean": _t2l(self.mean),
            "std": _t2l(self.std),
            "init_mean": _t2l(self.init_mean),
            "init_std": _t2l(self.init_std),
            "best_z": _t2l(self.best_z),
            "best_cost": _f2j(self.best_cost),
            "best_feasible": self.best_feasible,
            "best_progress": _f2j(self.best_progress),
            "best_distance": _f2j(self.best_distance),
            "best_iteration": self.best_iteration,
            "converged": self.converged,
        }
        if self.weights is not None:
            d["weights"] = _t2l(self.weights)
        return d

    @classmethod
    def from_dict(cls, d: Mapping[str, Any], dtype: torch.dtype = torch.float64) -> CEState:
        def t(v: Any) -> Tensor | None:
            return None if v is None else torch.tensor(v, dtype=dtype)

        return cls(
            iteration=int(d["iteration"]),
            rng_state=torch.tensor(d["rng_state"], dtype=torch.uint8),
            mean=t(d.get("mean")),
            std=t(d.get("std")),
            init_mean=t(d.get("init_mean")),
            init_std=t(d.get("init_std")),
            best_z=t(d.get("best_z")),
            best_cost=_j2f(d.get("best_cost", math.inf)),
            best_feasible=bool(d.get("best_feasible", False)),
            best_progress=_j2f(d.get("best_progress", -math.inf)),
            best_distance=_j2f(d.get("best_distance", math.inf)),
            best_iteration=int(d.get("best_iteration", -1)),
            converged=bool(d.get("converged", False)),
            weights=t(d.get("weights")),
        )

    def copy(self) -> CEState:
        def c(v: Tensor | None) -> Tensor | None:
            return None if v is None else v.clone()

        return CEState(
            iteration=self.iteration,
            rng_state=self.rng_state.clone(),
            mean=c(self.mean),
            std=c(self.std),
            init_mean=c(self.init_mean),
            init_std=c(self.init_std),
            best_z=c(self.best_z),
            best_cost=self.best_cost,
            best_feasible=self.best_feasible,
            best_progress=self.best_progress,
            best_distance=self.best_distance,
            best_iteration=self.best_iteration,
            converged=self.converged,
            weights=c(self.weights),
        )


@dataclass
class IterationRecord:
    """One CE iteration, all tensors on the CPU.

    ``Z`` (N, D) the samples (``None`` when ``keep_samples`` is off); ``cost``/``feasible``/
    ``progress``/``distance`` (N,) the evaluation; ``elite_idx`` the rows used for the refit, best first
    (or, when the distribution was kept, the feasible rows); ``mean``/``std`` (D,) the
    distribution *after* this iteration's update (``None`` while still uniform);
    ``sampled_from`` is ``"uniform"`` or ``"gaussian"``; ``refit`` says what happened:
    ``"elite"`` (>= n_elite feasible), ``"fallback_progress"``, ``"feasible_only"`` or ``"kept"``.
    ``best_cost`` is the best feasible cost of all iterations so far (inf if none; never
    increases); ``iteration_best_cost`` the best feasible cost of this batch. Elite cost stats
    are over the feasible elites (NaN if none). Times in seconds.

    With ``n_modes > 1`` ``mean``/``std`` are ``(k, D)`` and ``weights`` ``(k,)`` (else
    ``None``). ``best_idx`` is the batch's best single sample (feasible by cost, else the
    fallback order), which with ``knn_robust`` need not be ``elite_idx[0]``; ``robust_cost`` (N,)
    is the kNN score used to rank the feasible elites (``None`` when ``knn_robust`` is 0).
    """

    iteration: int
    n_samples: int
    Z: Tensor | None
    cost: Tensor
    feasible: Tensor
    progress: Tensor | None
    distance: Tensor | None
    elite_idx: Tensor
    sampled_from: str
    refit: str
    mean: Tensor | None
    std: Tensor | None
    n_feasible: int
    success_share: float
    best_cost: float
    iteration_best_cost: float
    elite_cost_min: float
    elite_cost_mean: float
    elite_cost_max: float
    eval_time: float
    wall_time: float
    converged: bool
    weights: Tensor | None = None
    best_idx: int = -1
    robust_cost: Tensor | None = None

    def summary(self) -> dict[str, Any]:
        """Scalars and the distribution as plain Python values (for JSON/CSV logs)."""
        out = {
            "iteration": self.iteration,
            "n_samples": self.n_samples,
            "sampled_from": self.sampled_from,
            "refit": self.refit,
            "n_feasible": self.n_feasible,
            "success_share": self.success_share,
            "best_cost": _f2j(self.best_cost),
            "iteration_best_cost": _f2j(self.iteration_best_cost),
            "elite_cost_min": _f2j(self.elite_cost_min),
            "elite_cost_mean": _f2j(self.elite_cost_mean),
            "elite_cost_max": _f2j(self.elite_cost_max),
            "n_elite": int(self.elite_idx.numel()),
            "mean": _t2l(self.mean),
            "std": _t2l(self.std),
            "eval_time": self.eval_time,
            "wall_time": self.wall_time,
            "converged": self.converged,
        }
        if self.weights is not None:
            out["weights"] = _t2l(self.weights)
        return out


@dataclass
class CEResult:
    """Outcome of a run: the best sample of all iterations, the final distribution, history.

    ``best_z`` (D,) with ``best_params`` its per-parameter split; ``best_feasible`` is False
    only when no sample was ever feasible (then ``best_z`` is the top-ranked infeasible one).
    ``history`` holds the iterations run by *this* call (a resumed run starts at its
    ``state.iteration``). ``mean``/``std``/``weights`` as in ``CEState``.
    """

    best_z: Tensor
    best_params: dict[str, Tensor]
    best_cost: float
    best_feasible: bool
    best_iteration: int
    mean: Tensor | None
    std: Tensor | None
    converged: bool
    history: list[IterationRecord] = field(default_factory=list)
    state: CEState | None = None
    weights: Tensor | None = None


# --------------------------------------------------------------------------------------------
# optimizer
# --------------------------------------------------------------------------------------------

Evaluator = Callable[[Tensor], EvalResult]
IterationCallback = Callable[[IterationRecord, CEState], "bool | None"]


class CrossEntropyOptimizer:
    """Ask/tell cross-entropy optimizer over a ``ParamLayout``.

    ``ask()`` returns the current batch ``(N, D)`` on ``device``; ``tell(result)`` ranks it,
    refits the distribution and returns the ``IterationRecord``; ``run(evaluate)`` loops until
    done. Pass ``state`` (e.g. ``CEState.from_dict(json.load(...))``) to resume: the continued
    run draws exactly the samples the uninterrupted one would have.
    """

    def __init__(
        self,
        layout: ParamLayout,
        config: CEConfig,
        device: torch.device | str | None = None,
        state: CEState | None = None,
    ) -> None:
        if not isinstance(layout, ParamLayout):
            raise TypeError(f"layout must be a ParamLayout, got {type(layout).__name__}")
        config.validate()
        self.layout = layout
        self.config = config
        self.device = torch.device(device) if device is not None else torch.device("cpu")
        self.dtype = config.torch_dtype
        self._gen = torch.Generator(device="cpu")
        self._gen.manual_seed(config.seed)
        if state is None:
            self._state = CEState(iteration=0, rng_state=self._gen.get_state())
        else:
            self._state = self._check_state(state.copy())
            self._gen.set_state(self._state.rng_state)
        self._pending: tuple[Tensor, str, float] | None = None
        self._eval_time = math.nan  # set by run() around evaluate
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

    # ---- public ------------------------------------------------------------------------

    @property
    def state(self) -> CEState:
        """A copy of the current state (safe to serialise/keep)."""
        return self._state.copy()

    @property
    def iteration(self) -> int:
        return self._state.iteration

    @property
    def done(self) -> bool:
        return self._state.iteration >= self.config.iterations or self._state.converged

    def ask(self) -> Tensor:
        """The batch for the current iteration, ``(N, D)`` on ``self.device``.

        Calling it again before ``tell`` returns the same batch."""
        if self._pending is None:
            t0 = time.perf_counter()
            Z, source = self._sample(self.config.n_samples_at(self._state.iteration))
            self._pending = (Z, source, t0)
        return self._pending[0].to(self.device, copy=True)  # the evaluator may not alter our copy

    def tell(self, result: EvalResult) -> IterationRecord:
        """Score the pending batch, update the distribution and the best, return the record."""
        if self._pending is None:
            raise RuntimeError("tell() called without a pending batch; call ask() first")
        Z, source, t0 = self._pending
        t_eval, self._eval_time = self._eval_time, math.nan
        cfg, s = self.config, self._state
        n = Z.shape[0]
        r = result.to_cpu(n, self.dtype)
        order = rank_samples(r.cost, r.feasible, r.progress, r.distance)
        best_order = order  # the true best single sample comes first here
        n_feas = int(r.feasible.sum())
        robust = None
        if cfg.knn_robust > 0:
            robust = self._robust_cost(Z, r)
            # feasible rows by their neighbourhood cost, infeasible rows keep the fallback order
            key = torch.where(r.feasible, robust, torch.zeros_like(robust))
            order = _stable_argsort((~r.feasible).to(torch.int8), _stable_argsort(key, order))

        # -- choose elites and refit
        if n_feas >= cfg.n_elite:
            elite, refit = order[: cfg.n_elite], "elite"
        elif cfg.fallback == "progress":
            elite, refit = order[: cfg.n_elite], "fallback_progress"
        elif cfg.fallback == "feasible_only" and n_feas >= cfg.min_feasible_refit:
            elite, refit = order[:n_feas], "feasible_only"
        else:
            elite, refit = order[:n_feas], "kept"

        if source == "uniform":
            s.init_mean = Z.mean(0)
            s.init_std = Z.std(0, correction=0)
        if refit != "kept" and cfg.n_modes > 1:
            self._refit_mixture(Z[elite])
        elif refit != "kept":
            new_mean, new_std = self._fit(Z[elite])
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

        # -- best of all iterations
        top = int(best_order[0])
        cand = _sort_key(
            bool(r.feasible[top]),
            float(r.cost[top]),
            math.nan if r.progress is None else float(r.progress[top]),
            math.nan if r.distance is None else float(r.distance[top]),
        )
        if s.best_z is None or cand < _sort_key(s.best_feasible, s.best_cost, s.best_progress, s.best_distance):
            s.best_z = Z[top].clone()
            s.best_cost = float(r.cost[top])
            s.best_feasible = bool(r.feasible[top])
            s.best_progress = math.nan if r.progress is None else float(r.progress[top])
            s.best_distance = math.nan if r.distance is None else float(r.distance[top])
            s.best_iteration = s.iteration

        feas_cost = r.cost[r.feasible]
        elite_feas = r.cost[elite][r.feasible[elite]]
        rec = IterationRecord(
            iteration=s.iteration,
            n_samples=n,
            Z=Z.clone() if cfg.keep_samples else None,
            cost=r.cost,
            feasible=r.feasible,
            progress=r.progress,
            distance=r.distance,
            elite_idx=elite.clone(),
            sampled_from=source,
            refit=refit,
            mean=None if s.mean is None else s.mean.clone(),
            std=None if s.std is None else s.std.clone(),
            n_feasible=n_feas,
            success_share=n_feas / n,
            best_cost=s.best_cost if s.best_feasible else math.inf,
            iteration_best_cost=float(feas_cost.min()) if n_feas else math.inf,
            elite_cost_min=float(elite_feas.min()) if elite_feas.numel() else math.nan,
            elite_cost_mean=float(elite_feas.mean()) if elite_feas.numel() else math.nan,
            elite_cost_max=float(elite_feas.max()) if elite_feas.numel() else math.nan,
            eval_time=t_eval,
            wall_time=time.perf_counter() - t0,
            converged=s.converged,
            weights=None if s.weights is None else s.weights.clone(),
            best_idx=top,
            robust_cost=robust,
        )
        s.iteration += 1
        s.rng_state = self._gen.get_state()
        self._pending = None
        return rec

    def run(self, evaluate: Evaluator, on_iteration: IterationCallback | None = None) -> CEResult:
        """Iterate ask -> evaluate -> tell until done. ``on_iteration(record, state)`` is called
        after each iteration (state is a copy, ready to serialise); returning ``True`` stops."""
        history: list[IterationRecord] = []
        while not self.done:
            Z = self.ask()
            t0 = time.perf_counter()
            res = evaluate(Z)
            self._eval_time = time.perf_counter() - t0
            rec = self.tell(res)
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
            mean=None if s.mean is None else s.mean.clone(),
            std=None if s.std is None else s.std.clone(),
            converged=s.converged,
            history=history or [],
            state=self.state,
            weights=None if s.weights is None else s.weights.clone(),
        )

    # ---- internals ---------------------------------------------------------------------

    def _sample(self, n: int) -> tuple[Tensor, str]:
        s, g = self._state, self._gen
        if s.mean is None or s.std is None:
            return self.layout.sample_uniform(n, g, self.dtype), "uniform"
        n_u = int(round(self.config.uniform_share * n))
        n_g = n - n_u
        eps = torch.randn(n_g, self.layout.dim, generator=g, dtype=self.dtype)
        if s.weights is None:
            Z = self.layout.project(s.mean + s.std * eps)
        else:  # mixture: rows of mode 0 first, then mode 1, ...
            mode = torch.repeat_interleave(torch.arange(s.weights.numel()), mode_counts(s.weights, n_g))
            Z = self.layout.project(s.mean[mode] + s.std[mode] * eps)
        if n_u:
            Z = torch.cat([Z, self.layout.sample_uniform(n_u, g, self.dtype)], dim=0)
        return Z, "gaussian"

    def _elite_weights(self, k: int) -> Tensor:
        """``(k,)`` normalised weights of the elites (best first): equal, or the CMA-ES log
        weights ``w_i ~ log(k + 1/2) - log(i)``, i = 1..k, with ``rank_weighted``."""
        if self.config.rank_weighted and k > 1:
            i = torch.arange(1, k + 1, dtype=self.dtype)
            w = math.log(k + 0.5) - torch.log(i)
        else:
            w = torch.ones(k, dtype=self.dtype)
        return w / w.sum()

    def _fit(self, Ze: Tensor) -> tuple[Tensor, Tensor]:
        """Mean and population std of the elite rows (best first), optionally rank-weighted."""
        w = self._elite_weights(Ze.shape[0])
        mean = (w[:, None] * Ze).sum(0)
        var = (w[:, None] * (Ze - mean) ** 2).sum(0)
        return mean, var.sqrt()

    def _robust_cost(self, Z: Tensor, r: EvalResult) -> Tensor:
        """``(N,)`` mean cost of each row's ``knn_robust`` nearest rows (itself included);
        infeasible or non-finite costs count as the failure cost (only needed when there are any)."""
        ok = r.feasible & torch.isfinite(r.cost)
        fail = self.config.failure_cost if self.config.failure_cost is not None else r.failure_cost
        if fail is None or not math.isfinite(float(fail)):
            if not bool(ok.all()):
                raise ValueError(
                    f"ce.knn_robust = {self.config.knn_robust} needs the cost of a failed plan: set ce.failure_cost "
                    "or return EvalResult.failure_cost from the evaluator"
                )
            fail = 0.0  # unused
        c = torch.where(ok, r.cost, torch.full_like(r.cost, float(fail)))
        return knn_mean(self.normalize(Z), c, self.config.knn_robust)

    def _refit_mixture(self, Ze: Tensor) -> None:
        """Refit the k-mode mixture from the elite rows (best first); updates the state."""
        cfg, s = self.config, self._state
        k, D = cfg.n_modes, self.layout.dim
        if s.mean is None:  # first refit: every mode's predecessor is the uniform batch
            assert s.init_mean is not None and s.init_std is not None
            old_mean = s.init_mean.expand(k, D).clone()
            old_std = s.init_std.expand(k, D).clone()
            old_w = torch.full((k,), 1.0 / k, dtype=self.dtype)
        else:
            assert s.std is not None and s.weights is not None
            old_mean, old_std, old_w = s.mean, s.std, s.weights
        w = self._elite_weights(Ze.shape[0])
        X = self.normalize(Ze)
        labels, c = kmeans(X, k, self._gen)
        onehot = torch.nn.functional.one_hot(labels, c).to(self.dtype) * w[:, None]  # (m, c)
        mass = onehot.sum(0)
        keep = torch.nonzero(mass > 0).flatten()  # clusters with elites, in label order
        onehot, mass = onehot[:, keep], mass[keep]
        c_mean = (onehot.T @ Ze) / mass[:, None]
        c_var = (onehot[:, :, None] * (Ze[:, None, :] - c_mean[None]) ** 2).sum(0) / mass[:, None]  # (c, D)
        if s.mean is None:
            slot = list(range(keep.numel()))
        else:
            slot = _match_modes(self.normalize(c_mean), self.normalize(old_mean))
        new_mean, new_std, new_w = old_mean.clone(), old_std.clone(), torch.zeros(k, dtype=self.dtype)
        for ci, j in enumerate(slot):
            new_mean[j], new_std[j], new_w[j] = c_mean[ci], c_var[ci].sqrt(), mass[ci]
        a = cfg.alpha
        if a < 1.0:
            new_mean = a * new_mean + (1 - a) * old_mean
            new_std = a * new_std + (1 - a) * old_std
            new_w = a * new_w + (1 - a) * old_w
        s.mean, s.std, s.weights = new_mean, new_std.clamp_min(cfg.min_std), new_w / new_w.sum()
        if cfg.converge_std is not None:
            live = s.weights > 0
            if float(s.std[live].max()) < cfg.converge_std:
                s.converged = True


def optimize(
    layout: ParamLayout,
    evaluate: Evaluator,
    config: CEConfig,
    device: torch.device | str | None = None,
    on_iteration: IterationCallback | None = None,
    state: CEState | None = None,
) -> CEResult:
    """Run Algorithm 1: ``CrossEntropyOptimizer(layout, config, device, state).run(...)``."""
    return CrossEntropyOptimizer(layout, config, device=device, state=state).run(evaluate, on_iteration)
