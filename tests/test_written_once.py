"""Every setting's default is written in one place: its settings dataclass, or the one YAML file
that documents it.

The rule this file checks:

* A settings dataclass (``realize.config.Settings``) is where a default is written. Where the
  class is registered as its group's option (``realize.spec.hydra_edge.register_schema``: ``sim``,
  ``workers``, ``logging``, ``validation``, ``controller``, ``ce``, a task's ``perturbation``) no YAML file says its values
  (``test_a_registered_group_has_no_yaml``).
* The other files Hydra composes a run from by default (``configs/config.yaml`` and the option
  its defaults list picks in each group: ``scene/plain.yaml``, ``robot/fetch_omni.yaml``, ...)
  exist to document every key of their group: they are what ``realize --help`` and
  ``realize --cfg job`` show, and what a command line overrides without ``+``. They may say the
  dataclass's value again, and tests/test_defaults.py fails when they say another (until their
  class is registered as well).
* Every other YAML file writes only what differs from what it is merged over: a preset
  (``configs/experiment/``, ``configs/ablation/``), a group option built on another one
  (``defaults: [plain, _self_]``), a global option in place of its group's default one (the
  ``levers`` options, over the run config without them), a node built on a registered dataclass (a task's
  ``perturbation:`` over ``Perturbation``, ``realize.spec.hydra_edge.register_schema``) and the
  presets read without Hydra (``configs/execute/`` over ``ExecuteSettings``, ``configs/noise/``
  over ``Noise``). A value equal to the one it overrides is the default written a second time:
  taking it out changes no composed config. (A group option that replaces its group's default
  option whole, as ``robot=panda`` or ``scene=plain``'s alternatives without a defaults list, is
  merged over nothing and says every key it has.)
"""

from __future__ import annotations

import dataclasses
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import yaml
from omegaconf import OmegaConf

from helpers import comparable
from realize.spec.hydra_edge import compose_or_error
from realize.execution.perception import Noise
from realize.execution.settings import ExecuteSettings
from realize.paths import CONFIG_DIR

# presets read without Hydra, and the dataclass each is merged over
PRESETS = {"execute": ExecuteSettings, "noise": Noise}
_ABSENT = object()


def _leaves(x: Any, path: str = "") -> Iterator[tuple[str, Any]]:
    if isinstance(x, dict) and x:
        for k, v in x.items():
            yield from _leaves(v, f"{path}.{k}" if path else str(k))
    else:
        yield path, x


def _at(d: Any, path: str) -> Any:
    for part in path.split("."):
        if not isinstance(d, dict) or part not in d:
            return _ABSENT
        d = d[part]
    return d


def _registered(group: str, name: str, option: str) -> dict[str, Any] | None:
    """The values of the structured config ``group/name/option`` (None: not registered)."""
    from hydra.core.config_store import ConfigStore

    try:
        node = ConfigStore.instance().load(f"{group}/{name}/{option}.yaml").node
    except Exception:  # (ConfigLoadError: no such node)
        return None
    out = OmegaConf.to_container(node, resolve=False)
    return {name: out} if isinstance(out, dict) else None


def _bases(path: Path) -> tuple[dict[str, Any], str, list[dict[str, Any]]]:
    """A file of configs/GROUP/: (its values without the defaults list, the package its keys
    are under, the configs it is merged over, composed without it)."""
    group, text = path.parent.name, path.read_text()
    d = yaml.safe_load(text) or {}
    listed = d.pop("defaults", None) or []
    package = "" if "@package _global_" in text else group
    choices = [f"{str(k).removeprefix('override /')}={v}" for e in listed if isinstance(e, dict)
               for k, v in e.items() if str(k).startswith("override /")]
    siblings = [e for e in listed if isinstance(e, str) and e != "_self_"]
    bases: list[dict[str, Any]] = []
    if group in ("experiment", "ablation"):  # merged over the run config of its group choices
        bases.append(OmegaConf.to_container(compose_or_error(choices), resolve=False))
    elif siblings:  # built on another option of its group
        bases.append(OmegaConf.to_container(compose_or_error([f"{group}={siblings[0]}", *choices]), resolve=False))
    elif package == "":  # a global option in place of its group's default (levers): over the run config without it
        bases.append(OmegaConf.to_container(compose_or_error([f"~{group}"]), resolve=False))
    for e in listed:  # a node of a registered dataclass (task/perturbation/default)
        if isinstance(e, dict):
            for k, v in e.items():
                node = None if str(k).startswith("override") else _registered(group, str(k), str(v))
                if node is not None:
                    bases.append({group: node} if package else node)
    return d, package, bases


def _repeats_in_configs(config_dir: Path = CONFIG_DIR) -> list[str]:
    """Every value of ``config_dir``'s files equal to what it is merged over (the bases are
    composed from configs/: a file's own values are not in them)."""
    out = []
    for path in sorted(config_dir.glob("*/*.yaml")):
        group = path.parent.name
        if group in PRESETS:
            cls = PRESETS[group]
            values, package, bases = yaml.safe_load(path.read_text()) or {}, "", [dataclasses.asdict(cls())]
        elif group == "hydra":
            continue
        else:
            values, package, bases = _bases(path)
        for key, v in _leaves(values):
            full = f"{package}.{key}" if package else key
            for base in bases:
                b = _at(base, full)
                if b is not _ABSENT and comparable(b) == comparable(v):
                    out.append(f"{path.relative_to(config_dir)}: {full} = {v!r}")
    return out


def test_no_value_is_written_where_it_is_already_the_default() -> None:
    """The module docstring's rule, over every file of configs/."""
    repeats = _repeats_in_configs()
    assert not repeats, f"values equal to what they override (write only what differs): {repeats}"


def test_a_repeated_value_is_found(tmp_path: Path) -> None:
    """The check finds a repeat of each kind: a preset's value equal to the config it is merged
    over, a task's perturbation key at ``Perturbation``'s default, an execute preset's key at
    ``ExecuteSettings``' default."""
    import shutil

    copy = tmp_path / "configs"
    shutil.copytree(CONFIG_DIR, copy)
    tolerance = compose_or_error([]).controller.move_tolerance
    with (copy / "experiment" / "wall.yaml").open("a") as f:
        f.write(f"controller:\n  move_tolerance: {tolerance}\n")
    task = copy / "task" / "tower3.yaml"
    task.write_text(task.read_text() + "perturbation:\n  object_xy: 0.02\n")
    (copy / "execute" / "again.yaml").write_text(f"worlds: {ExecuteSettings().worlds}\n")
    found = _repeats_in_configs(copy)
    assert sorted(f.split(" =")[0] for f in found) == [
        "execute/again.yaml: worlds", "experiment/wall.yaml: controller.move_tolerance",
        "task/tower3.yaml: task.perturbation.object_xy"], found


def test_a_registered_group_has_no_yaml() -> None:
    """A group whose option is a registered dataclass has no YAML file of that option (Hydra would
    take the file and leave the class's values unread), and the composed group is the class's
    defaults."""
    from realize.spec.compose import compose_config
    from realize.spec.hydra_edge import registered_options
    from realize.spec.run_settings import LoggingSettings, ValidationSettings
    from realize.spec.workers_settings import WorkersSettings
    from realize.scene.settings import SimSettings

    from realize.search.ce.config import CEConfig

    composed = compose_config(["levers=exact"])  # (levers=exact turns ce's two default levers off)
    for group, option, cls in (("sim", "default", SimSettings), ("workers", "default", WorkersSettings),
                               ("logging", "default", LoggingSettings), ("validation", "default", ValidationSettings),
                               ("ce", "seed_paper", CEConfig)):
        assert option in registered_options(group), group
        assert not (CONFIG_DIR / group / f"{option}.yaml").exists(), group
        defaults = {k: v for k, v in dataclasses.asdict(cls()).items() if k != "seed"}  # (ce.seed: the run's seed)
        assert sorted(composed[group]) == sorted(defaults), group
        differ = {k for k, v in composed[group].items() if comparable(v) != comparable(defaults[k])}
        assert differ == ({"prune", "patience"} if group == "ce" else set()), (group, differ)
    assert not (CONFIG_DIR / "task" / "perturbation").exists()
