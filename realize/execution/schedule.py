"""When one world's disturbances fire: the schedule an executor asks at every control step.

What it does: ``Schedule(scheduled, control_dt)`` holds a world's drawn disturbances
(``realize.execution.disturbances.draw``); the executor reports when each action of the ORIGINAL
plan begins (``action_began``) and asks ``due(step, held)``; each disturbance fires once.
What it doesn't: read or draw disturbances (``realize.execution.disturbances``) or carry them out
(``realize.execution.world``).
"""

from __future__ import annotations

from collections.abc import Sequence

from realize.config import ConfigError
from realize.execution.disturbances import Scheduled, Trigger

__all__ = ["Schedule"]


class Schedule:
    """Which of one world's disturbances are due. The executor reports when each action of the
    ORIGINAL plan begins (``action_began``, 0-based index, control step) and asks ``due(step,
    held)`` every control step with the object in hand (or None); a disturbance fires once, at
    the first step ``>=`` its start step + ``round(delay_s / control_dt)``. An action trigger
    whose action never begins (a re-sequenced plan) never fires; ``pending`` lists those left."""

    def __init__(self, scheduled: Sequence[Scheduled], control_dt: float):
        if not control_dt > 0:
            raise ConfigError(f"control_dt = {control_dt!r} is invalid: must be > 0")
        self.scheduled = list(scheduled)
        self.control_dt = float(control_dt)
        self._began: dict[int, int] = {}
        self._held: dict[str, int] = {}
        self._fired: set[int] = set()

    def action_began(self, k: int, step: int) -> None:
        self._began.setdefault(int(k), int(step))

    def _start(self, t: Trigger) -> int | None:
        if t.action is not None:
            return self._began.get(t.action)
        return self._held.get(str(t.object))

    def due(self, step: int, held: str | None = None) -> list[Scheduled]:
        if held is not None:
            self._held.setdefault(held, int(step))
        out = []
        for i, s in enumerate(self.scheduled):
            if i in self._fired:
                continue
            start = self._start(s.trigger)
            if start is not None and step >= start + round(s.trigger.delay_s / self.control_dt):
                self._fired.add(i)
                out.append(s)
        return out

    @property
    def pending(self) -> list[Scheduled]:
        return [s for i, s in enumerate(self.scheduled) if i not in self._fired]
