"""A stitched chain's pool of start states (``realize.search.chain``): feasible partial plans.

What it does: ``Pool`` holds, row for row, a partial plan's columns (chain order, through its
segment), its cumulative cost, the end state it reached, an id, its parent's id (the entry of the
pool before it that its start came from; -1 for the first segment), whether it was doomed when
it was realized (credit), and how many rows were started from it (tries) and ended feasible
(wins). ``merged`` keeps the ``n`` cheapest of two pools (doomed entries after the others; ties
to the older, then row order); ``to_json``/``from_json`` round-trip it (states through their
``to_json`` and a reader).
What it doesn't: decide what is dead or doomed (``ChainSearch``), or simulate.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

import torch
from torch import Tensor

__all__ = ["Pool"]


def _state_json(s: Any) -> Any:
    return s.to_json() if hasattr(s, "to_json") else s


@dataclass
class Pool:
    """Feasible partial plans and their end states (module docstring)."""

    z: Tensor  # (n, d) columns in chain order
    cost: Tensor  # (n,) cumulative cost
    states: list[Any]
    ids: Tensor  # (n,) long
    parent: Tensor  # (n,) long, -1: none
    doomed: Tensor  # (n,) bool
    tries: Tensor = field(default_factory=lambda: torch.zeros(0, dtype=torch.long))
    wins: Tensor = field(default_factory=lambda: torch.zeros(0, dtype=torch.long))

    def __post_init__(self) -> None:
        n = self.z.shape[0]
        if self.tries.shape[0] != n:
            self.tries = torch.zeros(n, dtype=torch.long)
        if self.wins.shape[0] != n:
            self.wins = torch.zeros(n, dtype=torch.long)
        if not (self.cost.shape[0] == len(self.states) == self.ids.shape[0] == self.parent.shape[0]
                == self.doomed.shape[0] == n):
            raise ValueError(f"a pool's rows disagree: {n} columns, {self.cost.shape[0]} costs, {len(self.states)} states")

    @classmethod
    def empty(cls, d: int, dtype: torch.dtype) -> Pool:
        none = torch.zeros(0, dtype=torch.long)
        return cls(torch.zeros(0, d, dtype=dtype), torch.zeros(0, dtype=dtype), [], none, none.clone(),
                   torch.zeros(0, dtype=torch.bool))

    def __len__(self) -> int:
        return self.z.shape[0]

    def take(self, idx: Tensor) -> Pool:
        """The rows ``idx``, in that order."""
        return Pool(self.z[idx], self.cost[idx], [self.states[i] for i in idx.tolist()], self.ids[idx],
                    self.parent[idx], self.doomed[idx], self.tries[idx], self.wins[idx])

    def merged(self, other: Pool, n: int) -> Pool:
        """The ``n`` best of this pool's rows then ``other``'s: the not doomed before the doomed,
        each by cost (stable: ties to the earlier row)."""
        both = Pool(torch.cat([self.z, other.z]), torch.cat([self.cost, other.cost]), self.states + other.states,
                    torch.cat([self.ids, other.ids]), torch.cat([self.parent, other.parent]),
                    torch.cat([self.doomed, other.doomed]), torch.cat([self.tries, other.tries]),
                    torch.cat([self.wins, other.wins]))
        order = torch.sort(both.cost, stable=True).indices
        order = order[torch.sort(both.doomed[order].to(torch.int8), stable=True).indices]
        return both.take(order[:n])

    def to_json(self) -> dict[str, Any]:
        return {"z": self.z.tolist(), "cost": self.cost.tolist(), "states": [_state_json(s) for s in self.states],
                "ids": self.ids.tolist(), "parent": self.parent.tolist(), "doomed": self.doomed.tolist(),
                "tries": self.tries.tolist(), "wins": self.wins.tolist()}

    @classmethod
    def from_json(cls, d: Mapping[str, Any], dim: int, dtype: torch.dtype, read_state: Callable[[Any], Any]) -> Pool:
        def long(key: str) -> Tensor:
            return torch.tensor(d[key], dtype=torch.long).reshape(-1)

        return cls(torch.tensor(d["z"], dtype=dtype).reshape(-1, dim), torch.tensor(d["cost"], dtype=dtype).reshape(-1),
                   [read_state(s) for s in d["states"]], long("ids"), long("parent"),
                   torch.tensor(d["doomed"], dtype=torch.bool).reshape(-1), long("tries"), long("wins"))
