"""Where things live in a CE run's rerun recording, and how the viewer arranges them.

What it does: the ``ce_iteration`` timeline (:data:`TIMELINE`), the entity-path roots
(``/world/...`` for the top-down scene, ``/distributions/<param>/...``, ``/stats/...``, ``/log``),
the scalar series logged per iteration (:data:`SCALAR_PATHS`: path -> ``IterationRecord``
attribute, series name, colour), helpers that build entity paths (:func:`entity`,
:func:`param_path`), and the default blueprint (:func:`blueprint`: top-down scene | cost and
success plots | one distribution view per parameter; the 3-D view of ``/world3d`` under the
top-down scene).

What it doesn't: log anything (``realize.recording.log``, ``realize.recording.scene``) or read a
recording back (``realize.recording.read``).
"""

from __future__ import annotations

from collections.abc import Sequence

import rerun.blueprint as rrb

__all__ = ["TIMELINE", "ENTITY_WORLD", "ENTITY_WORLD_3D", "ENTITY_DIST", "ENTITY_STATS", "ENTITY_LOG", "SCALAR_PATHS",
           "entity", "param_path", "blueprint"]

TIMELINE = "ce_iteration"

ENTITY_WORLD = "world"
ENTITY_WORLD_3D = "world3d"  # realize.recording.world3d
ENTITY_DIST = "distributions"
ENTITY_STATS = "stats"
ENTITY_LOG = "log"

# scalar entity -> (IterationRecord attribute or special key, series name, colour)
SCALAR_PATHS: dict[str, tuple[str, str, tuple[int, int, int]]] = {
    "stats/cost/best": ("best_cost", "best cost (all iterations)", (20, 90, 200)),
    "stats/cost/iteration_best": ("iteration_best_cost", "best cost (this iteration)", (100, 160, 240)),
    "stats/cost/elite_min": ("elite_cost_min", "elite cost min", (120, 120, 120)),
    "stats/cost/elite_mean": ("elite_cost_mean", "elite cost mean", (60, 60, 60)),
    "stats/cost/elite_max": ("elite_cost_max", "elite cost max", (170, 170, 170)),
    "stats/success/share": ("success_share", "share of successful samples", (40, 170, 70)),
    "stats/samples/n_envs": ("n_envs", "samples (n_envs)", (90, 90, 90)),
    "stats/samples/n_feasible": ("n_feasible", "successful samples", (40, 170, 70)),
    "stats/time/eval_s": ("eval_time", "evaluation time [s]", (200, 120, 40)),
}


def entity(*parts: str) -> str:
    """Join entity-path parts with "/" (empty parts dropped)."""
    out = []
    for p in parts:
        for q in str(p).split("/"):
            if q:
                out.append(q)
    return "/".join(out)


def param_path(root: str, name: str, *rest: str) -> str:
    """Entity path of parameter ``name`` under ``root`` (characters rerun treats specially -> ``_``)."""
    # parameter names are identifiers in practice; escape anything rerun treats specially
    safe = "".join(ch if (ch.isalnum() or ch in "_-.") else "_" for ch in name)
    return entity(root, safe, *rest)


def blueprint(params: Sequence[str]) -> rrb.Blueprint:
    """Default layout: top-down scene | cost and success plots | one view per parameter in ``params``."""
    dist_views = [
        rrb.Spatial2DView(
            name=f"{p} distribution",
            origin="/",
            contents=[f"+ /{param_path(ENTITY_DIST, p)}/**", f"+ /{ENTITY_DIST}"],
        )
        for p in params
    ]
    plots = rrb.Vertical(
        rrb.TimeSeriesView(name="Cost", origin=f"/{ENTITY_STATS}/cost"),
        rrb.TimeSeriesView(
            name="Success share",
            origin=f"/{ENTITY_STATS}/success",
            axis_y=rrb.ScalarAxis(range=(0.0, 1.0)),
        ),
        rrb.TextLogView(name="Log", origin=f"/{ENTITY_LOG}"),
        row_shares=[2, 2, 1],
    )
    scene = rrb.Vertical(
        rrb.Spatial2DView(name="Top-down scene", origin="/", contents=[f"+ /{ENTITY_WORLD}/**"]),
        rrb.Spatial3DView(name="3-D: best plan per iteration (timeline control_step)", origin=f"/{ENTITY_WORLD_3D}"),
    )
    return rrb.Blueprint(
        rrb.Horizontal(
            scene,
            plots,
            rrb.Grid(*dist_views, name="Distributions") if dist_views else rrb.Vertical(),
            column_shares=[3, 2, 3],
        ),
        rrb.TimePanel(state="expanded"),
        collapse_panels=False,
    )
