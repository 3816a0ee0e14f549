"""Configs that earlier versions saved, read as today's: keys retired since are moved or dropped.

What it does: ``upgrade_config(cfg)`` returns a run's saved config (``result.json``'s or
``checkpoint.json``'s ``config``) as today's code reads it, so that a run recorded before still
replays, resumes, validates and draws. ``RETIRED`` names each retired key (group, key) with
what replaced it:
  * ``scene.exit_low`` / ``scene.exit_high`` (retired 2026-12-04): a second copy of the exit,
    which the task's goal region (``task.params.Exit``, named by ``goal.base_in``) gives; dropped;
  * ``workers.physx_threads`` (retired 2026-12-04): a second key for PhysX threads; its value
    moves to ``sim.cpu_workers`` where that is unset;
  * ``scene.robot_radius`` (retired 2026-12-04): a robot's footprint, which is its spec's; its
    value moves to ``robot.base.footprint_radius`` where that is unset.
A group added since: ``validation`` (added 2026-12-02): a run saved without it never validated, so
it reads as ``validation: {replicas: 0}`` (a new config without the group gets the dataclass's
defaults, ``realize.spec.run_spec.ValidationSettings``).
``check_retired(cfg)`` refuses a retired key in a new config in one line, saying what replaced it
(``realize.spec.run_spec`` calls it before anything is read).
What it doesn't: upgrade anything but configs (``scene.json``'s reader,
``realize.run_dir.scene_files``, skips fields it does not know by itself).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from realize.config import ConfigError

__all__ = ["RETIRED", "upgrade_config", "check_retired"]

_EXIT = "the exit is the task's goal region (task.params.Exit, named by task.goal.base_in)"
RETIRED: dict[tuple[str, str], str] = {
    ("scene", "exit_low"): _EXIT,
    ("scene", "exit_high"): _EXIT,
    ("workers", "physx_threads"): "sim.cpu_workers is the one key for PhysX threads (per worker; null: its share "
                                  "of the cores)",
    ("scene", "robot_radius"): "a robot's footprint is its spec's: robot.base.footprint_radius",
}
# where a retired key's value goes (group, key), if there is nowhere it is set already
_MOVED = {("workers", "physx_threads"): ("sim", "cpu_workers"), ("scene", "robot_radius"): ("robot", "base", "footprint_radius")}


def upgrade_config(cfg: Mapping[str, Any]) -> dict[str, Any]:
    """``cfg`` (a saved run config) without its retired keys, with the groups added since as the
    run ran without them; the rest as it was."""
    out = dict(cfg)
    out.setdefault("validation", {"replicas": 0})  # saved before the group: the run did not validate
    for (group, key) in RETIRED:
        node = out.get(group)
        if not isinstance(node, Mapping) or key not in node:
            continue
        node = dict(node)
        value = node.pop(key)
        out[group] = node
        to = _MOVED.get((group, key))
        if to is not None:
            _set_unset(out, to, value)
    return out


def _set_unset(cfg: dict[str, Any], path: tuple[str, ...], value: Any) -> None:
    """``cfg[path] = value`` unless a value is there already (copies on the way: ``cfg`` only is changed)."""
    node = cfg
    for part in path[:-1]:
        child = node.get(part)
        if not isinstance(child, Mapping):
            return  # no such group in this config: its reader's default stands
        node[part] = dict(child)
        node = node[part]
    if node.get(path[-1]) is None:
        node[path[-1]] = value


def check_retired(cfg: Mapping[str, Any]) -> None:
    """Refuse a retired key of a new config (``ConfigError``, one line naming it)."""
    for (group, key), instead in RETIRED.items():
        node = cfg.get(group)
        if isinstance(node, Mapping) and key in node:
            raise ConfigError(f"{group}.{key}: not a config key any more: {instead}; delete it")
