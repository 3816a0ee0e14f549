"""Tests for realize.tasks.regions: uniformity, contains/project properties, orientation, validation."""

from __future__ import annotations

import math

import pytest
import torch

from realize.config import ConfigError
from realize.tasks.hemisphere import Hemisphere
from realize.tasks.param_layout import ParamLayout, region_from_dict
from realize.tasks.regions import Annulus, Box, Fixed, Region

F64 = torch.float64
N_UNIF = 20000
# Kolmogorov-Smirnov critical value at the 0.1 % level is 1.95 / sqrt(n); seeds are fixed, so
# these tests are deterministic, the bound only says the sampler is not off.
KS_BOUND = 1.95 / math.sqrt(N_UNIF)


def gen(seed: int = 0) -> torch.Generator:
    return torch.Generator().manual_seed(seed)


def ks_stat(samples: torch.Tensor, cdf) -> float:
    x, _ = torch.sort(samples)
    n = x.numel()
    f = cdf(x)
    i = torch.arange(1, n + 1, dtype=x.dtype)
    return float(torch.maximum(i / n - f, f - (i - 1) / n).max())


REGIONS: dict[str, Region] = {
    "annulus": Annulus([1.0, -2.0], 0.5, 1.2),
    "disc": Annulus([0.0, 0.0], 0.0, 1.0),
    "hemisphere": Hemisphere([0.3, 0.1, 0.8], 0.25),
    "band_yaw": Hemisphere([0.0, 0.0, 1.0], 0.2, polar_min=0.3, polar_max=1.2, yaw=True, yaw_min=-1.0, yaw_max=2.0),
    "hemi_fullyaw": Hemisphere([0.0, 0.0, 0.0], 1.0, yaw=True),
    "box": Box([-1.0, 2.0, 0.0], [1.0, 3.0, 0.5]),
    "fixed": Fixed([0.5, -0.5]),
}


# ---------------------------------------------------------------- uniformity


def test_annulus_radius_and_angle_uniform_by_area():
    a = Annulus([1.0, -2.0], 0.5, 1.2)
    z = a.sample_uniform(N_UNIF, gen(1), F64)
    d = z - torch.tensor([1.0, -2.0], dtype=F64)
    r = d.norm(dim=1)
    ks_r = ks_stat(r, lambda x: (x**2 - 0.25) / (1.44 - 0.25))
    phi = torch.atan2(d[:, 1], d[:, 0])
    ks_phi = ks_stat(phi, lambda x: (x + math.pi) / (2 * math.pi))
    assert ks_r < KS_BOUND and ks_phi < KS_BOUND
    # a naive radius-uniform sampler would fail the same test
    r_naive = 0.5 + 0.7 * torch.rand(N_UNIF, generator=gen(2), dtype=F64)
    assert ks_stat(r_naive, lambda x: (x**2 - 0.25) / (1.44 - 0.25)) > KS_BOUND


@pytest.mark.parametrize("polar", [(0.0, math.pi / 2), (0.3, 1.2), (0.0, math.pi)])
def test_hemisphere_height_uniform_archimedes(polar):
    h = Hemisphere([0.3, 0.1, 0.8], 0.25, polar_min=polar[0], polar_max=polar[1])
    z = h.sample_uniform(N_UNIF, gen(3), F64)
    d = (z - torch.tensor(h.center, dtype=F64)) / h.radius
    assert torch.allclose(d.norm(dim=1), torch.ones(N_UNIF, dtype=F64))
    lo, hi = math.cos(polar[1]), math.cos(polar[0])
    assert ks_stat(d[:, 2], lambda x: (x - lo) / (hi - lo)) < KS_BOUND
    phi = torch.atan2(d[:, 1], d[:, 0])
    assert ks_stat(phi, lambda x: (x + math.pi) / (2 * math.pi)) < KS_BOUND


def test_hemisphere_yaw_uniform_in_range():
    h = REGIONS["band_yaw"]
    z = h.sample_uniform(N_UNIF, gen(4), F64)
    assert ks_stat(z[:, 3], lambda x: (x + 1.0) / 3.0) < KS_BOUND


def test_box_uniform_per_coordinate():
    b = REGIONS["box"]
    z = b.sample_uniform(N_UNIF, gen(5), F64)
    for j, (lo, hi) in enumerate(zip(b.low, b.high)):
        assert ks_stat(z[:, j], lambda x: (x - lo) / (hi - lo)) < KS_BOUND


# ---------------------------------------------------------------- contains / project


@pytest.mark.parametrize("name", list(REGIONS))
def test_samples_inside_and_deterministic(name):
    r = REGIONS[name]
    z = r.sample_uniform(500, gen(6), F64)
    assert z.shape == (500, r.dim) and z.dtype == F64
    assert bool(r.contains(z).all())
    assert torch.equal(z, r.sample_uniform(500, gen(6), F64))
    z32 = r.sample_uniform(10, gen(6), torch.float32)
    assert z32.dtype == torch.float32 and bool(r.contains(z32, tol=1e-5).all())


@pytest.mark.parametrize("name", list(REGIONS))
def test_project_lands_inside_idempotent_and_keeps_inside_points(name):
    r = REGIONS[name]
    lo, hi = r.bounds()
    mid, span = (lo + hi) / 2, (hi - lo).clamp_min(0.1)
    wild = mid + 2.0 * span * torch.randn(2000, r.dim, generator=gen(7), dtype=F64)
    p = r.project(wild)
    assert p.shape == wild.shape
    assert bool(r.contains(p).all())
    assert torch.allclose(r.project(p), p, atol=1e-12)
    inside = r.sample_uniform(500, gen(8), F64)
    assert torch.allclose(r.project(inside), inside, atol=1e-12)


@pytest.mark.parametrize("name", ["annulus", "disc", "hemisphere", "box"])
def test_project_is_nearest_point(name):
    """No point of a dense uniform sample of the region is closer than the projection."""
    r = REGIONS[name]
    lo, hi = r.bounds()
    q = (lo + hi) / 2 + (hi - lo) * torch.randn(200, r.dim, generator=gen(9), dtype=F64)
    p = r.project(q)
    dense = r.sample_uniform(20000, gen(10), F64)
    d_proj = (q - p).norm(dim=1)
    d_best = torch.cdist(q, dense).min(dim=1).values
    assert bool((d_proj <= d_best + 1e-9).all())


def test_project_degenerate_points():
    a = Annulus([1.0, 1.0], 0.5, 1.0)
    assert torch.allclose(a.project(torch.tensor([[1.0, 1.0]], dtype=F64)), torch.tensor([[1.5, 1.0]], dtype=F64))
    h = Hemisphere([0.0, 0.0, 1.0], 0.2, polar_min=0.0, polar_max=1.0)
    # the centre goes to the top; a point straight below goes to the lower rim at azimuth 0
    top = h.project(torch.tensor([[0.0, 0.0, 1.0], [0.0, 0.0, 0.0]], dtype=F64))
    assert torch.allclose(top[0], torch.tensor([0.0, 0.0, 1.2], dtype=F64))
    assert torch.allclose(top[1], torch.tensor([0.2 * math.sin(1.0), 0.0, 1.0 + 0.2 * math.cos(1.0)], dtype=F64))
    # below the equator of an upper hemisphere: onto the rim, same azimuth
    hh = Hemisphere([0.0, 0.0, 0.0], 1.0)
    assert torch.allclose(hh.project(torch.tensor([[0.0, 3.0, -1.0]], dtype=F64)), torch.tensor([[0.0, 1.0, 0.0]], dtype=F64), atol=1e-12)


def test_yaw_projection_wraps_or_clamps():
    full = REGIONS["hemi_fullyaw"]
    z = torch.tensor([[0.0, 0.0, 1.0, 3 * math.pi / 2]], dtype=F64)
    assert math.isclose(float(full.project(z)[0, 3]), -math.pi / 2, abs_tol=1e-12)
    band = REGIONS["band_yaw"]  # yaw in [-1, 2]
    base = band.sample_uniform(1, gen(0), F64)[:, :3]
    def yaw_of(y):
        return float(band.project(torch.cat([base, torch.tensor([[y]], dtype=F64)], 1))[0, 3])
    assert yaw_of(2.5) == 2.0 and yaw_of(-1.4) == -1.0 and yaw_of(0.5) == 0.5
    # 2*pi - 1.3 is circularly 1.3 away from -1 and ~2.7 from 2: goes to -1
    assert yaw_of(2 * math.pi - 1.3) == -1.0


def test_contains_tolerance():
    a = Annulus([0.0, 0.0], 1.0, 2.0)
    z = torch.tensor([[2.0 + 1e-4, 0.0], [0.999, 0.0], [1.5, 0.0]], dtype=F64)
    assert a.contains(z).tolist() == [False, False, True]
    assert a.contains(z, tol=1e-3).tolist() == [True, True, True]
    f = Fixed([1.0])
    assert f.contains(torch.tensor([[1.0], [1.1]], dtype=F64)).tolist() == [True, False]


# ---------------------------------------------------------------- hemisphere orientation


def test_hemisphere_frames_orthonormal_and_point_at_center():
    h = REGIONS["hemi_fullyaw"]
    z = h.sample_uniform(300, gen(11), F64)
    R = h.frames(z)
    eye = torch.eye(3, dtype=F64).expand(300, 3, 3)
    assert torch.allclose(R.transpose(1, 2) @ R, eye, atol=1e-10)
    assert torch.allclose(torch.linalg.det(R), torch.ones(300, dtype=F64), atol=1e-10)
    assert torch.allclose(R[:, :, 2], h.approach(z), atol=1e-12)
    expect = (torch.tensor(h.center, dtype=F64) - z[:, :3]) / h.radius
    assert torch.allclose(h.approach(z), expect, atol=1e-12)


def test_hemisphere_top_frame_and_yaw_about_approach():
    h = Hemisphere([0.0, 0.0, 0.0], 0.5, yaw=True)
    z = torch.tensor([[0.0, 0.0, 0.5, 0.0], [0.0, 0.0, 0.5, math.pi / 2]], dtype=F64)
    R = h.frames(z)
    assert torch.allclose(R[0], torch.diag(torch.tensor([1.0, -1.0, -1.0], dtype=F64)))
    assert torch.allclose(R[1][:, 2], R[0][:, 2])  # yaw keeps the approach axis
    assert torch.allclose(R[1][:, 0], torch.tensor([0.0, -1.0, 0.0], dtype=F64), atol=1e-12)


# ---------------------------------------------------------------- validation


@pytest.mark.parametrize(
    "ctor, field",
    [
        (lambda: Annulus([0, 0], -0.1, 1.0), "r_min"),
        (lambda: Annulus([0, 0], 2.0, 1.0), "r_min"),
        (lambda: Annulus([0, 0, 0], 0.1, 1.0), "center"),
        (lambda: Annulus([0, float("nan")], 0.1, 1.0), "center"),
        (lambda: Annulus([0, 0], 0.1, float("nan")), "r_max"),
        (lambda: Hemisphere([0, 0, 0], -1.0), "radius"),
        (lambda: Hemisphere([0, 0], 1.0), "center"),
        (lambda: Hemisphere([0, 0, 0], 1.0, polar_min=1.0, polar_max=0.5), "polar_min"),
        (lambda: Hemisphere([0, 0, 0], 1.0, polar_max=4.0), "polar_max"),
        (lambda: Hemisphere([0, 0, 0], 1.0, yaw=True, yaw_min=1.0, yaw_max=0.0), "yaw_min"),
        (lambda: Box([0, 0], [1, 0]), "low"),
        (lambda: Box([0, 0], [1, 1, 1]), "high"),
        (lambda: Box([], []), "low"),
        (lambda: Fixed([float("inf")]), "value"),
        (lambda: Fixed("abc"), "value"),
    ],
)
def test_bad_input_names_field(ctor, field):
    with pytest.raises(ConfigError, match=field):
        ctor()


def test_region_from_dict_roundtrip_and_errors():
    where = "configs/task/pick_place.yaml:params.Table1"
    for r in REGIONS.values():
        assert region_from_dict(r.to_dict(), where) == r
    a = region_from_dict({"type": "annulus", "center": [1, 2], "r_min": 0.5, "r_max": 1.0}, where)
    assert isinstance(a, Annulus) and a.dim == 2
    with pytest.raises(ConfigError, match=r"^configs/task/pick_place\.yaml:params\.Table1\.r_max = -1\.0 is invalid: must be > 0"):
        region_from_dict({"type": "annulus", "center": [1, 2], "r_min": 0.5, "r_max": -1.0}, where)
    with pytest.raises(ConfigError, match=r"^configs.*Table1: unknown region type 'torus'.*annulus, box, fixed, hemisphere"):
        region_from_dict({"type": "torus"}, where)
    with pytest.raises(ConfigError, match=r"Table1: .*missing key.*'r_max'"):
        region_from_dict({"type": "annulus", "center": [1, 2], "r_min": 0.5}, where)
    with pytest.raises(ConfigError, match=r"Table1: unknown key.*'radius'"):
        region_from_dict({"type": "box", "low": [0], "high": [1], "radius": 2}, where)
    with pytest.raises(ConfigError, match=r"Table1: missing key 'type'"):
        region_from_dict({"low": [0], "high": [1]}, where)
    with pytest.raises(ConfigError, match="wrong.yaml:x: .*mapping"):
        region_from_dict([1, 2], "wrong.yaml:x")  # type: ignore[arg-type]


def test_wrong_batch_shape_raises():
    with pytest.raises(ValueError, match=r"shape \(n, 2\)"):
        REGIONS["annulus"].project(torch.zeros(3, 3))
    with pytest.raises(ValueError, match=r"shape \(n, 3\)"):
        REGIONS["hemisphere"].contains(torch.zeros(3))


# ---------------------------------------------------------------- layout


def make_layout() -> ParamLayout:
    return ParamLayout.from_dict(
        {
            "Table1": {"type": "annulus", "center": [1.0, 0.0], "r_min": 0.6, "r_max": 1.0},
            "Cube_g": {"type": "hemisphere", "center": [1.0, 0.0, 0.8], "radius": 0.15, "yaw": True},
            "Exit": {"type": "box", "low": [-2.0, -1.0], "high": [-1.5, 1.0]},
            "Torso": {"type": "fixed", "value": [0.2]},
        },
        where="task.yaml:params",
    )


def test_layout_slices_split_join():
    lay = make_layout()
    assert lay.names == ["Table1", "Cube_g", "Exit", "Torso"]
    assert lay.dim == 2 + 4 + 2 + 1
    assert lay.slices["Cube_g"] == slice(2, 6)
    assert lay.column_names[:3] == ["Table1.x", "Table1.y", "Cube_g.x"]
    Z = lay.sample_uniform(64, gen(12), F64)
    assert Z.shape == (64, 9) and bool(lay.contains(Z).all())
    parts = lay.split(Z)
    assert {k: v.shape[1] for k, v in parts.items()} == {"Table1": 2, "Cube_g": 4, "Exit": 2, "Torso": 1}
    assert torch.equal(parts["Exit"], Z[:, 6:8])
    assert torch.equal(lay.join(parts), Z)
    assert torch.equal(Z, lay.sample_uniform(64, gen(12), F64))
    low, high = lay.bounds()
    assert low.shape == (9,) and bool((Z >= low - 1e-12).all() and (Z <= high + 1e-12).all())
    assert ParamLayout.from_dict(lay.to_dict()).to_dict() == lay.to_dict()


def test_layout_project_into_all_regions():
    lay = make_layout()
    Z = 3.0 * torch.randn(500, lay.dim, generator=gen(13), dtype=F64)
    P = lay.project(Z)
    assert bool(lay.contains(P).all())
    assert torch.allclose(lay.project(P), P, atol=1e-12)


def test_layout_errors_name_the_parameter():
    with pytest.raises(ConfigError, match=r"^task\.yaml:params\.Cube_g\.radius = 0(\.0)? is invalid: must be > 0"):
        ParamLayout.from_dict({"Cube_g": {"type": "hemisphere", "center": [0, 0, 0], "radius": 0}}, "task.yaml:params")
    with pytest.raises(ConfigError, match="task.yaml:params: expected a non-empty mapping"):
        ParamLayout.from_dict({}, "task.yaml:params")
    with pytest.raises(ValueError, match=r"shape \(n, 9\)"):
        make_layout().split(torch.zeros(4, 8))
