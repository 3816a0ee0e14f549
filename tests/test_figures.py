"""Tests for realize.figures and scripts/fig{2,3,4}.py on run directories built from a synthetic
CE run in the app's file format (tests/_synthetic.py), and the figure inputs of realize.run_dir."""

from __future__ import annotations

import csv
import json
import os
from pathlib import Path

import numpy as np
import pytest

from _synthetic import PARAMS, run_synthetic, write_run_dir
from helpers import load_script
from realize.figures.fig2 import fig2
from realize.figures.fig3 import fig3, sampling_distributions
from realize.figures.fig4 import fig4, find_run_dirs
from realize.tasks.param_layout import ParamLayout
from realize.run_dir.directory import RunDir
from realize.run_dir.history import History
from realize.run_dir.names import SCENE_FILE
from realize.run_dir.scene_files import load_trajectories, save_scene, save_trajectories

REPO = Path(__file__).resolve().parents[1]
TESTS = Path(__file__).resolve().parent


def _png_ok(path: Path) -> None:
    data = path.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n"
    assert len(data) > 10_000


def _rows(path: Path) -> list[dict[str, str]]:
    with path.open() as f:
        return list(csv.DictReader(f))


@pytest.fixture(scope="module")
def synthetic():
    return run_synthetic(n=40, iterations=4, n_elite=5, seed=2, T=30)


@pytest.fixture(scope="module")
def run_dir(synthetic, tmp_path_factory):
    return write_run_dir(synthetic, tmp_path_factory.mktemp("run") / "seed2")


def test_fig2_png_and_csv(run_dir, synthetic):
    png, csv_path = fig2(run_dir, [0, 3], max_points=20)
    assert png == run_dir / "figures" / "fig2.png" and csv_path == png.with_suffix(".csv")
    _png_ok(png)
    rows = _rows(csv_path)
    assert set(rows[0]) == {"iteration", "sample", "feasible", "best", "series", "step", "x", "y"}
    for k in (0, 3):
        rec = synthetic.records[k]
        mine = [r for r in rows if r["iteration"] == str(k)]
        base = [r for r in mine if r["series"] == "base"]
        assert len({r["sample"] for r in base}) == rec.n_envs
        assert max(int(r["step"]) for r in base) <= 20
        ee = [r for r in mine if r["series"] == "ee"]
        assert ee and {r["sample"] for r in ee} == {str(int(rec.elite_idx[0]))}
        crosses = [r for r in mine if r["series"] == "Table1"]
        z = rec.Z.numpy()[:, synthetic.layout.slices["Table1"]]
        got = np.array([[float(r["x"]), float(r["y"])] for r in sorted(crosses, key=lambda r: int(r["sample"]))])
        np.testing.assert_allclose(got, z, rtol=1e-5, atol=1e-6)
        feas = {int(r["sample"]): r["feasible"] == "True" for r in crosses}
        assert sum(feas.values()) == rec.n_feasible


def test_fig2_default_iterations_cap_and_errors(run_dir, tmp_path):
    png, csv_path = fig2(run_dir, out_png=tmp_path / "f2.png", max_plans=5)
    _png_ok(png)
    rows = _rows(csv_path)
    assert sorted({int(r["iteration"]) for r in rows}) == [0, 2, 3]
    assert len({(r["iteration"], r["sample"]) for r in rows if r["series"] == "base"}) == 3 * 5
    with pytest.raises(FileNotFoundError, match="trajectories_iter7.npz"):
        fig2(run_dir, [7], out_png=tmp_path / "x.png")


def test_fig3_png_and_csv(run_dir, synthetic):
    png, csv_path = fig3(run_dir)
    _png_ok(png)
    rows = _rows(csv_path)
    layout = synthetic.layout
    n_it = len(synthetic.records)
    for name in layout.names:
        mine = sorted((r for r in rows if r["param"] == name), key=lambda r: int(r["iteration"]))
        assert [r["kind"] for r in mine] == ["uniform"] + ["gaussian"] * (n_it - 1) + ["final"]
        sl = layout.slices[name]
        Z0 = synthetic.records[0].Z.numpy()[:, sl]
        assert float(mine[0]["mean_x"]) == pytest.approx(Z0[:, 0].mean(), rel=1e-5)
        for i in range(1, n_it + 1):  # iteration i sampled from the refit of iteration i - 1
            m = synthetic.records[i - 1].mean.numpy()[sl]
            s = synthetic.records[i - 1].std.numpy()[sl]
            r = mine[i]
            assert float(r["mean_y"]) == pytest.approx(m[1], rel=1e-5, abs=1e-9)
            assert float(r["half_x"]) == pytest.approx(2 * s[0], rel=1e-5, abs=1e-9)
            assert float(r["std_y"]) == pytest.approx(s[1], rel=1e-5, abs=1e-9)


def test_scene_from_result_config(synthetic, tmp_path):
    d = write_run_dir(synthetic, tmp_path / "noscene", scene=False)
    assert not (d / SCENE_FILE).exists()
    scene = RunDir(d).scene()
    assert scene is not None and scene.layout.to_dict() == ParamLayout.from_dict(PARAMS).to_dict()
    assert scene.geometry == synthetic.geometry and scene.padding == 0.2
    _png_ok(fig2(d, [1])[0])
    # a run dir without any scene description: a clear error
    (d / "result.json").write_text(json.dumps({"success_per_iter": [0.1], "best_cost_per_iter": [None]}))
    with pytest.raises(FileNotFoundError, match="scene.json"):
        fig2(d, [1])


def test_scene_json_round_trip(synthetic, tmp_path):
    save_scene(tmp_path, synthetic.layout, synthetic.geometry, padding=0.35)
    scene = RunDir(write_run_dir(synthetic, tmp_path, trajectories=False, scene=False)).scene()
    assert scene is not None and scene.geometry == synthetic.geometry and scene.padding == 0.35


def test_save_trajectories_validates(tmp_path):
    base = np.zeros((3, 5, 2))
    with pytest.raises(ValueError, match="traj_ee"):
        save_trajectories(tmp_path, 0, base, np.zeros((3, 4, 3)), np.ones(3, bool), 0)
    with pytest.raises(ValueError, match="feasible"):
        save_trajectories(tmp_path, 0, base, np.zeros((3, 5, 3)), np.ones(2, bool), 0)
    p = save_trajectories(tmp_path, 4, base, np.zeros((3, 5, 3)), np.ones(3, bool), 1)
    assert p.name == "trajectories_iter4.npz"
    t = load_trajectories(tmp_path, 4)
    assert t["traj_base"].dtype == np.float32 and int(t["best"]) == 1 and "Z" not in t


def test_fig4_mean_and_band(tmp_path):
    dirs = [write_run_dir(run_synthetic(n=30, iterations=3, n_elite=5, seed=s), tmp_path / f"seed{s}",
                          trajectories=False, scene=False) for s in range(3)]
    # one run found nothing in its first iteration: a null cost there
    doc = json.loads((dirs[0] / "result.json").read_text())
    doc["best_cost_per_iter"][0] = None
    (dirs[0] / "result.json").write_text(json.dumps(doc))
    png, csv_path = fig4(find_run_dirs([tmp_path]), tmp_path / "out" / "fig4.png")
    _png_ok(png)
    rows = _rows(csv_path)
    assert len(rows) == 3
    share = np.array([json.loads((d / "result.json").read_text())["success_per_iter"] for d in dirs]) * 100
    np.testing.assert_allclose([float(r["share_mean"]) for r in rows], share.mean(axis=0), rtol=1e-5)
    np.testing.assert_allclose([float(r["share_std"] or 0) for r in rows], share.std(axis=0), rtol=1e-5, atol=1e-9)
    cost = np.array([[np.nan if v is None else v for v in json.loads((d / "result.json").read_text())["best_cost_per_iter"]]
                     for d in dirs])
    assert [int(r["n_cost"]) for r in rows] == np.isfinite(cost).sum(axis=0).tolist()
    np.testing.assert_allclose([float(r["cost_mean"]) for r in rows], np.nanmean(cost, axis=0), rtol=1e-5)
    assert rows[0]["cost_seed0"] == ""


def test_fig4_reads_the_share_of_rows_that_finished(tmp_path):
    """A pruned run's share is of the rows that ran to their end (``finished_success_per_iter``),
    not ``success_per_iter``, which counts the stopped rows as failed; a pruned run written before
    that key gets it from its counts, a run without pruning keeps ``success_per_iter``."""
    dirs = [write_run_dir(run_synthetic(n=30, iterations=3, n_elite=5, seed=s), tmp_path / f"seed{s}",
                          trajectories=False, scene=False) for s in range(3)]
    docs = [json.loads((d / "result.json").read_text()) for d in dirs]
    # seed0: pruned, with the key; seed1: pruned, before the key (counts only); seed2: no pruning
    docs[0].update(n_envs_per_iter=[30, 30, 30], n_feasible_per_iter=[3, 3, 3], success_per_iter=[0.1, 0.1, 0.1],
                   n_stopped_per_iter=[0, 15, 27], finished_success_per_iter=[0.1, 0.2, 1.0])
    docs[1].update(n_envs_per_iter=[30, 30, 30], n_feasible_per_iter=[6, 6, 0], success_per_iter=[0.2, 0.2, 0.0],
                   n_stopped_per_iter=[0, 10, 30])
    docs[1].pop("finished_success_per_iter", None)
    for d, doc in zip(dirs, docs):
        (d / "result.json").write_text(json.dumps(doc))
    assert RunDir(dirs[2]).n_stopped_per_iter() is None
    np.testing.assert_allclose(RunDir(dirs[1]).finished_success_per_iter(), [0.2, 0.3, np.nan])
    _, csv_path = fig4(dirs, tmp_path / "fig4.png")
    rows = _rows(csv_path)
    plain = np.asarray(docs[2]["success_per_iter"]) * 100
    assert [float(r["share_seed0"]) for r in rows] == pytest.approx([10, 20, 100])
    assert [float(r["share_seed1"]) for r in rows[:2]] == pytest.approx([20, 30]) and rows[2]["share_seed1"] == ""
    np.testing.assert_allclose([float(r["share_seed2"]) for r in rows], plain, rtol=1e-5)
    assert [float(r["stopped_seed0"]) for r in rows] == [0, 15, 27] and rows[0]["stopped_seed2"] == ""
    assert [float(r["stopped_mean"]) for r in rows] == pytest.approx([0, 12.5, 28.5])
    assert float(rows[2]["share_mean"]) == pytest.approx((100 + plain[2]) / 2, rel=1e-5)  # seed1 all stopped there


def test_history_written_by_the_history_writer_loads(synthetic, tmp_path):
    h = History(synthetic.layout.column_names)
    for r in synthetic.records:
        h.append({"Z": r.Z, "cost": r.cost, "feasible": r.feasible, "elite_idx": r.elite_idx},
                 n_envs=r.n_envs, success_share=r.success_share, best_cost=r.best_cost, mean=r.mean, std=r.std)
    rd = RunDir(tmp_path)
    rd.write_history(h)
    rd.write_scene(synthetic.layout, synthetic.geometry)
    m, s, kinds = sampling_distributions(rd.history_arrays())
    assert kinds[0] == "uniform" and kinds[-1] == "final" and np.isfinite(m).all()
    np.testing.assert_allclose(rd.success_per_iter(), [r.success_share for r in synthetic.records])
    _png_ok(fig3(tmp_path)[0])


# ---- the scripts ---------------------------------------------------------------------------


def test_scripts_fig2_fig3(run_dir, tmp_path, capsys):
    assert load_script("fig2").main([str(run_dir), "--iterations", "0", "2", "--out", str(tmp_path / "a.png")]) == 0
    _png_ok(tmp_path / "a.png")
    assert (tmp_path / "a.csv").stat().st_size > 0
    assert load_script("fig3").main([str(run_dir), "--out", str(tmp_path / "b.png")]) == 0
    _png_ok(tmp_path / "b.png")
    assert (tmp_path / "b.csv").stat().st_size > 0
    assert load_script("fig2").main([str(tmp_path / "missing")]) == 1
    assert "error:" in capsys.readouterr().err


def test_script_fig4_launches_runs_then_plots(tmp_path, monkeypatch):
    """``--runs N`` launches N app processes (here a stand-in app) with seeds 0..N-1, keeps
    finished runs on a second call, and plots; ``--run-dirs`` only plots."""
    monkeypatch.setenv("PYTHONPATH", os.pathsep.join([str(TESTS), str(REPO), os.environ.get("PYTHONPATH", "")]))
    fig4 = load_script("fig4")
    root = tmp_path / "runs"
    args = ["--runs", "2", "--root", str(root), "--module", "_fake_app", "--override", "ce.iterations=2"]
    assert fig4.main(args) == 0
    assert (tmp_path / "fig4.png").is_file() and (tmp_path / "fig4.csv").is_file()
    for s in (0, 1):
        res = json.loads((root / f"seed{s}" / "result.json").read_text())
        assert res["status"] == "done" and len(res["success_per_iter"]) == 2
        assert res["argv"] == ["experiment=seed_paper", f"seed={s}", f"hydra.run.dir={root / f'seed{s}'}",
                               "ce.iterations=2"]
        assert (root / f"seed{s}.log").is_file()
    mtime = (root / "seed0" / "result.json").stat().st_mtime_ns
    assert fig4.main(args) == 0  # done runs are kept
    assert (root / "seed0" / "result.json").stat().st_mtime_ns == mtime
    assert fig4.main(["--run-dirs", str(root), "--out", str(tmp_path / "only.png")]) == 0
    _png_ok(tmp_path / "only.png")
    rows = _rows(tmp_path / "only.csv")
    assert {"cost_seed0", "cost_seed1"} <= set(rows[0])
    # a failing app: reported, nothing to plot
    assert fig4.main(["--runs", "1", "--root", str(tmp_path / "bad"), "--module", "_fake_app",
                      "--experiment", "broken"]) == 1


def test_ramp_modes_classifies_release_points(tmp_path) -> None:
    """scripts/ramp_modes.py: a release point over the ramp is a slide, over table 2 a carry."""
    import csv
    import json

    from scripts.ramp_modes import main

    plan = "move_to(Table1), grasp(cube, Cube_g), move_to(Drop), place(cube, Cube_p), move_to(Exit)"
    runs = {"s0": (0.0, -0.6, 500.0, True), "s1": (0.05, -1.2, 540.0, True), "s2": (0.0, 0.0, None, False)}
    for name, (x, y, cost, ok) in runs.items():
        d = tmp_path / name
        d.mkdir()
        doc = {"feasible": ok, "best_cost": cost, "seed": int(name[1]), "plan": plan,
               "best_params": {"Cube_p": {"x": x, "y": y, "z": 1.0}} if ok else None,
               "success_per_iter": [0.1, 0.5], "config": {"scene": {"variant": "ramp", "ramps": [{}]}, "ce": {}}}
        (d / "result.json").write_text(json.dumps(doc))
    assert main([str(tmp_path), "--out", str(tmp_path / "m.csv")]) == 0
    modes = {r["run"].rsplit("/", 1)[-1]: r["mode"] for r in csv.DictReader((tmp_path / "m.csv").open())}
    assert modes == {"s0": "slide", "s1": "carry", "s2": "none"}
    summ = list(csv.DictReader((tmp_path / "m_summary.csv").open()))
    assert {(r["mode"], r["runs"]) for r in summ} == {("slide", "1"), ("carry", "1"), ("none", "1")}


def _kept_figure(monkeypatch: pytest.MonkeyPatch) -> list:
    """The figures the next fig2/fig3 call draws (``plt.close`` no longer discards them)."""
    from realize.figures.common import plt

    kept: list = []
    monkeypatch.setattr(plt, "close", lambda fig=None: kept.append(fig))
    return kept


def test_fig3_colour_bar_is_whole_iterations_and_outlines_have_a_legend(run_dir, monkeypatch, tmp_path):
    kept = _kept_figure(monkeypatch)
    fig3(run_dir, out_png=tmp_path / "f3.png")
    fig = kept[-1]
    cbar_ax = fig.axes[-1]  # the colour bar is the last axes
    labels = [t.get_text() for t in cbar_ax.get_yticklabels()]
    assert labels == ["0", "1", "2", "3", "final"], labels  # 4 iterations + the final refit, no 0.5 steps
    ticks = cbar_ax.get_yticks()
    assert np.array_equal(ticks, np.round(ticks))
    legend = [t.get_text() for lg in fig.legends for t in lg.get_texts()]
    assert "parameter region" in legend and "final refit" in legend


def test_fig2_legend_names_the_table_and_its_padding_apart(run_dir, monkeypatch, tmp_path):
    kept = _kept_figure(monkeypatch)
    fig2(run_dir, out_png=tmp_path / "f2.png")
    legend = [t.get_text() for lg in kept[-1].legends for t in lg.get_texts()]
    assert "tables and other obstacles" in legend and any(t.startswith("A* padding (+") for t in legend)
    assert not any("tables (+" in t for t in legend)
