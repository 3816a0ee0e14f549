"""A small cache of what the A* planner derives from a free-cell grid alone (components, move
tables, octile tables), so the static map of a run is processed once, not at every ``move_to``.

What it does: :func:`grid_cached` returns ``fn(free)`` for a grid, computed once per distinct grid
content and kept for the most recent ``_MAX_GRIDS`` grids. A lookup matches on shape, dtype,
device and content (``torch.equal``), never on object identity, so a different scene or an
edited occupancy tensor (even modified in place) misses and is computed afresh.

What it doesn't: cache search results (those depend on the batch, see
``realize.controllers.astar``), or bound memory beyond the number of grids kept.
"""

from __future__ import annotations

from typing import Callable, TypeVar

import torch
from torch import Tensor

__all__ = ["grid_cached", "clear_grid_cache"]

T = TypeVar("T")
_MAX_GRIDS = 4
# most recent first: (private copy of the grid, {name: value})
_ENTRIES: list[tuple[Tensor, dict[str, object]]] = []


def _entry(free: Tensor) -> dict[str, object]:
    for i, (key, values) in enumerate(_ENTRIES):
        if key.shape == free.shape and key.dtype == free.dtype and key.device == free.device \
                and torch.equal(key, free):
            if i:
                _ENTRIES.insert(0, _ENTRIES.pop(i))
            return values
    values: dict[str, object] = {}
    _ENTRIES.insert(0, (free.clone(), values))
    del _ENTRIES[_MAX_GRIDS:]
    return values


def grid_cached(name: str, free: Tensor, fn: Callable[[Tensor], T]) -> T:
    """``fn(free)``, computed once per distinct content of ``free`` (any shape) and ``name``."""
    values = _entry(free)
    if name not in values:
        values[name] = fn(free)
    return values[name]  # type: ignore[return-value]


def clear_grid_cache() -> None:
    """Forget every cached grid (tests; memory)."""
    _ENTRIES.clear()
