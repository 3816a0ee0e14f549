"""The interface of an action template (paper eq. 1): parameters, controller, success, failure.

What it does: ``Template`` is the base class of the action templates. A template keeps per-plan
state as (N, ...) tensors and works on index sets ``rows`` of plans, so N plans in different
actions advance together; the rollout calls, per control step, ``act`` (write commands into the
``StepContext``) before physics and ``check`` (``Outcome``: done, success, failure code) after
it, and ``begin`` when a plan enters the action. The cost is 1 per control step until the
action finishes (counted by the rollout); success predicates read the simulator (through the
context).
What it doesn't: loop over time or decide which action a plan is in
(``realize.realization.rollout``), or talk to the simulator directly.

Adding a template: a module beside this one with a subclass that implements ``accepts``,
``begin``, ``act``, ``check`` (and ``distance`` for ranking its failures), registered in
``realize.realization.actions.TEMPLATES``; plans can then name it.
"""

from __future__ import annotations

from typing import ClassVar, NamedTuple

import torch
from torch import Tensor

from realize.realization.context import StepContext
from realize.tasks.regions import Region


class Outcome(NamedTuple):
    """What ``Template.check`` found for its rows, each (len(rows),)."""

    done: Tensor  # bool: the action ended (succeeded or failed)
    success: Tensor  # bool: it succeeded
    failure: Tensor  # int64 ``Failure`` code, 0 where it did not fail


class Template:
    """Base class of action templates; subclasses keep (N, ...) state tensors."""

    name: ClassVar[str] = "template"
    n_params: ClassVar[int] = 1
    param_doc: ClassVar[str] = ""
    moves_base: ClassVar[bool] = False  # drives the base (a fixed-base robot's plans cannot hold it)
    takes_object: ClassVar[bool] = False  # the plan names the object it handles first: grasp(cube, Cube_g)

    def __init__(self, n_envs: int, device: torch.device):
        self.n_envs, self.device = n_envs, device
        self.t = torch.zeros(n_envs, dtype=torch.long, device=device)  # steps spent in the action

    @classmethod
    def accepts(cls, region: Region) -> bool:  # pragma: no cover - abstract
        """Whether a parameter drawn from ``region`` fits this template."""
        raise NotImplementedError

    def begin(self, ctx: StepContext, rows: Tensor, params: Tensor, region: Region, obj: int = -1,
              shift: Tensor | None = None, support: int = -1) -> Tensor:
        """Start the action for plans ``rows`` with parameters (len(rows), d) drawn from
        ``region`` on object ``obj`` (its index on the scene's m axis; -1 for templates that
        handle none); returns a (len,) failure code (0 = fine) for plans that fail immediately.
        ``shift`` (len, 3): how far the object the region is framed by lies from its config
        pose (the rollout already moved ``params`` by it; a template that reads a fixed point of
        the region itself, a hemisphere's centre, moves it too), None: not tracked. ``support``:
        the index of the movable object the region is framed by (-1: a table, or no frame)."""
        raise NotImplementedError

    def act(self, ctx: StepContext, rows: Tensor) -> None:
        """Write commands for ``rows`` into ``ctx``."""
        raise NotImplementedError

    def check(self, ctx: StepContext, rows: Tensor) -> Outcome:
        """After a step: (done, success, failure code) for ``rows``."""
        raise NotImplementedError

    def distance(self, ctx: StepContext, rows: Tensor) -> Tensor:
        """Distance-to-success proxy (m) for ranking infeasible plans."""
        return torch.zeros(len(rows), device=self.device)
