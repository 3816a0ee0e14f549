"""The config a resumed run goes on with: its saved one, with only what may change taken from the command line.

What it does: ``resume_config(current, ckpt, overrides)`` and ``RESUME_ALLOWED_PREFIXES``, the
overrides a resumed run accepts (the ``logging``, ``workers`` and ``validation`` groups and
``sim.cpu_workers``: none of them changes the search's numbers).
What it doesn't: read the checkpoint (``realize.run_dir.checkpoint``) or run anything (``realize.run.assembly``).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from omegaconf import OmegaConf

from realize.config import ConfigError
from realize.run_dir.checkpoint import Checkpoint

__all__ = ["resume_config", "RESUME_ALLOWED_PREFIXES"]

# overrides a resumed run accepts (everything else comes from the run's saved config)
RESUME_ALLOWED_PREFIXES = ("resume", "logging", "workers", "hydra.", "validation", "sim.cpu_workers")


def resume_config(current: dict[str, Any], ckpt: Checkpoint, overrides: Sequence[str]) -> dict[str, Any]:
    """The config a resumed run uses: the saved one, every group of it included, with only what
    ``overrides`` (the command line's) name of the ``logging``, ``workers`` and ``validation``
    groups and ``sim.cpu_workers`` taken from ``current`` on top (none changes the search's
    numbers: a run may go on with other workers and threads, e.g. on another machine, and
    validate its candidates once it ends).
    ``validation=off`` replaces the saved group; ``workers.n=2`` changes that one key."""
    from realize.spec.compose import parse_overrides

    extra = [o for o in overrides if not str(o).lstrip("+~").startswith(RESUME_ALLOWED_PREFIXES)]
    if extra:
        raise ConfigError(
            f"resume: a resumed run uses its saved config; drop the override(s) {extra} "
            "(only logging.*, workers.*, validation.* and sim.cpu_workers may change)"
        )
    base, cur = OmegaConf.create(dict(ckpt.config)), OmegaConf.create(dict(current))
    for o in parse_overrides([str(x) for x in overrides]):
        key = o.key_or_group
        if not key.startswith(("resume", "hydra")) and not o.is_delete():  # (the others were refused)
            OmegaConf.update(base, key, OmegaConf.select(cur, key, throw_on_missing=False), merge=False,
                             force_add=True)
    cfg = OmegaConf.to_container(base, resolve=True)
    assert isinstance(cfg, dict)
    cfg["resume"] = current.get("resume")
    return cfg
