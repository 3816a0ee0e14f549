"""Write configs/controller/default.yaml from the defaults of ``realize.realization.config.RolloutConfig``.

The Hydra ``controller`` group must list every key (Hydra refuses overrides of keys a config
does not have), and its values must be the dataclass defaults. This script keeps the two in
step: it walks the dataclass (and its nested dataclasses ``pid``, ``astar``, ``fabric``, ...)
and writes one YAML line per field, with the field's trailing ``# comment`` from the source.
``tests/test_app.py`` checks that the file and the dataclass agree.

Usage: ``python scripts/sync_controller_config.py [--check]`` (``--check``: exit 1 if stale).
"""

from __future__ import annotations

import argparse
import dataclasses
import inspect
import re
import sys
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parent.parent
TARGET = ROOT / "configs" / "controller" / "default.yaml"
HEADER = """\
# Action tolerances, timeouts and controller settings (realize.realization.config.RolloutConfig).
# Generated from the dataclass defaults by scripts/sync_controller_config.py: edit the
# dataclass, then re-run it (tests/test_app.py checks that the two agree).
"""


def _comments(cls: type) -> dict[str, str]:
    """``field name -> trailing comment`` from the class source (empty where none)."""
    try:
        src = inspect.getsource(cls)
    except (OSError, TypeError):
        return {}
    out: dict[str, str] = {}
    for line in src.splitlines():
        m = re.match(r"\s+([A-Za-z_][A-Za-z0-9_]*)\s*:[^#]*?(?:#\s*(.*))?$", line)
        if m and m.group(2):
            out.setdefault(m.group(1), m.group(2).strip())
    return out


def _scalar(v: Any) -> str:
    if v is None:
        return "null"
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, float):
        return repr(v)
    if isinstance(v, int):
        return str(v)
    if isinstance(v, str):
        return v if re.fullmatch(r"[A-Za-z_][A-Za-z0-9_.\-]*", v) and v not in ("true", "false", "null") else repr(v)
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_scalar(x) for x in v) + "]"
    raise TypeError(f"cannot write {v!r} as YAML")


def _lines(obj: Any, indent: int, cls_comment: str = "") -> list[str]:
    comments = _comments(type(obj))
    out: list[str] = []
    pad = "  " * indent
    for f in dataclasses.fields(obj):
        v = getattr(obj, f.name)
        c = comments.get(f.name, "")
        if dataclasses.is_dataclass(v):
            doc = (inspect.getdoc(type(v)) or "").splitlines()[0] if inspect.getdoc(type(v)) else ""
            out.append(f"{pad}{f.name}:" + (f"  # {c or doc}" if (c or doc) else ""))
            out.extend(_lines(v, indent + 1))
        else:
            out.append(f"{pad}{f.name}: {_scalar(v)}" + (f"  # {c}" if c else ""))
    return out


def render() -> str:
    sys.path.insert(0, str(ROOT))
    from realize.realization.config import RolloutConfig

    return HEADER + "\n".join(_lines(RolloutConfig(), 0)) + "\n"


def main() -> int:
    ap = argparse.ArgumentParser(description=" ".join(__doc__.split("\n\n")[0].split()))
    ap.add_argument("--check", action="store_true", help="exit 1 if the file is out of date")
    args = ap.parse_args()
    text = render()
    if args.check:
        stale = not TARGET.is_file() or TARGET.read_text() != text
        print(f"{TARGET.relative_to(ROOT)} is {'out of date' if stale else 'up to date'}")
        return int(stale)
    TARGET.write_text(text)
    print(f"wrote {TARGET.relative_to(ROOT)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
