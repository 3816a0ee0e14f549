"""A misspelled name gets the closest known names on every entry path, not only on the command
line: the Python API's ``compose_config``, a composed config edited in a notebook (``+key=``
additions and plain dict edits reach the dataclass readers), a task file, a scene state file,
and a config group choice. Nothing is simulated."""

from __future__ import annotations

import copy
import json
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest
import yaml

from realize.spec.compose import compose_config
from realize.spec.run_spec import build_run_spec
from realize.config import ConfigError
from realize.world.state import load_state

BASE = compose_config(["device=cpu", "validation=off"])


def _edited(edit: Callable[[dict[str, Any]], None]) -> dict[str, Any]:
    d = copy.deepcopy(BASE)
    edit(d)
    return d


def _rename(node: dict[str, Any], old: str, new: str) -> None:
    node[new] = node.pop(old)


def _set(node: dict[str, Any], key: Any, value: Any) -> None:
    node[key] = value


EDITS = {
    "ce key": (lambda d: _rename(d["ce"], "n_envs", "n_envz"), "'n_envz' -> 'n_envs'"),
    "task key": (lambda d: _rename(d["task"], "goal", "goals"), "'goals' -> 'goal'"),
    "goal predicate": (lambda d: _rename(d["task"]["goal"], "rests_on", "rest_on"), "'rest_on' -> 'rests_on'"),
    "action template": (lambda d: _set(d["task"]["plan"], 0, "move_too(Table1)"), "did you mean 'move_to'?"),
    "plan parameter": (lambda d: _set(d["task"]["plan"], 0, "move_to(Tabel1)"), "did you mean 'Table1'"),
    "plan object": (lambda d: _set(d["task"]["plan"], 1, "grasp(cueb, Cube_g)"), "did you mean 'cube'?"),
    "region type": (lambda d: _set(d["task"]["params"]["Table1"], "type", "anulus"), "did you mean 'annulus'?"),
}


@pytest.mark.parametrize("name", list(EDITS))
def test_an_edited_config_suggests_the_name(name: str) -> None:
    edit, hint = EDITS[name]
    with pytest.raises(ConfigError) as e:
        build_run_spec(_edited(edit))
    assert hint in str(e.value) and "\n" not in str(e.value)


@pytest.mark.parametrize("overrides, hint", [
    (["ce.n_envz=3"], "did you mean 'ce.n_envs'"),
    (["validation.replica=3"], "did you mean 'validation.replicas'?"),
    (["experiment=seedpaper"], "did you mean 'seed_paper'"),
    (["robot=fetch"], "did you mean 'fetch_omni'?"),
])
def test_compose_config_suggests_the_name(overrides: list[str], hint: str) -> None:
    with pytest.raises(ConfigError) as e:
        compose_config(overrides)
    assert hint in str(e.value)


def test_added_key_is_refused_with_the_closest_name() -> None:
    """``+ce.n_envz=3`` composes (Hydra adds the key); the ce reader refuses it by name."""
    with pytest.raises(ConfigError, match=r"'n_envz' -> 'n_envs'"):
        build_run_spec(compose_config(["device=cpu", "+ce.n_envz=3"]))


def test_a_task_file_suggests_the_name(tmp_path: Path) -> None:
    task = copy.deepcopy(BASE["task"])
    _rename(task, "goal", "goals")
    path = tmp_path / "my_task.yaml"
    path.write_text(yaml.safe_dump(task))
    with pytest.raises(ConfigError, match=r"my_task.yaml.*'goals' -> 'goal'"):
        build_run_spec(compose_config(["device=cpu", f"task_file={path}"]))


def test_a_state_file_suggests_the_name(tmp_path: Path) -> None:
    path = tmp_path / "state.json"
    path.write_text(json.dumps({"format": "realize.scene_state/2", "base": [0, 0, 0], "objects": {}, "objcts": {}}))
    with pytest.raises(ConfigError, match=r"'objcts' -> 'objects'"):
        load_state(path)


def test_a_bad_state_file_is_named_by_its_path_not_its_free_text_source(tmp_path: Path) -> None:
    """A state with a ``source`` description and a bad joint (found by scripts/fuzz_inputs.py):
    the message named the description, not the file to fix."""
    path = tmp_path / "state.json"
    path.write_text(json.dumps({"format": "realize.scene_state/2", "base": [0, 0, 0], "objects": {},
                                "joints": {"torso_lift_joint": {}}, "source": "a replay of some run"}))
    with pytest.raises(ConfigError) as e:
        load_state(path)
    assert str(e.value).startswith(str(path)) and "torso_lift_joint" in str(e.value)
    good = json.loads(path.read_text())
    good["joints"] = {"torso_lift_joint": 0.1}
    path.write_text(json.dumps(good))
    assert load_state(path).source == "a replay of some run"  # its own text is kept
