"""One source for each default: the composed default config (``configs/``, no overrides) and the
config dataclasses agree on every leaf both give, and what was given twice is given once.

Every leaf of a group's YAML that its dataclass also defaults (nested settings, named entries and
lists of entries included) must be equal; a leaf only the YAML gives, or only the dataclass, has
one source already. Retired keys (``realize.run_dir.upgrade``) are refused in new configs and
dropped from saved ones; the exit is the task's region only; PhysX threads have one key."""

from __future__ import annotations

import dataclasses
import json
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from helpers import comparable
import pytest

from realize.spec.compose import compose_config
from realize.spec.run_spec import LoggingSettings, StitchSettings, ValidationSettings, _TopLevel, build_run_spec
from realize.spec.replan_from import ReplanSettings
from realize.spec.workers_settings import WorkersSettings
from realize.config import ConfigError
from realize.paths import CONFIG_DIR
from realize.realization.config import RolloutConfig
from realize.run_dir.upgrade import RETIRED, upgrade_config
from realize.scene.settings import SimSettings
from realize.search.ce.config import CEConfig
from realize.world.geometry import GeometryCfg

DEFAULT = compose_config([])  # (device=auto is the CPU backend, also where CUDA is)
GROUPS = {"sim": SimSettings, "controller": RolloutConfig, "ce": CEConfig, "logging": LoggingSettings,
          "workers": WorkersSettings, "validation": ValidationSettings, "scene": GeometryCfg, "replan": ReplanSettings,
          "stitch": StitchSettings}
# top-level nodes whose dataclass the comparison above leaves out, and why
# (robot: RobotSpec's defaults name the default robot, a second copy of configs/robot/fetch_omni.yaml
# that this file does not compare yet)
NOT_COMPARED = {"robot"}


def _leaves(x: Any, path: str = "") -> Iterator[tuple[str, Any]]:
    if isinstance(x, dict):
        for k, v in x.items():
            yield from _leaves(v, f"{path}.{k}" if path else str(k))
    elif isinstance(x, (list, tuple)) and x and all(isinstance(v, dict) for v in x):
        for i, v in enumerate(x):
            yield from _leaves(v, f"{path}[{i}]")
    else:
        yield path, x


def _dataclass_leaves(cls: type) -> dict[str, Any]:
    return dict(_leaves(json.loads(json.dumps(dataclasses.asdict(cls()), default=str))))


@pytest.mark.parametrize("group", list(GROUPS))
def test_the_yaml_and_the_dataclass_agree_on_every_default(group: str) -> None:
    yaml_leaves = dict(_leaves(DEFAULT[group]))
    ours = _dataclass_leaves(GROUPS[group])
    both = sorted(set(yaml_leaves) & set(ours))
    assert both, f"{group}: no leaf in common"
    drift = {k: (yaml_leaves[k], ours[k]) for k in both if comparable(yaml_leaves[k]) != comparable(ours[k])}
    assert not drift, f"{group}: configs/ says (left) and {GROUPS[group].__name__} says (right): {drift}"


def test_every_top_level_settings_node_is_compared() -> None:
    """A settings class read at a top-level node of the run config (its ``config_key``) is in
    GROUPS, so a default written both in configs/ and in the class cannot drift unseen."""
    nodes = {cls.config_key: cls.__name__ for cls in _settings_classes()
             if cls.__module__.startswith(("realize", "envs")) and cls.config_key in DEFAULT}
    missing = sorted(f"{key} ({name})" for key, name in nodes.items() if key not in GROUPS and key not in NOT_COMPARED)
    assert not missing, f"not compared with configs/: {missing}"


def test_the_top_level_defaults_agree() -> None:
    ours = dataclasses.asdict(_TopLevel())
    drift = {k: (DEFAULT[k], v) for k, v in ours.items() if DEFAULT.get(k, v) != v}
    assert not drift


def test_the_exit_is_given_once_as_the_tasks_region() -> None:
    for path in sorted((CONFIG_DIR / "scene").glob("*.yaml")):
        assert "exit_" not in path.read_text(), f"{path.name} gives an exit: the task's region is the one"
    spec = build_run_spec(DEFAULT)
    assert spec.task.goal.base_in == "Exit" and not hasattr(spec.geometry, "exit_low")


@pytest.mark.parametrize("group, key", list(RETIRED))
def test_a_retired_key_is_refused_in_one_line(group: str, key: str) -> None:
    with pytest.raises(ConfigError) as e:
        build_run_spec(compose_config(["device=cpu", f"+{group}.{key}=1"]))
    assert str(e.value).startswith(f"{group}.{key}: not a config key any more") and "\n" not in str(e.value)
    with pytest.raises(ConfigError, match=f"{group}.{key} is not a config key any more"):
        compose_config([f"{group}.{key}=1"])


def test_a_saved_config_with_retired_keys_still_builds() -> None:
    """What a run recorded before the keys retired saved: the exit twice, PhysX threads under workers."""
    old = json.loads(json.dumps(DEFAULT))
    old["scene"].update(exit_low=[1.8, -0.4], exit_high=[2.6, 0.4])
    old["workers"]["physx_threads"] = 0
    old["scene"]["robot_radius"] = 0.3
    del old["robot"]["base"]["footprint_radius"]  # (a robot spec from before it had one)
    new = upgrade_config(old)
    assert "exit_low" not in new["scene"] and "physx_threads" not in new["workers"]
    assert new["sim"]["cpu_workers"] == 0  # the old key's value, under the one key
    assert "robot_radius" not in new["scene"] and new["robot"]["base"]["footprint_radius"] == 0.3
    spec = build_run_spec(new)
    assert spec.sim.cpu_workers == 0 and spec.robot.base.footprint_radius == 0.3


def test_the_footprint_is_the_robots() -> None:
    """A* pads obstacles by the robot spec's footprint, and the start is checked against it."""
    for robot in ("fetch_omni", "mobile_panda"):
        assert build_run_spec(compose_config([f"robot={robot}"])).robot.base.footprint_radius == 0.32
    for path in sorted((CONFIG_DIR / "scene").glob("*.yaml")):
        assert "robot_radius" not in path.read_text(), path.name
    with pytest.raises(ConfigError, match=r"scene.robot_start .*footprint \(robot.base.footprint_radius = 1.2\)"):
        build_run_spec(compose_config(["robot.base.footprint_radius=1.2"]))


def _settings_classes() -> list[type]:
    from realize.config import Settings

    out, todo = [], list(Settings.__subclasses__())
    while todo:
        cls = todo.pop()
        out.append(cls)
        todo += cls.__subclasses__()
    return out


def _names_code_uses(source: str) -> set[str]:
    """The names a module's code (not its docstrings, other bare strings or comments) uses:
    attributes (``x.key``), string constants (``d["key"]``, ``getattr(x, "key")``) and keyword
    arguments (``f(key=...)``)."""
    import ast

    tree = ast.parse(source)
    prose = {id(node.value) for node in ast.walk(tree)  # a string standing alone as a statement
             if isinstance(node, ast.Expr) and isinstance(node.value, ast.Constant) and isinstance(node.value.value, str)}
    out: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Attribute):
            out.add(node.attr)
        elif isinstance(node, ast.Constant) and isinstance(node.value, str) and id(node) not in prose:
            out.add(node.value)
        elif isinstance(node, ast.keyword) and node.arg:
            out.add(node.arg)
    return out


def _names_interpolated(text: str) -> set[str]:
    """The last names of the keys a YAML file's values interpolate (``${ce.batch_scale}`` ->
    ``batch_scale``, nested in a resolver's arguments too); its comments do not count."""
    import re

    import yaml

    def strings(x: Any) -> Iterator[str]:
        if isinstance(x, dict):
            for v in x.values():
                yield from strings(v)
        elif isinstance(x, list):
            for v in x:
                yield from strings(v)
        elif isinstance(x, str):
            yield x

    return {m.rsplit(".", 1)[-1] for s in strings(yaml.safe_load(text)) for m in re.findall(r"\$\{([\w.]+)\}", s)}


def test_a_name_in_prose_is_not_a_use() -> None:
    """The key-use test below cannot be fooled by a docstring, a field's docstring or a comment,
    in the code or in a config file."""
    src = ('"""batch_scale in a module docstring."""\n'
           'class C:\n    """batch_scale in a class docstring."""\n    x: int = 1\n    """batch_scale below a field."""\n'
           'def f(d):\n    """batch_scale in a function docstring."""\n    # batch_scale in a comment\n'
           '    return d["n_envs"], d.shard_rows, g(pool=1)\n')
    used = _names_code_uses(src)
    assert "batch_scale" not in used and {"n_envs", "shard_rows", "pool"} <= used
    yaml_text = ("# n_envs: ${realize_scaled:200,${ce.batch_scale}} in a comment\n"
                 "ce:\n  n_envs: ${realize_scaled:200,${ce.scale}}  # ${ce.knn_robust}\n  iterations: 3\n")
    assert _names_interpolated(yaml_text) == {"scale"}


def test_every_config_key_is_read_somewhere() -> None:
    """A settings field that no code reads would be a key that changes nothing: each one is used
    by the code of ``realize/`` or ``envs/`` (an attribute, a string key, a keyword argument; a
    docstring or a comment that names it does not count), or by a config's interpolation
    (``${ce.batch_scale}`` in a value of configs/, not in a comment). Unknown keys are refused by the readers themselves."""
    from helpers import REPO

    used: set[str] = set()
    for d in ("realize", "envs"):
        for p in (REPO / d).rglob("*.py"):
            used |= _names_code_uses(p.read_text())
    interpolated = {name for p in (REPO / "configs").rglob("*.yaml") for name in _names_interpolated(p.read_text())}
    unread = []
    for cls in _settings_classes():
        if not cls.__module__.startswith(("realize", "envs")):
            continue  # a test's own settings class
        for f in dataclasses.fields(cls):
            if f.name not in used and f.name not in interpolated:
                unread.append(f"{cls.__name__}.{f.name}")
    assert not unread, f"config keys nothing reads: {unread}"


def test_a_config_without_the_validation_group_gets_the_dataclass_defaults() -> None:
    """One default: a new config that leaves the group out validates as ``ValidationSettings``
    says; a run saved before the group existed (it never validated) reads as ``replicas: 0``."""
    without = {k: v for k, v in DEFAULT.items() if k != "validation"}
    assert build_run_spec(without).validation == ValidationSettings()
    saved = upgrade_config(without)
    assert saved["validation"] == {"replicas": 0} and build_run_spec(saved).validation.replicas == 0
    assert upgrade_config(DEFAULT)["validation"] == DEFAULT["validation"]  # a group it has is kept
