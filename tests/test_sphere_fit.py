"""Tests for realize.robot.sphere_fit, scripts/fit_spheres.py and the committed sphere files.

* The fitter on analytic shapes (a rotated, offset box and a cylinder given as URDF primitives):
  fresh surface samples covered, radii bounded, same output for the same seed.
* ``scripts/fit_spheres.py`` on a small URDF: the file it writes reads back, and ``check_floor``
  is false only for a column that hangs down to the floor at every lift height.
* Every committed sphere file (Fetch's hand-made one, mobile_panda's fitted one): on each link
  that carries spheres, at least 99 % of fresh collision-surface samples lie inside the union of
  that link's own spheres; the largest overshoot is printed. Fetch's links without spheres of
  their own (wheels, head tilt, bellows, e-stop, laser) are covered by neighbouring links'
  spheres, which ``tests/test_kinematics.py::test_spheres_cover_collision_meshes`` checks at
  random configurations; here they must be exactly that known set.
"""

from __future__ import annotations

import importlib.util
import math
import sys
from pathlib import Path

import numpy as np
import pytest

from realize.robot.spec import known_robots, load_robot_spec
from realize.robot.sphere_file import links_without_spheres, load_spheres
from realize.robot.sphere_fit import Sphere, collision_links, coverage, fit_spheres, link_geometry
from realize.robot.urdf import source_urdf

REPO = Path(__file__).resolve().parent.parent

SHAPES_URDF = """<?xml version="1.0"?>
<robot name="shapes">
  <link name="root"/>
  <link name="block">
    <collision>
      <origin xyz="0.1 -0.05 0.3" rpy="0.3 -0.2 0.7"/>
      <geometry><box size="0.4 0.1 0.16"/></geometry>
    </collision>
  </link>
  <link name="can">
    <collision>
      <origin xyz="0 0 0.2" rpy="1.5707963 0 0"/>
      <geometry><cylinder radius="0.05" length="0.3"/></geometry>
    </collision>
    <collision>
      <origin xyz="0 0.2 0.2"/>
      <geometry><sphere radius="0.04"/></geometry>
    </collision>
  </link>
  <joint name="lift" type="prismatic">
    <parent link="root"/><child link="column"/><axis xyz="0 0 1"/>
    <limit lower="0" upper="1.0" velocity="0.5"/>
  </joint>
  <link name="column">
    <collision>
      <origin xyz="0 0 -0.5"/>
      <geometry><box size="0.2 0.2 1.0"/></geometry>
    </collision>
  </link>
  <joint name="top_joint" type="fixed">
    <parent link="column"/><child link="top"/><origin xyz="0 0 0.05"/>
  </joint>
  <link name="top">
    <collision><geometry><box size="0.2 0.2 0.1"/></geometry></collision>
  </link>
  <joint name="j_block" type="fixed"><parent link="top"/><child link="block"/></joint>
  <joint name="j_can" type="fixed"><parent link="top"/><child link="can"/></joint>
</robot>
"""

# Fetch links that carry no spheres of their own (see the module docstring).


@pytest.fixture(scope="module")
def shapes_urdf(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("urdf") / "shapes.urdf"
    path.write_text(SHAPES_URDF)
    return path


def test_fit_box_and_cylinder(shapes_urdf: Path) -> None:
    block = link_geometry(shapes_urdf, "block")
    spheres = fit_spheres(block, n_spheres=3, n_samples=1000, seed=0)
    assert len(spheres) == 3
    cov = coverage(block, spheres, n_samples=4000, seed=99, n_dirs=64)
    assert cov.share_inside >= 0.99 and cov.worst_outside < 0.002
    # three slices of a 0.4 x 0.1 x 0.16 box: half the diagonal of a 0.133 x 0.1 x 0.16 block, +2 mm
    bound = 0.5 * math.sqrt((0.4 / 3) ** 2 + 0.1 ** 2 + 0.16 ** 2) + 0.002
    assert max(s.radius for s in spheres) <= bound
    assert cov.overshoot <= max(s.radius for s in spheres)
    # in the link frame: the centres sit around the box's origin
    np.testing.assert_allclose(np.mean([s.centre for s in spheres], axis=0), [0.1, -0.05, 0.3], atol=0.02)
    assert fit_spheres(block, n_spheres=3, n_samples=1000, seed=0) == spheres  # deterministic

    can = link_geometry(shapes_urdf, "can")  # a cylinder along y (rpy) and a sphere: two <collision>s
    fitted = fit_spheres(can, max_radius=0.07, n_samples=1000, seed=1)
    assert all(s.radius <= 0.07 for s in fitted) and 2 <= len(fitted) <= 8
    cov = coverage(can, fitted, n_samples=4000, seed=7, n_dirs=64)
    assert cov.share_inside >= 0.99
    one = fit_spheres(link_geometry(shapes_urdf, "can"), n_spheres=1, n_samples=500, seed=0)
    assert one[0].radius >= 0.195 - 1e-9  # spans y = -0.15 (cylinder end) .. 0.24 (the sphere's far side)


def test_script_writes_file_and_floor_rule(shapes_urdf: Path, tmp_path: Path, capsys: pytest.CaptureFixture,
                                           monkeypatch: pytest.MonkeyPatch) -> None:
    spec = importlib.util.spec_from_file_location("fit_spheres_script", REPO / "scripts" / "fit_spheres.py")
    assert spec is not None and spec.loader is not None
    script = importlib.util.module_from_spec(spec)
    monkeypatch.setitem(sys.modules, spec.name, script)  # its dataclasses look their module up
    spec.loader.exec_module(script)
    out = tmp_path / "shapes.yaml"
    assert script.main(["--urdf", str(shapes_urdf), "--out", str(out), "--links", "column", "top",
                        "--count", "column=3", "--count", "top=1", "--samples", "500"]) == 0
    assert "total: 4 spheres" in capsys.readouterr().out
    spheres = load_spheres(str(out))
    assert [s.link for s in spheres] == ["column"] * 3 + ["top"]
    assert [s.check_floor for s in spheres] == [False] * 3 + [True]  # the top leaves the floor as the lift rises


@pytest.mark.parametrize("robot", known_robots())  # every file of configs/robot/, none listed by hand
def test_sphere_file_covers_collision_geometry(robot: str, capsys: pytest.CaptureFixture) -> None:
    spec = load_robot_spec(robot)
    urdf = source_urdf(spec.urdf)
    spheres = load_spheres(spec.spheres_file)
    links = collision_links(urdf)
    assert {s.link for s in spheres} <= set(links), "spheres on links without collision geometry"
    # the links the sphere file leaves to a neighbour's spheres, and no other
    assert set(links) - {s.link for s in spheres} == set(links_without_spheres(spec.spheres_file))
    rows = []
    for link in links:
        own = [Sphere(s.offset, s.radius) for s in spheres if s.link == link]
        if own:
            # 16 directions per sphere for the printed overshoot (96: the SO-100's fine meshes took 22 s, 3 s now)
            cov = coverage(link_geometry(urdf, link), own, n_samples=2000, seed=2024, n_dirs=16)
            rows.append((link, cov))
    low = [(l, round(c.share_inside, 4)) for l, c in rows if c.share_inside < 0.99]
    worst = max(rows, key=lambda r: r[1].overshoot)
    with capsys.disabled():
        print(f"\n[spheres] {robot}: {len(spheres)} spheres on {len(rows)} links; lowest share inside "
              f"{100 * min(c.share_inside for _, c in rows):.2f} %; largest overshoot "
              f"{1000 * worst[1].overshoot:.0f} mm ({worst[0]})")
    assert not low, f"{robot}: links under 99 % covered by their own spheres: {low}"


def test_links_left_without_spheres_are_data_of_the_sphere_file(tmp_path: Path) -> None:
    """A sphere file says which collision links its spheres leave to a neighbour's (Fetch's wheels
    inside the base's sphere), so the coverage check above names no robot; written and read back."""
    from realize.config import ConfigError
    from realize.robot.sphere_file import SphereSpec, write_spheres

    path = tmp_path / "arm.yaml"
    write_spheres(path, "arm", [SphereSpec("a", "link_a", (0.0, 0.0, 0.1), 0.05)], without_spheres=["wheel"])
    assert links_without_spheres(str(path)) == ("wheel",) and [s.link for s in load_spheres(str(path))] == ["link_a"]
    write_spheres(path, "arm", [SphereSpec("a", "link_a", (0.0, 0.0, 0.1), 0.05)])
    assert links_without_spheres(str(path)) == ()
    path.write_text(path.read_text().replace("spheres:", "links_without_spheres: wheel\nspheres:", 1))
    with pytest.raises(ConfigError, match=r"arm.yaml: links_without_spheres = 'wheel' is invalid"):
        links_without_spheres(str(path))
