"""The replan budget's and the execution study's defaults are written once, in their dataclasses
(``realize.app.plan_result.ReplanBudget``, ``realize.execution.settings.ExecuteSettings``):
``scripts/execute.py --help`` is built from them, and the docs that name them say the same
numbers."""

from __future__ import annotations

import contextlib
import dataclasses
import importlib.util
import io
import re
from pathlib import Path
from typing import Any

import pytest

import realize.app.planner
import realize.execution.settings
from realize.app.planner import ReplanBudget
from realize.execution.settings import ExecuteSettings, PrecheckSettings

REPO = Path(__file__).resolve().parent.parent


def _execute_help() -> str:
    spec = importlib.util.spec_from_file_location("execute_script", REPO / "scripts" / "execute.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    out = io.StringIO()
    with contextlib.redirect_stdout(out), pytest.raises(SystemExit):
        module.main(["--help"])
    return " ".join(out.getvalue().split())


def test_the_execute_help_names_the_dataclasses_defaults(monkeypatch: pytest.MonkeyPatch) -> None:
    """Other defaults in the dataclasses, other numbers in the help: none is written there."""

    @dataclasses.dataclass(frozen=True)
    class OtherBudget(ReplanBudget):
        n_envs: int = 40
        n_elite: int = 5
        iterations: int = 7

    @dataclasses.dataclass
    class OtherStudy(ExecuteSettings):
        precheck: PrecheckSettings = dataclasses.field(default_factory=lambda: PrecheckSettings(copies=3))
        think: Any = "frozen"

    monkeypatch.setattr(realize.app.planner, "ReplanBudget", OtherBudget)
    monkeypatch.setattr(realize.execution.settings, "ExecuteSettings", OtherStudy)
    text = _execute_help()
    assert "(default 40, 5 elites;" in text and "(default 7)" in text, text
    assert "default: the preset's, else 3)" in text and "(default: the preset's, else frozen)" in text, text


def test_the_docs_name_the_replan_budgets_defaults() -> None:
    b = ReplanBudget()
    found = 0
    for page in ("python_api.md", "replanning.md"):
        text = " ".join((REPO / "docs" / page).read_text().split())
        for said in re.findall(r"`ReplanBudget` \(([^)]*)\)", text):
            found += 1
            assert f"{b.n_envs} copies" in said and f"at most {b.iterations} iterations" in said, (page, said)
            m = re.search(r"in (\w+) scenes of (\d+)", said)
            if m:
                assert b.shard_rows is not None and int(m[2]) == b.shard_rows, (page, said)
                assert {"two": 2}.get(m[1]) == -(-b.n_envs // b.shard_rows), (page, said)
            assert ("stopped at the first plan that reaches" in said) == b.stop_when_feasible, (page, said)
            assert b.validation == 0 or "no validation" not in said, (page, said)
    assert found == 2


def test_the_docs_name_the_checks_defaults() -> None:
    p = ExecuteSettings().precheck
    text = " ".join((REPO / "docs" / "replanning.md").read_text().split())
    for said in (f"`copies` ({p.copies}) copies", f"`scatter_m` ({p.scatter_m * 100:g} cm)",
                 f"`min_success` ({p.min_success:g})"):
        assert said in text, said


def _leaves(x: Any, path: str = "") -> dict[str, Any]:
    if isinstance(x, dict):
        return {k: v for key, sub in x.items() for k, v in _leaves(sub, f"{path}.{key}" if path else key).items()}
    return {path: x}


def test_no_execute_preset_repeats_a_default() -> None:
    """A preset of configs/execute/ writes only what it changes: a key set to ExecuteSettings'
    default would be that default written a second time."""
    import yaml

    defaults = _leaves(dataclasses.asdict(ExecuteSettings()))
    repeated = []
    for path in sorted((REPO / "configs" / "execute").glob("*.yaml")):
        preset = _leaves(yaml.safe_load(path.read_text()) or {})
        repeated += [f"{path.name}: {k}" for k, v in preset.items() if k in defaults and k != "disturbances"
                     and (v == defaults[k] or (isinstance(v, (list, tuple)) and list(v) == list(defaults[k])))]
    assert not repeated, f"presets that repeat ExecuteSettings' default: {repeated}"
