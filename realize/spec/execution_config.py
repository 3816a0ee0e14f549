"""An execution study's config: Hydra composes ``configs/execution.yaml``, a disturbance family
of ``configs/execute/`` and an observation model of ``configs/noise/`` over ``ExecuteSettings``.

What it does: ``compose_execution(overrides, preset_file=None, noise_file=None)`` composes
``execute_defaults`` (``realize.execution.settings.ExecuteSettings``' own defaults, registered
here on first use, so that no YAML repeats them), the ``execute`` group's option (``execute=
table_moved``; default ``none``), the ``noise`` group's at ``execute.noise`` (``noise=realistic``;
default ``none``), then the value overrides (``execute.worlds=8``,
``execute.budget.iterations=4``), in that order; a YAML file given as ``preset_file`` (a family
of one's own, the keys of a preset) or ``noise_file`` is merged over the group's option before
the value overrides. Returns the checked ``ExecuteSettings``. Unknown groups' options, unknown
keys, a sweep and bad values are one-line ``ConfigError``\\ s.
What it doesn't: run an execution (``realize.repair.study.execute``), or read the run config
(``realize.spec.compose``).
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

from realize.config import ConfigError, did_you_mean
from realize.paths import CONFIG_DIR
from realize.spec.hydra_edge import (_compose_whole, _one_line, _plain_data, parse_overrides, resolution_error,
                                     split_overrides)

if TYPE_CHECKING:
    from realize.execution.settings import ExecuteSettings

__all__ = ["EXECUTION_GROUPS", "compose_execution"]

EXECUTION_CONFIG = "execution"  # configs/execution.yaml
EXECUTION_GROUPS = ("execute", "noise")  # their options: the files of configs/execute/, configs/noise/


def _register() -> None:
    """``execute_defaults``: ExecuteSettings' defaults at package ``execute`` (idempotent)."""
    from hydra.core.config_store import ConfigStore

    from realize.execution.settings import ExecuteSettings

    store = ConfigStore.instance()
    if "execute_defaults.yaml" not in store.list(""):
        store.store(name="execute_defaults", node=_plain_data(ExecuteSettings()), package="execute")


def _check_choices(parsed: Sequence[Any]) -> None:
    for o in parsed:
        if o.is_sweep_override():
            raise ConfigError(f"{o.input_line}: a sweep (several values) composes several configs; give one value")
        key = o.key_or_group
        if key in EXECUTION_GROUPS and not o.is_delete():
            v = o.get_value_element_as_str()
            options = sorted(p.stem for p in (CONFIG_DIR / key).glob("*.yaml"))
            if v not in options:
                raise ConfigError(f"{key}={v}: unknown {key} preset {v!r}{did_you_mean(v, options)}; available: "
                                  f"{', '.join(options)} (files in configs/{key}/)")
        elif not key.startswith(("execute.", "hydra")):
            raise ConfigError(f"{o.input_line}: an execution's config has the groups {', '.join(EXECUTION_GROUPS)} "
                              f"and the keys execute.* (realize.execution.settings.ExecuteSettings)")


def _merge_file(cfg: Any, node: str, path: str | Path, what: str) -> None:
    from omegaconf import OmegaConf

    from realize.config import read_preset

    d, _ = read_preset(path, CONFIG_DIR / what, f"{what} preset")
    if d is None:
        return
    if not isinstance(d, dict):
        raise ConfigError(f"{Path(path).name}: must be a mapping of {node}'s keys")
    try:
        OmegaConf.update(cfg, node, d, merge=True)
    except Exception as e:
        raise ConfigError(f"{Path(path).name}: {' '.join(str(e).split())}") from None


def compose_execution(overrides: Sequence[str] = (), preset_file: str | Path | None = None,
                      noise_file: str | Path | None = None) -> ExecuteSettings:
    """The checked ``ExecuteSettings`` of ``overrides`` (module docstring):
    ``compose_execution(["execute=table_moved", "noise=realistic", "execute.worlds=8"])``."""
    from omegaconf import OmegaConf

    from realize.execution.settings import ExecuteSettings

    _register()
    parsed = parse_overrides([str(o) for o in overrides])
    _check_choices(parsed)
    # the noise group sits at execute.noise (its package in the defaults list): noise=X selects it there
    overrides = [f"noise@execute.noise={o.get_value_element_as_str()}" if o.key_or_group == "noise" else o.input_line
                 for o in parsed]
    split = split_overrides(overrides)
    assert split is not None  # (parsed, no sweep, no searchpath)
    choices, values = split
    cfg = _compose_whole(choices, EXECUTION_CONFIG)
    OmegaConf.set_struct(cfg, False)
    if preset_file is not None:
        _merge_file(cfg, "execute", preset_file, "execute")
    if noise_file is not None:
        _merge_file(cfg, "execute.noise", noise_file, "noise")
    OmegaConf.set_struct(cfg, True)
    if values:
        from hydra._internal.config_loader_impl import ConfigLoaderImpl

        try:
            ConfigLoaderImpl._apply_overrides_to_config(values, cfg)
        except Exception as e:
            raise _one_line(e) from None
    try:
        d = OmegaConf.to_container(cfg, resolve=True, throw_on_missing=True)
    except Exception as e:
        raise resolution_error(e) from None
    assert isinstance(d, dict)
    return ExecuteSettings.from_mapping(d.get("execute"), "execute")
