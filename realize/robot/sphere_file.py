"""Collision-sphere files: ``SphereSpec`` and reading ``realize/robot/spheres/<robot>.yaml``.

What it does: ``SphereSpec`` is one sphere rigidly attached to a link (centre offset in the link
frame, radius, whether it is kept above the floor); ``load_spheres(name_or_path)`` reads a sphere
file (``robot:`` and a ``spheres:`` list of ``{name, link, offset, radius, check_floor}``),
``links_without_spheres`` its optional list of collision links left to their neighbours' spheres
(a wheel inside the base's sphere; the robot checks hold every other link to its own spheres),
and ``write_spheres`` writes one. Bad entries are refused in one line naming the file and entry.
What it doesn't: fit spheres to meshes (``realize.robot.sphere_fit``) or place them by forward
kinematics (``realize.robot.kinematics``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Sequence

import yaml

from realize.config import ConfigError
from realize.paths import REPO_ROOT

__all__ = ["SphereSpec", "SPHERE_DIR", "sphere_file_path", "load_spheres", "links_without_spheres", "write_spheres"]

SPHERE_DIR = Path(__file__).resolve().parent / "spheres"


@dataclass(frozen=True)
class SphereSpec:
    """A collision sphere rigidly attached to a link.

    ``check_floor`` is False for spheres that touch the floor by design (a base, a lift column);
    the fabric leaves those out of floor avoidance."""

    name: str
    link: str
    offset: tuple[float, float, float]
    radius: float
    check_floor: bool = True


def sphere_file_path(name_or_path: str) -> Path:
    """``realize/robot/spheres/<name>.yaml`` for a bare name, else the path (relative: to the repo)."""
    if "/" not in name_or_path and not name_or_path.endswith((".yaml", ".yml")):
        return SPHERE_DIR / f"{name_or_path}.yaml"
    p = Path(name_or_path)
    return p if p.is_absolute() else REPO_ROOT / p


def _read(name_or_path: str) -> tuple[Path, dict]:
    path = sphere_file_path(name_or_path)
    if not path.is_file():
        known = sorted(p.stem for p in SPHERE_DIR.glob("*.yaml"))
        raise ConfigError(f"robot.spheres_file = {name_or_path!r}: no file {path.name} (known: {known})")
    with open(path) as f:
        data = yaml.safe_load(f) or {}
    return path, data


def links_without_spheres(name_or_path: str) -> tuple[str, ...]:
    """The file's ``links_without_spheres`` (collision links its spheres leave to a neighbour's)."""
    path, data = _read(name_or_path)
    names = data.get("links_without_spheres", []) if isinstance(data, dict) else []
    if not isinstance(names, list) or not all(isinstance(n, str) for n in names):
        raise ConfigError(f"{path.name}: links_without_spheres = {names!r} is invalid: a list of link names")
    return tuple(names)


def load_spheres(name_or_path: str) -> tuple[SphereSpec, ...]:
    """The spheres of a sphere file (see the module docstring)."""
    path, data = _read(name_or_path)
    entries = data.get("spheres") if isinstance(data, dict) else None
    if not isinstance(entries, list) or not entries:
        raise ConfigError(f"{path.name}: needs a non-empty 'spheres:' list")
    out = []
    for i, e in enumerate(entries):
        where = f"{path.name}: spheres[{i}]"
        if not isinstance(e, dict) or set(e) - {"name", "link", "offset", "radius", "check_floor"}:
            raise ConfigError(f"{where} = {e!r} is invalid: keys are name, link, offset, radius, check_floor")
        try:
            off = tuple(float(v) for v in e["offset"])
            radius = float(e["radius"])
            s = SphereSpec(str(e["name"]), str(e["link"]), off, radius, bool(e.get("check_floor", True)))
        except (KeyError, TypeError, ValueError) as err:
            raise ConfigError(f"{where} = {e!r} is invalid: {err}") from None
        if len(off) != 3 or not all(math.isfinite(v) for v in off) or not (radius > 0 and math.isfinite(radius)):
            raise ConfigError(f"{where} = {e!r} is invalid: offset needs 3 finite numbers and radius > 0")
        out.append(s)
    names = [s.name for s in out]
    dup = sorted({n for n in names if names.count(n) > 1})
    if dup:
        raise ConfigError(f"{path.name}: sphere names {dup} appear more than once")
    return tuple(out)


def write_spheres(path: Path, robot: str, spheres: Sequence[SphereSpec], header: Sequence[str] = (),
                  without_spheres: Sequence[str] = ()) -> None:
    """Write a sphere file that ``load_spheres`` (and ``links_without_spheres``) read back to the same numbers."""
    lines = [f"# {h}" for h in header] + [f"robot: {robot}"]
    if without_spheres:
        lines.append(f"links_without_spheres: [{', '.join(without_spheres)}]")
    lines.append("spheres:")
    for s in spheres:
        off = ", ".join(repr(float(v)) for v in s.offset)
        lines.append(f"  - {{name: {s.name}, link: {s.link}, offset: [{off}], radius: {float(s.radius)!r}, "
                     f"check_floor: {str(bool(s.check_floor)).lower()}}}")
    Path(path).write_text("\n".join(lines) + "\n")
