"""The planner you import (realize/run/planner.py, realize/spec/compose.py): configs composed from
Python with one-line errors, ``plan()`` twice through kept workers, ``replan`` from a state (its
result block, refusals before anything runs, kept vs rebuilt scenes). The README's example runs in
tests/test_doc_commands.py.

The plans are tiny (4 copies, one iteration) and start from a run directory written by hand
(the seed task's known plan ``GOOD`` as its final distribution, as tests/test_replay.py writes
its runs) through ``warm_start``: a feasible plan in seconds, no search from scratch.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest

from helpers import GOOD, STATE_GRASPED, TINY, write_known_run
from realize.spec.compose import compose_config
from realize.run.planner import Planner, PlanResult, ReplanBudget
from realize.spec.run_spec import build_run_spec
from realize.config import ConfigError
from realize.run_dir.names import RESULT_FILE
from realize.world.state import load_state

BUDGET = ReplanBudget(n_envs=4, n_elite=2, iterations=1, shard_rows=None, workers=1)  # the planner's 4 copies


# ------------------------------------------------------------------------------ compose_config
@pytest.mark.parametrize("override, needles", [
    ("ce.n_envz=3", ["unknown key 'ce.n_envz'", "did you mean", "'ce.n_envs'"]),
    ("task.goals.x=1", ["'task.goals'", "did you mean 'task.goal'"]),
    ("experiment=nope", ["unknown experiment preset 'nope'", "seed_paper"]),
    ("ce.n_envs=1,2", ["ce.n_envs=1,2", "sweep", "one value"]),
])
def test_compose_config_refuses_in_one_line(override: str, needles: list[str]) -> None:
    with pytest.raises(ConfigError) as ei:
        compose_config(["device=cpu", override])
    msg = str(ei.value)
    assert "\n" not in msg, msg
    for n in needles:
        assert n in msg, (n, msg)


def test_compose_config_gives_the_plain_config() -> None:
    d = compose_config(["device=cpu", "ce.n_envs=3"])
    assert isinstance(d, dict) and "hydra" not in d and d["ce"]["n_envs"] == 3


def test_from_config_checks_a_composed_config_at_once() -> None:
    """A Hydra app's composed config (DictConfig) or compose_config's plain data: checked into a
    RunSpec when the planner is made; a bad value is one line there, before any worker starts."""
    from omegaconf import OmegaConf

    cfg = compose_config(["device=cpu", "ce.n_envs=3", "ce.n_elite=2"])
    planner = Planner.from_config(OmegaConf.create(cfg))
    assert planner.config == cfg and planner.open_pools == 0
    planner.close()
    bad = compose_config(["device=cpu", "ce.n_envs=3", "ce.n_elite=2"])
    bad["ce"]["n_elite"] = 5  # more elites than copies: build_run_spec's refusal
    with pytest.raises(ConfigError, match=r"ce.n_elite") as ei:
        Planner.from_config(bad)
    assert "\n" not in str(ei.value)
    with pytest.raises(ConfigError, match="a list of overrides goes to Planner"):
        Planner.from_config(["ce.n_envs=3"])  # type: ignore[arg-type]


# ------------------------------------------------------------------------------ plan twice
@pytest.fixture(scope="module")
def known(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return write_known_run(tmp_path_factory.mktemp("known") / "run")


@pytest.fixture(scope="module")
def planned(tmp_path_factory: pytest.TempPathFactory, known: Path):
    """One planner, ``plan()`` twice into two directories; then kept open for the replans."""
    overrides = [o for o in TINY if not o.startswith("controller.max_time_s")]  # the whole plan's horizon
    overrides += ["device=cpu", "validation=off", "workers.n=1", "ce.iterations=1", f"warm_start={known}"]
    root = tmp_path_factory.mktemp("planner")
    planner = Planner(overrides)
    try:
        first = planner.plan(root / "first")
        second = planner.plan(root / "second")
        yield planner, first, second, root
    finally:
        planner.close()


def test_plan_twice_keeps_the_workers_and_gives_the_same_plan(planned) -> None:
    _, first, second, _ = planned
    assert first.scene == "built" and second.scene == "kept"
    assert first.feasible and second.feasible, (first.status, second.status)
    assert (second.cost, second.z, second.feasible) == (first.cost, first.z, first.feasible)
    assert first.run_dir != second.run_dir


def test_plan_result_is_typed(planned) -> None:
    planner, first, _, root = planned
    assert isinstance(first, PlanResult) and first.from_action == 0 and planner.last is not None
    task = build_run_spec(planner.config).task
    assert first.plan == task.describe()
    assert isinstance(first.actions, tuple) and first.actions == tuple(str(a) for a in task.plan)
    assert first.actions[1] == "grasp(cube, Cube_g)"
    assert isinstance(first.cost, float) and math.isfinite(first.cost)
    assert len(first.z) == task.layout.dim and all(isinstance(v, float) for v in first.z)
    assert first.columns == tuple(task.layout.column_names)
    names = {p for a in task.plan for p in a.params}
    assert set(first.params) == names == {"Table1", "Cube_g", "Table2", "Cube_p", "Exit"}
    assert [len(first.params[n]) for n in ("Table1", "Cube_g", "Exit")] == [2, 3, 2]
    assert first.params["Table1"] == list(first.z[:2])
    assert first.run_dir == root / "first" and (first.run_dir / RESULT_FILE).is_file()
    doc = json.loads((first.run_dir / RESULT_FILE).read_text())
    assert doc["feasible"] is True and doc["plan"] == first.plan
    assert first.validation is None  # validation=off
    assert first.timings.total_s > 0 and first.iterations_done == 1


# ------------------------------------------------------------------------------ replan
def test_replan_writes_its_block_and_keeps_or_rebuilds_scenes(planned, tmp_path: Path) -> None:
    planner, first, _, _ = planned
    state = load_state(STATE_GRASPED)
    same = planner.replan(state, 2, source=first, run_dir=tmp_path / "same", budget=BUDGET)
    assert same.scene == "kept" and same.from_action == 2
    assert same.plan == "move_to(Table2), place(cube, Cube_p), move_to(Exit)"
    assert same.actions == ("move_to(Table2)", "place(cube, Cube_p)", "move_to(Exit)")
    assert same.whole_plan == first.plan
    doc = json.loads((tmp_path / "same" / RESULT_FILE).read_text())
    rp = doc["replan"]
    assert rp["action"] == 2 and rp["from"] == str(first.run_dir) and rp["state"]["held"] == "cube"
    assert (tmp_path / "same" / "start_state.json").is_file()
    moved = planner.replan(state, 2, ["scene.tables.1.center=[0.1,-1.3]"], source=first,
                           run_dir=tmp_path / "moved", budget=BUDGET)
    assert moved.scene == "rebuilt"
    doc = json.loads((tmp_path / "moved" / RESULT_FILE).read_text())
    assert doc["config"]["scene"]["tables"][1]["center"] == [0.1, -1.3] and doc["replan"]["action"] == 2
    again = planner.replan(state, 2, ["scene.tables.1.center=[0.1,-1.3]"], source=first,
                           run_dir=tmp_path / "again", budget=BUDGET)
    assert again.scene == "kept"  # the same moved world: the rebuilt scenes are taken over


@pytest.mark.parametrize("from_action, changes, needles", [
    (2, ["task.plan='move_to(Exit)'"], ["task.plan", "would change the plan"]),
    (7, [], ["replan.action = 7 is invalid", "5 actions"]),
    (-1, [], ["replan.action = -1 is invalid", ">= 0"]),
])
def test_replan_refusals_before_anything_runs(planned, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, no_sim,
                                             from_action: int, changes: list[str], needles: list[str]) -> None:
    planner, first, _, _ = planned

    def no_workers(*a, **k):
        raise AssertionError("workers were asked for an invalid replan")

    monkeypatch.setattr(planner, "_pool", no_workers)
    with pytest.raises(ConfigError) as ei:
        planner.replan(load_state(STATE_GRASPED), from_action, changes, source=first, run_dir=tmp_path / "r", budget=BUDGET)
    msg = str(ei.value)
    assert "\n" not in msg, msg
    for n in needles:
        assert n in msg, (n, msg)
    assert not (tmp_path / "r" / "history.npz").exists()
    if (tmp_path / "r" / RESULT_FILE).exists():  # a refused run says so in its result.json
        doc = json.loads((tmp_path / "r" / RESULT_FILE).read_text())
        assert doc["status"] == "failed" and doc["simulated"] is False and doc["error"] == msg
