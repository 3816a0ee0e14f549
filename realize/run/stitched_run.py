"""A run with stitched segments (``stitch.enabled``, ``levers=stitched``): its tasks, searcher and result block.

What it does:
  * ``run_segments(spec)``: the run's tasks (the whole plan and its K segments of
    ``realize.tasks.split.chain_tasks``: the workers' tasks 0 .. K), the history keys of their
    batches (None, 1 .. K: ``history.npz`` holds the confirmation, ``history_c{j}.npz`` segment
    j's rounds; one cut: ``history_c1.npz`` the prefix's, ``history_c2.npz`` the suffix's) and
    the ``realize.search.chain.ChainSearch`` that ``realize.run.assembly`` runs in the search
    loop like any searcher (one cut is its two-segment case);
  * ``segment_names(st)``: the segments' names by history key;
  * ``stitched_doc``: what the run's ``result.json`` says of the segments (with each segment's
    seconds, ``segment_s``: the sum of its batches' evaluation times; a chain's cuts, credit and
    segments where ``StitchConfig.chain``).
On a CPU host the segments run as batches on the same workers, one after the other: each
worker realizes its shards one after another anyway, so a batch holding several segments would
cost the same.
What it doesn't: search (``realize.search.chain``), check the config (``realize.spec.run_spec``
refuses what a stitched search cannot do), or validate (the run's own candidate validation does).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

from realize.spec.run_spec import RunSpec
from realize.run_dir.names import HISTORY_FILE, candidate_file
from realize.run_dir.summaries import IterationSummary
from realize.search.chain import ChainSearch
from realize.search.segments import StitchConfig, chain_names
from realize.tasks.spec import TaskSpec
from realize.tasks.split import chain_tasks

__all__ = ["run_segments", "stitched_doc", "segment_names"]


def segment_names(st: StitchConfig) -> dict[int | None, str]:
    """The batches' segment names by history key (``chain_names``: "prefix" and "suffix" for one cut)."""
    return chain_names(len(st.cuts) + 1)


def run_segments(spec: RunSpec) -> tuple[list[TaskSpec], list[int | None], ChainSearch]:
    """A run with ``stitch.enabled``: its tasks (the whole plan and its segments: the workers'
    tasks 0 .. K; one cut: the prefix and the suffix), the history keys of their batches (None,
    1 .. K) and the searcher (its pools' states read back from a checkpoint as ``SceneState``)."""
    from realize.world.state import SceneState

    st = spec.stitch
    assert st is not None and st.split is not None  # (resolved by build_run_spec)
    parts, cols = chain_tasks(spec.task, list(st.cuts), "stitch.splits" if st.splits is not None else "stitch.split")
    search = ChainSearch(spec.task.layout, [t.layout for t in parts], cols, spec.ce, st,
                         device=spec.placement.device, read_state=SceneState.from_json)
    return [spec.task, *parts], [None, *range(1, len(parts) + 1)], search


def stitched_doc(st: StitchConfig, tasks: Sequence[TaskSpec], records: Sequence[IterationSummary]) -> dict[str, Any]:
    """``result.json["stitched"]``: the cut, the budget, each batch's segment (the top level's
    per-iteration series hold every batch, in order) and each segment's history file."""
    names = segment_names(st)
    seconds = {name: 0.0 for name in names.values()}
    for r in records:
        seconds[names[r.candidate]] += r.eval_time if math.isfinite(r.eval_time) else 0.0
    doc = {"split": st.split, "prefix": tasks[1].describe(), "suffix": tasks[-1].describe(),
           "n_prefix": st.n_prefix, "n_suffix": st.n_suffix, "rounds": st.iterations, "pool": st.pool,
           "confirm": st.confirm, "segment_per_iter": [names[r.candidate] for r in records],
           "history": {name: HISTORY_FILE if k is None else candidate_file(HISTORY_FILE, k)
                       for k, name in names.items()},
           "segment_s": seconds}
    if st.chain:
        doc.update(splits=list(st.cuts), credit=st.credit, credit_radius=st.credit_radius,
                   segments={names[k]: t.describe() for k, t in enumerate(tasks) if k})
    return doc
