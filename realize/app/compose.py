"""The run config from Python: compose ``configs/`` with overrides, every mistake one line.

What it does: ``compose_config(overrides)`` is what the ``realize`` command does with its
arguments before a run, for a notebook or a script: it parses each override (Hydra's syntax),
checks group choices (``experiment=foo`` -> the presets there are), keys (``secne=wall`` ->
"did you mean 'scene'", ``realize.app.cli_keys``), composes ``configs/config.yaml`` and returns
the resolved plain config (no ``hydra`` node). Every problem is a ``ConfigError`` with one line.
``check_group_choices`` and ``compose_or_error`` are the pieces the command line shares
(``realize.app.cli``); ``apply_overrides(config, overrides)`` puts overrides on a plain config
(a replan's world changes), ``set_key`` one dotted key. ``CONFIG_GROUPS`` are the groups a plain ``group=option`` may choose.
What it doesn't: validate values (``realize.app.run_config.build_run_spec`` does) or run.
"""

from __future__ import annotations

import json
from collections.abc import Mapping, Sequence
from typing import Any

from realize.app.cli_keys import check_override_keys
from realize.config import ConfigError, did_you_mean
from realize.paths import CONFIG_DIR

__all__ = ["CONFIG_GROUPS", "compose_config", "apply_overrides", "set_key", "compose_or_error", "check_group_choices", "group_options",
           "parse_overrides", "override_values", "register_resolvers"]

CONFIG_GROUPS = ("task", "scene", "robot", "sim", "controller", "ce", "logging", "workers", "validation",
                 "experiment", "ablation", "levers")


def _sqlite_in(directory: str, name: str) -> str:
    """``${realize_sqlite:DIR,NAME}``: the SQLite URL of ``DIR/NAME``, ``DIR`` made first (an
    Optuna study stored in a sweep directory that Hydra creates only when the first job starts)."""
    from pathlib import Path

    d = Path(str(directory)).resolve()
    d.mkdir(parents=True, exist_ok=True)
    return f"sqlite:///{d / str(name)}"


def register_resolvers() -> None:
    """The config's own resolvers (``realize_sqlite``); idempotent."""
    from omegaconf import OmegaConf

    if not OmegaConf.has_resolver("realize_sqlite"):
        OmegaConf.register_new_resolver("realize_sqlite", _sqlite_in)


register_resolvers()


def group_options(group: str) -> list[str]:
    """The options of a config group (its files in ``configs/GROUP/``)."""
    d = CONFIG_DIR / group
    return sorted(p.stem for p in d.glob("*.yaml")) if d.is_dir() else []


def parse_overrides(overrides: Sequence[str]) -> list[Any]:
    """Hydra ``Override`` objects, one ``ConfigError`` line for one that does not parse."""
    from hydra.core.override_parser.overrides_parser import OverridesParser

    parser, parsed = OverridesParser.create(), []
    for a in overrides:
        try:
            parsed.extend(parser.parse_overrides([str(a)]))
        except Exception as e:
            msg = " ".join(str(e).split()).split(" See https://")[0]
            raise ConfigError(f"cannot parse the override {a!r}: {msg}") from None
    return parsed


def override_values(o: Any) -> list[str]:
    """The values an override gives: one, a sweep's listed ones (``a,b``, ``range(3)``,
    ``choice(a,b)``), or none for a range it cannot list (``interval(0.5, 1.0)``: an Optuna
    sweeper's; each trial's value is checked when it starts)."""
    if not o.is_sweep_override():
        return [o.get_value_element_as_str()]
    if o.is_interval_sweep():
        return []
    return list(o.sweep_string_iterator())


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


def compose_or_error(overrides: Sequence[str]) -> Any:
    """Hydra's compose of ``configs/config.yaml`` with ``overrides`` (a DictConfig); a
    composition error becomes one ``ConfigError`` line."""
    from hydra import compose, initialize_config_dir

    try:
        with initialize_config_dir(config_dir=str(CONFIG_DIR), version_base="1.3", job_name="realize"):
            return compose(config_name="config", overrides=list(overrides))
    except Exception as e:
        lines = [ln.strip() for ln in str(e).splitlines() if ln.strip()]
        if e.__cause__ is not None and str(e.__cause__).strip():
            lines.append(str(e.__cause__).strip().splitlines()[0])
        lines = [ln for ln in lines if "HYDRA_FULL_ERROR" not in ln]
        cut = next((i for i, ln in enumerate(lines) if ln.startswith("Config search path")), len(lines))
        raise ConfigError("; ".join(lines[:cut]) or type(e).__name__) from None


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
        raise ConfigError(" ".join(str(e).split())) from None
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
