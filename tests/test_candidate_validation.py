"""Validating a run's K cheapest distinct plans (``realize.validation.candidates``).

* the 95 % Wilson interval equals scipy's (``binomtest(...).proportion_ci(method="wilson")``);
* the candidates are the K cheapest distinct feasible samples of the last iterations, and the
  run's best where an earlier iteration found it;
* a run with ``validation.replicas > 0`` validates its candidates after the search, into
  ``result.json``, with the numbers a later call gives (deterministic on CPU), returning the
  cheapest candidate whose lower bound reaches ``min_success`` (else the most robust one);
  validation is on by default (64 worlds x 5 candidates), ``validation=off`` or
  ``validation.replicas=0`` turns it off (the other tests' runs do: ``helpers.quiet_validation``).
"""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest
import yaml
from scipy.stats import binomtest

from helpers import compose_config, realize_result
from realize.spec.run_spec import build_run_spec
from realize.config import ConfigError
from realize.paths import CONFIG_DIR
from realize.validation.candidates import pick_candidates, validate_candidates, wilson_interval
from realize.spec.run_settings import ValidationSettings
from realize.validation.returned_plan import run_validation
from realize.run_dir.directory import BestPlan
from realize.run_dir.history import History


@pytest.mark.parametrize("k, n", [(0, 10), (10, 10), (5, 10), (61, 64), (1, 3), (30, 32)])
def test_wilson_interval_is_scipys(k: int, n: int) -> None:
    ci = binomtest(k, n).proportion_ci(method="wilson")
    lo, hi = wilson_interval(k, n)
    assert lo == pytest.approx(ci.low, abs=1e-12) and hi == pytest.approx(ci.high, abs=1e-12)


def _history(its: list[tuple[list, list[float], list[bool]]]) -> History:
    """A search history of the iterations ``its``: (Z, cost, feasible) each."""
    h = History([f"p{j}" for j in range(len(its[0][0][0]))])
    for Z, cost, ok in its:
        h.append({"Z": np.array(Z, float), "cost": np.array(cost), "feasible": np.array(ok)}, n_envs=len(Z),
                 success_share=float(np.mean(ok)), best_cost=min(c for c, f in zip(cost, ok) if f),
                 mean=np.zeros(len(Z[0])), std=np.ones(len(Z[0])))
    return h


def test_candidates_are_the_cheapest_distinct_feasible_samples_of_the_last_iterations() -> None:
    its = [  # (Z, cost, feasible) per iteration
        ([[0, 0], [1, 1], [2, 2]], [100.0, 50.0, 60.0], [True, True, False]),   # too early but for the best
        ([[3, 3], [4, 4], [3, 3]], [90.0, 80.0, 90.0], [True, True, True]),     # [3, 3] twice
        ([[5, 5], [6, 6], [7, 7]], [85.0, 70.0, 10.0], [True, True, False]),    # 10: infeasible
    ]
    h = _history(its)
    got = pick_candidates(h, 4, iterations=2)
    assert [(z.tolist(), c, i) for z, c, i, _ in got] == [([1, 1], 50.0, 0), ([6, 6], 70.0, 2), ([4, 4], 80.0, 1),
                                                       ([5, 5], 85.0, 2)]
    assert len(pick_candidates(h, 2, iterations=1)) == 2


def test_the_runs_best_is_a_candidate_when_an_earlier_iteration_found_it() -> None:
    its = [  # (Z, cost, feasible) per iteration; the run's best (40) comes first, its runner-up (45) never counts
        ([[0], [1], [2]], [40.0, 45.0, 30.0], [True, True, False]),
        ([[3], [4], [5]], [60.0, 50.0, 55.0], [True, True, True]),
        ([[6], [0], [7]], [70.0, 40.0, 65.0], [True, True, True]),     # z = [0] again: one candidate
    ]
    h = _history(its)
    got = pick_candidates(h, 3, iterations=1)
    assert [(z.tolist(), c, i) for z, c, i, _ in got] == [([0], 40.0, 2), ([7], 65.0, 2), ([6], 70.0, 2)]
    got = pick_candidates(h, 3, iterations=2)
    assert [(z.tolist(), c, i) for z, c, i, _ in got] == [([0], 40.0, 2), ([4], 50.0, 1), ([5], 55.0, 1)]
    got = pick_candidates(_history(its[:2]), 2, iterations=1)
    assert [(z.tolist(), c, i) for z, c, i, _ in got] == [([0], 40.0, 0), ([4], 50.0, 1)]


def test_a_robust_searchs_candidates_rank_by_share_first() -> None:
    h = History(["a"])
    Z, cost, ok, share = [[0], [1], [2], [3]], [100.0, 200.0, 150.0, 50.0], [True, True, True, False], [0.5, 1.0, 1.0, 0.0]
    h.append({"Z": np.array(Z, float), "cost": np.array(cost), "feasible": np.array(ok), "share": np.array(share)},
             n_envs=4, success_share=0.625, best_cost=150.0, mean=np.zeros(1), std=np.ones(1))
    got = pick_candidates(h, 3, iterations=1)
    assert [(z.tolist(), c, sh) for z, c, _, sh in got] == [([2], 150.0, 1.0), ([1], 200.0, 1.0), ([0], 100.0, 0.5)]


@pytest.mark.slow  # a whole run or several processes: make test-all (make test keeps a smoke test)
def test_a_run_validates_its_candidates_after_the_search_deterministically(tmp_path: Path) -> None:
    run = tmp_path / "run"
    res = realize_result("ce.n_envs=12", "ce.n_elite=3", "ce.iterations=2", "seed=3", "logging.rerun=false",
                         "logging.progress=false", "validation.replicas=3", "validation.candidates=2",
                         "validation.min_success=0.5", run_dir=run)
    saved = res["validation"]
    again = validate_candidates(run, write=False).to_dict()  # every setting the run's: its validation, its seed
    saved.pop("wall_time_s"), again.pop("wall_time_s")
    assert json.loads(json.dumps(again)) == saved  # the run's stage and a later call: the same replicas, numbers
    assert (saved["replicas"], saved["seed"], saved["min_success"]) == (3, 3, 0.5)
    cands = saved["candidates"]
    assert len(cands) == 2 and cands[0]["cost"] <= cands[1]["cost"] and res["best_cost"] == cands[0]["cost"]
    above = [j for j, c in enumerate(cands) if c["ci95"][0] >= 0.5]
    if above:
        assert saved["returned"] == above[0] and saved["reason"] == "cheapest above min_success"
    else:
        assert cands[saved["returned"]]["success_share"] == max(c["success_share"] for c in cands)
        assert saved["reason"] == "most robust"


def test_a_later_check_defaults_to_the_runs_validation_and_seed() -> None:
    def run_with(config: dict) -> BestPlan:
        return BestPlan(Path("."), config, [], [], 0.0, True, None, None, "done", None)

    v, seed = run_validation(run_with({"seed": 7, "validation": {"replicas": 8, "candidates": 2, "min_success": 0.5}}))
    assert (v.replicas, v.candidates, v.min_success, seed) == (8, 2, 0.5, 7)
    group = dataclasses.asdict(ValidationSettings())  # the group's defaults
    for off in ({"seed": 2, "validation": {"replicas": 0}}, {"seed": 2}):  # off, or recorded before validation
        v, seed = run_validation(run_with(off))
        assert (v.replicas, v.candidates, seed) == (group["replicas"], group["candidates"], 2)


def test_validation_is_on_by_default_off_by_choice_and_checked() -> None:
    defaults = yaml.safe_load((CONFIG_DIR / "config.yaml").read_text())["defaults"]
    assert {"validation": "default"} in defaults  # what a run without overrides gets
    on = build_run_spec(compose_config("validation=default")).validation
    assert (on.replicas, on.candidates, on.min_success) == (64, 5, 0.9)
    assert build_run_spec(compose_config("validation=off")).validation.replicas == 0
    assert build_run_spec(compose_config("validation.replicas=0")).validation.replicas == 0
    with pytest.raises(ConfigError, match="validation.min_success"):
        build_run_spec(compose_config("validation.min_success=1.5"))
