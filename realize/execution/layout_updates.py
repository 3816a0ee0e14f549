"""What an observation changes in the planner's map: moved tables and new boxes as changes of
the run's ``scene`` config.

What it does: ``geometry_updates`` / ``geometry_changes`` turn an ``Observation``
(``realize.execution.world``; exact or believed) into the changes of the belief: table centres
and the new boxes as ``scene.walls`` entries, as plain values or Hydra override strings;
``apply_geometry_updates`` applies them to a scene config; ``geometry_now(world)`` is an
execution world as it is (tables where they stand, the boxes as walls), as a geometry.
What it doesn't: observe, or decide whether a change needs a repair.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from typing import TYPE_CHECKING, Any

from realize.config import ConfigError
from realize.world.geometry import GeometryCfg, SceneGeometry, build_geometry

if TYPE_CHECKING:
    from realize.execution.world import ExecutionWorld, Observation

__all__ = ["geometry_updates", "geometry_changes", "apply_geometry_updates", "geometry_now"]

_MOVED = 1e-6  # m: a table centre this close to its belief counts as unmoved


def _cfg(belief: GeometryCfg | Mapping[str, Any]) -> GeometryCfg:
    return belief if isinstance(belief, GeometryCfg) else GeometryCfg.from_mapping(belief)


def _r(v: float) -> float:
    return round(float(v), 6)


def geometry_updates(observation: Observation, belief: GeometryCfg | Mapping[str, Any],
                     moved_m: float | None = None) -> dict[str, Any]:
    """What changes the belief (the run's ``scene`` config) into the observed world, as config
    keys -> plain values: ``scene.tables.<i>.center`` for each table more than ``moved_m``
    from its config centre (None: any move; a noisy belief passes its tolerance, so that noise
    alone changes no layout), and ``scene.walls``
    (the belief's walls, then every observed box not among them) when a box appeared. Empty:
    nothing to change. Table yaw is not a config key: a turned table is refused."""
    cfg = _cfg(belief)
    out: dict[str, Any] = {}
    for i, t in enumerate(cfg.tables):
        seen = observation.tables.get(t.name)
        if seen is None:
            continue
        if abs(seen.yaw) > 1e-6:
            raise ConfigError(f"table {t.name!r} turned by {seen.yaw:.3f} rad: scene.tables have no yaw")
        if math.hypot(seen.x - t.center[0], seen.y - t.center[1]) > (_MOVED if moved_m is None else moved_m):
            out[f"scene.tables.{i}.center"] = [_r(seen.x), _r(seen.y)]
    known = {w.name for w in cfg.walls}
    new = [b for b in observation.boxes if b.name not in known]
    if new:
        walls = [{"name": w.name, "center": [_r(v) for v in w.center], "size": [_r(v) for v in w.size]}
                 for w in cfg.walls]
        walls += [{"name": b.name, "center": [_r(v) for v in b.center], "size": [_r(v) for v in b.size]} for b in new]
        out["scene.walls"] = walls
    return out


def _hydra(v: Any) -> str:
    if isinstance(v, Mapping):
        return "{" + ",".join(f"{k}:{_hydra(x)}" for k, x in v.items()) + "}"
    if isinstance(v, (list, tuple)):
        return "[" + ",".join(_hydra(x) for x in v) + "]"
    return repr(v) if isinstance(v, float) else str(v)


def geometry_changes(observation: Observation, belief: GeometryCfg | Mapping[str, Any],
                     moved_m: float | None = None) -> list[str]:
    """``geometry_updates`` as Hydra override strings (``scene.tables.1.center=[0.1,-1.5]``,
    ``scene.walls=[{name:obstacle,center:[-0.5,0.0],size:[0.5,0.5,0.5]}]``)."""
    return [f"{k}={_hydra(v)}" for k, v in geometry_updates(observation, belief, moved_m).items()]


def apply_geometry_updates(belief: GeometryCfg | Mapping[str, Any], updates: Mapping[str, Any]) -> GeometryCfg:
    """The belief with ``geometry_updates``' changes applied, checked as a ``GeometryCfg``."""
    d = dataclasses.asdict(_cfg(belief))
    for key, value in updates.items():
        parts = key.split(".")
        if parts[:2] == ["scene", "tables"] and len(parts) == 4:
            d["tables"][int(parts[2])][parts[3]] = value
        elif parts == ["scene", "walls"]:
            d["walls"] = [dict(w) for w in value]
        else:
            raise ConfigError(f"geometry update {key!r} is not a table centre or scene.walls")
    return GeometryCfg.from_mapping(d)


def geometry_now(world: ExecutionWorld) -> SceneGeometry:
    """The execution world as it is (tables where they stand, the boxes as walls), as a geometry."""
    cfg = world.spec.geometry_cfg
    return build_geometry(apply_geometry_updates(cfg, geometry_updates(world.observe(), cfg)))
