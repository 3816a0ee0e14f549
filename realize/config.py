"""One way to read config mappings into dataclasses: field metadata, one error type.

What it does:
  * ``ConfigError``: the one error for bad configuration anywhere in realize (a config group, a
    task file, a region, a scene); its message is one line naming the key, the value and what
    is allowed. It is a ``ValueError``.
  * ``setting(default, ge=, gt=, le=, lt=, choices=, check=, help=)``: a dataclass field with
    the bounds / choices the reader enforces (``check(value) -> str | None`` for anything else:
    return what is wrong, or None).
  * ``Settings``: base of config dataclasses. ``Cls.from_mapping(d, where)`` reads a mapping
    (unknown keys refused, types checked and converted: bool, int (an integral float is
    accepted), float (finite), str (non-empty), ``X | None``, ``tuple[float, ...]``, nested
    ``Settings``, ``dict[str, X]`` of named entries), then the field metadata, then the class's own cross-field ``check(where)``.
    Constructing a ``Settings`` directly validates the same way (``__post_init__``), with
    ``where`` = the class's ``config_key``.
What it doesn't: know Hydra (``realize.cli.main`` turns Hydra's objects into plain data first), or
know any particular config group: those live beside the code they configure.
"""

from __future__ import annotations

import contextvars
import dataclasses
import difflib
import math
import types
import typing
from collections.abc import Callable, Mapping, Sequence
from typing import Any, ClassVar

__all__ = ["ConfigError", "Settings", "setting", "read_mapping", "check_unknown", "as_mapping", "closest", "did_you_mean",
           "read_preset"]

_WHERE: contextvars.ContextVar[str | None] = contextvars.ContextVar("realize_config_where", default=None)


class ConfigError(ValueError):
    """Invalid configuration; the message is one line naming the key (or file), the value and what is allowed."""


def setting(
    default: Any = dataclasses.MISSING,
    *,
    default_factory: Callable[[], Any] | Any = dataclasses.MISSING,
    ge: float | None = None,
    gt: float | None = None,
    le: float | None = None,
    lt: float | None = None,
    choices: Sequence[Any] | None = None,
    check: Callable[[Any], str | None] | None = None,
    help: str = "",
) -> Any:
    """A dataclass field whose value the reader checks (bounds and choices skip ``None``)."""
    meta = {"ge": ge, "gt": gt, "le": le, "lt": lt, "choices": tuple(choices) if choices is not None else None,
            "check": check, "help": help}
    if default_factory is not dataclasses.MISSING:
        return dataclasses.field(default_factory=default_factory, metadata=meta)
    return dataclasses.field(default=default, metadata=meta)


def as_mapping(value: Any, where: str) -> dict[str, Any]:
    """``value`` as a dict (None -> {}); anything else than a mapping is a ``ConfigError``."""
    if value is None:
        return {}
    if not isinstance(value, Mapping):
        raise ConfigError(f"{where} = {value!r} is invalid: must be a mapping")
    return dict(value)


def closest(name: str, known: Sequence[str], n: int = 3) -> list[str]:
    """The up to ``n`` names of ``known`` closest to ``name`` (case-insensitive), best first."""
    lower = {str(k).lower(): str(k) for k in known}
    return [lower[m] for m in difflib.get_close_matches(name.lower(), list(lower), n=n, cutoff=0.6)]


def did_you_mean(names: str | Sequence[str], known: Sequence[str]) -> str:
    """`` (did you mean 'goal'?)`` for the known names closest to ``names`` (one, or several
    misspelled ones: ``'goals' -> 'goal'``); ``""`` when none is close. Appended to the
    one-line errors that refuse an unknown name."""
    if isinstance(names, str):
        near = closest(names, known, 2)
        return f" (did you mean {' or '.join(repr(c) for c in near)}?)" if near else ""
    pairs = [f"{b!r} -> " + " or ".join(repr(c) for c in cs) for b in names if (cs := closest(str(b), known, 2))]
    return f" (did you mean: {', '.join(pairs)}?)" if pairs else ""


def check_unknown(d: Mapping[str, Any], allowed: Sequence[str], where: str, what: str = "key(s)") -> None:
    """Refuse keys of ``d`` that are not in ``allowed`` (with the closest allowed names)."""
    bad = sorted(str(k) for k in d if k not in allowed)
    if bad:
        raise ConfigError(f"{where}: unknown {what} {bad}; allowed: {sorted(allowed)}{did_you_mean(bad, allowed)}")


def _key(where: str, name: str) -> str:
    return f"{where}.{name}" if where else name


def _convert(value: Any, hint: Any, key: str) -> Any:
    """Check ``value`` against a type annotation and convert it where that is lossless."""
    origin = typing.get_origin(hint)
    if origin in (typing.Union, types.UnionType):
        args = typing.get_args(hint)
        if value is None and type(None) in args:
            return None
        rest = [a for a in args if a is not type(None)]
        if len(rest) == 1:
            return _convert(value, rest[0], key)
        return value
    if hint is Any:
        return value
    if isinstance(hint, type) and issubclass(hint, Settings):
        return hint.from_mapping(value, key)
    if hint is bool:
        if not isinstance(value, bool):
            raise ConfigError(f"{key} = {value!r} is invalid: must be true or false")
        return value
    if hint is int:
        if isinstance(value, float) and value.is_integer():
            value = int(value)
        if isinstance(value, bool) or not isinstance(value, int):
            raise ConfigError(f"{key} = {value!r} is invalid: must be an integer")
        return value
    if hint is float:
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
            raise ConfigError(f"{key} = {value!r} is invalid: must be a finite number")
        return float(value)
    if hint is str:
        if not isinstance(value, str) or not value:
            raise ConfigError(f"{key} = {value!r} is invalid: must be a non-empty string")
        return value
    if origin is dict:
        args = typing.get_args(hint)
        item = args[1] if len(args) == 2 else Any
        if not isinstance(value, Mapping):
            raise ConfigError(f"{key} = {value!r} is invalid: must be a mapping of name -> entry")
        out = {}
        for name, v in value.items():
            if not isinstance(name, str) or not name:
                raise ConfigError(f"{key} has a key {name!r} that is not a name")
            out[name] = _convert(v, item, f"{key}.{name}")
        return out
    if origin in (tuple, list):
        args = typing.get_args(hint)
        if isinstance(value, (str, bytes)) or not isinstance(value, Sequence):
            raise ConfigError(f"{key} = {value!r} is invalid: must be a list")
        if origin is tuple and args and args[-1] is not Ellipsis:
            if len(value) != len(args):
                raise ConfigError(f"{key} = {list(value)!r} is invalid: must be a list of {len(args)} values")
            items = [_convert(v, a, f"{key}[{i}]") for i, (v, a) in enumerate(zip(value, args))]
        else:
            item = args[0] if args else Any
            items = [_convert(v, item, f"{key}[{i}]") for i, v in enumerate(value)]
        return tuple(items) if origin is tuple else items
    return value


def _check_field(f: dataclasses.Field, value: Any, key: str) -> None:
    m = f.metadata
    if value is None or not m:
        return
    if m.get("choices") is not None and value not in m["choices"]:
        raise ConfigError(f"{key} = {value!r} is invalid: allowed {list(m['choices'])}")
    for name, op, ok in (("ge", ">=", lambda v, b: v >= b), ("gt", ">", lambda v, b: v > b),
                         ("le", "<=", lambda v, b: v <= b), ("lt", "<", lambda v, b: v < b)):
        bound = m.get(name)
        if bound is not None and not ok(value, bound):
            raise ConfigError(f"{key} = {value!r} is invalid: must be {op} {bound}")
    if m.get("check") is not None:
        problem = m["check"](value)
        if problem:
            raise ConfigError(f"{key} = {value!r} is invalid: {problem}")


def read_mapping(cls: type, d: Any, where: str) -> Any:
    """``cls`` (a dataclass) from the mapping ``d``; unknown keys, wrong types and bounds refused."""
    d = as_mapping(d, where)
    flds = [f for f in dataclasses.fields(cls) if f.init]
    check_unknown(d, [f.name for f in flds], where)
    hints = typing.get_type_hints(cls)
    kwargs = {}
    for f in flds:
        if f.name in d:
            key = _key(where, f.name)
            kwargs[f.name] = _convert(d[f.name], hints.get(f.name, Any), key)
            _check_field(f, kwargs[f.name], key)
    token = _WHERE.set(where)
    try:
        return cls(**kwargs)
    finally:
        _WHERE.reset(token)


@dataclasses.dataclass
class Settings:
    """Base of realize's config dataclasses (see the module docstring)."""

    config_key: ClassVar[str] = ""  # where the group lives in the run config, e.g. "ce"

    def __post_init__(self) -> None:
        where = _WHERE.get()
        if where is None:
            where = self.config_key
        _WHERE.set(None)  # nested Settings built below read their own config_key
        hints = typing.get_type_hints(type(self))
        for f in dataclasses.fields(self):
            value = getattr(self, f.name)
            hint = hints.get(f.name, Any)
            if value is not None and not _is_settings(hint):
                value = _convert(value, hint, _key(where, f.name))
            _check_field(f, value, _key(where, f.name))
        self.check(where)

    def check(self, where: str) -> None:
        """Cross-field checks; raise ``ConfigError`` naming ``<where>.<key>``. Override."""

    @classmethod
    def from_mapping(cls, d: Any, where: str | None = None) -> Any:
        """Read ``d`` (None: all defaults) at config path ``where`` (default ``config_key``)."""
        return read_mapping(cls, d, cls.config_key if where is None else where)

    def to_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)


def _is_settings(hint: Any) -> bool:
    if isinstance(hint, type):
        return issubclass(hint, Settings)
    return any(isinstance(a, type) and issubclass(a, Settings) for a in typing.get_args(hint))


def read_preset(name: Any, directory: Any, what: str) -> tuple[Any, str]:
    """The YAML of preset ``name`` of ``directory`` (``<directory>/<name>.yaml``), or of the YAML
    file ``name``, and its stem; an unknown preset (the known ones listed), a missing file or bad
    YAML is one ``ConfigError`` (``what`` names the kind: "execute preset", "noise preset")."""
    from pathlib import Path

    import yaml

    path = Path(name)
    if path.suffix not in (".yaml", ".yml"):
        path = Path(directory) / f"{name}.yaml"
        if not path.is_file():
            known = sorted(p.stem for p in Path(directory).glob("*.yaml"))
            raise ConfigError(f"{what} {str(name)!r} is unknown; presets: {known}")
    elif not path.is_file():
        raise ConfigError(f"{what} file {str(path)!r} does not exist")
    try:
        return yaml.safe_load(path.read_text()), path.stem
    except yaml.YAMLError as e:
        raise ConfigError(f"{path.name}: not YAML ({str(e).splitlines()[0]})") from None
