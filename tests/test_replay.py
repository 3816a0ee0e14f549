"""Replay, video and validation replicas from a run directory (CPU simulator).

The run directory is made by hand: the composed default config (the seed task) and a plan
vector known to reach the goal, written as ``result.json`` in the app's format. No CE search
runs here, so the tests take seconds per rollout rather than a whole run.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import torch

from helpers import GOOD, compose_config, load_script
from realize.validation.replay import ReplayError, build_replay_spec, replay, saved_plan
from realize.run_dir.jsonio import atomic_write_json
from realize.run_dir.names import RESULT_FILE
from realize.spec.run_spec import build_run_spec
from realize.scene import BatchedScene, EnvOptions, SimSettings
from realize.validation.returned_plan import validate
from realize.realization.rollout import PlanRealizer

FEASIBLE_Z = GOOD  # a plan of the seed task that reaches the goal with the default configs
SAVED_COST = 1.5  # a stand-in cost where the saved number does not matter (not a whole step: never a match)
SIM = SimSettings(backend="cpu")


def _direct_cost(z: list[float]) -> float:
    """The seed task's cost of ``z`` from a one-copy rollout built here, not by replay's code."""
    spec = build_run_spec(compose_config())
    with BatchedScene(1, spec.geometry_cfg, spec.sim) as scene:
        scene.reset()
        res = PlanRealizer(spec.task, scene, spec.rollout, seed=0).rollout(torch.tensor([z]))
    assert bool(res.feasible[0]), res.failure
    return float(res.cost[0])


def _write_run(run_dir: Path, overrides: list[str] = (), z: list[float] = FEASIBLE_Z,
               cost: float = SAVED_COST) -> Path:
    config = compose_config(*overrides, cpu=False)
    spec = build_run_spec(config)
    run_dir.mkdir(parents=True, exist_ok=True)
    atomic_write_json(run_dir / RESULT_FILE, {
        "status": "done", "feasible": True, "best_cost": cost, "best_z": z,
        "columns": list(spec.task.layout.column_names),
        "n_envs_scene": 1, "backend": "cpu", "config": config,
    })
    return run_dir


@pytest.fixture(scope="module")
def direct_cost() -> float:
    return _direct_cost(FEASIBLE_Z)


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory: pytest.TempPathFactory, direct_cost: float) -> Path:
    return _write_run(tmp_path_factory.mktemp("run") / "seed", cost=direct_cost)


def test_load_run_and_spec(run_dir: Path, direct_cost: float) -> None:
    run = saved_plan(run_dir)
    assert run.best_z == FEASIBLE_Z and run.best_cost == direct_cost and run.n_envs == 1
    spec = build_replay_spec(run)
    assert spec.sim.backend == "cpu" and spec.task.layout.dim == len(FEASIBLE_Z)


def test_replay_keeps_the_runs_backend_unless_told(run_dir: Path) -> None:
    """Replay, validation and the run's own candidate validation simulate on the backend the run's
    config names; they used to put every run on the CPU silently. A run made for the GPU is then
    refused on a machine without one (its config's device), and backend="cpu" says so on purpose."""
    import dataclasses

    run = saved_plan(run_dir)
    gpu = dataclasses.replace(run, config={**run.config, "device": "cuda",
                                           "sim": {**run.config["sim"], "backend": "gpu"}})
    if not torch.cuda.is_available():
        with pytest.raises(ReplayError, match="cuda|CUDA|GPU"):
            build_replay_spec(gpu)
    assert build_replay_spec(gpu, "cpu").sim.backend == "cpu"
    with pytest.raises(ReplayError, match="backend = 'tpu' is invalid"):
        build_replay_spec(run, "tpu")


def test_bad_run_dirs(tmp_path: Path) -> None:
    with pytest.raises(ReplayError, match="not found"):
        saved_plan(tmp_path)
    (tmp_path / RESULT_FILE).write_text(json.dumps({"config": {}, "best_z": None}))
    with pytest.raises(ReplayError, match="best_z"):
        saved_plan(tmp_path)
    for script in ("replay", "validate"):  # the command lines say so and exit 2
        assert load_script(script).main([str(tmp_path)]) == 2


def test_validate_candidates_zero_is_refused_not_read_as_the_runs(run_dir: Path, capsys: pytest.CaptureFixture) -> None:
    assert load_script("validate").main([str(run_dir), "--candidates", "0", "--dry-run"]) == 2
    assert "candidates = 0 must be an integer >= 1" in capsys.readouterr().err


def test_replay_reaches_the_goal(run_dir: Path, direct_cost: float) -> None:
    rep = replay(run_dir)
    assert rep.feasible, rep.failure
    assert rep.failure == "" and rep.backend == "cpu" and rep.video is None
    assert 300 < rep.cost < 1000
    # the run's saved cost is a one-copy rollout's: replay reproduces it bit for bit
    assert rep.cost == direct_cost and rep.matches and rep.cost_diff == 0.0


def test_randomized_reset_and_friction_per_copy() -> None:
    with BatchedScene(3, sim=SIM, env=EnvOptions(randomize_resets=True)) as s:
        s.reset(seed=7)
        cube_a, base_a = s.object_pose("cube"), s.base_pose()
        s.reset(seed=7)
        assert torch.equal(s.object_pose("cube"), cube_a) and torch.equal(s.base_pose(), base_a)  # seeded
        g = s.geometry
        nominal = torch.tensor(g.object("cube").position[:2], dtype=torch.float32)
        off = (cube_a[:, :2] - nominal).abs()
        assert (off.max(dim=1).values > 1e-4).all() and (off <= s.object_xy_noise + 1e-4).all()
        assert len({round(float(v), 5) for v in cube_a[:, 0]}) == 3  # each copy drew its own
        start_off = (base_a[:, :2] - torch.tensor(g.robot_start[:2])).abs()
        assert (start_off <= s.robot_xy_noise + 1e-4).all() and (start_off.max(dim=1).values > 1e-4).all()

        mu = s.set_object_friction("cube", [0.2, 1.0, 1.0]).numpy()
        assert np.allclose(s.object_friction("cube").numpy(), np.stack([mu, mu], axis=1))
        assert np.allclose(mu, g.object("cube").friction * np.array([0.2, 1.0, 1.0]))
        with pytest.raises(ValueError):
            s.set_object_friction("cube", [1.0, 1.0])
        # the same shove slides the slippery cube further along the table
        s.reset(seed=7)
        start = s.object_pose("cube")[:, :2]
        for c in range(2):
            s.push_object("cube", c, (0.0, 0.6, 0.0))
        for _ in range(10):
            s.step()
        slid = (s.object_pose("cube")[:, :2] - start).norm(dim=1)
        assert slid[0] > slid[1] + 0.01


def test_validation_writes_result_json(run_dir: Path) -> None:
    rep = validate(run_dir, replicas=4, seed=3, friction=(0.8, 1.2))
    doc = json.loads((run_dir / RESULT_FILE).read_text())
    v = doc["plan_validation"]
    assert v["replicas"] == 4 and v["seed"] == 3 and 0.0 <= v["success_share"] <= 1.0
    assert v["success_share"] == rep.success_share
    assert sum(v["failures"].values()) == round(4 * (1 - v["success_share"]))
    assert v["perturbation"]["friction"] == [0.8, 1.2]
    assert set(v["friction"]) == {"cube"} and len(v["friction"]["cube"]) == 4
    assert all(0.8 <= f / doc["config"]["scene"]["objects"]["cube"]["friction"] <= 1.2 for f in v["friction"]["cube"])
    assert doc["best_z"] == FEASIBLE_Z and doc["config"]["seed"] == 0  # the rest is kept
    assert rep.success_share > 0  # seed 3 gave 3 of 4 when written; the key matters here
    # where the replicas failed adds up (realize.validation.action_outcomes): completed never grows along the
    # plan, the goal's is the successes, each entry's failures are its started - completed, all sum to the misses
    acts, ok = v["per_action"], round(4 * v["success_share"])
    assert [a["action"] for a in acts] == [str(a) for a in build_replay_spec(saved_plan(run_dir)).task.plan] + ["goal"]
    assert all(x["completed"] >= y["completed"] for x, y in zip(acts, acts[1:])) and acts[-1]["completed"] == ok
    assert all(sum(a["failures"].values()) == a["started"] - a["completed"] for a in acts)
    assert sum(sum(a["failures"].values()) for a in acts) == 4 - ok == sum(v["failures"].values())
    assert [(s["first"], s["last"], s["completed"]) for s in v["per_segment"]] == [(0, len(acts) - 2, ok)]


@pytest.mark.slow  # a whole run and its video: make test-all
def test_push_scene_gets_its_camera_and_noise(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """scene=push builds RealizeMoveAndPush-v1: the video camera and the validation noise reach
    that task too (they used to be patched into the pick-and-place task's registry entry only)."""
    import imageio.v2 as imageio

    spec = build_run_spec(compose_config("experiment=move_and_push", cpu=False))
    z = spec.task.layout.sample_uniform(1, torch.Generator().manual_seed(0))[0].tolist()
    d = _write_run(tmp_path / "push", ["experiment=move_and_push", "controller.max_time_s=0.5"], z=z)
    import realize.workers.realizers as realizers

    opened, noise = realizers.open_realization, []

    def open_and_note(*args, **kwargs):  # the task that validation built and the worlds its copies meet
        scene, rs = opened(*args, **kwargs)
        w = kwargs.get("worlds")
        if w is None:  # the replay below: the task's own world
            return scene, rs
        k = {n: i for i, n in enumerate(w.names)}
        noise.append((scene.u.unwrapped.spec.id, float(np.abs(w.object_xy[:, k["cube"]]).max()),
                      float(np.abs(w.object_xy[:, k["stick"]]).max()), float(np.abs(w.robot_xy).max())))
        return scene, rs

    monkeypatch.setattr(realizers, "open_realization", open_and_note)
    rep = validate(d, replicas=2, seed=1, friction=(1.0, 1.0), object_xy=0.004, robot_xy=0.01, write=False)
    assert (rep.perturbation["object_xy"], rep.perturbation["robot_xy"]) == (0.004, 0.01)
    [(task_id, cube_xy, stick_xy, robot_xy)] = noise
    assert task_id == "RealizeMoveAndPush-v1" and 0 < cube_xy <= 0.004 and stick_xy == 0.0 and 0 < robot_xy <= 0.01
    assert set(rep.friction) == {"stick", "cube"}  # no friction range: every object keeps its own
    assert rep.friction["stick"] == [0.8, 0.8] and rep.friction["cube"] == [1.0, 1.0]
    out = tmp_path / "push.mp4"
    v = replay(d, out, fps=10, every=5, width=96, height=64, hold_s=0.0).video
    assert v is not None and (v.width, v.height) == (96, 64)
    reader = imageio.get_reader(str(out))
    assert reader.get_data(0).shape == (64, 96, 3)
    reader.close()


@pytest.mark.slow  # a whole run or several processes: make test-all (make test keeps a smoke test)
def test_video_follows_the_action_and_labels_every_frame(tmp_path: Path) -> None:
    """The default video camera follows the robot and what it acts on: during the grasp the
    4.5 cm (red) cube is at least 20 px wide, and a dark caption band with white text tops
    every frame (the caption's text itself: ``Caption.text``)."""
    import imageio.v2 as imageio

    from realize.validation.video import Caption

    # an 11 s horizon: the rollout is cut (infeasible) but the video covers the start of the grasp
    d = _write_run(tmp_path / "grasp", ["controller.max_time_s=11"])
    out = tmp_path / "v" / "grasp.mp4"
    rep = replay(d, out, fps=10, every=10, hold_s=0.5)
    v = rep.video
    assert v is not None and out.is_file() and v.bytes == out.stat().st_size > 1000
    assert (v.width, v.height) == (960, 720)
    assert v.frames == 1 + 220 // 10 + 5 and v.seconds == pytest.approx(v.frames / 10)
    reader = imageio.get_reader(str(out))
    frames = np.stack(list(reader.iter_data())).astype(int)  # list(reader) trips on its unknown length
    reader.close()
    assert frames.shape == (v.frames, 720, 960, 3)
    assert frames.std(axis=(1, 2, 3)).min() > 10  # not blank
    assert np.abs(frames[0] - frames[-1]).mean() > 0.5  # the robot moved
    band = frames[:, :30]
    assert (band.mean(axis=(1, 2, 3)) < 80).all() and ((band > 200).all(axis=-1).sum(axis=(1, 2)) > 50).all()
    red = (frames[..., 0] > 150) & (frames[..., 1] < 90) & (frames[..., 2] < 90)
    widths = [int(np.ptp(np.nonzero(r.any(axis=0))[0])) + 1 if r.any() else 0 for r in red]
    assert max(widths) >= 20, widths
    cap = Caption(["move_to(Table1)", "grasp(cube, Cube_g)"], control_freq=20, height=720)
    cap.on_action(1, torch.tensor([0]))
    assert cap.text(412) == "2/2 grasp(cube, Cube_g)   step 412   20.6 s"
