"""The config edge composes the defaults tree once per set of group choices and applies value
overrides to a copy (``realize.spec.hydra_edge.compose_or_error``). It must give what Hydra's
whole compose gives, config and flags, or the same one-line error: checked on hand-picked
override sets (every override form: set, ``+`` add, ``++`` force-add, ``~`` delete, a dict
value on a group, null, lists, a group choice next to a value in that group) and on override
sets drawn by the input fuzzer's own strategy."""

from __future__ import annotations

import pytest
from hypothesis import HealthCheck, Phase, given, seed, settings
from omegaconf import OmegaConf

from helpers import load_script
from realize.spec.hydra_edge import _compose_whole, compose_or_error
from realize.config import ConfigError

HAND = [
    [],
    ["ce.n_envs=100"],
    ["experiment=wall", "ce.n_envs=100", "scene.tables.1.center=[0.3,-1.2]"],
    ["scene=wall", "scene.tables.0.center=[0.0,1.1]"],
    ["robot=mobile_panda", "++ce.n_envs=7"],
    ["+ce.extra=3"],
    ["+ce.n_envs=3"],
    ["~ce.n_envs"],
    ["~ce.n_envs=5"],
    ["ce={n_envs: 5}"],
    ["ce.n_envs=null", "validation=off"],
    ["ce.n_envz=3"],
    ["experiment=seed_paper_exact", "levers=all", "seed=4"],
    ["hydra/sweeper=optuna", "ce.alpha=0.5"],
]


def _outcome(overrides: list[str], compose) -> tuple:
    try:
        cfg = compose(overrides)
    except ConfigError as e:
        return ("error", str(e))
    d = OmegaConf.to_container(cfg, resolve=False)
    d.pop("hydra", None)
    return ("config", d, OmegaConf.is_struct(cfg), OmegaConf.is_readonly(cfg))


@pytest.mark.parametrize("overrides", HAND, ids=[" ".join(h) or "defaults" for h in HAND])
def test_cached_compose_equals_hydras_whole_compose(overrides: list[str]) -> None:
    whole = _outcome(overrides, _compose_whole)
    assert _outcome(overrides, compose_or_error) == whole
    assert _outcome(overrides, compose_or_error) == whole  # the second time, from the cache


def test_a_returned_config_is_the_callers_own() -> None:
    default = compose_or_error([]).ce.n_elite
    a = compose_or_error(["ce.n_envs=100"])
    a.ce.n_elite = default + 1
    assert compose_or_error(["ce.n_envs=100"]).ce.n_elite == default
    assert compose_or_error([]).ce.n_envs != 100


# make test draws the first 8 sets, make test-slow 25 (about 1.5 s each on a busy 2-core host)
@pytest.mark.parametrize("examples", [8, pytest.param(25, marks=pytest.mark.slow)])
def test_fuzzed_override_sets_compose_as_hydra_does(examples: int) -> None:
    fz = load_script("fuzz_inputs")
    differ: list[str] = []

    @seed(1)
    @settings(max_examples=examples, database=None, deadline=None, phases=[Phase.generate],
              suppress_health_check=list(HealthCheck))
    @given(fz.override_case())
    def one(case) -> None:
        args = [a for a in case.args if "{" not in a]
        if _outcome(args, compose_or_error) != _outcome(args, _compose_whole):
            differ.append(repr(args))

    one()
    assert not differ, differ
