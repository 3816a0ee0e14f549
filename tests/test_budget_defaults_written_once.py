"""The replan budget's and the execution study's defaults are written once, in their dataclasses
(``realize.execution.replan_budget.ReplanBudget``, ``realize.execution.settings.ExecuteSettings``,
whose ``budget`` it is): ``scripts/execute.py --help`` is built from them, the docs that name the
budget point to its module instead of repeating its numbers, and the check's numbers the docs
give are the dataclass's."""

from __future__ import annotations

import contextlib
import dataclasses
import importlib.util
import io
import re
from pathlib import Path
from typing import Any

import pytest

import realize.execution.settings
from realize.config import ConfigError
from realize.execution.replan_budget import ReplanBudget
from realize.execution.settings import ExecuteSettings, PrecheckSettings, load_preset

REPO = Path(__file__).resolve().parent.parent


def _execute_help() -> str:
    out = io.StringIO()
    with contextlib.redirect_stdout(out), pytest.raises(SystemExit):
        _execute_script().main(["--help"])
    return " ".join(out.getvalue().split())


def test_the_execute_help_names_the_dataclasses_defaults(monkeypatch: pytest.MonkeyPatch) -> None:
    """Other defaults in the dataclasses, other numbers in the help: none is written there."""

    @dataclasses.dataclass
    class OtherBudget(ReplanBudget):
        n_envs: int = 40
        n_elite: int = 5
        iterations: int = 7
        validation: int = 2

    @dataclasses.dataclass
    class OtherStudy(ExecuteSettings):
        precheck: PrecheckSettings = dataclasses.field(default_factory=lambda: PrecheckSettings(copies=3))
        think: Any = "frozen"
        budget: ReplanBudget = dataclasses.field(default_factory=OtherBudget)

    monkeypatch.setattr(realize.execution.settings, "ExecuteSettings", OtherStudy)
    text = _execute_help()
    assert "else 40, 5 elites;" in text and "(default: the preset's, else 7)" in text, text
    assert "(default: the preset's, else 2;" in text, text
    assert "default: the preset's, else 3)" in text and "(default: the preset's, else frozen)" in text, text


def test_a_preset_sets_the_budget_where_it_differs(tmp_path: Path) -> None:
    """The budget is a group of the execute schema: a preset writes the keys it changes, the rest
    are ReplanBudget's; a bad key or value is one line naming it."""
    path = tmp_path / "slow.yaml"
    path.write_text("budget:\n  iterations: 5\n")
    s = load_preset(path)
    assert s.budget == dataclasses.replace(ReplanBudget(), iterations=5)
    assert load_preset("none").budget == ReplanBudget()
    for text, needle in (("budget: {n_env: 8}", r"execute\[bad\]\.budget: unknown key\(s\) \['n_env'\]"),
                         ("budget: {n_envs: 2, n_elite: 3}", r"execute\[bad\]\.budget\.n_elite = 3 is invalid"),
                         ("budget: {iterations: 0}", r"execute\[bad\]\.budget\.iterations = 0 is invalid")):
        (tmp_path / "bad.yaml").write_text(text + "\n")
        with pytest.raises(ConfigError, match=needle):
            load_preset(tmp_path / "bad.yaml")


def test_the_docs_point_to_the_replan_budget_instead_of_repeating_it() -> None:
    """Where a page's prose names ``ReplanBudget`` (its code examples aside), the module that
    holds the defaults follows within a few lines, and no default copies or iterations do."""
    b = ReplanBudget()
    for page in ("python_api.md", "replanning.md"):
        prose = re.sub(r"```.*?```", "", (REPO / "docs" / page).read_text(), flags=re.S)
        text = " ".join(prose.split())
        spots = [m.start() for m in re.finditer("`ReplanBudget`", text)]
        assert spots, page
        for at in spots:
            said = text[at:at + 300]
            assert "realize/execution/replan_budget.py" in said, (page, said)
            assert not re.search(rf"\b({b.n_envs} copies|{b.iterations} iterations)", said), (page, said)


def test_the_docs_name_the_checks_defaults() -> None:
    p = ExecuteSettings().precheck
    text = " ".join((REPO / "docs" / "replanning.md").read_text().split())
    for said in (f"`copies` ({p.copies}) copies", f"`scatter_m` ({p.scatter_m * 100:g} cm)",
                 f"`min_success` ({p.min_success:g})"):
        assert said in text, said


def _execute_script() -> Any:
    spec = importlib.util.spec_from_file_location("execute_script", REPO / "scripts" / "execute.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_the_command_line_changes_the_presets_budget(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """``--n-envs`` (with its elites), ``--iterations`` and ``--validation`` change the preset's
    budget key by key; without them the study runs on the preset's budget."""
    import realize.repair.study

    run = tmp_path / "run"
    run.mkdir()
    (run / "result.json").write_text("{}")
    preset = tmp_path / "slow.yaml"
    preset.write_text("budget: {iterations: 5, validation: 2}\n")
    seen: list[ExecuteSettings] = []

    def study(run_dir: Any, settings: ExecuteSettings, **kw: Any) -> Any:
        assert "budget" not in kw  # the study's budget is the settings'
        seen.append(settings)
        raise ConfigError("stop here")

    monkeypatch.setattr(realize.repair.study, "execute", study)
    script = _execute_script()
    assert script.main([str(run), "--disturbance", str(preset)]) == 2
    assert script.main([str(run), "--disturbance", str(preset), "--n-envs", "8"]) == 2
    assert script.main([str(run), "--disturbance", str(preset), "--iterations", "1", "--validation", "0"]) == 2
    preset_budget = dataclasses.replace(ReplanBudget(), iterations=5, validation=2)
    assert [s.budget for s in seen] == [preset_budget,
                                        dataclasses.replace(preset_budget, n_envs=8, n_elite=ReplanBudget.elites_for(8)),
                                        dataclasses.replace(preset_budget, iterations=1, validation=0)]
