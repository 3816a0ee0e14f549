"""The one JSON encoding of a run directory, and atomic file writes.

What it does:
  * the encoding: in memory, float fields hold real floats, ``inf`` and ``nan`` included; in
    JSON a non-finite float is ``null`` (strict JSON, readable by any tool). ``encode_float`` /
    ``json_safe`` write it, ``decode_float(v, missing)`` reads it back: each field says what
    ``null`` means for it (``inf`` for "no feasible cost yet", ``nan`` for "no value"). The
    strings ``"inf"``/``"-inf"``/``"nan"`` that run directories written before this module hold
    (checkpoint records) are read too;
  * ``atomic_write_text`` / ``atomic_write_json`` / ``atomic_write_npz`` write to a temporary
    file in the target's directory and ``os.replace`` it over the target, so a reader (or a run
    killed mid-write) only ever sees the old or the new complete file; ``read_json`` reads a
    JSON object or gives ``None``.
What it doesn't: know which files a run directory holds (``realize.run_dir.names``) or their
schema (``realize.run_dir.summaries``, ``realize.run_dir.result_doc``); it never unpickles.
"""

from __future__ import annotations

import json
import math
import os
import tempfile
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import IO, Any

import numpy as np

__all__ = [
    "encode_float",
    "decode_float",
    "encode_floats",
    "decode_floats",
    "json_safe",
    "atomic_write_text",
    "atomic_write_json",
    "atomic_write_npz",
    "read_json",
]


def encode_float(x: float | None) -> float | None:
    """A float as JSON: itself if finite, else ``null``."""
    if x is None:
        return None
    x = float(x)
    return x if math.isfinite(x) else None


def decode_float(v: Any, missing: float = math.nan) -> float:
    """A JSON value back to a float: ``null`` -> ``missing``; numbers and (older files) the
    strings ``"inf"``, ``"-inf"``, ``"nan"`` -> their float. Anything else is a ``ValueError``."""
    if v is None:
        return missing
    if isinstance(v, bool):
        raise ValueError(f"expected a number, got {v!r}")
    if isinstance(v, (int, float, str)):
        return float(v)
    raise ValueError(f"expected a number, got {v!r}")


def encode_floats(v: Any) -> Any:
    """Nested lists of floats (or ``None``) as JSON: non-finite entries become ``null``."""
    if v is None:
        return None
    if isinstance(v, (list, tuple)):
        return [encode_floats(x) for x in v]
    return encode_float(v)


def decode_floats(v: Any) -> Any:
    """Inverse of ``encode_floats``: ``null`` entries become ``nan`` (``None`` stays ``None``)."""
    if v is None:
        return None
    if isinstance(v, (list, tuple)):
        return [math.nan if x is None else decode_floats(x) for x in v]
    return decode_float(v)


def json_safe(x: Any) -> Any:
    """Plain JSON value for ``x``: tensors/arrays become lists, non-finite floats ``null``,
    paths strings, mappings dicts with string keys."""
    if x is None or isinstance(x, (bool, str)):
        return x
    if isinstance(x, float):
        return encode_float(x)
    if isinstance(x, int):
        return x
    if isinstance(x, Path):
        return str(x)
    if isinstance(x, Mapping):
        return {str(k): json_safe(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [json_safe(v) for v in x]
    if hasattr(x, "detach"):  # torch tensor, without importing torch here
        x = x.detach().cpu().numpy()
    if isinstance(x, np.ndarray):
        return json_safe(x.tolist())
    if isinstance(x, np.generic):
        return json_safe(x.item())
    return str(x)


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def _atomic(path: Path, write: Callable[[IO[Any]], Any], mode: str) -> None:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        os.chmod(tmp, 0o666 & ~_umask())  # mkstemp makes 0600; results are ordinary files
        with os.fdopen(fd, mode) as f:
            write(f)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        try:
            os.unlink(tmp)
        except OSError:
            pass
        raise


def atomic_write_text(path: Path, text: str) -> None:
    """Write ``text`` to ``path`` atomically."""
    _atomic(path, lambda f: f.write(text), "w")


def atomic_write_json(path: Path, obj: Any, indent: int | None = 2) -> None:
    """Write ``json_safe(obj)`` to ``path`` atomically (strict JSON: no NaN/Infinity)."""
    text = json.dumps(json_safe(obj), indent=indent, allow_nan=False)
    atomic_write_text(path, text + "\n")


def atomic_write_npz(path: Path, arrays: Mapping[str, np.ndarray]) -> None:
    """``np.savez_compressed`` to ``path`` atomically; object arrays are refused."""
    for k, a in arrays.items():
        if np.asarray(a).dtype == object:
            raise TypeError(f"array {k!r} has dtype object; only numeric/str arrays are stored")
    _atomic(path, lambda f: np.savez_compressed(f, **arrays), "wb")


def read_json(path: Path) -> dict[str, Any] | None:
    """The JSON object in ``path``, or ``None`` if it is missing, unreadable or not an object."""
    try:
        d = json.loads(Path(path).read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError):
        return None
    return d if isinstance(d, dict) else None
