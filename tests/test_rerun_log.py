"""Tests for realize.recording.log (real rerun writing and reading back) and realize.tasks.topdown."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
import torch

from _synthetic import make_geometry, make_layout, run_synthetic
from realize.world.geometry import Box as ObstacleBox
from realize.world.geometry import GeometryCfg, RampCfg, WallCfg, build_geometry
from realize.tasks.hemisphere import Hemisphere
from realize.recording.log import RerunLogger
from realize.recording.paths import SCALAR_PATHS
from realize.recording.read import read_rrd_summary
from realize.tasks.topdown import (
    decimate_time,
    fill_nan_forward,
    padded_outline,
    region_outlines,
    region_xy_radii,
    rounded_rectangle,
    success_colors,
)


@pytest.fixture(scope="module")
def synthetic():
    return run_synthetic(n=40, iterations=4, n_elite=5, seed=1, T=30)


@pytest.fixture(scope="module")
def summary(synthetic, tmp_path_factory):
    path = tmp_path_factory.mktemp("rrd") / "run.rrd"
    with RerunLogger(path, synthetic.layout, synthetic.geometry, n_iterations=4, recording_id="test-run") as lg:
        for rec, ro, (m, s) in zip(synthetic.records, synthetic.rollouts, synthetic.sampling):
            lg.log_iteration(rec, ro, m, s)
    assert lg.closed
    return read_rrd_summary(path)


def test_every_iteration_has_ellipses_costs_and_shares(synthetic, summary):
    recs = synthetic.records
    assert summary["iterations"] == [r.iteration for r in recs]
    assert summary["application_id"] == "realize"
    assert summary["recording_id"] == "test-run"
    assert summary["n_blueprints"] == 1
    for rec in recs:
        got = summary["per_iteration"][rec.iteration]
        assert got["/stats/success/share"] == pytest.approx(rec.success_share)
        assert got["/stats/samples/n_envs"] == rec.n_envs
        for path, (attr, _, _) in SCALAR_PATHS.items():
            v = float(getattr(rec, attr))
            if math.isfinite(v):
                assert got["/" + path] == pytest.approx(v), path
            else:  # non-finite values are not logged
                assert "/" + path not in got


def test_ellipses_are_two_sigma_of_the_sampling_distribution(synthetic, summary):
    layout = synthetic.layout
    for rec, (m, s) in zip(synthetic.records, synthetic.sampling):
        if m is None:  # uniform iteration: the samples' moments
            Z = rec.Z.numpy()
            m, s = Z.mean(axis=0), Z.std(axis=0)
        else:
            m, s = m.numpy(), s.numpy()
        for name in layout.names:
            sl = layout.slices[name]
            e = summary["ellipses"][f"/distributions/{name}/sigma2"][rec.iteration]
            np.testing.assert_allclose(e["centers"][0], m[sl][:2], rtol=1e-5, atol=1e-6)
            np.testing.assert_allclose(e["half_sizes"][0], 2 * s[sl][:2], rtol=1e-5, atol=1e-6)
            # the history entity accumulates one ellipse per iteration so far (Fig. 3)
            assert len(summary["ellipses"][f"/distributions/{name}/history"][rec.iteration]["centers"]) == rec.iteration + 1


def test_scene_and_samples(synthetic, summary):
    paths = set(summary["entity_paths"])
    static = set(summary["static_paths"])
    for p in ("/world/obstacles", "/world/obstacles_padded", "/world/objects", "/world/robot_start"):
        assert p in static
    for name in synthetic.layout.names:
        assert f"/world/regions/{name}" in static
        assert f"/world/samples/{name}" in paths
    counts = summary["counts"]
    for rec in synthetic.records:
        i, n = rec.iteration, rec.n_envs
        assert counts["/world/samples/Table1"][i] == n
        assert counts["/distributions/Cube_g/samples"][i] == n
        n_ok = counts["/world/trajectories/succeeded"][i]
        n_bad = counts["/world/trajectories/failed"][i]
        assert (n_ok, n_bad) == (rec.n_feasible, n - rec.n_feasible)
        assert counts["/world/best/base"][i] == 1
        assert counts["/world/best/ee"][i] == 1
        assert counts["/world/best/params"][i] == len(synthetic.layout)
        assert counts["/log"][i] == 1


def test_without_rollout_or_samples_and_infinite_costs(tmp_path, synthetic):
    rec0 = synthetic.records[0]
    n = rec0.n_envs
    # no sample kept, no rollout, nothing feasible yet
    rec = replace(rec0, Z=None, feasible=torch.zeros(n, dtype=torch.bool), n_feasible=0, success_share=0.0,
                  best_cost=math.inf, iteration_best_cost=math.inf, elite_cost_min=math.nan,
                  elite_cost_mean=math.nan, elite_cost_max=math.nan)
    path = tmp_path / "bare.rrd"
    lg = RerunLogger(path, synthetic.layout, synthetic.geometry, padding=0.0, blueprint=False)
    lg.log_iteration(rec)  # uniform iteration without samples: no ellipse to draw
    rec1 = synthetic.records[1]
    m, s = synthetic.sampling[1]
    lg.log_iteration(rec1, None, m, s)
    lg.close()
    lg.close()  # idempotent
    with pytest.raises(RuntimeError):
        lg.log_iteration(rec1)
    S = read_rrd_summary(path)
    assert S["n_blueprints"] == 0
    assert S["iterations"] == [0, 1]
    assert S["per_iteration"][0]["/stats/success/share"] == 0.0
    assert "/stats/cost/best" not in S["per_iteration"][0]
    assert "/world/obstacles_padded" not in S["entity_paths"]
    assert 0 not in S["ellipses"].get("/distributions/Table1/sigma2", {})
    assert 1 in S["ellipses"]["/distributions/Table1/sigma2"]
    # cleared, not stale: trajectories and samples report 0 instances
    assert S["counts"]["/world/trajectories/succeeded"][1] == 0
    assert S["counts"]["/world/samples/Table1"][0] == 0
    assert S["counts"]["/world/samples/Table1"][1] == rec1.n_envs


def test_mixture_logs_one_ellipse_per_live_mode(tmp_path, synthetic):
    """A k-mode distribution (ce.n_modes > 1): (k, D) mean/std and weights; a mode of weight 0
    (never sampled) gets no ellipse."""
    rec = synthetic.records[1]
    m, s = synthetic.sampling[1]
    mean = torch.stack([m, m + 0.1, m - 0.1])
    std = torch.stack([s, 0.5 * s, s])
    path = tmp_path / "mix.rrd"
    with RerunLogger(path, synthetic.layout, synthetic.geometry, blueprint=False) as lg:
        lg.log_iteration(rec, None, mean, std, torch.tensor([0.7, 0.3, 0.0]))
    S = read_rrd_summary(path)
    e = S["ellipses"]["/distributions/Table1/sigma2"][1]
    sl = synthetic.layout.slices["Table1"]
    np.testing.assert_allclose(np.asarray(e["centers"]), mean[:2, sl].numpy(), rtol=1e-5)
    np.testing.assert_allclose(np.asarray(e["half_sizes"]), 2 * std[:2, sl].numpy(), rtol=1e-5)


def test_trajectory_cap_and_nan_padding(tmp_path, synthetic):
    rec, ro = synthetic.records[2], synthetic.rollouts[2]
    base = ro.traj_base.clone()
    base[:, -5:] = float("nan")  # e.g. a rollout that pads finished plans with NaN
    ro2 = replace(ro, traj_base=base)
    path = tmp_path / "cap.rrd"
    with RerunLogger(path, synthetic.layout, synthetic.geometry, max_trajectories=7, max_traj_points=10) as lg:
        lg.log_iteration(rec, ro2, *synthetic.sampling[2])
    S = read_rrd_summary(path)
    c = S["counts"]
    assert c["/world/trajectories/succeeded"][2] + c["/world/trajectories/failed"][2] == 7
    assert c["/world/trajectories/succeeded"][2] == min(7, rec.n_feasible)


def test_variants_with_extras(tmp_path):
    layout = make_layout()
    for variant, fixtures in (("wall", dict(walls=[WallCfg()])), ("ramp", dict(ramps=[RampCfg()]))):
        geom = build_geometry(GeometryCfg(variant=variant, **fixtures))
        path = tmp_path / f"{variant}.rrd"
        with RerunLogger(path, layout, geom):
            pass
        S = read_rrd_summary(path)
        assert "/world/obstacles" in S["static_paths"]
        assert S["iterations"] == []


def test_bad_arguments(tmp_path):
    with pytest.raises(ValueError, match="padding"):
        RerunLogger(tmp_path / "x.rrd", make_layout(), make_geometry(), padding=-1.0)


# ---- topdown geometry ------------------------------------------------------------------------


def test_rounded_rectangle_is_the_padded_footprint():
    o = rounded_rectangle((1.0, 2.0), (0.3, 0.2), 0.0, 0.1)
    assert np.allclose(o[0], o[-1])
    assert o[:, 0].min() == pytest.approx(0.6) and o[:, 0].max() == pytest.approx(1.4)
    assert o[:, 1].min() == pytest.approx(1.7) and o[:, 1].max() == pytest.approx(2.3)
    # every vertex is exactly `padding` away from the (unpadded) rectangle
    d = np.hypot(np.maximum(np.abs(o[:, 0] - 1.0) - 0.3, 0), np.maximum(np.abs(o[:, 1] - 2.0) - 0.2, 0))
    assert np.allclose(d, 0.1)
    yawed = padded_outline(ObstacleBox("b", (0, 0, 0.5), (0.3, 0.2, 0.5), yaw=math.pi / 2), 0.1)
    assert yawed[:, 0].max() == pytest.approx(0.3) and yawed[:, 1].max() == pytest.approx(0.4)


def test_region_outlines():
    layout = make_layout()
    t1 = region_outlines(layout.regions["Table1"])
    assert len(t1) == 2
    assert np.allclose(np.hypot(t1[0][:, 0], t1[0][:, 1] - 1.2), 1.25)
    cap = layout.regions["Cube_g"]
    r_in, r_out = region_xy_radii(cap)
    assert r_in == 0.0 and r_out == pytest.approx(0.15 * math.sin(1.0))
    band = Hemisphere((0, 0, 0), 1.0, polar_min=0.5, polar_max=2.0)
    assert region_xy_radii(band) == pytest.approx((math.sin(0.5), 1.0))
    exit_box = region_outlines(layout.regions["Exit"])[0]
    assert exit_box[:, 0].min() == pytest.approx(1.8) and exit_box[:, 1].max() == pytest.approx(0.4)


def test_trajectory_helpers_and_colors():
    t = np.arange(10, dtype=float)[None, :, None].repeat(2, axis=2)
    t[0, 3:5] = np.nan
    t[0, 0] = np.nan
    f = fill_nan_forward(t)
    assert np.isfinite(f).all()
    assert f[0, 0, 0] == 1 and f[0, 3, 0] == 2 and f[0, 4, 0] == 2 and f[0, 5, 0] == 5
    d = decimate_time(np.arange(101, dtype=float)[None, :, None], 10)
    assert d.shape[1] <= 11 and d[0, -1, 0] == 100 and d[0, 0, 0] == 0
    c = success_colors(np.array([True, False, False]), np.array([5, 0, 4]), 5)
    assert c.shape == (3, 4) and c.dtype == np.uint8
    assert tuple(c[0, :3]) == (40, 170, 70) and tuple(c[1, :3]) == (200, 40, 30) and tuple(c[2, :3]) == (245, 160, 40)
