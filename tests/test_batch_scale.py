"""The batch lever ``ce.batch_scale``: a preset's batch times the levers' scale, resolved where the
config is composed (``${realize_scaled:N,SCALE}``, ``realize.spec.hydra_edge``).

What a user relies on: ``levers=exact`` gives the paper's batch, ``levers=fast`` (what
``experiment=seed_paper`` uses) half of it in as many shards (both cores busy), a number on the
command line is used as it is, and a bad scale is one error line naming the key. The search-time
and cost A/B is ``scripts/bench_levers.py`` (docs/results.md); the golden runs check that
``levers=exact`` is the paper's algorithm bit for bit.
"""

from __future__ import annotations

import math

import pytest

from helpers import compose_config, realize_cli
from realize.spec.hydra_edge import scaled_count
from realize.spec.run_spec import build_run_spec
from realize.scene.shards import shard_rows
from realize.config import ConfigError


def _batch(*overrides: str) -> tuple[int, int, float]:
    d = compose_config(*overrides)
    return d["ce"]["n_envs"], d["sim"]["shard_rows"], d["ce"]["batch_scale"]


def test_levers_exact_runs_the_papers_batch_and_levers_fast_half_of_it_on_as_many_shards() -> None:
    assert _batch("experiment=seed_paper_exact") == (200, 100, 1.0)
    assert _batch("experiment=seed_paper", "levers=exact") == (200, 100, 1.0)
    assert _batch("experiment=seed_paper", "levers=all") == (200, 100, 1.0)  # the default levers: no scale
    n, rows, scale = _batch("experiment=seed_paper", "levers=fast")
    assert (n, rows, scale) == (100, 50, 0.5)
    # the shards (what keeps both cores of a laptop busy) are as many as the paper's batch has
    assert len(shard_rows(n, rows)) == len(shard_rows(200, 100)) == 2
    n, rows, scale = _batch("experiment=seed_paper")  # levers=stitched, the preset's choice: 76 copies
    assert (n, rows, scale) == (76, 38, 0.38) and len(shard_rows(n, rows)) == 2
    spec = build_run_spec(compose_config("experiment=seed_paper", "levers=fast"))  # the named set of both
    assert (spec.ce.n_envs, spec.sim.shard_rows, spec.ce.keep_elites, spec.ce.prune) == (100, 50, True, True)


def test_a_batch_given_on_the_command_line_is_not_scaled() -> None:
    assert _batch("experiment=seed_paper", "ce.n_envs=150")[0] == 150
    assert _batch("experiment=seed_paper", "levers=fast", "ce.batch_scale=0.25") == (50, 25, 0.25)
    # presets that write their batch as a number keep it under every lever
    for preset in ("wall", "ramp", "tower3", "two_cubes"):
        assert _batch(f"experiment={preset}")[:2] == _batch(f"experiment={preset}", "levers=exact")[:2]


def test_scaled_count_rounds_half_up_and_keeps_one_copy() -> None:
    assert [scaled_count(200, s) for s in (0.5, 0.25, 0.333, 1.0, 1.5)] == [100, 50, 67, 200, 300]
    assert scaled_count(3, 0.5) == 2 and scaled_count(1, 0.01) == 1
    for bad in (0, -0.5, math.inf, "half"):
        with pytest.raises(ConfigError, match="ce.batch_scale"):
            scaled_count(200, bad)


def test_a_bad_scale_is_one_error_line_naming_the_key(tmp_path) -> None:
    p = realize_cli("experiment=seed_paper", "ce.batch_scale=-1", f"hydra.run.dir={tmp_path / 'run'}", timeout=120)
    assert p.returncode == 2, p.stderr
    err = [ln for ln in p.stderr.splitlines() if ln.startswith("error:")]
    assert len(err) == 1 and "ce.batch_scale = -1 is invalid" in err[0], p.stderr
    assert "Traceback" not in p.stderr and "full_key" not in p.stderr
    assert not (tmp_path / "run" / "result.json").exists()
