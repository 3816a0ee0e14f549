"""Synthetic CE runs of the right shapes, for the logging and figure tests (no simulator).

A real ``CrossEntropyOptimizer`` runs on the seed task's parameter layout with a toy evaluator
(a plan "succeeds" when its parameters are close enough to a hand-picked good plan); a fake
rollout gives each sample straight-line base and end-effector trajectories through its
parameters, cut short where the plan fails. ``write_run_dir`` stores all of it in the files the
app writes (``result.json``, ``history.npz``, ``scene.json``, ``trajectories_iter{k}.npz``),
through the same writers (``realize.run_dir``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import torch

from realize.search.ce.config import CEConfig
from realize.search.ce.optimizer import CrossEntropyOptimizer
from realize.search.ce.state import IterationRecord
from realize.world.geometry import GeometryCfg, SceneGeometry, build_geometry
from realize.tasks.param_layout import ParamLayout
from realize.run_dir.directory import RunDir
from realize.run_dir.history import History
from realize.run_dir.result_doc import ResultDoc
from realize.search.protocol import EvalResult

PARAMS = {
    "Table1": {"type": "annulus", "center": [0.0, 1.2], "r_min": 0.75, "r_max": 1.25},
    "Cube_g": {"type": "hemisphere", "center": [0.0, 1.2, 0.7425], "radius": 0.15, "polar_max": 1.0},
    "Table2": {"type": "annulus", "center": [0.0, -1.2], "r_min": 0.75, "r_max": 1.25},
    "Cube_p": {"type": "hemisphere", "center": [0.0, -1.2, 0.7475], "radius": 0.15, "polar_max": 1.0},
    "Exit": {"type": "box", "low": [1.8, -0.4], "high": [2.6, 0.4]},
}
# a good plan: approach table1 from the start side, grasp from the top, place on table2, leave
GOOD = {
    "Table1": [-0.55, 0.55],
    "Cube_g": [-0.06, 1.2, 0.88],
    "Table2": [0.55, -0.55],
    "Cube_p": [0.06, -1.2, 0.88],
    "Exit": [2.0, 0.0],
}
TOL = {"Table1": 0.75, "Cube_g": 0.12, "Table2": 0.75, "Cube_p": 0.12, "Exit": 10.0}
N_ACTIONS = 5


def make_layout() -> ParamLayout:
    return ParamLayout.from_dict(PARAMS)


def make_geometry() -> SceneGeometry:
    return build_geometry(GeometryCfg())


@dataclass
class FakeRollout:
    """The fields of ``realize.realization.result.RolloutResult`` the logger and figures read."""

    cost: torch.Tensor
    feasible: torch.Tensor
    action_success: torch.Tensor
    goal: torch.Tensor
    steps: torch.Tensor
    progress: torch.Tensor
    distance: torch.Tensor
    failure: list[str]
    traj_t: torch.Tensor | None = None
    traj_base: torch.Tensor | None = None
    traj_ee: torch.Tensor | None = None
    traj_objects: torch.Tensor | None = None  # (N, T, m, 3)
    wall_time_s: float = 0.0


def _rows_close(layout: ParamLayout, Z: torch.Tensor) -> torch.Tensor:
    """(N, n_params) bool: parameter i of each row lies within TOL of the good plan."""
    parts = layout.split(Z)
    ok = []
    for name in layout.names:
        g = torch.tensor(GOOD[name][: parts[name].shape[1]], dtype=Z.dtype)
        ok.append(torch.linalg.vector_norm((parts[name][:, :2] - g[:2]), dim=1) <= TOL[name])
    return torch.stack(ok, dim=1)


def fake_rollout(layout: ParamLayout, geometry: SceneGeometry, Z: torch.Tensor, T: int = 60) -> FakeRollout:
    """Evaluate ``Z`` with the toy rule and make trajectories of shape (N, T, 2|3)."""
    n = Z.shape[0]
    close = _rows_close(layout, Z)  # (N, 5) in plan order
    # an action succeeds if it and all before it are close enough
    success = torch.cumprod(close.to(torch.int64), dim=1).bool()
    progress = success.sum(dim=1)
    feasible = progress == N_ACTIONS
    p = layout.split(Z)
    start = torch.tensor(geometry.robot_start[:2], dtype=Z.dtype).expand(n, 2)
    base_wp = torch.stack([start, p["Table1"], p["Table1"], p["Table2"], p["Table2"], p["Exit"]], dim=1)
    ee_wp = torch.stack([start, p["Table1"], p["Cube_g"][:, :2], p["Table2"], p["Cube_p"][:, :2], p["Exit"]], dim=1)
    seg = torch.linalg.vector_norm(base_wp[:, 1:] - base_wp[:, :-1], dim=-1)
    cost = 20.0 * seg.sum(dim=1) + 40.0 * (1 - close.double()).sum(dim=1)
    # time along the waypoints; a failed plan stops at the waypoint of its failing action
    stop = torch.clamp(progress + 1, max=base_wp.shape[1] - 1).to(Z.dtype)
    s = torch.linspace(0, 1, T, dtype=Z.dtype)[None, :] * stop[:, None]  # (N, T) in [0, stop]
    i0 = torch.clamp(s.floor().long(), max=base_wp.shape[1] - 2)
    f = (s - i0)[..., None]

    def interp(wp: torch.Tensor) -> torch.Tensor:
        a = torch.gather(wp, 1, i0[..., None].expand(-1, -1, 2))
        b = torch.gather(wp, 1, (i0 + 1)[..., None].expand(-1, -1, 2))
        return a + f * (b - a)

    base = interp(base_wp)
    ee_xy = interp(ee_wp)
    ee = torch.cat([ee_xy, torch.full((n, T, 1), 0.8, dtype=Z.dtype)], dim=-1)
    failure = ["" if ok else f"{k}:action{k}:timeout" for ok, k in zip(feasible.tolist(), progress.tolist())]
    return FakeRollout(
        cost=cost,
        feasible=feasible,
        action_success=success,
        goal=feasible.clone(),
        steps=torch.full((n,), T),
        progress=progress.double(),
        distance=(1 - close.double()).sum(dim=1),
        failure=failure,
        traj_t=torch.linspace(0, 30, T),
        traj_base=base.float(),
        traj_ee=ee.float(),
        wall_time_s=0.01,
    )


@dataclass
class SyntheticRun:
    layout: ParamLayout
    geometry: SceneGeometry
    records: list[IterationRecord] = field(default_factory=list)
    rollouts: list[FakeRollout] = field(default_factory=list)
    sampling: list[tuple[torch.Tensor | None, torch.Tensor | None]] = field(default_factory=list)


def run_synthetic(n: int = 60, iterations: int = 4, n_elite: int = 6, seed: int = 0, T: int = 40) -> SyntheticRun:
    """A real CE run over the toy evaluator; keeps records, rollouts and the sampling
    distribution (mean, std) each iteration drew from (None, None for the uniform one)."""
    layout, geometry = make_layout(), make_geometry()
    opt = CrossEntropyOptimizer(layout, CEConfig(n_envs=n, n_elite=n_elite, iterations=iterations, seed=seed))
    out = SyntheticRun(layout, geometry)
    prev: tuple[torch.Tensor | None, torch.Tensor | None] = (None, None)
    while not opt.done:
        Z = opt.ask().Z
        ro = fake_rollout(layout, geometry, Z, T)
        rec = opt.tell(EvalResult(ro.cost, ro.feasible, ro.progress, ro.distance))
        out.records.append(rec)
        out.rollouts.append(ro)
        out.sampling.append(prev)
        prev = (rec.mean, rec.std)
    return out


def write_run_dir(run: SyntheticRun, run_dir: Path, trajectories: bool = True, scene: bool = True) -> Path:
    """Store ``run`` as an app run directory (formats documented in ``realize.run_dir``)."""
    rd = RunDir(run_dir)
    recs = run.records
    history = History(run.layout.column_names)
    for r in recs:
        history.append({"Z": r.Z, "cost": r.cost, "feasible": r.feasible, "elite_idx": r.elite_idx},
                       n_envs=r.n_envs, success_share=r.success_share, best_cost=r.best_cost, mean=r.mean,
                       std=r.std)
    rd.write_history(history)
    feasible = any(r.n_feasible > 0 for r in recs)
    rd.write_result(ResultDoc(
        status="done",
        feasible=feasible,
        best_cost=recs[-1].best_cost if feasible else math.inf,
        iterations_done=len(recs),
        success_per_iter=[r.success_share for r in recs],
        best_cost_per_iter=[r.best_cost for r in recs],
        wall_time_s=1.0,
        config={"scene": {}, "task": {"params": PARAMS}, "controller": {"astar": {"padding": 0.2}}},
    ))
    if scene:
        rd.write_scene(run.layout, run.geometry, padding=0.2)
    if trajectories:
        for r, ro in zip(recs, run.rollouts):
            best = int(r.elite_idx[0]) if r.elite_idx.numel() else -1
            rd.write_trajectories(r.iteration, ro.traj_base, ro.traj_ee, ro.feasible, best, Z=r.Z, cost=ro.cost,
                                  progress=ro.progress, traj_t=ro.traj_t)
    return run_dir
