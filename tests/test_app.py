"""The ``realize`` command: config validation at the edge, results on disk, interrupt and resume,
sweeps with their summary table. Runs the real simulator with tiny budgets (4 plans, short
horizon); bad-input cases check that no simulator is built."""

from __future__ import annotations

import csv
import json
import os
import shutil
import signal
import subprocess
import time
from dataclasses import asdict
from pathlib import Path

import numpy as np
import pytest
import yaml

import realize.scene
from helpers import TINY, cfg_of, compose_config, expect_config_error, plain, realize_cli, tiny
from realize.cli.main import preflight
from realize.config import ConfigError
from realize.paths import CONFIG_DIR
from realize.run.one_run import run
from realize.spec.run_spec import build_run_spec
from realize.run_dir.checkpoint import CheckpointError, load_checkpoint
from realize.run_dir.directory import RunDir
from realize.run_dir.history import History, load_history
from realize.run_dir.names import CHECKPOINT_FILE, HISTORY_FILE, JOB_STATUS_FILE, RESULT_FILE
from realize.run_dir.result_doc import ResultDoc
from realize.cli.sweep_summary import COLUMNS, write_summary


# --------------------------------------------------------------------------------------------
# config tree
# --------------------------------------------------------------------------------------------


def test_default_config_validates_without_simulating(no_sim: None) -> None:
    spec = build_run_spec(plain([]))
    assert spec.ce.n_envs == 200 and spec.ce.n_elite == 10 and spec.ce.iterations == 10
    assert spec.task.describe() == "move_to(Table1), grasp(cube, Cube_g), move_to(Table2), place(cube, Cube_p), move_to(Exit)"
    assert spec.task.layout.names == ["Table1", "Cube_g", "Table2", "Cube_p", "Exit"]
    # the yaml spells out the defaults; the backend is resolved at the edge (device=auto)
    assert asdict(spec.sim) == dict(asdict(realize.scene.SimSettings()), backend=spec.placement.backend)
    assert spec.placement.backend in ("cpu", "gpu") and spec.placement.device.type in ("cpu", "cuda")
    assert spec.placement.dtype == spec.ce.torch_dtype


def test_experiment_presets() -> None:
    seed = build_run_spec(plain(["experiment=seed_paper_exact"]))
    assert (seed.ce.n_envs, seed.ce.n_elite, seed.ce.iterations) == (200, 10, 10)
    fast = build_run_spec(plain(["experiment=seed_paper", "levers=fast"]))  # half the batch, memory, screen
    assert (fast.ce.n_envs, fast.ce.n_elite, fast.ce.iterations, fast.ce.keep_elites) == (100, 10, 10, True)
    assert (fast.ce.screen, fast.ce.patience, fast.ce.prune, fast.stitch) == (True, 3, True, None)
    stitched = build_run_spec(plain(["experiment=seed_paper"]))  # levers=stitched, the preset's choice
    assert stitched.stitch is not None and (stitched.ce.n_envs, stitched.stitch.n_prefix) == (76, 50)
    journal = build_run_spec(plain(["experiment=journal", "scene=wall"]))
    assert journal.ce.schedule == "linear"
    assert journal.ce.n_envs_at(0) == 3000 and journal.ce.n_envs_at(19) == 300
    assert (journal.ce.n_elite, journal.ce.iterations) == (50, 20)
    assert journal.ce.n_envs == 3000  # the scene's size: the schedule only shrinks the batch
    assert journal.geometry.variant == "wall" and journal.geometry.extras[0].name == "wall"
    assert build_run_spec(plain(["scene=ramp"])).geometry.extras[0].name == "ramp"


def test_ramp_ablation_sweep_composes() -> None:
    """Every arm of the ramp ablation sweep builds a valid run spec that differs from plain CE
    in exactly its one option (no simulation)."""
    params = cfg_of(["experiment=ramp_ablation"], hydra_cfg=True).hydra.sweeper.params
    assert set(params) == {"ablation", "seed"}
    arms = str(params["ablation"]).split(",")
    assert arms == ["baseline", "modes2", "uniform10", "rank", "knn5"]
    base = build_run_spec(plain(["experiment=ramp_ablation"])).ce
    assert (base.n_modes, base.uniform_share, base.rank_weighted, base.knn_robust) == (1, 0.0, False, 0)
    changed = {}
    for arm in arms:
        spec = build_run_spec(plain(["experiment=ramp_ablation", f"ablation={arm}"]))
        assert spec.geometry.variant == "ramp" and spec.ce.n_envs == 64
        assert "Cube_p" in spec.task.layout.names and spec.task.layout.regions["Cube_p"].dim == 3
        changed[arm] = {k for k in ("n_modes", "uniform_share", "rank_weighted", "knn_robust")
                        if getattr(spec.ce, k) != getattr(base, k)}
    assert changed == {"baseline": set(), "modes2": {"n_modes"}, "uniform10": {"uniform_share"},
                       "rank": {"rank_weighted"}, "knn5": {"knn_robust"}}
    with pytest.raises(ConfigError, match=r"ce\.n_modes \(9\) must be <= ce\.n_elite \(8\)"):
        build_run_spec(plain(["experiment=ramp_ablation", "ce.n_modes=9"]))


def test_plan_from_pddl_matches_the_yaml_plan(no_sim: None) -> None:
    spec = build_run_spec(plain(["task.planner.enabled=true", "task.plan=null"]))
    assert spec.task.describe() == build_run_spec(plain([])).task.describe()


def test_the_composed_controller_is_rollout_config_itself() -> None:
    """The controller group is RolloutConfig's defaults (realize.spec.hydra_edge.register_schema),
    nested pid, astar and fabric included: no YAML copy to keep in step."""
    from realize.spec.compose import compose_config
    from realize.realization.config import RolloutConfig

    assert compose_config([])["controller"] == json.loads(json.dumps(asdict(RolloutConfig())))  # tuples -> lists
    assert not (CONFIG_DIR / "controller").exists()


def test_the_composed_sim_keys_are_sim_settings_fields() -> None:
    """The sim group is SimSettings itself (realize.spec.hydra_edge.register_schema)."""
    from dataclasses import fields

    from realize.spec.compose import compose_config

    assert set(compose_config([])["sim"]) == {f.name for f in fields(realize.scene.SimSettings)}


@pytest.mark.parametrize(
    "launcher, target",
    [
        ("basic", "BasicLauncher"),
        ("joblib", "JoblibLauncher"),
        ("submitit_local", "LocalLauncher"),
        ("submitit_slurm", "SlurmLauncher"),
        ("slurm", "SlurmLauncher"),
    ],
)
def test_launchers_resolve(launcher: str, target: str) -> None:
    cfg = cfg_of([f"hydra/launcher={launcher}"], hydra_cfg=True)
    assert cfg.hydra.launcher._target_.endswith(target)
    assert any(cb._target_ == "realize.cli.sweep_summary.SweepSummary" for cb in cfg.hydra.callbacks.values())


# --------------------------------------------------------------------------------------------
# bad input: one clear message naming the key/file, nothing simulated
# --------------------------------------------------------------------------------------------

BAD = [
    (["ce.n_envs=4", "ce.n_elite=5"], ["ce.n_elite = 5", "ce.n_envs = 4"]),
    (["ce.iterations=0"], ["ce.iterations = 0"]),
    (["ce.schedule=linear"], ["ce.n_envs_end"]),
    (["ce.schedule=linear", "ce.n_envs_end=300"], ["ce.n_envs_end = 300", "ce.n_envs = 4"]),
    (["ce.fallback=magic"], ["ce.fallback", "magic"]),
    (["+ce.n_samples=3"], ["ce", "n_samples"]),
    (["+task.foo=1"], ["task", "foo"]),
    (["task.params.Cube_g.radius=-0.1"], ["params.Cube_g", "radius"]),
    (["task.params.Table1.r_min=2.0"], ["params.Table1", "r_min"]),
    (["task.params.Exit.type=triangle"], ["params.Exit", "triangle"]),
    (['task.plan=["move_to(Table1)","grasp(cube,Nowhere)"]'], ["plan[1]", "Nowhere"]),
    (['task.plan=["fly(Table1)"]'], ["plan[0]", "fly"]),
    (['task.plan=["grasp(cube,Table1)"]'], ["plan[0]", "Table1", "grasp"]),
    (["task.goal.rests_on.cube=table9"], ["goal.rests_on.cube", "table9"]),
    (["task.planner.enabled=true", "task.planner.domain=missing_domain.pddl"], ["missing_domain.pddl"]),
    (["sim.sim_freq=50"], ["sim.sim_freq = 50"]),
    (["sim.backend=tpu"], ["sim.backend", "tpu"]),
    (["sim.solver_position_iterations=0"], ["sim.solver_position_iterations = 0"]),
    (["sim.control_freq=fast"], ["sim.control_freq", "fast", "integer"]),
    (["scene.variant=moon"], ["scene.variant", "moon"]),
    (["scene.robot_start=[0.0,1.2,0.0]"], ["scene.robot_start", "table1"]),
    (["controller.pid.kp=-1"], ["controller.pid", "kp", "-1"]),
    (["controller.max_time_s=0"], ["controller.max_time_s"]),
    (["device=gpu"], ["device", "gpu"]),
    (["seed=-1"], ["seed = -1"]),
    (["logging.rrd=../elsewhere.rrd"], ["logging.rrd"]),
    (["task_file=no/such/task.yaml"], ["task_file", "no/such/task.yaml"]),
]


@pytest.mark.parametrize("overrides, needles", BAD, ids=[" ".join(o) for o, _ in BAD])
def test_bad_config_fails_before_simulation(overrides: list[str], needles: list[str], tmp_path: Path,
                                             no_sim: None) -> None:
    t0 = time.perf_counter()
    msg, res = expect_config_error(overrides, needles, tmp_path)
    assert time.perf_counter() - t0 < 30
    # the failure is on disk for sweeps and post-mortems
    assert res["status"] == "failed" and res["error"] == msg and res["simulated"] is False
    assert not (tmp_path / CHECKPOINT_FILE).exists() and not (tmp_path / HISTORY_FILE).exists()


def test_malformed_yaml_task_file(tmp_path: Path, no_sim: None) -> None:
    bad = tmp_path / "my_task.yaml"
    bad.write_text("params:\n  Table1: {type: annulus, center: [0, 1.2]\nplan: [move_to(Table1)]\n")
    with pytest.raises(ConfigError) as ei:
        run(cfg_of(TINY + [f"task_file={bad}"]), tmp_path / "run")
    assert str(bad) in str(ei.value) and "not valid YAML" in str(ei.value) and "line" in str(ei.value)


def test_malformed_yaml_in_a_config_group(tmp_path: Path) -> None:
    (tmp_path / "task").mkdir()
    bad = tmp_path / "task" / "broken.yaml"
    bad.write_text("params:\n  Table1: {type: annulus, center: [0, 1.2]\nplan: [move_to(Table1)]\n")
    with pytest.raises(ConfigError) as ei:
        preflight([f"hydra.searchpath=[file://{tmp_path}]", "task=broken"])
    assert str(bad) in str(ei.value) and "line 2" in str(ei.value) and "\n" not in str(ei.value)


def test_a_group_outside_the_defaults_list_with_a_key_is_one_line() -> None:
    """``ablation=modes2 ce.n_envs=3`` (found by scripts/fuzz_inputs.py): the key check composed
    the group choices and let Hydra's composition error out as a traceback."""
    with pytest.raises(ConfigError) as e:
        preflight(["ablation=modes2", "ce.n_envs=3"])
    assert "Could not override 'ablation'" in str(e.value) and "+ablation=modes2" in str(e.value)
    assert "\n" not in str(e.value)


def test_task_file_errors_name_the_file(tmp_path: Path, no_sim: None) -> None:
    task = yaml.safe_load((CONFIG_DIR / "task" / "pick_place.yaml").read_text())
    task["params"]["Cube_p"]["polar_max"] = 4.0
    path = tmp_path / "polar.yaml"
    path.write_text(yaml.safe_dump(task))
    with pytest.raises(ConfigError) as ei:
        run(cfg_of(TINY + [f"task_file={path}"]), tmp_path / "run")
    assert f"{path}:params.Cube_p" in str(ei.value) and "polar_max" in str(ei.value)
    # result.json records the task the run was given (the file's), not the default task group
    res = json.loads((tmp_path / "run" / RESULT_FILE).read_text())
    assert res["status"] == "failed" and res["config"]["task"] == task and res["config"]["task_file"] == str(path)


def test_a_missing_task_file_records_no_task(tmp_path: Path, no_sim: None) -> None:
    with pytest.raises(ConfigError, match="file not found"):
        run(cfg_of(TINY + [f"task_file={tmp_path / 'nope.yaml'}"]), tmp_path / "run")
    res = json.loads((tmp_path / "run" / RESULT_FILE).read_text())
    assert res["config"]["task"] is None and res["config"]["task_file"] == str(tmp_path / "nope.yaml")


def test_resume_dir_that_is_not_a_run(tmp_path: Path, no_sim: None) -> None:
    with pytest.raises(ConfigError, match=r"resume: .* is not a realize run directory \(no checkpoint.json\)"):
        run(cfg_of(TINY + [f"resume={tmp_path}"]), tmp_path / "run")
    with pytest.raises(ConfigError, match="is not a realize run directory"):
        preflight([f"resume={tmp_path}"])


def test_resume_with_corrupt_checkpoint(tmp_path: Path, no_sim: None) -> None:
    (tmp_path / CHECKPOINT_FILE).write_text("{not json")
    with pytest.raises(ConfigError, match=r"checkpoint.json is not valid JSON"):
        run(cfg_of(TINY + [f"resume={tmp_path}"]), tmp_path / "run")
    (tmp_path / CHECKPOINT_FILE).write_text(json.dumps({"format": "something-else"}))
    with pytest.raises(CheckpointError, match="not a realize checkpoint"):
        load_checkpoint(tmp_path)


@pytest.mark.parametrize(
    "args, needles",
    [
        (["experiment=foo"], ["experiment=foo", "seed_paper", "journal"]),
        (["task=nope"], ["task=nope", "pick_place"]),
        (["-m", "ce=seed_paper,bogus"], ["ce=bogus"]),
        (["ce.foo=1"], ["ce.foo"]),
        (["ce.n_envs=[1"], ["ce.n_envs=[1"]),
        (["experiment=ramp_ablation", "ablation=knn9"], ["ablation=knn9", "knn5", "uniform10"]),
        (["ablation=knn5"], ["ablation", "+ablation=knn5"]),  # no preset chose the group
    ],
)
def test_preflight_errors(args: list[str], needles: list[str]) -> None:
    with pytest.raises(ConfigError) as ei:
        preflight(args)
    for n in needles:
        assert n in str(ei.value)


def test_an_ablation_arm_is_chosen_on_the_command_line() -> None:
    args = ["experiment=ramp_ablation", "ablation=knn5"]
    assert preflight(args) == args
    assert compose_config(*args)["ce"]["knn_robust"] == 5
    assert compose_config("experiment=ramp_ablation")["ce"]["knn_robust"] == 0  # the baseline arm


def test_cli_bad_input_exit_code_and_one_line(tmp_path: Path) -> None:
    for args, needle in ((["experiment=foo"], "experiment=foo"),
                         (["ce.n_envs=4", "ce.n_elite=9", f"hydra.run.dir={tmp_path / 'r'}"], "ce.n_elite = 9")):
        p = realize_cli(*args, cwd=tmp_path, timeout=120)
        assert p.returncode == 2, p.stderr
        err = [ln for ln in p.stderr.splitlines() if ln.startswith("error:")]
        assert len(err) == 1 and needle in err[0], p.stderr
        assert "Traceback" not in p.stderr


# --------------------------------------------------------------------------------------------
# real runs (tiny budgets)
# --------------------------------------------------------------------------------------------

RESULT_KEYS = {
    "status", "interrupted", "feasible", "best_cost", "best_params", "success_per_iter", "best_cost_per_iter",
    "elite_per_iter", "wall_time_s", "config", "versions", "seed", "plan", "iterations_done", "final_mean",
    "final_std",
}


def test_tiny_run_writes_results(tmp_path: Path) -> None:
    out = run(cfg_of(tiny(logging__rerun="true") + ["seed=3"]), tmp_path)
    assert out.status == "done" and out.iterations_done == 2 and out.exit_code == 0
    res = json.loads((tmp_path / RESULT_FILE).read_text())
    assert RESULT_KEYS <= set(res)
    assert res["status"] == "done" and res["interrupted"] is False and res["seed"] == 3
    assert len(res["success_per_iter"]) == len(res["best_cost_per_iter"]) == len(res["elite_per_iter"]) == 2
    assert set(res["best_params"]) == {"Table1", "Cube_g", "Table2", "Cube_p", "Exit"}
    assert set(res["best_params"]["Cube_g"]) == {"x", "y", "z"}
    assert res["config"]["ce"]["n_envs"] == 4 and res["plan"].startswith("move_to(Table1)")
    assert {"torch", "mani_skill", "sapien", "numpy", "realize"} <= set(res["versions"])
    assert res["wall_time_s"] > 0
    with np.load(tmp_path / HISTORY_FILE, allow_pickle=False) as h:
        assert h["Z_000"].shape == (4, 12) and h["cost_001"].shape == (4,)
        assert h["feasible_000"].dtype == bool and h["mean"].shape == (2, 12)
        assert np.isnan(h["mean"]).sum() == 0  # refit after every iteration (fallback: progress)
        assert list(h["column_names"][:2]) == ["Table1.x", "Table1.y"]
        assert h["action_success_000"].shape == (4, 5)
    ck = load_checkpoint(tmp_path)
    assert ck.iteration == 2 and len(ck.records) == 2
    rrd = tmp_path / "realize.rrd"
    assert rrd.is_file() and rrd.stat().st_size > 0
    from realize.recording.read import read_rrd_summary

    rr = read_rrd_summary(rrd)
    assert rr["iterations"] == [0, 1]
    assert [rr["scalars"]["/stats/success/share"][i] for i in (0, 1)] == res["success_per_iter"]
    assert (tmp_path / "scene.json").is_file()
    with np.load(tmp_path / "trajectories_iter1.npz", allow_pickle=False) as tr:
        assert tr["traj_base"].shape[0] == 4 and tr["traj_base"].shape[2] == 2
    # the typed reader sees the same run, and writes back the same document
    rd = RunDir(tmp_path)
    doc = rd.result()
    assert isinstance(doc, ResultDoc) and doc.to_json() == res
    assert doc.n_envs == 4 and doc.backend == "cpu" and doc.n_envs_per_iter == [4, 4]
    assert [r.success_share for r in rd.checkpoint().records] == doc.success_per_iter
    assert [r.best_cost for r in rd.checkpoint().records] == doc.best_cost_per_iter
    plan = rd.best_plan()
    assert plan.best_z == res["best_z"] and plan.config == res["config"] and plan.leader is None
    assert rd.load_history().column_names == doc.columns and rd.trajectory_iterations() == [0, 1]
    scene = rd.scene()
    assert scene is not None and scene.layout.column_names == doc.columns


def _compare(a: Path, b: Path) -> None:
    ra, rb = (json.loads((d / RESULT_FILE).read_text()) for d in (a, b))
    for k in ("best_z", "best_cost", "feasible", "best_iteration", "success_per_iter", "best_cost_per_iter",
              "n_feasible_per_iter", "elite_per_iter", "final_mean", "final_std", "iterations_done"):
        assert ra[k] == rb[k], k
    with np.load(a / HISTORY_FILE, allow_pickle=False) as ha, np.load(b / HISTORY_FILE, allow_pickle=False) as hb:
        assert sorted(ha.files) == sorted(hb.files)
        for k in ha.files:
            np.testing.assert_array_equal(ha[k], hb[k], err_msg=k)


RESUME = tiny(ce__iterations=3) + ["seed=7"]


@pytest.fixture(scope="module")
def uninterrupted(tmp_path_factory: pytest.TempPathFactory) -> Path:
    d = tmp_path_factory.mktemp("uninterrupted")
    run(cfg_of(RESUME), d)
    return d


def test_interrupt_after_iteration_2_then_resume(tmp_path: Path, uninterrupted: Path) -> None:
    def stop(i: int) -> None:
        if i == 1:  # iterations 0 and 1 are on disk
            raise KeyboardInterrupt

    out = run(cfg_of(RESUME), tmp_path, after_iteration=stop)
    assert out.status == "interrupted" and out.exit_code == 130 and out.iterations_done == 2
    res = json.loads((tmp_path / RESULT_FILE).read_text())
    assert res["interrupted"] is True and res["iterations_done"] == 2 and "SIGINT" in res["error"]
    assert load_checkpoint(tmp_path).iteration == 2 and len(load_history(tmp_path / HISTORY_FILE)) == 2

    other = tmp_path.parent / (tmp_path.name + "_hydra_dir")
    done = run(cfg_of(["logging.progress=false", f"resume={tmp_path}"]), other)
    assert done.status == "done" and done.run_dir == tmp_path and done.iterations_done == 3
    res = json.loads((tmp_path / RESULT_FILE).read_text())
    assert res["interrupted"] is False and res["segments"] == 2 and res["resumed_from_iteration"] == 2
    _compare(uninterrupted, tmp_path)


@pytest.mark.slow  # a whole run (7 s on a busy 2-core host): make test keeps an interrupted run resumed
# (test_interrupt_after_iteration_2_then_resume)
def test_sigterm_marks_the_run_interrupted(tmp_path: Path) -> None:
    def term(i: int) -> None:
        if i == 0:
            os.kill(os.getpid(), signal.SIGTERM)

    before = signal.getsignal(signal.SIGTERM)
    out = run(cfg_of(tiny(ce__iterations=3)), tmp_path, after_iteration=term)
    assert out.status == "interrupted" and out.exit_code == 143 and out.iterations_done == 1
    res = json.loads((tmp_path / RESULT_FILE).read_text())
    assert res["interrupted"] is True and "SIGTERM" in res["error"]
    assert load_checkpoint(tmp_path).iteration == 1
    assert signal.getsignal(signal.SIGTERM) == before  # handlers restored


def test_resume_refuses_changed_settings(uninterrupted: Path, no_sim: None) -> None:
    before = (uninterrupted / RESULT_FILE).read_text()
    with pytest.raises(ConfigError, match=r"drop the override\(s\) \['ce.n_elite=3'\]"):
        # as from the command line, where the resumed run's Hydra dir is the run dir itself
        run(cfg_of([f"resume={uninterrupted}"]), uninterrupted,
            cli_overrides=[f"resume={uninterrupted}", "ce.n_elite=3"])
    assert (uninterrupted / RESULT_FILE).read_text() == before  # the run's result is untouched


@pytest.mark.slow  # a whole run and its resume (10 s on a busy 2-core host): make test keeps an
# interrupted run resumed (test_interrupt_after_iteration_2_then_resume)
def test_resume_keeps_the_runs_own_groups(tmp_path: Path) -> None:
    """A run made with ``validation=off`` (and its logging), interrupted, resumes with its saved
    groups, though the composed default validates: only what the command line names goes on top."""
    def stop(i: int) -> None:
        if i == 0:
            raise KeyboardInterrupt

    run_dir = tmp_path / "run"
    assert run(cfg_of(tiny(ce__iterations=2) + ["validation=off"]), run_dir, after_iteration=stop).interrupted
    composed = cfg_of([f"resume={run_dir}", "validation=default", "workers.n=1"])  # the defaults: 64 replicas
    done = run(composed, tmp_path / "hydra", cli_overrides=[f"resume={run_dir}", "workers.n=1"])
    assert done.status == "done" and done.iterations_done == 2
    res = json.loads((run_dir / RESULT_FILE).read_text())
    assert "validation" not in res and res["config"]["validation"]["replicas"] == 0
    assert res["config"]["logging"]["progress"] is False and res["config"]["workers"]["n"] == 1


def test_resume_of_a_finished_run_changes_nothing(tmp_path: Path, uninterrupted: Path,
                                                  capsys: pytest.CaptureFixture[str]) -> None:
    run_dir = tmp_path / "done"
    shutil.copytree(uninterrupted, run_dir)
    files = (RESULT_FILE, CHECKPOINT_FILE, HISTORY_FILE)
    before = {f: (run_dir / f).read_bytes() for f in files}
    out = run(cfg_of([f"resume={run_dir}", "validation=default"]), run_dir, cli_overrides=[f"resume={run_dir}"])
    assert out.status == "done" and out.exit_code == 0
    assert "was already complete; nothing changed" in capsys.readouterr().out
    assert {f: (run_dir / f).read_bytes() for f in files} == before


def _checkpoint_iteration(run_dir: Path) -> int | None:
    try:
        return int(json.loads((run_dir / CHECKPOINT_FILE).read_text())["iteration"])
    except (OSError, ValueError, KeyError):
        return None


@pytest.mark.slow  # a whole run or several processes: make test-all (make test keeps a smoke test)
def test_sigint_subprocess_then_resume(tmp_path: Path, uninterrupted: Path) -> None:
    """Ctrl-C to the command mid-run: it exits 130 with an ``interrupted`` result, and resuming
    gives the uninterrupted run. The interrupt cannot miss the run: the process is frozen
    (SIGSTOP) while the test reads its checkpoint, and SIGINT is sent while it is still frozen
    at a checkpoint of 1 or 2 of its 3 iterations, so it lands before the last iteration ends."""
    total = 3
    run_dir = tmp_path / "run"
    p = realize_cli(*RESUME, f"hydra.run.dir={run_dir}", cwd=tmp_path, background=True, stdout=subprocess.PIPE,
                    stderr=subprocess.PIPE)
    at, ended = None, None
    try:
        deadline = time.time() + 180
        while time.time() < deadline and at is None:
            os.kill(p.pid, signal.SIGSTOP)
            _, status = os.waitpid(p.pid, os.WUNTRACED)  # until it is stopped (or has ended)
            if not os.WIFSTOPPED(status):
                ended = status
                break
            k = _checkpoint_iteration(run_dir)
            if k is not None and k >= 1:
                at = k
                if k < total:
                    p.send_signal(signal.SIGINT)  # pending until it runs again
            os.kill(p.pid, signal.SIGCONT)
            time.sleep(0.05)
        assert ended is None, f"the run ended (wait status {ended}) before the test could interrupt it"
        assert at is not None, "no checkpoint within 180 s"
        assert at < total, f"the frozen run had already done all {total} iterations: the signal would miss"
        _, err = p.communicate(timeout=120)
    finally:
        if p.returncode is None and ended is None:
            p.kill()
            p.communicate()
    assert p.returncode == 130, err[-3000:]
    res = json.loads((run_dir / RESULT_FILE).read_text())
    assert res["interrupted"] is True and res["status"] == "interrupted" and "SIGINT" in res["error"]
    assert res["iterations_done"] < total and load_checkpoint(run_dir).iteration == at

    r = realize_cli(f"resume={run_dir}", "logging.progress=false", cwd=tmp_path, timeout=240)
    assert r.returncode == 0, r.stderr[-3000:]
    res = json.loads((run_dir / RESULT_FILE).read_text())
    assert res["status"] == "done" and res["interrupted"] is False and res["iterations_done"] == total
    assert res["segments"] == 2 and res["resumed_from_iteration"] == at
    _compare(uninterrupted, run_dir)


def _read_summary(path: Path) -> list[dict[str, str]]:
    with path.open() as f:
        rows = list(csv.DictReader(f))
    assert rows and set(COLUMNS) <= set(rows[0])
    return rows


def test_a_one_job_sweep_writes_its_summary(tmp_path: Path) -> None:
    """The sweep smoke test of make test: ``-m`` with one job through the launcher, its row in
    summary.csv (several jobs and swept keys: the 2x2 sweep in make test-slow)."""
    sweep = tmp_path / "sweep"
    p = realize_cli("-m", *tiny(ce__iterations=1, controller__max_time_s=3), "seed=1",
                    f"hydra.sweep.dir={sweep}", cwd=tmp_path, timeout=240)
    assert p.returncode == 0, p.stderr[-3000:]
    rows = _read_summary(sweep / "summary.csv")
    assert [(r["job"], r["status"]) for r in rows] == [("0", "done")]
    assert f"sweep summary: {sweep / 'summary.csv'}" in p.stdout
    res = json.loads((sweep / rows[0]["run_dir"] / RESULT_FILE).read_text())
    assert float(rows[0]["final_success"]) == res["success_per_iter"][-1] and res["seed"] == 1


@pytest.mark.slow  # four jobs of two swept keys: make test-all (the two-job smoke test above stays)
def test_multirun_2x2_basic_launcher_summary(tmp_path: Path) -> None:
    sweep = tmp_path / "sweep"
    p = realize_cli("-m", *tiny(ce__iterations=1, controller__max_time_s=3, ce__n_elite="1,2"), "seed=0,1",
                    f"hydra.sweep.dir={sweep}", cwd=tmp_path, timeout=240)
    assert p.returncode == 0, p.stderr[-3000:]
    rows = _read_summary(sweep / "summary.csv")
    assert len(rows) == 4 and {r["status"] for r in rows} == {"done"}
    assert [r["job"] for r in rows] == ["0", "1", "2", "3"]
    combos = {(o.split("ce.n_elite=")[1].split()[0], o.split("seed=")[1].split()[0])
              for o in (r["overrides"] for r in rows)}
    assert combos == {("1", "0"), ("1", "1"), ("2", "0"), ("2", "1")}
    assert {(r["ce.n_elite"], r["seed"]) for r in rows} == combos  # a column per swept key
    header = next(csv.reader((sweep / "summary.csv").open()))
    assert header[:2] == ["job", "ce.n_envs"] and "final_success" in header
    assert f"sweep summary: {sweep / 'summary.csv'}" in p.stdout  # the run says where it wrote the table
    for r in rows:
        assert r["feasible"] in ("True", "False") and float(r["wall_time_s"]) > 0
        assert (sweep / r["run_dir"] / RESULT_FILE).is_file()
        res = json.loads((sweep / r["run_dir"] / RESULT_FILE).read_text())
        assert float(r["final_success"]) == res["success_per_iter"][-1]


@pytest.mark.slow  # a whole run or several processes: make test-all (make test keeps a smoke test)
def test_sweep_values_are_checked_before_job_0(tmp_path: Path) -> None:
    """``ce.n_elite=1,9,2`` with 4 plans: refused in one line, exit 2, before any job runs."""
    sweep = tmp_path / "sweep"
    p = realize_cli("-m", *tiny(ce__iterations=1, controller__max_time_s=3, ce__n_elite="1,9,2"),
                    f"hydra.sweep.dir={sweep}", cwd=tmp_path, timeout=240)
    assert p.returncode == 2, p.stderr[-3000:]
    assert p.stderr.strip().splitlines()[-1].startswith("error: sweep job 1 (ce.n_elite=9): ce.n_elite = 9")
    assert "Traceback" not in p.stderr and not sweep.exists()  # nothing ran
    p = realize_cli("-m", *tiny(ce__iterations=1), "ce.n_envs=4,abc", f"hydra.sweep.dir={sweep}", cwd=tmp_path,
                    timeout=240)
    assert p.returncode == 2 and "sweep job 1 (ce.n_envs=abc): ce.n_envs = 'abc'" in p.stderr
    p = realize_cli("-m", *tiny(ce__iterations=1), f"warm_start=null,{tmp_path / 'nope'}", f"hydra.sweep.dir={sweep}",
                    cwd=tmp_path, timeout=240)
    assert p.returncode == 2 and "sweep job 1 (warm_start=" in p.stderr and not sweep.exists()


@pytest.mark.slow  # a whole run or several processes: make test-all (make test keeps a smoke test)
def test_sweep_with_a_job_that_fails_when_it_starts(tmp_path: Path) -> None:
    """What only a job's start can find (a resumed run's corrupt checkpoint) fails that job;
    the others run, and every job is in the summary."""
    broken = tmp_path / "broken"
    broken.mkdir()
    (broken / CHECKPOINT_FILE).write_text("{not json")
    sweep = tmp_path / "sweep"
    p = realize_cli("-m", *tiny(ce__iterations=1, controller__max_time_s=3), f"resume=null,{broken}",
                    f"hydra.sweep.dir={sweep}", cwd=tmp_path, timeout=240)
    assert p.returncode != 0 and "Traceback" not in p.stderr  # the sweep reports the failure ...
    rows = _read_summary(sweep / "summary.csv")  # ... and every job is in the table
    assert [r["status"] for r in rows] == ["done", "failed"]
    assert "resume:" in rows[1]["error"] and (sweep / rows[1]["run_dir"] / "error.txt").is_file()


def _two_seeds_done(tmp_path: Path, *launcher: str) -> None:
    sweep = tmp_path / "sweep"
    p = realize_cli("-m", *launcher, *tiny(ce__iterations=1, controller__max_time_s=3), "seed=0,1",
                    f"hydra.sweep.dir={sweep}", cwd=tmp_path, timeout=240)
    assert p.returncode == 0, p.stderr[-3000:]
    rows = _read_summary(sweep / "summary.csv")
    assert len(rows) == 2 and {r["status"] for r in rows} == {"done"}


@pytest.mark.slow  # a whole run or several processes: make test-all (make test keeps a smoke test)
def test_joblib_launcher_sweep(tmp_path: Path) -> None:
    _two_seeds_done(tmp_path, "hydra/launcher=joblib", "hydra.launcher.n_jobs=2")


@pytest.mark.slow  # a whole run or several processes: make test-all (make test keeps a smoke test)
def test_submitit_local_sweep(tmp_path: Path) -> None:
    _two_seeds_done(tmp_path, "hydra/launcher=submitit_local", "hydra.launcher.timeout_min=5")


# --------------------------------------------------------------------------------------------
# files (no simulator)
# --------------------------------------------------------------------------------------------


def test_history_roundtrip_without_pickle(tmp_path: Path) -> None:
    h = History(["a.x", "a.y"])
    for i in range(3):
        h.append({"Z": np.full((2 + i, 2), float(i)), "cost": np.arange(2 + i, dtype=float)},
                 n_envs=2 + i, success_share=0.5, best_cost=float("inf") if i == 0 else 10.0 - i,
                 mean=None if i == 0 else np.ones(2), std=None if i == 0 else np.ones(2))
    h.save(tmp_path / HISTORY_FILE)
    back = load_history(tmp_path / HISTORY_FILE, keep=2)
    assert len(back) == 2 and back.column_names == ["a.x", "a.y"]
    np.testing.assert_array_equal(back.arrays()["Z_001"], np.ones((3, 2)))
    assert np.isnan(back.arrays()["mean"][0]).all()
    # a mixture: the heaviest mode in mean/std (I, D), every mode in mode_* (I, k, D)
    mix = History(["a.x", "a.y"])
    mix.append({"cost": np.zeros(2)}, n_envs=2, success_share=0.0, best_cost=float("inf"), mean=None, std=None)
    mix.append({"cost": np.zeros(2)}, n_envs=2, success_share=1.0, best_cost=1.0,
               mean=np.array([[0.0, 0.0], [5.0, 5.0]]), std=np.array([[1.0, 1.0], [2.0, 2.0]]),
               weights=np.array([0.25, 0.75]))
    mix.save(tmp_path / "mix.npz")
    a = load_history(tmp_path / "mix.npz").arrays()
    np.testing.assert_array_equal(a["mean"][1], [5.0, 5.0])
    np.testing.assert_array_equal(a["std"][1], [2.0, 2.0])
    assert a["mode_mean"].shape == (2, 2, 2) and np.isnan(a["mode_mean"][0]).all()
    np.testing.assert_array_equal(a["mode_weight"][1], [0.25, 0.75])
    assert "mode_mean" not in back.arrays()  # single-mode runs keep the old file layout
    bad = History(["x"])
    bad.append({"bad": np.array([object()])}, n_envs=1, success_share=0, best_cost=0, mean=None, std=None)
    with pytest.raises(TypeError, match="object"):
        bad.save(tmp_path / "x.npz")


def test_summary_lists_jobs_without_results(tmp_path: Path) -> None:
    for num, (status, err) in enumerate([("done", ""), ("failed", "RuntimeError: boom")]):
        d = tmp_path / str(num)
        d.mkdir()
        (d / JOB_STATUS_FILE).write_text(json.dumps({"job_num": num, "overrides": [f"seed={num}"],
                                                     "status": status, "error": err}))
    (tmp_path / "0" / RESULT_FILE).write_text(json.dumps({"status": "done", "feasible": True, "best_cost": 412.0,
                                                          "wall_time_s": 12.5, "iterations_done": 10}))
    (tmp_path / "0" / RESULT_FILE).write_text(json.dumps({"status": "done", "feasible": True, "best_cost": 412.0,
                                                          "wall_time_s": 12.5, "iterations_done": 10,
                                                          "success_per_iter": [0.25, 0.5]}))
    rows = _read_summary(write_summary(tmp_path))
    assert [r["status"] for r in rows] == ["done", "failed"]
    assert [r["seed"] for r in rows] == ["0", "1"] and [r["final_success"] for r in rows] == ["0.5", ""]
    assert rows[0]["best_cost"] == "412.0" and rows[0]["feasible"] == "True"
    assert rows[1]["error"] == "RuntimeError: boom"
    assert rows[0]["final_stopped"] == rows[0]["final_finished_success"] == ""  # a run without pruning


def test_summary_says_a_pruned_jobs_finished_share_beside_its_stopped_rows(tmp_path: Path) -> None:
    """With ce.prune, final_success counts a stopped row as failed; the summary also says how many
    were stopped and the share of the rest that ended feasible (issue 58)."""
    d = tmp_path / "0"
    d.mkdir()
    (d / JOB_STATUS_FILE).write_text(json.dumps({"job_num": 0, "overrides": ["seed=0"], "status": "done"}))
    (d / RESULT_FILE).write_text(json.dumps({"status": "done", "feasible": True, "best_cost": 412.0, "iterations_done": 2,
                                             "success_per_iter": [0.1, 0.1], "n_envs_per_iter": [100, 100],
                                             "n_feasible_per_iter": [10, 10], "n_stopped_per_iter": [50, 80]}))
    (row,) = _read_summary(write_summary(tmp_path))
    assert (row["final_success"], row["final_stopped"], row["final_finished_success"]) == ("0.1", "80", "0.5")


@pytest.mark.slow
def test_resume_equals_uninterrupted_with_feasible_plans(tmp_path: Path) -> None:
    """The full horizon (plans succeed, elites ranked by cost): interrupt after iteration 2,
    resume in a fresh scene, same result as without the interruption."""
    over = ["ce.n_envs=8", "ce.n_elite=3", "ce.iterations=3", "seed=1", "logging.progress=false",
            "logging.rerun=false", "logging.record=false"]
    ref = tmp_path / "ref"
    run(cfg_of(over), ref)

    def stop(i: int) -> None:
        if i == 1:
            raise KeyboardInterrupt

    cut = tmp_path / "cut"
    assert run(cfg_of(over), cut, after_iteration=stop).interrupted
    run(cfg_of(["logging.progress=false", f"resume={cut}"]), tmp_path / "hydra_dir")
    _compare(ref, cut)
    assert json.loads((ref / RESULT_FILE).read_text())["feasible"]
