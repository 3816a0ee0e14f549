"""The run config from Python: compose ``configs/`` with overrides, every mistake one line.

What it does: ``compose_config(overrides)`` is what the ``realize`` command does with its
arguments before a run, for a notebook or a script: it parses each override (Hydra's syntax),
checks group choices (``experiment=foo`` -> the presets there are), keys (``secne=wall`` ->
"did you mean 'scene'", ``realize.spec.keys``), composes ``configs/config.yaml`` and returns
the resolved plain config (no ``hydra`` node). Every problem is a ``ConfigError`` with one line.
``check_group_choices`` and ``compose_or_error`` are the pieces the command line shares
(``realize.cli.main``); ``apply_overrides(config, overrides)`` puts overrides on a plain config
(a replan's world changes), ``set_key`` one dotted key. ``CONFIG_GROUPS`` are the groups a plain ``group=option`` may choose.
What it doesn't: validate values (``realize.spec.run_spec.build_run_spec`` does) or run.
"""

from __future__ import annotations

import json
from collections.abc import Mapping, Sequence
from typing import Any

from realize.spec.keys import check_override_keys
from realize.spec.hydra_edge import (compose_or_error, override_values, parse_overrides, register_resolvers,
                                    registered_options, resolution_error)
from realize.config import ConfigError, did_you_mean
from realize.paths import CONFIG_DIR

__all__ = ["CONFIG_GROUPS", "compose_config", "apply_overrides", "set_key", "compose_or_error", "check_group_choices", "group_options",
           "parse_overrides", "override_values", "register_resolvers"]

CONFIG_GROUPS = ("task", "scene", "robot", "sim", "controller", "ce", "logging", "workers", "validation",
                 "experiment", "ablation", "levers")


def group_options(group: str) -> list[str]:
    """The options of a config group: its files in ``configs/GROUP/`` and the settings
    dataclasses registered as its options (``realize.spec.hydra_edge.register_schema``)."""
    d = CONFIG_DIR / group
    files = [p.stem for p in d.glob("*.yaml")] if d.is_dir() else []
    return sorted({*files, *registered_options(group)})


def check_group_choices(parsed: Sequence[Any]) -> None:
    """``experiment=foo``, ``scene=nope``: one line listing the options (sweep values included)."""
    for o in parsed:
        key = o.key_or_group
        if o.is_delete() or key not in CONFIG_GROUPS or o.package is not None:
            continue
        values = override_values(o)
        options = group_options(key)
        for v in values:
            if v not in options and v != "null":
                what = "preset" if key == "experiment" else "option"
                raise ConfigError(f"{key}={v}: unknown {key} {what} {v!r}{did_you_mean(v, options)}; available: "
                                  f"{', '.join(options)} (files in configs/{key}/)")


def compose_config(overrides: Sequence[str] = ()) -> dict[str, Any]:
    """The resolved run config of ``overrides`` (plain data, no ``hydra`` node), checked as the
    command line is: ``compose_config(["experiment=seed_paper", "ce.iterations=3"])``."""
    from omegaconf import OmegaConf

    overrides = [str(o) for o in overrides]
    parsed = parse_overrides(overrides)
    if any(o.is_sweep_override() for o in parsed):
        bad = next(o.input_line for o in parsed if o.is_sweep_override())
        raise ConfigError(f"{bad}: a sweep (several values) composes several configs; give one value")
    if not any(o.key_or_group.startswith("hydra.searchpath") for o in parsed):
        check_group_choices(parsed)
        check_override_keys(parsed, CONFIG_GROUPS)
    cfg = compose_or_error(overrides)
    try:
        d = OmegaConf.to_container(cfg, resolve=True, throw_on_missing=True)
    except Exception as e:
        raise resolution_error(e) from None
    assert isinstance(d, dict)
    d.pop("hydra", None)
    return d


def set_key(d: dict[str, Any], dotted: str, value: Any) -> None:
    parts = dotted.split(".")
    node = d
    for p in parts[:-1]:
        nxt = node.get(p)
        if not isinstance(nxt, dict):
            nxt = {}
            node[p] = nxt
        node = nxt
    node[parts[-1]] = value


def apply_overrides(config: Mapping[str, Any], overrides: Sequence[str], where: str = "changes") -> dict[str, Any]:
    """``config`` (plain data) with Hydra-syntax ``key=value`` overrides applied (values parsed
    as the command line parses them: ``scene.tables.1.center=[0.1,-1.5]``); one ``ConfigError``
    line for an override that does not parse or names no key of ``config``."""
    from omegaconf import OmegaConf

    base = OmegaConf.create(json.loads(json.dumps(dict(config), default=str)))
    for o in parse_overrides(overrides):
        key = o.key_or_group
        if o.is_delete() or o.is_sweep_override():
            raise ConfigError(f"{where}: {o.input_line!r}: give one value for a key (no deletions or sweeps)")
        try:
            present = OmegaConf.select(base, key, throw_on_missing=False, default="__missing__") != "__missing__"
        except Exception:
            present = False
        if not present and not (o.is_add() or o.is_force_add()):
            raise ConfigError(f"{where}: {o.input_line!r}: the config has no key {key!r}")
        OmegaConf.update(base, key, o.value(), merge=False, force_add=True)
    out = OmegaConf.to_container(base, resolve=True)
    assert isinstance(out, dict)
    return out
