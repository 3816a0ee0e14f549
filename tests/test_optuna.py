"""Optuna sweeps (``hydra/sweeper=optuna``, ``experiment=tune_ce``): 3 trials at tiny N through
the command line. The study is stored in the sweep directory (SQLite), every trial's value is
the objective its run wrote (``realize.run.objective``), and summary.csv lists every trial."""

from __future__ import annotations

import contextlib
import csv
import io
import json
from pathlib import Path

import optuna
import pytest
import yaml

from helpers import doc_block, realize_cli
from realize.cli.main import preflight
from realize.run.objective import INFEASIBLE_FACTOR, run_objective
from realize.config import ConfigError
from realize.run_dir.names import RESULT_FILE


@pytest.mark.slow  # a whole run or several processes: make test-all (make test keeps a smoke test)
def test_three_trials_at_tiny_n(tmp_path: Path) -> None:
    sweep = tmp_path / "sweep"
    p = realize_cli("-m", "experiment=tune_ce", "hydra.sweeper.n_trials=3", "ce.n_envs=choice(4)",
                    "ce.n_elite=int(interval(1,2))", "ce.iterations=int(interval(1,3))", "ce.sample_budget=8",
                    "controller.max_time_s=3", "logging.rerun=false", f"hydra.sweep.dir={sweep}", cwd=tmp_path,
                    timeout=300)
    assert p.returncode == 0, p.stderr[-3000:]
    study = optuna.load_study(study_name="tune_ce", storage=f"sqlite:///{sweep / 'optuna.db'}")
    trials = study.trials
    assert len(trials) == 3 and all(t.state == optuna.trial.TrialState.COMPLETE for t in trials)
    with (sweep / "summary.csv").open() as f:
        rows = sorted(csv.DictReader(f), key=lambda r: int(r["job"]))
    assert [r["status"] for r in rows] == ["done"] * 3
    for t, r in zip(sorted(trials, key=lambda t: t.number), rows):
        res = json.loads((sweep / r["run_dir"] / RESULT_FILE).read_text())
        assert t.value == res["objective"] == float(r["objective"])
        assert int(r["ce.n_elite"]) == t.params["ce.n_elite"] and r["ce.n_envs"] == "4"
        assert res["iterations_done"] * 4 <= 8  # the sample budget: 8 copies, 4 per iteration
    best = yaml.safe_load((sweep / "optimization_results.yaml").read_text())
    assert best["best_value"] == min(t.value for t in trials)
    # docs/optuna.md's example reads this study back
    code = doc_block("docs/optuna.md", "python").text.replace("multirun/<date>/<time>", str(sweep))
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        exec(compile(code, "docs/optuna.md", "exec"), {})
    assert out.getvalue().split()[-1] == str(study.best_value)


def test_the_objective_is_the_returned_plans_cost() -> None:
    assert run_objective({"feasible": False, "best_cost": None}, 120.0) == INFEASIBLE_FACTOR * 120.0
    assert run_objective({"feasible": True, "best_cost": 450.0}, 2400.0) == 450.0
    validated = {"feasible": True, "best_cost": 450.0,
                 "validation": {"returned": 1, "candidates": [{"cost": 450.0}, {"cost": 470.0}]}}
    assert run_objective(validated, 2400.0) == 470.0  # the cheapest plan failed validation: the next one


def test_a_search_space_with_invalid_trials_is_refused_before_the_study() -> None:
    """An interval is checked at its ends: n_elite up to 9 with 4 samples cannot work. The
    command's preflight refuses it (the command prints that line alone and exits 2 before the
    study's database exists: tests/test_app.py's CLI test)."""
    with pytest.raises(ConfigError) as ei:
        preflight(["-m", "experiment=tune_ce", "ce.n_envs=choice(4)", "ce.n_elite=int(interval(1,9))",
                   "ce.sample_budget=8"])
    assert "(ce.n_envs=4 ce.n_elite=9" in str(ei.value) and "ce.n_elite = 9" in str(ei.value)
