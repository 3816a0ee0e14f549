"""The figure inputs of a run directory: ``scene.json`` and ``trajectories_iter{k}.npz``.

What it does:
  * ``save_scene`` writes ``scene.json`` = ``{"layout": ParamLayout.to_dict(), "geometry":
    dataclasses.asdict(SceneGeometry), "padding": float}``; ``read_scene`` reads it back as a
    ``SceneInfo``, or, without the file, rebuilds the scene from a run's resolved config
    (``task.params`` or ``task_file``, ``scene``, ``controller.astar.padding``);
  * ``save_trajectories`` writes ``trajectories_iter{k}.npz`` (``k`` the iteration, not zero
    padded): ``traj_base`` (N, T, 2) float32 base (x, y) per recorded step, ``traj_ee``
    (N, T, 3) float32 end-effector position, ``feasible`` (N,) bool, ``best`` () int64 index of
    the iteration's best sample (-1 if none), and optionally ``Z`` (N, D) float64, ``cost``
    (N,) float64, ``progress`` (N,) float64, ``traj_t`` (T,) float32 seconds;
    ``load_trajectories`` reads it (no unpickling).
What it doesn't: draw (``realize.figures``) or decide when to record (the search loop).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from realize.world.geometry import Box as ObstacleBox
from realize.world.geometry import GeometryCfg, SceneGeometry, build_geometry
from realize.world.objects import SceneObject
from realize.tasks.param_layout import ParamLayout
from realize.run_dir.jsonio import atomic_write_json, atomic_write_npz, read_json
from realize.run_dir.names import SCENE_FILE, TRAJ_PATTERN, trajectories_name
from realize.run_dir.upgrade import upgrade_config

__all__ = [
    "SceneInfo",
    "save_scene",
    "read_scene",
    "scene_from_config",
    "geometry_from_dict",
    "save_trajectories",
    "load_trajectories",
    "trajectories_path",
    "trajectory_iterations",
]


@dataclass
class SceneInfo:
    """What the figures need to draw a run's world: its parameters, geometry, A* padding."""

    layout: ParamLayout
    geometry: SceneGeometry
    padding: float = 0.2


def save_scene(run_dir: str | Path, layout: ParamLayout, geometry: SceneGeometry, padding: float = 0.2) -> Path:
    """Write ``scene.json`` atomically; returns its path."""
    path = Path(run_dir) / SCENE_FILE
    doc = {"layout": layout.to_dict(), "geometry": dataclasses.asdict(geometry), "padding": float(padding)}
    atomic_write_json(path, doc)
    return path


def geometry_from_dict(d: Mapping[str, Any]) -> SceneGeometry:
    """Inverse of ``dataclasses.asdict(SceneGeometry)``."""

    def box(b: Mapping[str, Any]) -> ObstacleBox:
        return ObstacleBox(**{k: (tuple(v) if isinstance(v, list) else v) for k, v in b.items()})

    def obj(o: Mapping[str, Any]) -> SceneObject:
        return SceneObject(**{k: (tuple(v) if isinstance(v, list) else v) for k, v in o.items()})

    if "objects" not in d and "cube_pos" in d:  # written before objects were data: the cube (and stick)
        h, stick = float(d["cube_half_size"]), d.get("stick")
        objs = [dict(name="cube", shape="box", half_size=[h, h, h], position=d["cube_pos"], yaw=0.0,
                     mass=d["cube_mass"], friction=d["cube_friction"], color=[0.85, 0.1, 0.1, 1.0],
                     rests_on="stick" if stick else "table1")]
        if stick:
            objs.append(dict(name="stick", shape="box", half_size=stick["half_size"], position=stick["center"],
                             yaw=stick.get("yaw", 0.0), mass=d.get("stick_mass", 0.0),
                             friction=d.get("stick_friction", 0.0), color=stick.get("color", [0.75, 0.6, 0.35, 1.0]),
                             rests_on="floor"))
        d = dict(d, objects=objs)
    kw: dict[str, Any] = {}
    for f in dataclasses.fields(SceneGeometry):
        if f.name not in d and f.default is not dataclasses.MISSING:
            continue  # written before the field existed
        v = d[f.name]
        if f.name in ("tables", "extras", "containers"):
            v = tuple(box(b) for b in v)
        elif f.name == "objects":
            v = tuple(obj(o) for o in v)
        elif isinstance(v, list):
            v = tuple(v)
        kw[f.name] = v
    return SceneGeometry(**kw)


def scene_from_config(cfg: Mapping[str, Any]) -> SceneInfo | None:
    """The scene of a run's resolved config, or ``None`` if the config does not describe one."""
    try:
        geometry = build_geometry(GeometryCfg.from_mapping(upgrade_config(cfg)["scene"]))
        params = cfg.get("task", {}).get("params")
        if cfg.get("task_file"):
            import yaml

            p = Path(str(cfg["task_file"]))
            if p.is_file():
                params = (yaml.safe_load(p.read_text()) or {}).get("params", params)
        layout = ParamLayout.from_dict(params)
        padding = float(cfg.get("controller", {}).get("astar", {}).get("padding", 0.2))
    except Exception:  # a partial or foreign config: the caller reports what is missing
        return None
    return SceneInfo(layout, geometry, padding)


def read_scene(run_dir: str | Path, config: Mapping[str, Any] | None = None) -> SceneInfo | None:
    """``scene.json`` of ``run_dir``, else the scene of ``config``, else ``None``."""
    doc = read_json(Path(run_dir) / SCENE_FILE)
    if doc is not None:
        return SceneInfo(ParamLayout.from_dict(doc["layout"]), geometry_from_dict(doc["geometry"]),
                         float(doc.get("padding", 0.2)))
    return scene_from_config(config) if isinstance(config, Mapping) else None


def trajectories_path(run_dir: str | Path, iteration: int) -> Path:
    return Path(run_dir) / trajectories_name(iteration)


def trajectory_iterations(run_dir: str | Path) -> list[int]:
    """The iterations with a trajectories file, ascending."""
    head, tail = TRAJ_PATTERN.split("{k}")
    out = []
    for p in Path(run_dir).glob(TRAJ_PATTERN.format(k="*")):
        k = p.name[len(head): len(p.name) - len(tail)]
        if k.isdigit():
            out.append(int(k))
    return sorted(out)


def _array(x: Any, dtype: Any) -> np.ndarray | None:
    if x is None:
        return None
    if hasattr(x, "detach"):
        x = x.detach().cpu().numpy()
    return np.asarray(x, dtype=dtype)


def save_trajectories(
    run_dir: str | Path,
    iteration: int,
    traj_base: Any,
    traj_ee: Any,
    feasible: Any,
    best: int,
    *,
    Z: Any = None,
    cost: Any = None,
    progress: Any = None,
    traj_t: Any = None,
) -> Path:
    """Write ``trajectories_iter{iteration}.npz`` atomically (format in the module docstring).

    Accepts torch tensors or arrays; with a ``RolloutResult`` ``r`` and an ``IterationRecord``
    ``rec``: ``save_trajectories(d, rec.iteration, r.traj_base, r.traj_ee, r.feasible, best,
    Z=rec.Z, cost=r.cost, progress=r.progress, traj_t=r.traj_t)``.
    """
    base = _array(traj_base, np.float32)
    ee = _array(traj_ee, np.float32)
    feas = _array(feasible, bool)
    if base is None or base.ndim != 3 or base.shape[2] < 2:
        raise ValueError(f"traj_base must be (N, T, 2), got {None if base is None else base.shape}")
    n, t = base.shape[:2]
    if ee is None or ee.shape[:2] != (n, t):
        raise ValueError(f"traj_ee must be (N, T, 3) with N={n}, T={t}, got {None if ee is None else ee.shape}")
    if feas is None or feas.shape != (n,):
        raise ValueError(f"feasible must be ({n},), got {None if feas is None else feas.shape}")
    arrays: dict[str, np.ndarray] = {
        "traj_base": base[..., :2],
        "traj_ee": ee,
        "feasible": feas,
        "best": np.asarray(int(best), dtype=np.int64),
    }
    for key, v, dt in (("Z", Z, np.float64), ("cost", cost, np.float64), ("progress", progress, np.float64),
                       ("traj_t", traj_t, np.float32)):
        a = _array(v, dt)
        if a is not None:
            arrays[key] = a
    path = trajectories_path(run_dir, iteration)
    atomic_write_npz(path, arrays)
    return path


def load_trajectories(run_dir: str | Path, iteration: int) -> dict[str, np.ndarray]:
    """The arrays of ``trajectories_iter{iteration}.npz``; ``FileNotFoundError`` says which exist."""
    path = trajectories_path(run_dir, iteration)
    if not path.is_file():
        have = [trajectories_name(k) for k in trajectory_iterations(run_dir)]
        raise FileNotFoundError(f"{path} does not exist (have: {have or 'none'}); a run writes it when "
                                "trajectories are recorded (logging.record=true)")
    with np.load(path, allow_pickle=False) as z:
        return {k: z[k] for k in z.files}
