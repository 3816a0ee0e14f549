"""Stitched segments' budget: a plan cut into segments, each searched by its own CE, then confirmed whole.

The seed paper's "next step": break a plan into smaller action sequences that are simulated in
parallel and stitched together. A plan is cut before one action (``split``: for the seed task
after the grasp, a prefix and a suffix) or before several (``splits``: a chain of segments).

What it does: ``StitchConfig`` holds the search's budget (rows per segment and round, rounds,
the pool of start states, the stitched plans confirmed whole, the cuts and the credit) and
checks it; ``chain_names(k)`` names the batches of k segments by their candidate index (the
workers' task, the history key: ``history_c{j}.npz``, result.json's ``segment_per_iter``);
``SegmentEvaluator`` is the type of what realizes a segment's batch without a run directory
(``ChainSearch.run``). ``CHAIN_KIND`` is the kind of the search's ``state_dict`` (a
checkpoint's ``ce_state``); ``stitched_as_chain`` reads the state a one-cut run checkpointed
before the chain ran it (kind ``STITCHED_KIND``) as the two-segment chain's, so such a run resumes.
What it doesn't: search (``realize.search.chain``: every stitched search, one cut its
two-segment case), read the run config (``realize.spec.stitch_settings``), cut the plan
(``realize.tasks.split``) or simulate (``realize.run.stitched_run``).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from torch import Tensor

from realize.search.protocol import EvalResult

__all__ = ["StitchConfig", "SegmentEvaluator", "chain_names", "CHAIN_KIND", "STITCHED_KIND", "stitched_as_chain"]

CHAIN_KIND = "stitched_chain"  # the "kind" of ChainSearch.state_dict (a checkpoint's ce_state)
STITCHED_KIND = "stitched"  # the kind a one-cut run's state had before ChainSearch ran it

# (segment name, Z, starts or None) -> (result, the rows' end states or None); a state is whatever
# the evaluator hands out and gets back (a ``SceneState`` in a run, a tuple in the analytic tests)
SegmentEvaluator = Callable[[str, Tensor, "Sequence[Any] | None"], "tuple[EvalResult, list[Any] | None]"]


def chain_names(k: int) -> dict[int | None, str]:
    """The batches' segment names by candidate index (the workers' task, the history key):
    None is the confirmation ("full"); two segments are "prefix" and "suffix", more
    ``segment1 .. segmentK``."""
    if k == 2:
        return {None: "full", 1: "prefix", 2: "suffix"}
    return {None: "full", **{j: f"segment{j}" for j in range(1, k + 1)}}


@dataclass(frozen=True)
class StitchConfig:
    """The stitched search's budget: samples per segment and round (``n_prefix`` for the first
    segment, ``n_suffix`` for each later one), rounds, the pool of start states, how many
    stitched plans are confirmed whole, and the cuts (``split``: the second segment's first
    action, None: the action after the plan's first grasp, ``realize.tasks.split.default_split``;
    ``splits``: each later segment's first action, a chain of more segments), with ``credit``."""

    n_prefix: int = 100
    n_suffix: int = 100
    iterations: int = 10
    pool: int = 10
    confirm: int = 10
    split: int | None = None
    # a chain of more segments: every segment's first action after the first (None: ``(split,)``)
    splits: tuple[int, ...] | None = None
    credit: int = 0  # a pool entry is dead after this many rows from it, none feasible (0: off)
    credit_radius: float = 0.1  # a row is doomed within this normalized distance of a dead entry

    def __post_init__(self) -> None:
        for name in ("n_prefix", "n_suffix", "iterations", "pool", "confirm"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int) or v < 1:
                raise ValueError(f"stitch.{name} = {v!r} is invalid: expected an integer >= 1")
        if self.iterations < 2:
            raise ValueError("stitch.iterations must be >= 2: the suffix starts from the prefixes of round 0")
        if isinstance(self.credit, bool) or not isinstance(self.credit, int) or self.credit < 0:
            raise ValueError(f"stitch.credit = {self.credit!r} is invalid: expected an integer >= 0")
        if not self.credit_radius >= 0:
            raise ValueError(f"stitch.credit_radius = {self.credit_radius!r} is invalid: expected a number >= 0")
        if self.splits is not None and (not self.splits or list(self.splits) != sorted(set(self.splits))):
            raise ValueError(f"stitch.splits = {list(self.splits)!r} is invalid: expected increasing action indices")

    @property
    def cuts(self) -> tuple[int, ...]:
        """Each segment's first action after the first (the split, or a chain's ``splits``)."""
        if self.splits is not None:
            return tuple(self.splits)
        return () if self.split is None else (self.split,)

    @property
    def chain(self) -> bool:
        """More than one cut, or credit: what ``result.json``'s ``stitched`` block then says too
        (the cuts, the credit, each segment). The same ``ChainSearch`` runs either way."""
        return len(self.cuts) > 1 or self.credit > 0

    @property
    def batches(self) -> int:
        """Batches of a whole search (at most): segment j's in each round from round j on, then
        the confirmation (two segments: a prefix per round, a suffix per round after the first)."""
        k = len(self.cuts) + 1
        return k * self.iterations - k * (k - 1) // 2 + 1 if k > 2 else 2 * self.iterations


def stitched_as_chain(d: Mapping[str, Any]) -> dict[str, Any]:
    """A one-cut run's search state checkpointed before the chain ran it (kind ``STITCHED_KIND``:
    the prefix's, the suffix's and the confirmation's searches, the pool, the round's prefixes
    waiting for the suffix, the stitched plans as prefix and suffix columns; phase ``prefix``,
    ``suffix``, ``confirm`` or ``done``) as the two-segment chain's ``state_dict``: the same
    searches, rows and plans, so the run goes on as it would have. The pool's entries get ids in
    their order, no parent and no tries or wins: such a run had no credit, which alone reads them.
    ``ValueError`` if it is malformed."""
    try:
        pool, fresh = d["pool"], d["fresh"]

        def entries(p: Mapping[str, Any], first: int) -> dict[str, Any]:
            n = len(p["cost"])
            return {"z": p["z"], "cost": p["cost"], "states": p["states"], "ids": list(range(first, first + n)),
                    "parent": [-1] * n, "doomed": [False] * n, "tries": [0] * n, "wins": [0] * n}

        n_pool, phase = len(pool["cost"]), d["phase"]
        return {"kind": CHAIN_KIND, "round": d["round"], "batches": d["batches"],
                "phase": {"prefix": 0, "suffix": 1}.get(phase, phase),
                "segments": [d["prefix"], d["suffix"]], "full": d["full"],
                "pools": [entries(pool, 0)], "fresh": [entries(fresh, n_pool)], "known": [[]],
                "next_id": n_pool + len(fresh["cost"]), "dead_total": 0,
                "stitched": [[c, [*zp, *zs]] for c, zp, zs in d["stitched"]]}
    except (KeyError, TypeError, ValueError) as e:
        raise ValueError(f"malformed stitched state ({type(e).__name__}: {e})") from None
