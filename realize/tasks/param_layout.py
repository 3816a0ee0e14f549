"""Named parameter regions as column slices of one sample matrix, and reading regions from config.

What it does
------------
* :func:`region_from_dict` builds a region (``realize.tasks.regions``, ``realize.tasks.hemisphere``) from a
  config mapping such as ``{type: annulus, center: [x, y], r_min: 0.6, r_max: 1.0}``: the
  ``type`` key picks the class (:data:`REGION_TYPES`), the other keys are that class's
  ``Settings`` fields; every error is a ``realize.config.ConfigError`` naming ``<where>`` and the
  key (unknown type, missing or unknown key, bad value).
* :class:`ParamLayout` lays named regions side by side as column slices of ``Z (N, D)``
  (sampling, projection, containment, split / join, bounds); ``ParamLayout.from_dict`` reads
  ``{name: region mapping}``.

What it doesn't: define region geometry (the region classes do), or know about plans, the
cross-entropy search or simulation.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import MISSING, fields
from typing import Any

import torch
from torch import Tensor

from realize.config import ConfigError, did_you_mean
from realize.tasks.hemisphere import Hemisphere
from realize.tasks.regions import DEFAULT_TOL, Annulus, Box, Fixed, Region, check_batch

__all__ = ["ParamLayout", "region_from_dict", "REGION_TYPES"]

REGION_TYPES: dict[str, type[Region]] = {cls.type_name: cls for cls in (Annulus, Hemisphere, Box, Fixed)}


def region_from_dict(d: Mapping[str, Any], where: str = "region") -> Region:
    """Build a region from a config mapping such as
    ``{type: annulus, center: [x, y], r_min: 0.6, r_max: 1.0}``.

    Every error is a ``ConfigError`` starting with ``"<where>"`` and naming the offending key
    (unknown type, missing or unknown key, bad value).
    """
    if not isinstance(d, Mapping):
        raise ConfigError(f"{where}: a region must be a mapping with a 'type' key, got {d!r}")
    allowed = ", ".join(sorted(REGION_TYPES))
    if "type" not in d:
        raise ConfigError(f"{where}: missing key 'type' (one of: {allowed})")
    kind = str(d["type"]).lower()
    if kind not in REGION_TYPES:
        raise ConfigError(f"{where}: unknown region type {d['type']!r} in key 'type' (allowed: {allowed})"
                          f"{did_you_mean(kind, sorted(REGION_TYPES))}")
    cls = REGION_TYPES[kind]
    rest = {str(k): v for k, v in d.items() if k != "type"}
    required = [f.name for f in fields(cls) if f.init and f.default is MISSING and f.default_factory is MISSING]
    missing = [k for k in required if k not in rest]
    if missing:
        raise ConfigError(f"{where}: {kind} region is missing key(s) {missing} (needs {required})")
    return cls.from_mapping(rest, where)


class ParamLayout:
    """Named parameters (ordered name -> region) laid out as column slices of ``Z (N, D)``.

    Column order follows the insertion order of the mapping; each parameter owns the
    contiguous slice ``slices[name]``.
    """

    def __init__(self, regions: Mapping[str, Region]) -> None:
        if not isinstance(regions, Mapping) or len(regions) == 0:
            raise ConfigError("ParamLayout needs at least one named region")
        self.regions: dict[str, Region] = {}
        self.slices: dict[str, slice] = {}
        start = 0
        for name, reg in regions.items():
            if not isinstance(name, str) or not name:
                raise ConfigError(f"parameter names must be non-empty strings, got {name!r}")
            if not isinstance(reg, Region):
                raise ConfigError(f"{name}: expected a Region, got {type(reg).__name__}")
            self.regions[name] = reg
            self.slices[name] = slice(start, start + reg.dim)
            start += reg.dim
        self._dim = start

    @classmethod
    def from_dict(cls, d: Mapping[str, Mapping[str, Any]], where: str = "params") -> ParamLayout:
        """Build from ``{name: {type: ..., ...}, ...}``; errors read ``"<where>.<name>: ..."``."""
        if not isinstance(d, Mapping) or len(d) == 0:
            raise ConfigError(f"{where}: expected a non-empty mapping of parameter name -> region")
        return cls({str(k): region_from_dict(v, f"{where}.{k}") for k, v in d.items()})

    def to_dict(self) -> dict[str, dict[str, Any]]:
        return {k: r.to_dict() for k, r in self.regions.items()}

    @property
    def names(self) -> list[str]:
        return list(self.regions)

    @property
    def dim(self) -> int:
        return self._dim

    @property
    def column_names(self) -> list[str]:
        """``"<param>.<coord>"`` per column of Z, e.g. ``["Table1.x", "Table1.y", ...]``."""
        return [f"{n}.{c}" for n, r in self.regions.items() for c in r.coord_names]

    def _check(self, Z: Tensor, who: str) -> None:
        check_batch(Z, self._dim, f"ParamLayout.{who}")

    def sample_uniform(
        self, n: int, generator: torch.Generator | None = None, dtype: torch.dtype | None = None
    ) -> Tensor:
        """``(n, D)``: each parameter uniform over its region, independently, in name order."""
        return torch.cat([r.sample_uniform(n, generator, dtype) for r in self.regions.values()], dim=-1)

    def project(self, Z: Tensor) -> Tensor:
        self._check(Z, "project")
        return torch.cat([r.project(Z[:, self.slices[n]]) for n, r in self.regions.items()], dim=-1)

    def contains(self, Z: Tensor, tol: float = DEFAULT_TOL) -> Tensor:
        """``(N,)`` bool: every parameter of the row lies in its region."""
        self._check(Z, "contains")
        ok = torch.ones(Z.shape[0], dtype=torch.bool, device=Z.device)
        for n, r in self.regions.items():
            ok = ok & r.contains(Z[:, self.slices[n]], tol)
        return ok

    def split(self, Z: Tensor) -> dict[str, Tensor]:
        """``{name: Z[:, slice] (N, dim)}`` (views, not copies)."""
        self._check(Z, "split")
        return {n: Z[:, s] for n, s in self.slices.items()}

    def join(self, parts: Mapping[str, Tensor]) -> Tensor:
        """Inverse of ``split``: concatenate ``{name: (N, dim)}`` in layout order."""
        missing = [n for n in self.regions if n not in parts]
        if missing:
            raise ValueError(f"ParamLayout.join: missing parameter(s) {missing}")
        return torch.cat([parts[n] for n in self.regions], dim=-1)

    def bounds(self) -> tuple[Tensor, Tensor]:
        """``(low (D,), high (D,))`` float64 bounding box of all regions."""
        lows, highs = zip(*(r.bounds() for r in self.regions.values()))
        return torch.cat(lows), torch.cat(highs)

    def __len__(self) -> int:
        return len(self.regions)

    def __repr__(self) -> str:
        return f"ParamLayout({', '.join(f'{n}={r!r}' for n, r in self.regions.items())})"
