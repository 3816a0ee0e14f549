"""An execution study's config is Hydra's: ``configs/execution.yaml`` composes ``ExecuteSettings``'
defaults, an ``execute`` option, a ``noise`` option at ``execute.noise`` and value overrides, in
that order. Checked against the file reader (``load_preset``, ``load_noise``: the YAML read over
the dataclass's defaults, with no Hydra in it) and the command line's one-line refusals."""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Any

import pytest

from helpers import load_script
from realize.config import ConfigError
from realize.execution.perception import load_noise, noise_presets
from realize.execution.settings import ExecuteSettings, load_preset, presets
from realize.spec.execution_config import compose_execution


@pytest.mark.parametrize("name", presets())
def test_every_preset_composes_to_what_its_file_says(name: str) -> None:
    assert compose_execution([f"execute={name}"]) == load_preset(name)
    for noise in noise_presets():
        s = compose_execution([f"execute={name}", f"noise={noise}"])
        assert s == dataclasses.replace(load_preset(name), noise=load_noise(noise))


def test_the_defaults_are_the_dataclasses_and_overrides_come_last(tmp_path: Path) -> None:
    assert compose_execution() == ExecuteSettings()
    s = compose_execution(["execute=table_moved", "execute.worlds=3", "execute.budget.iterations=2",
                           "execute.tolerance.object_m=0.2"])
    want = load_preset("table_moved")
    want = dataclasses.replace(want, worlds=3, budget=dataclasses.replace(want.budget, iterations=2),
                               tolerance=dataclasses.replace(want.tolerance, object_m=0.2))
    assert s == want
    own = tmp_path / "mine.yaml"
    own.write_text("worlds: 5\nmax_replans: 1\n")
    s = compose_execution(["execute.worlds=2"], preset_file=own)  # the file over the defaults, the key over both
    assert (s.worlds, s.max_replans) == (2, 1)


@pytest.mark.parametrize("overrides, needle", [
    (["execute=nope"], "execute=nope: unknown execute preset 'nope' (did you mean 'none'?); available: "),
    (["noise=fog"], "noise=fog: unknown noise preset 'fog'; available: none, realistic"),
    (["execute.foo=1"], "Key 'foo' is not in struct"),
    (["execute.worlds=0"], "execute.worlds = 0 is invalid: must be >= 1"),
    (["execute.worlds=1,2"], "a sweep (several values)"),
    (["ce.n_envs=8"], "an execution's config has the groups execute, noise and the keys execute.*"),
])
def test_bad_input_is_one_line(overrides: list[str], needle: str) -> None:
    with pytest.raises(ConfigError) as e:
        compose_execution(overrides)
    assert needle in str(e.value) and "\n" not in str(e.value)


def test_the_command_line_flags_are_keys_and_trailing_keys_win(tmp_path: Path,
                                                               monkeypatch: pytest.MonkeyPatch) -> None:
    import realize.repair.study

    run = tmp_path / "run"
    run.mkdir()
    (run / "result.json").write_text("{}")
    seen: list[ExecuteSettings] = []

    def study(run_dir: Any, settings: ExecuteSettings, **kw: Any) -> Any:
        seen.append(settings)
        raise ConfigError("stop here")

    monkeypatch.setattr(realize.repair.study, "execute", study)
    script = load_script("execute")
    assert script.main([str(run), "--disturbance", "obstacle", "--noise", "realistic", "--worlds", "4",
                        "--think", "12", "execute.worlds=6", "execute.monitor_every=3"]) == 2
    (s,) = seen
    want = load_preset("obstacle")
    assert s == dataclasses.replace(want, noise=load_noise("realistic"), worlds=6, think=12, monitor_every=3)
    assert script.main([str(run), "execute.nope=1"]) == 2 and len(seen) == 1  # refused before the study
