"""Warm start (realize/search/warm_start.py, CE's WarmDistribution): where a search begins, and what it refuses."""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest
import torch

from realize.search.ce.config import CEConfig
from realize.search.ce.optimizer import CrossEntropyOptimizer, optimize
from realize.search.ce.state import WarmDistribution
from realize.config import ConfigError
from realize.tasks.param_layout import ParamLayout
from realize.tasks.regions import Box
from realize.spec.run_spec import build_run_spec
from realize.search.protocol import EvalResult
from realize.search.warm_start import load_warm_start, merge_modes
from helpers import compose_config

F64 = torch.float64


def _spec(*overrides: str):
    return build_run_spec(compose_config(*overrides))


def _source_run(path: Path, *overrides: str, mean=None, std=None, weights=None, **doc) -> Path:
    """A finished run's result.json as `realize` writes it (the fields a warm start reads)."""
    cfg = compose_config(*overrides)
    task = build_run_spec(cfg).task
    D = task.layout.dim
    path.mkdir(parents=True)
    body = {"status": "done", "plan": task.describe(), "columns": task.layout.column_names, "config": cfg,
            "final_mean": mean if mean is not None else [0.1 * i for i in range(D)],
            "final_std": std if std is not None else [0.01] * D, "final_weights": weights, **doc}
    (path / "result.json").write_text(json.dumps(body))
    return path


def test_means_follow_the_objects_their_regions_follow_and_the_std_widens(tmp_path):
    src = _source_run(tmp_path / "src")
    spec = _spec("scene.objects.cube.offset=[0.06,-0.05]", "scene.tables.1.center=[0.3,-1.5]", "ce.warm_widen=3.0",
                 "ce.warm_uniform_share=0.25")
    ws = load_warm_start(str(src), spec.task, spec.geometry, spec.ce)
    old = torch.tensor([0.1 * i for i in range(spec.task.layout.dim)], dtype=F64)
    shift = torch.zeros_like(old)
    sl = spec.task.layout.slices
    shift[sl["Cube_g"]] = torch.tensor([0.06, -0.05, 0.0], dtype=F64)
    shift[sl["Table2"]] = torch.tensor([0.3, -0.3], dtype=F64)
    shift[sl["Cube_p"]] = torch.tensor([0.3, -0.3, 0.0], dtype=F64)
    assert torch.allclose(ws.distribution.mean, old + shift, atol=1e-12)
    assert torch.allclose(ws.distribution.std, torch.full_like(old, 0.03))
    assert ws.distribution.uniform_share == 0.25 and ws.distribution.weights is None
    assert ws.moved["Table1"] == [0.0, 0.0, 0.0] and ws.moved["Cube_g"] == [0.06, -0.05, 0.0]
    assert "Exit" not in ws.moved  # a world-frame region stays


def test_a_mixture_is_merged_by_moments_for_a_one_mode_run_and_copied_for_a_mixture_run(tmp_path):
    D = _spec().task.layout.dim
    m = [[0.0] * D, [1.0] * D]
    src = _source_run(tmp_path / "src", mean=m, std=[[0.1] * D, [0.3] * D], weights=[0.75, 0.25])
    one = _spec("ce.warm_widen=1.0")
    ws = load_warm_start(str(src), one.task, one.geometry, one.ce)
    # mixture moments: mean 0.25; variance 0.75*0.01 + 0.25*0.09 + 0.75*0.25^2 + 0.25*0.75^2
    var = 0.75 * 0.01 + 0.25 * 0.09 + 0.75 * 0.0625 + 0.25 * 0.5625
    col = one.task.layout.slices["Exit"].start  # a world-frame column: not moved
    assert float(ws.distribution.mean[col]) == pytest.approx(0.25)
    assert float(ws.distribution.std[col]) == pytest.approx(math.sqrt(var))
    assert ws.source_modes == 2
    three = _spec("ce.n_modes=3", "ce.n_elite=10")
    ws3 = load_warm_start(str(src), three.task, three.geometry, three.ce)
    assert ws3.distribution.mean.shape == (3, D) and torch.allclose(ws3.distribution.weights, torch.full((3,), 1 / 3,
                                                                                                       dtype=F64))
    two = _spec("ce.n_modes=2", "ce.warm_widen=1.0")
    ws2 = load_warm_start(str(src), two.task, two.geometry, two.ce)
    assert torch.allclose(ws2.distribution.weights, torch.tensor([0.75, 0.25], dtype=F64))
    assert float(ws2.distribution.std[1, col]) == pytest.approx(0.3)


def test_merge_modes_of_equal_modes_is_that_mode():
    mean, std = torch.tensor([[1.0, 2.0], [1.0, 2.0]]), torch.tensor([[0.5, 0.1], [0.5, 0.1]])
    mu, sd = merge_modes(mean, std, torch.tensor([0.4, 0.6]))
    assert torch.allclose(mu, mean[0]) and torch.allclose(sd, std[0])


@pytest.mark.parametrize("problem, message", [
    ("missing", r"warm_start = '.*nowhere': .* is not a directory"),
    ("other_plan", r"that run realized the plan move_to\(Table1\), grasp\(cube, Cube_g\); this run realizes move_to\(Table1\)"),
    ("other_columns", r"that run's parameters are \['Table1.x'\]; this run's are \['Table1.x', 'Table1.y'"),
    ("no_distribution", r"has no final distribution \(final_mean/final_std\)"),
    ("top_k", r"a top-k run \(several candidate plans\) cannot seed"),
])
def test_a_run_that_cannot_seed_this_one_is_refused_naming_why(tmp_path, problem, message):
    spec = _spec()
    if problem == "missing":
        src = tmp_path / "nowhere"
    else:
        doc = {"other_plan": {"plan": "move_to(Table1), grasp(cube, Cube_g)"}, "other_columns": {"columns": ["Table1.x"]},
               "no_distribution": {"final_mean": None}, "top_k": {"top_k": 2, "candidates": []}}[problem]
        src = _source_run(tmp_path / "src")
        body = json.loads((src / "result.json").read_text())
        body.update(doc)
        (src / "result.json").write_text(json.dumps(body))
    with pytest.raises(ConfigError, match=message):
        load_warm_start(str(src), spec.task, spec.geometry, spec.ce)


def test_warm_start_with_top_k_is_refused_at_the_config_edge(tmp_path):
    with pytest.raises(ConfigError, match=r"warm_start = .*: a warm start seeds one plan's search; .*top_k = 2"):
        _spec("experiment=carry_or_push", "task.planner.top_k=2", f"warm_start={tmp_path}")


# ---------------------------------------------------------------- the optimizer's side


def _quadratic(target: list[float]):
    t = torch.tensor(target, dtype=F64)
    return lambda Z: EvalResult(cost=((Z - t) ** 2).sum(1), feasible=torch.ones(Z.shape[0], dtype=torch.bool))


def test_iteration_0_draws_the_warm_distribution_with_its_uniform_share():
    layout = ParamLayout({"p": Box([-5.0, -5.0], [5.0, 5.0])})
    warm = WarmDistribution(torch.tensor([1.0, -2.0], dtype=F64), torch.tensor([0.01, 0.01], dtype=F64),
                            uniform_share=0.25)
    opt = CrossEntropyOptimizer(layout, CEConfig(n_envs=400, n_elite=10, iterations=2, seed=0), warm=warm)
    Z = opt.ask().Z
    near = ((Z - warm.mean).abs() < 0.06).all(1)
    assert int(near[:300].sum()) == 300  # 300 Gaussian rows, all within 6 std
    assert int(near[300:].sum()) <= 2  # 100 uniform rows over a 10 x 10 box
    rec = opt.tell(_quadratic([1.0, -2.0])(Z))
    assert rec.sampled_from == "warm"
    assert opt.tell(_quadratic([1.0, -2.0])(opt.ask().Z)).sampled_from == "gaussian"


def test_a_warm_start_at_the_optimum_beats_a_cold_start_of_the_same_budget():
    layout, target = ParamLayout({"p": Box([-5.0] * 3, [5.0] * 3)}), [1.3, -2.1, 0.4]
    cfg = CEConfig(n_envs=50, n_elite=5, iterations=2, seed=3)
    warm = WarmDistribution(torch.tensor([1.2, -2.0, 0.5], dtype=F64), torch.full((3,), 0.2, dtype=F64), None, 0.2)
    cold = optimize(layout, _quadratic(target), cfg)
    hot = CrossEntropyOptimizer(layout, cfg, warm=warm).run(_quadratic(target))
    assert hot.best_cost < 0.05 < cold.best_cost


def test_a_run_refuses_a_missing_warm_start_run_before_simulating(tmp_path, no_sim):
    from realize.run.one_run import run

    cfg = compose_config(f"warm_start={tmp_path / 'nowhere'}", "ce.n_envs=4", "ce.n_elite=2", "ce.iterations=1")
    with pytest.raises(ConfigError, match="warm_start = .*nowhere.*is not a directory"):
        run(cfg, tmp_path / "run")
    doc = json.loads((tmp_path / "run" / "result.json").read_text())
    assert doc["status"] == "failed" and "is not a directory" in doc["error"]


def test_a_plan_tail_starts_from_the_marginal_of_the_earlier_run(tmp_path):
    from realize.tasks.spec import task_for_plan

    src = _source_run(tmp_path / "src")
    spec = _spec("ce.warm_widen=1.0")
    tail = task_for_plan(spec.task, spec.task.plan[2:])  # move_to(Table2), place(cube, Cube_p), move_to(Exit)
    ws = load_warm_start(str(src), tail, spec.geometry, spec.ce)
    full = spec.task.layout.column_names
    want = torch.tensor([0.1 * full.index(c) for c in tail.layout.column_names], dtype=F64)
    assert tail.layout.column_names[0] == "Table2.x" and torch.allclose(ws.distribution.mean, want)
    head = task_for_plan(spec.task, spec.task.plan[:2])  # not a tail: refused
    with pytest.raises(ConfigError, match="this run realizes move_to\\(Table1\\), grasp\\(cube, Cube_g\\)"):
        load_warm_start(str(src), head, spec.geometry, spec.ce)
