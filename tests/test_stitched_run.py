"""A run with stitched segments (``levers=stitched``: ``stitch.enabled``) through the search loop:
its files and their bookkeeping (every confirmed plan is a feasible prefix row joined to a
feasible suffix row, the best is the cheapest confirmed), its plan against the physics (replayed
alone, the cube ends on table 2), a resume equal to the run without the interruption, and the
config it refuses. Small batches, the seed task."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from helpers import compose_config, plain
from realize.validation.replay import replay
from realize.run.one_run import run
from realize.spec.run_spec import build_run_spec
from realize.config import ConfigError
from realize.run_dir.directory import RunDir

OVER = ["levers=stitched", "ce.n_envs=12", "stitch.n_prefix=8", "ce.n_elite=3", "ce.iterations=3", "seed=0",
        "validation=off", "logging.progress=false", "logging.rerun=false"]
# round 0's prefix, rounds 1 and 2's prefix and suffix, the confirmation
SEGMENTS = ["prefix", "prefix", "suffix", "prefix", "suffix", "full"]


# stitched_run, a whole run (20 s on a busy 2-core host), and the tests that read it are in make
# test-slow; make test keeps a stitched run of the realize command, bit for bit (tests/test_golden_default.py,
# seed_paper_default), and this file's config checks
@pytest.fixture(scope="module")
def stitched_run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    d = tmp_path_factory.mktemp("stitched")
    out = run(compose_config(*OVER), d)
    assert out.status == "done" and out.feasible
    return d


def _rows(h: dict[str, np.ndarray]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    its = sorted({k.rsplit("_", 1)[1] for k in h if k.startswith("Z_")}, key=int)
    return (np.concatenate([h[f"Z_{i}"] for i in its]), np.concatenate([h[f"cost_{i}"] for i in its]),
            np.concatenate([h[f"feasible_{i}"] for i in its]))


@pytest.mark.slow  # reads stitched_run (see the fixture)
def test_a_stitched_run_writes_each_segment_and_returns_the_cheapest_confirmed_plan(stitched_run: Path) -> None:
    doc = json.loads((stitched_run / "result.json").read_text())
    st = doc["stitched"]
    assert st["segment_per_iter"] == SEGMENTS and st["split"] == 2
    assert st["prefix"] == "move_to(Table1), grasp(cube, Cube_g)"
    assert doc["iterations_done"] == doc["iterations"] == 6
    assert doc["n_envs_per_iter"][:5] == [8, 8, 12, 8, 12] and 1 <= doc["n_envs_per_iter"][5] <= 10
    rd = RunDir(stitched_run)
    h1, h2 = rd.history_arrays(1), rd.history_arrays(2)
    zp, _, okp = _rows(h1)
    zs, _, oks = _rows(h2)
    zf, cf, okf = _rows(rd.history_arrays())
    assert len(zp) == 24 and len(zs) == 24 and len(zf) == doc["n_envs_per_iter"][5]
    cols = doc["columns"]  # each segment's columns, by name, in the whole plan's
    pc, sc = ([cols.index(str(c)) for c in h["column_names"]] for h in (h1, h2))
    assert sorted(pc + sc) == list(range(len(cols)))
    for z in zf:  # every confirmed plan: a feasible prefix row joined to a feasible suffix row
        assert any(np.array_equal(z[pc], p) for p in zp[okp])
        assert any(np.array_equal(z[sc], s) for s in zs[oks])
    assert okf.any()
    best = int(np.argmin(np.where(okf, cf, np.inf)))
    assert doc["best_cost"] == float(cf[best]) and doc["best_z"] == zf[best].tolist()


@pytest.mark.slow  # reads stitched_run (see the fixture)
def test_the_paper_figures_draw_a_stitched_run(stitched_run: Path, tmp_path: Path) -> None:
    """Fig. 2 draws the confirmation's whole plans (the run's only whole-plan batch); Fig. 3 each
    parameter's distribution per round from its segment's history: the prefix's from round 0,
    the suffix's from round 1."""
    from realize.figures.fig2 import fig2
    from realize.figures.fig3 import fig3

    assert (stitched_run / "scene.json").is_file() and (stitched_run / "trajectories_iter0.npz").is_file()
    assert not (stitched_run / "trajectories_iter1.npz").exists()  # (a segment's batches are not whole plans)
    png, _ = fig2(stitched_run, out_png=tmp_path / "fig2.png")
    assert png.stat().st_size > 0
    _, csv_path = fig3(stitched_run, out_png=tmp_path / "fig3.png")
    rows = [line.split(",") for line in csv_path.read_text().splitlines()[1:]]
    rounds = {p: sorted({int(r[1]) for r in rows if r[0] == p}) for p in {r[0] for r in rows}}
    assert rounds["Table1"] == [0, 1, 2, 3] and rounds["Table2"] == [1, 2, 3]  # 3 rounds and the final refit


@pytest.mark.slow  # reads stitched_run (see the fixture)
def test_the_stitched_runs_plan_puts_the_cube_on_table_2_replayed_alone(stitched_run: Path) -> None:
    rep = replay(stitched_run, exact=True)
    assert rep.feasible, rep.failure  # the goal: the cube on table 2, the robot at the exit
    assert rep.matches  # its shard re-run: the search's cost, bit for bit


@pytest.mark.slow  # a whole run or several processes: make test-all (make test keeps a smoke test)
def test_a_resumed_stitched_run_goes_on_from_its_checkpoint(stitched_run: Path, tmp_path: Path) -> None:
    """Interrupted after round 1's suffix, the resumed run goes on from the checkpoint's searches,
    pool and stitched plans, in fresh workers that restore the pool's states without the
    uninterrupted run's history, and ends with the same batches, costs and plan bit for bit
    (restores are history-free: test_stitched_segments.py). Before they were, the resumed run's
    suffix best was 365 against the uninterrupted 359."""
    def stop(i: int) -> None:
        if i == 2:
            raise KeyboardInterrupt

    cut = tmp_path / "cut"
    assert run(compose_config(*OVER), cut, after_iteration=stop).interrupted
    ckpt = json.loads((cut / "checkpoint.json").read_text())["ce_state"]
    # the one cut's search is the two-segment chain: round 2's prefix (segment 0) comes next
    assert ckpt["kind"] == "stitched_chain" and ckpt["phase"] == 0 and ckpt["pools"][0]["states"] and ckpt["stitched"]
    run(compose_config("logging.progress=false", f"resume={cut}"), tmp_path / "hydra_dir")
    a, b = (json.loads((d / "result.json").read_text()) for d in (stitched_run, cut))
    assert b["status"] == "done" and b["feasible"] and b["stitched"]["segment_per_iter"] == SEGMENTS
    for key in ("n_feasible_per_iter", "best_cost_per_iter", "best_cost", "best_z"):
        assert b[key] == a[key], key
    za, zb = (RunDir(d).history_arrays(1)["Z_002"] for d in (stitched_run, cut))  # round 2's prefix samples
    assert np.array_equal(za, zb)


@pytest.mark.parametrize("extra, needle", [
    (["stitch.n_prefix=20"], "stitch.n_prefix = 20 is more than ce.n_envs = 12"),
    (["stitch.split=5"], "stitch.split = 5 is invalid"),
    (["ce.replicas=2"], "cannot run a robust search"),
    (["warm_start=nowhere"], "cannot run a warm start"),
])
def test_what_a_stitched_run_cannot_do_is_one_config_error(extra: list[str], needle: str) -> None:
    with pytest.raises(ConfigError, match=needle):
        build_run_spec(plain(OVER + extra))


def test_levers_stitched_on_the_seed_task_runs_76_and_50_rows_in_38_copy_shards() -> None:
    spec = build_run_spec(plain(["experiment=seed_paper"]))
    assert spec.stitch is not None and (spec.ce.n_envs, spec.sim.shard_rows) == (76, 38)
    assert (spec.stitch.n_prefix, spec.stitch.n_suffix, spec.stitch.split, spec.stitch.iterations) == (50, 76, 2, 10)
    assert build_run_spec(plain(["experiment=seed_paper_exact"])).stitch is None
