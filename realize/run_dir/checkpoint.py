"""``checkpoint.json``: what ``resume=<run dir>`` needs to continue a run.

What it does: ``Checkpoint`` holds the search state after ``iteration`` complete iterations
(``ce_state``: the optimizer's own JSON form, e.g. ``CEState.to_dict()``, kept verbatim), the
run's resolved config, the ``IterationSummary`` of every completed iteration (``records``),
the wall time so far and the number of segments (starts) of the run. ``save_checkpoint`` writes
it atomically; ``load_checkpoint`` reads and checks it, raising ``CheckpointError`` naming the
directory or file.
What it doesn't: interpret ``ce_state`` (the optimizer does) or decide when to write.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from realize.run_dir.jsonio import atomic_write_json
from realize.run_dir.names import CHECKPOINT_FILE
from realize.run_dir.summaries import IterationSummary
from realize.run_dir.upgrade import upgrade_config

__all__ = ["CHECKPOINT_FORMAT", "Checkpoint", "CheckpointError", "save_checkpoint", "load_checkpoint"]

CHECKPOINT_FORMAT = "realize-checkpoint-v1"


class CheckpointError(ValueError):
    """A run directory cannot be resumed; the message names the directory or file."""


@dataclass
class Checkpoint:
    """The state of a run after ``iteration`` complete iterations (see the module docstring)."""

    iteration: int
    ce_state: dict[str, Any]
    config: dict[str, Any]
    records: list[IterationSummary]
    wall_time_s: float
    segments: int = 1

    def to_json(self) -> dict[str, Any]:
        return {
            "format": CHECKPOINT_FORMAT,
            "iteration": self.iteration,
            "ce_state": self.ce_state,
            "config": self.config,
            "records": [r.to_json() for r in self.records],
            "wall_time_s": self.wall_time_s,
            "segments": self.segments,
        }

    @classmethod
    def from_json(cls, d: Any, where: Path | str = CHECKPOINT_FILE) -> Checkpoint:
        """Read and check the JSON object of a checkpoint; ``CheckpointError`` names ``where``."""
        if not isinstance(d, dict) or d.get("format") != CHECKPOINT_FORMAT:
            raise CheckpointError(f"resume: {where} is not a realize checkpoint (format is not {CHECKPOINT_FORMAT!r})")
        try:
            it = int(d["iteration"])
            ce_state, config, raw = d["ce_state"], d["config"], d["records"]
            config = upgrade_config(config) if isinstance(config, dict) else config
            wall = float(d.get("wall_time_s", 0.0))
            segments = int(d.get("segments", 1))
        except (KeyError, TypeError, ValueError) as e:
            raise CheckpointError(f"resume: {where} is incomplete or malformed ({type(e).__name__}: {e})") from None
        if not isinstance(ce_state, dict) or not isinstance(config, dict) or not isinstance(raw, list):
            raise CheckpointError(f"resume: {where} is malformed (ce_state/config/records have the wrong type)")
        try:
            records = [IterationSummary.from_json(r) for r in raw]
        except (KeyError, TypeError, ValueError, AttributeError) as e:
            raise CheckpointError(f"resume: {where} has a malformed iteration record ({type(e).__name__}: {e})") from None
        if it < 1 or len(records) != it:
            raise CheckpointError(f"resume: {where} is inconsistent (iteration {it}, {len(records)} iteration records)")
        return cls(it, ce_state, config, records, wall, segments)


def save_checkpoint(run_dir: Path | str, ckpt: Checkpoint) -> None:
    """Write ``<run_dir>/checkpoint.json`` atomically (the commit point of an iteration)."""
    # ce_state is the optimizer's own JSON form (CEState.to_dict writes inf/nan as strings): kept verbatim
    atomic_write_json(Path(run_dir) / CHECKPOINT_FILE, ckpt.to_json(), indent=None)


def load_checkpoint(run_dir: Path | str) -> Checkpoint:
    """Read ``<run_dir>/checkpoint.json``; ``CheckpointError`` names the directory or file."""
    run_dir = Path(run_dir)
    path = run_dir / CHECKPOINT_FILE
    if not run_dir.is_dir() or not path.is_file():
        raise CheckpointError(f"resume: {run_dir} is not a realize run directory (no {CHECKPOINT_FILE})")
    try:
        d = json.loads(path.read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as e:
        raise CheckpointError(f"resume: {path} is not valid JSON ({e})") from None
    return Checkpoint.from_json(d, path)
