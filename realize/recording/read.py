"""Reading a CE run's rerun recording back into plain data, for tests and quick checks.

What it does: :func:`read_rrd_summary` reads a finished ``.rrd`` (written by
``realize.recording.log.RerunLogger``, or any recording on the ``ce_iteration`` timeline) with
``rerun.chunk.RrdReader``: entity paths, per-iteration scalars, ellipses and instance counts;
:func:`read_rrd_3d` reads its 3-D part (``realize.recording.world3d``): the ``Transform3D`` rows of every
entity on the ``control_step`` timeline, and which entities hold ``Asset3D``/``Boxes3D`` data.

What it doesn't: write recordings, or open a viewer.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from realize.recording.paths import TIMELINE

__all__ = ["read_rrd_summary", "read_rrd_3d", "Rrd3D"]

_PRIMARY = (
    "Scalars:scalars",
    "Ellipses2D:half_sizes",
    "Points2D:positions",
    "LineStrips2D:strips",
    "Arrows2D:vectors",
    "TextLog:text",
)


def read_rrd_summary(path: str | Path) -> dict[str, Any]:
    """Read a ``.rrd`` written by ``RerunLogger`` (or any recording on ``ce_iteration``).

    Returns a dict with
    ``entity_paths`` (sorted, with leading ``/``), ``static_paths``, ``iterations`` (sorted
    ``ce_iteration`` values), ``scalars`` ``{path: {iteration: value}}``, ``per_iteration``
    ``{iteration: {path: value}}`` (the same scalars by iteration), ``ellipses``
    ``{path: {iteration: {"centers": [[x, y], ...], "half_sizes": [[hx, hy], ...]}}}``,
    ``counts`` ``{path: {iteration: number of instances}}`` for points/strips/ellipses/arrows/
    text (0 for a clear), ``application_id``, ``recording_id`` and ``n_blueprints``.
    """
    import rerun.chunk as rc

    reader = rc.RrdReader(str(path))
    recs = reader.recordings()
    if not recs:
        raise ValueError(f"{path}: no recording store in the file")
    store = reader.stream(store=recs[0]).collect()
    entity_paths: set[str] = set()
    static_paths: set[str] = set()
    iterations: set[int] = set()
    scalars: dict[str, dict[int, float]] = {}
    ellipses: dict[str, dict[int, dict[str, list]]] = {}
    counts: dict[str, dict[int, int]] = {}
    for ch in store.stream().to_chunks():
        ep = ch.entity_path
        if ep.startswith("/__"):
            continue
        entity_paths.add(ep)
        rb = ch.to_record_batch()
        names = rb.schema.names
        if ch.is_static or TIMELINE not in names:
            static_paths.add(ep)
            continue
        its = [int(v) for v in rb.column(TIMELINE).to_pylist()]
        iterations.update(its)
        cleared = rb.column("Clear:is_recursive").to_pylist() if "Clear:is_recursive" in names else [None] * len(its)
        for comp in _PRIMARY:
            if comp not in names:
                continue
            vals = rb.column(comp).to_pylist()
            for i, v in zip(its, vals):
                if v is None:
                    continue
                counts.setdefault(ep, {})[i] = len(v)
                if comp == "Scalars:scalars" and len(v):
                    scalars.setdefault(ep, {})[i] = float(v[0])
            if comp == "Ellipses2D:half_sizes":
                cents = rb.column("Ellipses2D:centers").to_pylist() if "Ellipses2D:centers" in names else [None] * len(its)
                for i, h, c in zip(its, vals, cents):
                    if h is not None:
                        ellipses.setdefault(ep, {})[i] = {"centers": c or [], "half_sizes": h}
        for i, clr in zip(its, cleared):
            if clr is not None:
                counts.setdefault(ep, {}).setdefault(i, 0)
    per_iteration: dict[int, dict[str, float]] = {}
    for ep, d in scalars.items():
        for i, v in d.items():
            per_iteration.setdefault(i, {})[ep] = v
    return {
        "application_id": recs[0].application_id,
        "recording_id": recs[0].recording_id,
        "n_blueprints": len(reader.blueprints()),
        "entity_paths": sorted(entity_paths),
        "static_paths": sorted(static_paths),
        "iterations": sorted(iterations),
        "scalars": {k: dict(sorted(v.items())) for k, v in sorted(scalars.items())},
        "per_iteration": dict(sorted(per_iteration.items())),
        "ellipses": ellipses,
        "counts": counts,
    }


@dataclass
class Rrd3D:
    """The 3-D part of a recording: per entity, its ``Transform3D`` rows on ``control_step``
    (``steps``, ``translations`` (x, y, z), ``quaternions`` (x, y, z, w), ``iterations``:
    the rows' ``ce_iteration``), the entities with ``Asset3D`` meshes and those with
    ``Boxes3D`` (and how many boxes each static one holds), the labels logged per entity."""

    steps: dict[str, list[int]] = field(default_factory=dict)
    translations: dict[str, list[list[float]]] = field(default_factory=dict)
    quaternions: dict[str, list[list[float]]] = field(default_factory=dict)
    iterations: dict[str, list[int]] = field(default_factory=dict)
    assets: set[str] = field(default_factory=set)
    boxes: dict[str, int] = field(default_factory=dict)
    labels: dict[str, list[str]] = field(default_factory=dict)


def read_rrd_3d(path: str | Path, timeline: str = "control_step") -> Rrd3D:
    """Read the 3-D entities of a ``.rrd`` (see ``Rrd3D``)."""
    import rerun.chunk as rc

    reader = rc.RrdReader(str(path))
    recs = reader.recordings()
    if not recs:
        raise ValueError(f"{path}: no recording store in the file")
    out = Rrd3D()
    for ch in reader.stream(store=recs[0]).collect().stream().to_chunks():
        ep = ch.entity_path
        rb = ch.to_record_batch()
        names = rb.schema.names
        if "Asset3D:blob" in names:
            out.assets.add(ep)
        if "Boxes3D:half_sizes" in names or "Boxes3D:centers" in names:
            col = rb.column("Boxes3D:centers" if "Boxes3D:centers" in names else "Boxes3D:half_sizes").to_pylist()
            out.boxes[ep] = max(out.boxes.get(ep, 0), max((len(v) for v in col if v is not None), default=0))
        for comp in ("Points3D:labels", "Boxes3D:labels"):
            if comp in names:
                out.labels.setdefault(ep, []).extend(x for v in rb.column(comp).to_pylist() if v for x in v)
        if ch.is_static or timeline not in names or "Transform3D:translation" not in names:
            continue
        steps = [int(v) for v in rb.column(timeline).to_pylist()]
        its = rb.column(TIMELINE).to_pylist() if TIMELINE in names else [None] * len(steps)
        tr = rb.column("Transform3D:translation").to_pylist()
        qu = rb.column("Transform3D:quaternion").to_pylist() if "Transform3D:quaternion" in names else [None] * len(steps)
        for s_, i_, t_, q_ in zip(steps, its, tr, qu):
            if t_ is None:
                continue
            out.steps.setdefault(ep, []).append(s_)
            out.translations.setdefault(ep, []).append(list(t_[0]))
            out.quaternions.setdefault(ep, []).append(list(q_[0]) if q_ else [])
            out.iterations.setdefault(ep, []).append(-1 if i_ is None else int(i_))
    return out
