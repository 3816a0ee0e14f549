"""The fabric step built ahead of time (``controller.fabric.compiled``) against the eager step.

The oracle is the eager ``WholeBodyFabric.step`` (itself checked against the reference ``fabrics``
package in tests/test_fabrics*.py): the same valid rows, joint targets within float32 rounding of
the compiler's other summation order, one package for every batch size and scene, a row's result
independent of its batch mates bit for bit, and a clear error when the build fails. The package is
built once per machine by the first run or test that loads it (about a minute: no preset uses it,
so setup does not build it) and shared with the runs: the tests that load it are marked slow.
"""

from __future__ import annotations

import os

import pytest
import torch

from realize.config import ConfigError
from realize.controllers import fabric_package
from realize.controllers.whole_body import FabricState, WholeBodyConfig, WholeBodyFabric
from realize.robot.spec import load_robot_spec
from realize.world.geometry import GeometryCfg, RampCfg, WallCfg, build_geometry
from helpers import FABRIC_ROWS, fabric_states, row_subsets

F32 = torch.float32
ROBOT = load_robot_spec("fetch_omni")  # the fabric's default robot


def _fabric(compiled: bool, geometry: GeometryCfg | None = None, **cfg) -> WholeBodyFabric:
    return WholeBodyFabric(build_geometry(geometry or GeometryCfg()), WholeBodyConfig(compiled=compiled, **cfg),
                           dt=0.05, dtype=F32)


@pytest.fixture(scope="module")
def pair() -> tuple[WholeBodyFabric, WholeBodyFabric]:
    return _fabric(False), _fabric(True)


def _inputs(fab: WholeBodyFabric, seed: int):
    q, qd, pos = fabric_states(ROBOT, F32, seed=seed)
    goal = fab.goal_points(pos, torch.tensor([0.0, 0.0, -1.0]).expand(FABRIC_ROWS, 3), torch.tensor([0.0, 1.0, 0.0]).expand(FABRIC_ROWS, 3))
    q_meas = q.clone()
    q_meas[::5, 4] += 0.2  # some rows re-synchronise from the measurement
    return fab.start(q, qd), q_meas, goal


@pytest.mark.slow  # loads the built package: its first build on a machine takes about a minute
def test_built_step_matches_the_eager_step(pair) -> None:
    eager, built = pair
    assert built._package is not None and eager._package is None
    state, q_meas, goal = _inputs(eager, seed=1)
    with torch.inference_mode():
        for n in (1, 7, FABRIC_ROWS):
            sub = FabricState(state.q[:n], state.qd[:n])
            (a, va), (b, vb) = eager.step(sub, q_meas[:n], goal[:n]), built.step(sub, q_meas[:n], goal[:n])
            assert torch.equal(va, vb) and bool(va.all())
            assert torch.allclose(a.q, b.q, rtol=0, atol=2e-6), (a.q - b.q).abs().max()
            assert torch.allclose(a.qd, b.qd, rtol=0, atol=2e-5), (a.qd - b.qd).abs().max()
            assert not torch.equal(a.q, b.q) or n == 1  # it is the package that ran, not the eager step


@pytest.mark.slow  # loads the built package: its first build on a machine takes about a minute
def test_a_row_of_the_built_step_ignores_its_batch_mates(pair) -> None:
    _, built = pair
    state, q_meas, goal = _inputs(built, seed=3)
    with torch.inference_mode():
        full, valid = built.step(state, q_meas, goal)
        for rows in row_subsets(seed=4):
            part, v = built.step(FabricState(state.q[rows], state.qd[rows]), q_meas[rows], goal[rows])
            assert torch.equal(part.q, full.q[rows]) and torch.equal(part.qd, full.qd[rows]), len(rows)
            assert torch.equal(v, valid[rows])


@pytest.mark.slow  # loads the built package: its first build on a machine takes about a minute
def test_one_package_serves_every_scene_and_follows_the_settings(pair) -> None:
    eager, built = pair
    walls = GeometryCfg(variant="wall", walls=[WallCfg()])
    ramp = GeometryCfg(variant="ramp", ramps=[RampCfg()])
    path = fabric_package.package_path(built)
    assert fabric_package.package_path(eager) == path  # the switch itself is not part of the key
    for g in (walls, ramp):
        e, b = _fabric(False, g), _fabric(True, g)
        assert fabric_package.package_path(b) == path and b.boxes.shape != built.boxes.shape
        state, q_meas, goal = _inputs(e, seed=5)
        with torch.inference_mode():
            (x, vx), (y, vy) = e.step(state, q_meas, goal), b.step(state, q_meas, goal)
        assert torch.equal(vx, vy) and torch.allclose(x.q, y.q, rtol=0, atol=2e-6)
    # a setting the step uses, or another dtype, is another package
    assert fabric_package.package_path(_fabric(False, gamma=2.5)) != path
    assert fabric_package.package_path(
        WholeBodyFabric(build_geometry(GeometryCfg()), dt=0.05, dtype=torch.float64)) != path


@pytest.mark.slow  # loads the built package: its first build on a machine takes about a minute
def test_a_per_plan_weight_runs_the_eager_step(pair) -> None:
    eager, built = pair
    state, q_meas, goal = _inputs(eager, seed=6)
    w = torch.linspace(1.0, 4.0, FABRIC_ROWS)
    a, va = eager.step(state, q_meas, goal, weight=w)
    b, vb = built.step(state, q_meas, goal, weight=w)
    assert torch.equal(a.q, b.q) and torch.equal(va, vb)


def test_a_failed_build_names_the_key_and_the_way_out(monkeypatch, tmp_path) -> None:
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))

    def no_compiler(fabric, out):
        raise RuntimeError("C++ compile error: g++ not found")

    monkeypatch.setattr(fabric_package, "_build", no_compiler)
    with pytest.raises(ConfigError, match=r"controller\.fabric\.compiled = true: building .* g\+\+ not found.*"
                                          r"controller\.fabric\.compiled=false"):
        _fabric(True)
    assert not list((tmp_path / "realize" / "fabric").glob("*.pt2"))  # no half package left behind


@pytest.mark.slow  # loads the built package: its first build on a machine takes about a minute
def test_prebuild_finds_the_package_a_run_loads(pair, monkeypatch, capsys) -> None:
    from realize.cli import prebuild as pb

    _, built = pair  # built with the default settings at the scene's control period, as a run's
    assert pb.prebuild(["fetch_omni"])  # already there: nothing is built or loaded
    assert "building" not in capsys.readouterr().err

    def broken(fabric):
        raise ConfigError("controller.fabric.compiled = true: building the fabric step failed (no g++)")

    monkeypatch.setattr(pb, "ensure_built", broken)
    assert not pb.prebuild(["fetch_omni"])
    assert "no g++" in capsys.readouterr().err


def test_a_damaged_package_is_named_and_old_ones_are_pruned(monkeypatch, tmp_path) -> None:
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    eager = _fabric(False, gamma=2.9)  # a key no other test builds
    path = fabric_package.package_path(eager)
    path.write_bytes(b"not a package")
    with pytest.raises(ConfigError, match=r"cannot load the fabric step .*delete the file to build it again"):
        _fabric(True, gamma=2.9)
    # a build keeps the newest KEEP_PER_ROBOT packages of its robot, and other robots' packages
    folder = path.parent
    old = [folder / f"fetch_omni-{i:024d}.pt2" for i in range(fabric_package.KEEP_PER_ROBOT + 2)]
    for i, p in enumerate(old):
        p.write_bytes(b"x")
        os.utime(p, (1000 + i, 1000 + i))
    other = folder / "panda-000000000000000000000000.pt2"
    other.write_bytes(b"x")
    fabric_package._prune(path)
    left = sorted(p.name for p in folder.glob("fetch_omni-*.pt2"))
    assert path.name in left and len(left) == fabric_package.KEEP_PER_ROBOT
    assert old[0].name not in left and old[-1].name in left and other.is_file()
