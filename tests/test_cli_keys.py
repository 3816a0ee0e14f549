"""Misspelled config groups and keys on the command line: one line with "did you mean", before
Hydra (whose advice, ``+secne=wall``, the run would then refuse)."""

from __future__ import annotations

import pytest
from hydra.core.override_parser.overrides_parser import OverridesParser

from helpers import realize_cli
from realize.cli.main import CONFIG_GROUPS
from realize.spec.keys import check_override_keys, closest
from realize.config import ConfigError


def _check(args: list[str]) -> None:
    check_override_keys(OverridesParser.create().parse_overrides(args), CONFIG_GROUPS)


@pytest.mark.parametrize("args, names", [
    (["secne=wall"], ["'scene'"]),
    (["ce.n_envz=3"], ["'ce.n_envs'"]),
    (["task.params.Tabel2.center=[0,0]"], ["'task.params.Table2'"]),
    (["experiment=journal", "ce.iteratons=2"], ["'ce.iterations'"]),
])
def test_misspelled_keys_name_the_closest(args: list[str], names: list[str]) -> None:
    with pytest.raises(ConfigError, match="did you mean") as e:
        _check(args)
    msg = str(e.value)
    assert "\n" not in msg and "+" not in msg.split(":")[0] and all(n in msg for n in names)


def test_known_keys_sweeps_and_additions_pass() -> None:
    _check(["scene=wall", "scene.tables.1.center=[0.3,-1.2]", "ce.n_envs=3,4", "+extra=1", "seed=2",
            "replan.action=2", "hydra.run.dir=x"])


def test_nothing_close_lists_what_is_there() -> None:
    with pytest.raises(ConfigError, match=r"scene.tables.7.*known: 0, 1"):
        _check(["scene.tables.7.center=[0,0]"])
    with pytest.raises(ConfigError, match="seed is a value"):
        _check(["seed.x=1"])
    assert closest("SCENE", ["scene", "seed"])[0] == "scene" and closest("xyz", ["scene"]) == []


def test_the_command_answers_in_one_line() -> None:
    p = realize_cli("secne=wall", timeout=120)
    lines = [ln for ln in p.stderr.splitlines() if ln.strip()]
    assert p.returncode == 2 and lines == [lines[-1]] and "did you mean 'scene'" in lines[-1], p.stderr
    assert "+secne" not in p.stderr


def test_cfg_with_a_task_file_says_what_it_shows(capsys: pytest.CaptureFixture[str]) -> None:
    from realize.cli.main import preflight

    assert preflight(["--cfg", "job", "task_file=x.yaml"]) == ["--cfg", "job", "task_file=x.yaml"]
    assert "task_file replaces it" in capsys.readouterr().err
