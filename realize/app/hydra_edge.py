"""Hydra's side of the config edge: parsing overrides, composing ``configs/``, the config's resolvers.

What it does: ``parse_overrides`` (Hydra ``Override`` objects; one ``ConfigError`` line for one
that does not parse), ``override_values`` (the values an override gives, a sweep's listed ones),
``compose_or_error`` (Hydra's compose of ``configs/config.yaml``; a composition error becomes one
``ConfigError`` line) and ``register_resolvers`` (``${realize_sqlite:DIR,NAME}``, registered on
import). ``realize.app.compose`` and ``realize.app.cli_keys`` build on these; neither imports the other.
What it doesn't: check keys or group choices (``realize.app.cli_keys``, ``realize.app.compose``)
or validate values (``realize.app.run_config``).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from realize.config import ConfigError
from realize.paths import CONFIG_DIR

__all__ = ["parse_overrides", "override_values", "compose_or_error", "register_resolvers"]


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
