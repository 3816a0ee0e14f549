"""The goal psi_g of a task, by object name: what it says and how a task config writes it.

What it does: ``GoalSpec`` holds every condition a plan's end state must meet, each naming a
movable object of the scene (``realize.world.objects``):
  * ``rests_on: {cube_a: table2, cube_b: table2}``: the object rests on that table's top;
    ``rests_on: {cube_b: cube_a}``: on that object's top, where that object stands at the end;
  * ``rests_in: {cube: box}``: the object rests inside that open container;
  * ``rests_at: {cube: {region: Spot, tol: 0.02}}``: the object's centre rests within ``tol`` of the
    task parameter ``Spot`` (a fixed point, or inside a box region grown by ``tol``), e.g.
    "put the cube back on table 1, 15 cm further" (``Spot`` framed by ``table1``);
  * ``base_in: Exit``: the base ends inside that 2-D box parameter;
  * ``margin: 0.01`` (m, default 0): while a run searches, an object resting on another object must
    stand this much further inside its support's top than the goal asks (the support's inscribed
    circle shrunk by it), so that the search's plans keep off the edge of what stands; validation
    and execution judge the goal itself (``judged()``: the margin 0).
(``rests_*``, not ``on``: YAML 1.1, which Hydra reads, takes a bare ``on`` for true.)
``goal_from_dict`` reads and checks it against the scene and the task's regions: an unknown
object, table, container or parameter, or a region of the wrong kind, is one ``ConfigError``
naming ``<source>:goal.<key>``.
What it doesn't: evaluate anything (``realize.tasks.goals`` does, batched).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from typing import Any

from realize.config import ConfigError, check_unknown, did_you_mean
from realize.tasks.regions import Box, Fixed, Region
from realize.world.geometry import SceneGeometry

__all__ = ["AtGoal", "GoalSpec", "GOAL_KEYS", "goal_from_dict", "DEFAULT_AT_TOL"]

GOAL_KEYS = ("rests_on", "rests_in", "rests_at", "base_in", "margin")
DEFAULT_AT_TOL = 0.02  # m


@dataclass(frozen=True)
class AtGoal:
    """``rests_at``: the object's centre within ``tol`` (m) of parameter ``region``'s point or box."""

    region: str
    tol: float = DEFAULT_AT_TOL


@dataclass(frozen=True)
class GoalSpec:
    """psi_g: every given condition must hold at the end of the plan (module docstring)."""

    on: Mapping[str, str] = field(default_factory=dict)  # object -> table
    inside: Mapping[str, str] = field(default_factory=dict)  # object -> container (config key ``rests_in``)
    at: Mapping[str, AtGoal] = field(default_factory=dict)  # object -> point or box parameter
    base_in: str | None = None  # a parameter whose region is a 2-D box
    margin: float = 0.0  # m: a stacked object's centre this much further inside its support's top, while searching

    def judged(self) -> GoalSpec:
        """The goal as validation and execution judge it: without the search's ``margin``."""
        return replace(self, margin=0.0) if self.margin else self

    @property
    def objects(self) -> tuple[str, ...]:
        """Every object a condition names, in the order written (on, in, at)."""
        seen: dict[str, None] = {}
        for m in (self.on, self.inside, self.at):
            for name in m:
                seen.setdefault(name, None)
        return tuple(seen)

    @property
    def reads_objects(self) -> bool:
        return bool(self.on or self.inside or self.at)

    def params(self) -> tuple[str, ...]:
        """The task parameters the goal reads (``base_in`` and the ``at`` regions)."""
        out = [a.region for a in self.at.values()]
        if self.base_in is not None:
            out.insert(0, self.base_in)
        return tuple(out)

    def to_dict(self) -> dict[str, Any]:
        d: dict[str, Any] = {}
        if self.on:
            d["rests_on"] = dict(self.on)
        if self.inside:
            d["rests_in"] = dict(self.inside)
        if self.at:
            d["rests_at"] = {k: {"region": a.region, "tol": a.tol} for k, a in self.at.items()}
        if self.base_in is not None:
            d["base_in"] = self.base_in
        if self.margin:
            d["margin"] = self.margin
        return d


_OLD = {"cube_on": "rests_on: {cube: <table>}", "cube_in_box": "rests_in: {cube: <container>}",
        "on": "rests_on: {<object>: <table>}", "True": "rests_on: {<object>: <table>} (YAML reads a bare on as true)",
        "in": "rests_in: {<object>: <container>}", "at": "rests_at: {<object>: {region: <Param>}}"}


def _names(value: Any, where: str) -> dict[str, str]:
    if not isinstance(value, Mapping) or not value:
        raise ConfigError(f"{where} = {value!r} is invalid: a mapping of object -> name, e.g. {{cube: table2}}")
    return {str(k): str(v) for k, v in value.items()}


def goal_from_dict(d: Any, scene: SceneGeometry, regions: Mapping[str, Region], source: str = "task") -> GoalSpec:
    """Read and check a task config's ``goal`` mapping (module docstring)."""
    where = f"{source}:goal"
    if not isinstance(d, Mapping):
        raise ConfigError(f"{where} must be a mapping")
    for old, new in _OLD.items():
        if old in d or (old == "True" and True in d):
            raise ConfigError(f"{where}.{old}: goals name their object now; write {new}")
    check_unknown(d, list(GOAL_KEYS), where, "predicates")
    objects = list(scene.object_names)
    on = _names(d["rests_on"], f"{where}.rests_on") if d.get("rests_on") is not None else {}
    inside = _names(d["rests_in"], f"{where}.rests_in") if d.get("rests_in") is not None else {}
    at: dict[str, AtGoal] = {}
    if d.get("rests_at") is not None:
        if not isinstance(d["rests_at"], Mapping) or not d["rests_at"]:
            raise ConfigError(f"{where}.rests_at = {d['rests_at']!r} is invalid: a mapping of object -> "
                              "{region: Param, tol: m}")
        for name, spec in d["rests_at"].items():
            key = f"{where}.rests_at.{name}"
            if isinstance(spec, str):
                spec = {"region": spec}
            if not isinstance(spec, Mapping) or "region" not in spec or set(spec) - {"region", "tol"}:
                raise ConfigError(f"{key} = {spec!r} is invalid: write {{region: Param, tol: 0.02}}")
            tol = spec.get("tol", DEFAULT_AT_TOL)
            if isinstance(tol, bool) or not isinstance(tol, (int, float)) or not tol > 0:
                raise ConfigError(f"{key}.tol = {tol!r} is invalid: must be a distance > 0 (m)")
            at[str(name)] = AtGoal(str(spec["region"]), float(tol))
    tables = [t.name for t in scene.tables]
    containers = [c.name for c in scene.containers]
    for key, mapping in (("rests_on", on), ("rests_in", inside), ("rests_at", at)):
        for name, target in mapping.items():
            if name not in objects:
                raise ConfigError(f"{where}.{key}.{name}: unknown object {name!r}; the scene's objects: {objects}"
                                  f"{did_you_mean(name, objects)}")
            if key == "rests_on" and target not in tables and target not in objects:
                raise ConfigError(f"{where}.rests_on.{name} = {target!r} names no table or object; tables: {tables}, "
                                  f"objects: {objects}{did_you_mean(str(target), list(tables) + objects)}")
            if key == "rests_on" and target == name:
                raise ConfigError(f"{where}.rests_on.{name} = {target!r} is invalid: an object cannot rest on itself")
            if key == "rests_in" and target not in containers:
                raise ConfigError(f"{where}.rests_in.{name} = {target!r} names no container; containers: {containers}"
                                  f"{did_you_mean(str(target), list(containers))}")
            if key == "rests_at":
                r = regions.get(target.region)
                if r is None:
                    raise ConfigError(f"{where}.rests_at.{name}.region names unknown parameter {target.region!r}; "
                                      f"defined: {list(regions)}{did_you_mean(str(target.region), list(regions))}")
                if not (isinstance(r, (Box, Fixed)) and r.dim in (2, 3)):
                    raise ConfigError(f"{where}.rests_at.{name}.region: {target.region!r} must be a 2-D or 3-D fixed point "
                                      "or box region")
    for name, target in on.items():  # cube_a on cube_b on cube_a: no end state has that
        seen, below = {name}, target
        while below in on:
            if below in seen:
                raise ConfigError(f"{where}.rests_on: {name!r} would rest on itself through {sorted(seen)}")
            seen.add(below)
            below = on[below]
    for name in set(on) & set(inside):
        raise ConfigError(f"{where}: {name!r} is both on a table and in a container")
    base_in = d.get("base_in")
    if base_in is not None:
        base_in = str(base_in)
        if base_in not in regions:
            raise ConfigError(f"{where}.base_in names unknown parameter {base_in!r}; defined: {list(regions)}"
                              f"{did_you_mean(base_in, list(regions))}")
        r = regions[base_in]
        if not (isinstance(r, Box) and r.dim == 2):
            raise ConfigError(f"{where}.base_in: {base_in!r} must be a 2-D box region")
    margin = d.get("margin", 0.0)
    if isinstance(margin, bool) or not isinstance(margin, (int, float)) or not 0.0 <= margin < 1.0:
        raise ConfigError(f"{where}.margin = {margin!r} is invalid: must be a distance >= 0 (m)")
    for name, support in on.items():
        if margin and support in objects:
            s = scene.object(support)
            r = min(s.half_size[0], s.half_size[1])
            if margin >= r:
                raise ConfigError(f"{where}.margin = {margin!r} is invalid: {name!r} rests on {support!r}, whose top "
                                  f"admits a centre within {r:.4g} m of its middle; the margin must be smaller")
    return GoalSpec(on, inside, at, base_in, float(margin))
