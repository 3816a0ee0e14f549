"""Hydra's side of the config edge: parsing overrides, composing ``configs/``, the config's resolvers.

What it does: ``parse_overrides`` (Hydra ``Override`` objects; one ``ConfigError`` line for one
that does not parse), ``override_values`` (the values an override gives, a sweep's listed ones),
``compose_or_error`` (Hydra's compose of ``configs/config.yaml``; a composition error becomes one
``ConfigError`` line; see "Composing once per set of group choices" below), ``register_resolvers``
(``${realize_sqlite:DIR,NAME}`` and ``${realize_scaled:N,SCALE}``, registered on import),
``register_schema`` (the settings dataclasses whose defaults Hydra composes from the class
itself, registered on import: ``sim``, ``workers``, ``logging``, ``validation``, ``ce``, ``task/perturbation``;
``registered_options``) and
``resolution_error`` (a resolver's ``ConfigError`` as one line). ``realize.spec.compose`` and
``realize.spec.keys`` build on these; neither imports the other.
What it doesn't: check keys or group choices (``realize.spec.keys``, ``realize.spec.compose``)
or validate values (``realize.spec.run_spec``).

Composing once per set of group choices: a Hydra compose reads and merges the whole defaults
tree, about 0.55 s on 2 Intel cores (22 files, 40 % of it PyYAML parsing them), and a command
line composes several times (key check, trial compose, every job of a sweep check; the fuzzer
and the tests thousands of times) with the same few sets of group choices. So the defaults
tree is composed once per process and set of choices (and ``hydra...`` overrides), and each
compose applies its value overrides to a copy of it with Hydra's own override step, in the
order given, as Hydra's compose applies them after building the tree. The result is the
same config and the same errors (tests/test_compose_cache.py compares both paths). The cache
assumes ``configs/`` does not change while a process runs; a command with a
``hydra.searchpath`` (config dirs of its own) is composed whole every time.
"""

from __future__ import annotations

import copy
import functools
import math
from collections.abc import Sequence
from typing import Any

from realize.config import ConfigError
from realize.paths import CONFIG_DIR

__all__ = ["parse_overrides", "override_values", "compose_or_error", "split_overrides", "register_resolvers",
           "register_schema", "registered_options", "scaled_count", "resolution_error"]


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
    """Hydra's compose of ``configs/config.yaml`` with ``overrides`` (a DictConfig, the caller's
    own copy); a composition error becomes one ``ConfigError`` line. The defaults tree is
    composed once per set of group choices (module docstring)."""
    overrides = [str(o) for o in overrides]
    split = split_overrides(overrides)
    if split is None:
        return _compose_whole(overrides)
    choices, values = split
    cfg = copy.deepcopy(_compose_choices(tuple(choices)))
    if values:
        from hydra._internal.config_loader_impl import ConfigLoaderImpl

        try:
            ConfigLoaderImpl._apply_overrides_to_config(values, cfg)
        except Exception as e:
            raise _one_line(e) from None
    return cfg


def split_overrides(overrides: Sequence[str]) -> tuple[list[str], list[Any]] | None:
    """``(group choices and hydra overrides, value overrides)`` as Hydra's compose tells them
    apart (a group is a directory of ``configs/``, and a dict value always sets a value); None
    where the whole compose must run: a sweep, a ``hydra.searchpath``, an override that does
    not parse (Hydra's own compose then says what is wrong)."""
    try:
        parsed = parse_overrides(overrides)
    except ConfigError:
        return None
    choices, values = [], []
    for o in parsed:
        key = o.key_or_group
        if o.is_sweep_override() or key.startswith("hydra.searchpath"):
            return None
        group = key.startswith("hydra") or ((CONFIG_DIR / key).is_dir() and not isinstance(o.value(), dict))
        if group:
            choices.append(o.input_line)
        else:
            values.append(o)
    return choices, values


@functools.lru_cache(maxsize=64)
def _compose_choices(choices: tuple[str, ...]) -> Any:
    """The composed config of group choices alone (private: callers get a deep copy)."""
    return _compose_whole(list(choices))


def _compose_whole(overrides: list[str], config_name: str = "config") -> Any:
    """Hydra's compose of ``configs/<config_name>.yaml``, every file read (what ``compose_or_error``
    caches for the run config)."""
    from hydra import compose, initialize_config_dir

    try:
        with initialize_config_dir(config_dir=str(CONFIG_DIR), version_base="1.3", job_name="realize"):
            return compose(config_name=config_name, overrides=list(overrides))
    except Exception as e:
        raise _one_line(e) from None


def _one_line(e: Exception) -> ConfigError:
    """A composition error as one ``ConfigError`` line (Hydra's message, without its hints)."""
    lines = [ln.strip() for ln in str(e).splitlines() if ln.strip()]
    if e.__cause__ is not None and str(e.__cause__).strip():
        lines.append(str(e.__cause__).strip().splitlines()[0])
    lines = [ln for ln in lines if "HYDRA_FULL_ERROR" not in ln]
    cut = next((i for i, ln in enumerate(lines) if ln.startswith("Config search path")), len(lines))
    return ConfigError("; ".join(lines[:cut]) or type(e).__name__)


def _sqlite_in(directory: str, name: str) -> str:
    """``${realize_sqlite:DIR,NAME}``: the SQLite URL of ``DIR/NAME``, ``DIR`` made first (an
    Optuna study stored in a sweep directory that Hydra creates only when the first job starts)."""
    from pathlib import Path

    d = Path(str(directory)).resolve()
    d.mkdir(parents=True, exist_ok=True)
    return f"sqlite:///{d / str(name)}"


def scaled_count(n: Any, scale: Any) -> int:
    """``${realize_scaled:N,SCALE}``: the count ``N`` times ``SCALE``, rounded half up, at least 1.

    A preset writes its batch this way (``ce.n_envs: ${realize_scaled:200,${ce.batch_scale}}``) so
    that the levers group's ``ce.batch_scale`` scales the preset's own number; ``levers=exact``
    (scale 1) gives the number itself, and a count given on the command line replaces the
    interpolation, so it is never scaled."""
    try:
        n_, s_ = int(n), float(scale)
    except (TypeError, ValueError):
        raise ConfigError(f"ce.batch_scale = {scale!r} (scaling {n!r}): must be a number > 0") from None
    if not (s_ > 0 and math.isfinite(s_)):
        raise ConfigError(f"ce.batch_scale = {scale!r} is invalid: must be a number > 0 (1: the preset's batch)")
    return max(1, math.floor(n_ * s_ + 0.5))


def resolution_error(e: Exception) -> ConfigError:
    """One ``ConfigError`` line for an error OmegaConf raised while resolving a config: a
    resolver's own ``ConfigError`` as it is (without OmegaConf's frame around it), any other
    error's text on one line."""
    seen: Exception | None = e
    for _ in range(8):  # OmegaConf re-raises the resolver's error as the context of its own
        if seen is None:
            break
        if isinstance(seen, ConfigError):
            return ConfigError(str(seen))
        seen = seen.__cause__ or seen.__context__  # type: ignore[assignment]
    return ConfigError(" ".join(str(e).split()))


def register_resolvers() -> None:
    """The config's own resolvers (``realize_sqlite``, ``realize_scaled``); idempotent."""
    from omegaconf import OmegaConf

    if not OmegaConf.has_resolver("realize_sqlite"):
        OmegaConf.register_new_resolver("realize_sqlite", _sqlite_in)
    if not OmegaConf.has_resolver("realize_scaled"):
        OmegaConf.register_new_resolver("realize_scaled", scaled_count)


def register_schema() -> None:
    """Settings dataclasses as Hydra config groups (idempotent), so that their defaults are written
    in the class only: ``sim/default`` is ``realize.scene.settings.SimSettings``' defaults,
    ``workers/default`` ``realize.spec.workers_settings.WorkersSettings``', ``logging/default`` and
    ``validation/default`` those of ``realize.spec.run_settings``, ``controller/default``
    ``realize.realization.config.RolloutConfig``'s (with its ``pid``, ``astar`` and ``fabric``),
    ``stitch/default`` ``realize.spec.stitch_settings.StitchSettings``', ``replan/default``
    ``realize.spec.run_settings.ReplanSettings``', ``ce/seed_paper``
    ``realize.search.ce.config.CEConfig``'s but its ``seed`` (the run's top-level key; these groups'
    directories hold no YAML for them: a preset or the command line changes a key over them), and
    ``task/perturbation/default`` ``realize.tasks.perturbation.Perturbation``'s (a task file takes
    it in its defaults list, ``- perturbation: default``, and writes the keys it changes under
    ``perturbation:``). Each node is plain data, as a YAML file's would be: the values are checked
    by the class's reader (``build_run_spec``), with its messages. The classes' modules import
    nothing heavy (a refused command line stays quick)."""
    from hydra.core.config_store import ConfigStore

    from realize.spec.run_settings import LoggingSettings, ReplanSettings, ValidationSettings
    from realize.spec.stitch_settings import StitchSettings
    from realize.spec.workers_settings import WorkersSettings
    from realize.realization.config import RolloutConfig
    from realize.scene.settings import SimSettings
    from realize.search.ce.config import CEConfig
    from realize.tasks.perturbation import Perturbation

    store = ConfigStore.instance()
    for group, settings in (("sim", SimSettings()), ("workers", WorkersSettings()), ("logging", LoggingSettings()),
                            ("validation", ValidationSettings()), ("task/perturbation", Perturbation()),
                            ("controller", RolloutConfig()), ("stitch", StitchSettings()),
                            ("replan", ReplanSettings())):
        store.store(group=group, name="default", node=_plain_data(settings))
    ce = _plain_data(CEConfig())
    del ce["seed"]  # (the run's top-level seed)
    store.store(group="ce", name="seed_paper", node=ce)


def registered_options(group: str) -> list[str]:
    """The options of ``group`` that ``register_schema`` registered (``["default"]`` or none)."""
    from hydra.core.config_store import ConfigStore

    try:
        names = ConfigStore.instance().list(group)
    except OSError:  # (no such group in the store)
        return []
    return sorted(n.removesuffix(".yaml") for n in names if n.endswith(".yaml"))


def _plain_data(settings: Any) -> dict[str, Any]:
    """A settings dataclass's values as YAML would give them (tuples as lists)."""
    import dataclasses

    def plain(v: Any) -> Any:
        if isinstance(v, dict):
            return {k: plain(x) for k, x in v.items()}
        return [plain(x) for x in v] if isinstance(v, (list, tuple)) else v

    return plain(dataclasses.asdict(settings))


register_resolvers()
register_schema()
