"""The run config's ``stitch`` node, read into the stitched search's budget.

What it does: ``StitchSettings`` holds the node's keys and defaults (one cut after the grasp, or a
chain of segments: ``stitch.splits`` or ``stitch.cut``, with ``credit``); ``read_stitch(d, ce,
task)`` checks them against the run's CE settings and its task (the cuts, the rounds a chain
needs, what a stitched search cannot run) and returns a ``StitchConfig`` (None: off). Every
problem is one ``ConfigError`` naming the key.
What it doesn't: search (``realize.search.chain``) or read the rest
of the run config (``realize.spec.run_spec``).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from realize.config import ConfigError, Settings, setting
from realize.search.ce.config import CEConfig
if TYPE_CHECKING:
    from realize.search.segments import StitchConfig
    from realize.tasks.spec import TaskSpec

__all__ = ["StitchSettings", "read_stitch"]


@dataclass
class StitchSettings(Settings):
    """The run config's ``stitch`` node: search the plan as segments realized side by side,
    then confirmed whole (``realize.search.chain``; ``levers=stitched`` turns it on)."""

    config_key = "stitch"

    enabled: bool = False
    split: int | None = setting(None, ge=1)  # the second segment's first action (None: after the first grasp)
    n_prefix: int | None = setting(None, ge=1)  # prefix rows per round (None: ce.n_envs)
    n_suffix: int | None = setting(None, ge=1)  # suffix rows per round (None: ce.n_envs)
    pool: int = setting(10, ge=1)  # the cheapest prefixes whose end states the suffix rows start from
    confirm: int = setting(10, ge=1)  # the cheapest stitched plans realized whole at the end (at most ce.n_envs)
    # a chain of segments (realize.search.chain): each segment's first action after the first (None: one cut)
    splits: tuple[int, ...] | None = setting(None)
    cut: str = setting("after_grasp", choices=("after_grasp", "after_each_place"))  # the cuts where none is given
    credit: int = setting(0, ge=0)  # a start is dead after this many rows from it, none feasible (0: off)
    credit_radius: float = setting(0.1, ge=0)  # a row within this (normalized) distance of a dead start ranks last


def read_stitch(d: Any, ce: CEConfig, task: TaskSpec, top_k: int = 1, replan: bool = False,
                warm_start: bool = False) -> StitchConfig | None:
    """The stitched search's budget (``None``: off): rounds are ``ce.iterations``, the rows at
    most ``ce.n_envs`` (the scene's copies; ``confirm`` is capped there), the split checked on
    ``task``. A robust, kNN-ranked, top-k, replan or warm-started run is refused."""
    from realize.search.segments import StitchConfig
    from realize.tasks.split import default_split, split_task

    st = StitchSettings.from_mapping(d if d is not None else {})
    if not st.enabled:
        return None
    for bad, what in ((ce.replicas > 1, "a robust search (ce.replicas > 1)"),
                      (ce.knn_robust > 0, "a kNN-ranked search (ce.knn_robust > 0)"),
                      (top_k > 1, "several candidate plans (task.planner.top_k > 1)"),
                      (replan, "a replan (replan_from)"), (warm_start, "a warm start (warm_start)")):
        if bad:
            raise ConfigError(f"stitch.enabled: stitched segments cannot run {what}")
    n_prefix, n_suffix = st.n_prefix or ce.n_envs, st.n_suffix or ce.n_envs
    for name, v in (("n_prefix", n_prefix), ("n_suffix", n_suffix)):
        if v > ce.n_envs:
            raise ConfigError(f"stitch.{name} = {v} is more than ce.n_envs = {ce.n_envs}, the scene's copies: "
                              f"raise ce.n_envs or lower stitch.{name}")
    if ce.iterations < 2:
        raise ConfigError(f"ce.iterations = {ce.iterations}: a stitched search needs at least 2 rounds (the suffix "
                          "starts from the prefixes of the rounds before it)")
    if st.splits is not None or st.cut != "after_grasp":
        return _read_chain(st, ce, task, n_prefix, n_suffix)
    split = default_split(task) if st.split is None else st.split
    split_task(task, split)  # refuses a bad cut before anything runs
    return StitchConfig(n_prefix, n_suffix, ce.iterations, st.pool, min(st.confirm, ce.n_envs), split,
                        credit=st.credit, credit_radius=st.credit_radius)


def _read_chain(st: StitchSettings, ce: CEConfig, task: TaskSpec, n_prefix: int, n_suffix: int) -> StitchConfig:
    """A chain of segments: ``stitch.splits``, or the cuts of ``stitch.cut`` (checked on ``task``)."""
    from realize.search.segments import StitchConfig
    from realize.tasks.split import chain_tasks, place_cuts

    if st.split is not None:
        other = f"stitch.splits = {list(st.splits)}" if st.splits is not None else f"stitch.cut = {st.cut}"
        raise ConfigError(f"stitch.split = {st.split} and {other}: give one of them")
    cuts = list(st.splits) if st.splits is not None else place_cuts(task)
    chain_tasks(task, cuts, "stitch.splits" if st.splits is not None else f"stitch.cut = {st.cut}")
    if ce.iterations < len(cuts) + 1:
        raise ConfigError(f"ce.iterations = {ce.iterations}: a chain of {len(cuts) + 1} segments needs at least "
                          f"{len(cuts) + 1} rounds (segment j first runs in round j)")
    return StitchConfig(n_prefix, n_suffix, ce.iterations, st.pool, min(st.confirm, ce.n_envs), cuts[0],
                        splits=tuple(cuts), credit=st.credit, credit_radius=st.credit_radius)
