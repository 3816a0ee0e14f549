"""``CEConfig``: the cross-entropy settings (the ``ce`` config group), read and checked once.

What it does: declares every CE setting with its bounds and choices (``realize.config``
metadata), the cross-field rules (schedule, elites vs samples, modes vs elites, ...) and the
sample schedule ``n_envs_at(i)``.
What it doesn't: sample or rank (``realize.search.ce.optimizer``, ``realize.search.ce.ranking``), or know
the run's top-level ``seed`` key (``realize.spec.run_spec`` puts it into ``CEConfig.seed``).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, ClassVar

from realize.config import ConfigError, Settings, setting

if TYPE_CHECKING:
    import torch

__all__ = ["CEConfig", "FALLBACKS", "SCHEDULES", "DTYPES", "RISKS"]

FALLBACKS = ("progress", "feasible_only", "keep")
SCHEDULES = ("constant", "linear")
DTYPES = ("float32", "float64")  # torch dtypes by name (torch is imported where one is asked for)
RISKS = ("mean", "cvar")


@dataclass
class CEConfig(Settings):
    """Cross-entropy settings. Defaults follow the seed paper (200 samples, 10 elites, 10 its);
    they are the Hydra ``ce`` group's default option, ``seed_paper`` (``realize.spec.hydra_edge``).

    Fallback when fewer than ``n_elite`` samples are feasible (``fallback``):

    * ``"progress"`` (default): fill the elite set with the best infeasible samples, ranked by
      ``progress`` descending (e.g. number of actions completed), ties broken by ``distance``
      ascending (a distance-to-success proxy), then by cost ascending. Feasible samples always
      come first. Without progress/distance scores this ranks infeasible samples by cost.
    * ``"feasible_only"``: refit from the feasible samples alone if there are at least
      ``min_feasible_refit`` of them, otherwise keep the current distribution (at iteration 0
      that means sampling uniformly again).
    * ``"keep"``: keep the current distribution.

    Sample counts (``n_envs``: samples = parallel simulated plans per iteration, and the size
    of the batched scene): ``schedule="constant"`` uses ``n_envs`` every iteration; ``"linear"``
    goes from ``n_envs`` at iteration 0 down to ``n_envs_end`` (<= ``n_envs``) at iteration
    ``iterations - 1`` (rounded), as the journal version's 3000 -> 300.

    Multimodal / robust options (off by default, see ``realize.search.ce.mixture`` and
    ``realize.search.ce.ranking``): ``n_modes`` (>= 1, <= ``n_elite``) normals in a mixture;
    ``knn_robust`` (0 = off, else the neighbourhood size, <= the samples of every iteration)
    ranks feasible elites by their neighbourhood's mean cost; ``failure_cost`` (null or a
    number) is what an infeasible neighbour costs there (null: the evaluator's
    ``EvalResult.failure_cost``, e.g. the rollout's horizon in control steps).

    Warm start (top-level ``warm_start=RUN_DIR``, ``realize.search.warm_start``): iteration 0 draws
    from that run's final distribution, its std times ``warm_widen``, with a share
    ``warm_uniform_share`` of uniform samples so that a changed world is still explored.

    Robust search (``replicas`` = R > 1, ``realize.search.ce.risk``): each sample is realized in
    R perturbed worlds (the task's perturbation model; the same R worlds for every sample of the
    run), so an iteration draws ``n_envs / R`` samples (the budget counts copies). Samples rank
    by their success share over the worlds first, then by ``risk`` of their successful worlds'
    costs: ``"mean"``, or ``"cvar"`` (the mean of the worst ``cvar_alpha`` share of them).

    Speed levers (on by default, as the default Hydra group ``levers=all`` has them;
    ``levers=exact``, or ``prune=False, patience=None``, is the paper's algorithm exactly):
    ``prune`` lets the rollout stop a row that can no longer be among the batch's ``n_elite``
    cheapest feasible rows (``realize.realization.pruning``; within a rollout every other row is
    bit-identical, though a reused scene's later rollouts may drift a little: docs/results.md ("Speed
    levers"). ``patience`` makes ``iterations`` a maximum: the search stops once a
    feasible plan is in hand and the elites' mean cost fell by less than ``min_improvement``
    (relative) over the last ``patience`` iterations. On in ``levers=fast`` (``experiment=seed_paper``'s
    choice), off in ``levers=all``: ``keep_elites`` ranks each batch together with the last refit's
    feasible elites (``realize.search.ce.elite_memory``; pruning stays exact, as a row that cannot
    be among the batch's ``n_elite`` best cannot be among the pooled ones either);
    ``batch_scale`` is a record of the share of a preset's batch the config was composed with (a
    preset opts in with ``${realize_scaled:N,${ce.batch_scale}}``, ``realize.spec.hydra_edge``).

    ``dtype``: the search's bookkeeping dtype (sampling, ranking, refits). ``keep_samples``:
    keep each iteration's ``Z`` in its record.
    """

    config_key: ClassVar[str] = "ce"

    n_envs: int = setting(200, ge=1, help="samples (= parallel simulated plans) per iteration")
    n_elite: int = setting(10, ge=1)
    iterations: int = setting(10, ge=1)
    schedule: str = setting("constant", choices=SCHEDULES)
    n_envs_end: int | None = setting(None, ge=1)
    min_std: float = setting(1e-3, ge=0, help="floor of every refitted std")
    alpha: float = setting(1.0, gt=0, le=1, help="smoothing of the refit (1 = none, as the paper)")
    fallback: str = setting("progress", choices=FALLBACKS)
    min_feasible_refit: int = setting(2, ge=1)
    converge_std: float | None = setting(None, gt=0, help="stop early once every std is below this (null = off)")
    seed: int = 0
    uniform_share: float = setting(0.0, ge=0, lt=1, help="share of each batch drawn uniformly over the regions again")
    rank_weighted: bool = False
    n_modes: int = setting(1, ge=1, help="1 = a single Gaussian")
    knn_robust: int = setting(0, ge=0, help="0 = off")
    failure_cost: float | None = None
    warm_widen: float = setting(2.0, ge=1, help="warm start: the earlier run's std times this")
    warm_uniform_share: float = setting(0.2, ge=0, lt=1, help="warm start: share of iteration 0 drawn uniformly")
    dtype: str = setting("float64", choices=DTYPES)
    keep_samples: bool = True
    replicas: int = setting(1, ge=1, help="robust search: each sample in this many perturbed worlds (1 = off)")
    risk: str = setting("mean", choices=RISKS, help="robust search: a sample's cost over its successful worlds")
    cvar_alpha: float = setting(0.25, gt=0, le=1, help="risk=cvar: the share of worst successful worlds averaged")
    # speed levers (Hydra group ``levers``; all off is the seed paper's algorithm, bit for bit)
    prune: bool = setting(True, help="stop a row once it can no longer be among the batch's best feasible rows")
    patience: int | None = setting(2, ge=1, help="stopping rule: iterations looked back over (null = off)")
    min_improvement: float = setting(0.03, ge=0, help="stopping rule: least relative fall of the elites' mean cost")
    keep_elites: bool = setting(False, help="rank each batch with the last refit's feasible elites (elite memory)")
    batch_scale: float = setting(1.0, gt=0, help="the preset's batch times this (applied where the config is composed)")
    screen: bool = setting(False, help="draw again the samples a grasp would fail for certain (hand under the table)")
    screen_depth: float = setting(0.025, ge=0, help="screen: m the hand's spheres may reach below the support's top")
    screen_tries: int = setting(10, ge=1, help="screen: redraws of a rejected sample at most")
    # a fixed budget (experiment=tune_ce): the search stops before an iteration whose copies would
    # take the copies simulated past it; null: ce.iterations alone bounds the run
    sample_budget: int | None = setting(None, ge=1, help="copies simulated at most (null = no budget)")

    def check(self, where: str) -> None:
        if self.schedule == "linear":
            if self.n_envs_end is None:
                raise ConfigError(f"{where}.n_envs_end must be an integer >= 1 with schedule 'linear', got None")
            if self.n_envs_end > self.n_envs:
                raise ConfigError(
                    f"{where}.n_envs_end = {self.n_envs_end} is invalid: must be <= {where}.n_envs = {self.n_envs} "
                    f"(the schedule shrinks the batch; {where}.n_envs is the size of the batched scene)"
                )
            if self.n_elite > self.n_envs_end:
                raise ConfigError(
                    f"{where}.n_elite = {self.n_elite} is invalid: must be <= {where}.n_envs = {self.n_envs} and "
                    f"<= {where}.n_envs_end = {self.n_envs_end} (elites are chosen among the samples of an iteration)"
                )
        elif self.n_envs_end is not None and self.n_envs_end != self.n_envs:
            raise ConfigError(
                f"{where}.n_envs_end ({self.n_envs_end}) is only used with schedule 'linear' "
                f"(schedule is {self.schedule!r}); remove it or set {where}.schedule=linear"
            )
        elif self.n_elite > self.n_envs:
            raise ConfigError(
                f"{where}.n_elite = {self.n_elite} is invalid: must be <= {where}.n_envs = {self.n_envs} "
                "(elites are chosen among the samples of an iteration)"
            )
        if self.sample_budget is not None and self.sample_budget < self.n_envs_at(0):
            raise ConfigError(f"{where}.sample_budget = {self.sample_budget} is invalid: it must hold one iteration "
                              f"({where}.n_envs = {self.n_envs_at(0)} copies)")
        if self.converge_std is not None and self.converge_std <= self.min_std:
            raise ConfigError(
                f"{where}.converge_std ({self.converge_std}) must be > {where}.min_std ({self.min_std}), "
                "else it can never be reached"
            )
        if self.n_modes > self.n_elite:
            raise ConfigError(
                f"{where}.n_modes ({self.n_modes}) must be <= {where}.n_elite ({self.n_elite}): "
                "each mode is fitted to a cluster of elites"
            )
        n_min, i_min = min((self.samples_at(i), i) for i in range(self.iterations))
        if self.knn_robust > n_min:
            raise ConfigError(
                f"{where}.knn_robust ({self.knn_robust}) must be <= the number of samples at every iteration "
                f"(only {n_min} at iteration {i_min})"
            )
        if self.replicas > 1:
            self._check_replicas(where)

    def _check_replicas(self, where: str) -> None:
        R = self.replicas
        for key in ("n_envs", "n_envs_end"):
            v = getattr(self, key)
            if v is not None and v % R:
                raise ConfigError(f"{where}.{key} = {v} is invalid with {where}.replicas = {R}: the copies "
                                  f"({where}.{key}) must be a multiple of the worlds each sample meets")
        n_min = min(self.samples_at(i) for i in range(self.iterations))
        if self.n_elite > n_min:
            raise ConfigError(f"{where}.n_elite = {self.n_elite} is invalid with {where}.replicas = {R}: only "
                              f"{n_min} samples ({where}.n_envs / {where}.replicas) in an iteration")

    def within_budget(self, iteration: int) -> bool:
        """Whether iteration ``iteration`` (0-based) fits ``sample_budget`` after the ones before it."""
        if self.sample_budget is None:
            return True
        return sum(self.n_envs_at(i) for i in range(iteration + 1)) <= self.sample_budget

    def samples_at(self, iteration: int) -> int:
        """Samples drawn at ``iteration``: the copies ``n_envs_at(iteration)`` over ``replicas``
        (robust search: each sample fills ``replicas`` copies, one per world)."""
        return self.n_envs_at(iteration) // self.replicas

    def n_envs_at(self, iteration: int) -> int:
        """Number of samples drawn at ``iteration`` (0-based) under the schedule."""
        if self.schedule == "constant" or self.iterations == 1:
            return self.n_envs
        assert self.n_envs_end is not None
        t = min(max(iteration, 0), self.iterations - 1) / (self.iterations - 1)
        return int(round(self.n_envs + (self.n_envs_end - self.n_envs) * t))

    @property
    def torch_dtype(self) -> torch.dtype:
        import torch

        return getattr(torch, self.dtype)
