"""The state of one copy of the scene, to start a rollout from: robot, gripper, objects, grip.

What it does: ``SceneState`` holds what a plan's remaining actions need to begin where an
earlier execution left off, in one copy's local frame (the frame of ``realize.world.geometry``):

  * ``base``: the base pose (x, y, yaw) (m, m, rad);
  * ``joints``: the robot's other active joints by name (lift or torso, head, arm, fingers; the
    scene's ``state_joints``), in rad or m;
  * ``gripper_closed``: the gripper command (closed squeezes, open lets go);
  * ``objects``: every movable object's pose by name (``ObjectPose``: position (x, y, z) and
    quaternion (w, x, y, z)), in hand or not;
  * ``held``: the object the fingers hold, or None (needs ``gripper_closed``);
  * ``source``: free text saying where the state came from (a replay, a robot, a hand).

Velocities are not part of it: a restored copy starts at rest. ``save_state`` / ``load_state``
write and read it as JSON (``STATE_FORMAT``); every problem with a file (missing, not JSON,
unknown or missing keys, wrong lengths, non-finite numbers, an unnormalised quaternion, a
held object with an open gripper or not among the objects) is one
``realize.config.ConfigError`` naming the file and the key. A file written by hand may leave out
joints and objects: they take the robot's rest pose (``RobotSpec.rest``) and the objects' rest
poses when the scene restores the state, as a fresh scene has them; which joint and object names
exist is checked there too (``BatchedScene.reset(state=...)``). Files of the first format (one
``cube`` and ``cube_held``) still read: their cube is the object named ``cube``.

What it doesn't: read or write the simulator (``realize.scene.batched.BatchedScene``:
``capture_state`` and ``reset(state=...)``), or decide whether a plan can go on from a state
(``realize.tasks.suffix``).
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping
import dataclasses
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from realize.config import ConfigError, check_unknown

__all__ = ["ObjectPose", "SceneState", "STATE_FORMAT", "save_state", "load_state"]

STATE_FORMAT = "realize.scene_state/2"
_FORMAT_1 = "realize.scene_state/1"  # one cube: "cube" and "cube_held"
_KEYS = ("format", "base", "joints", "gripper_closed", "objects", "held", "source")
_KEYS_1 = ("format", "base", "joints", "gripper_closed", "cube", "cube_held", "source")
_QUAT_TOL = 1e-3


def _floats(value: Any, n: int, where: str) -> tuple[float, ...]:
    if isinstance(value, (str, bytes)) or not hasattr(value, "__len__"):
        raise ConfigError(f"{where} = {value!r} is invalid: expected a list of {n} numbers")
    if len(value) != n:
        raise ConfigError(f"{where} has {len(value)} values, expected {n}")
    out = []
    for i, v in enumerate(value):
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(float(v)):
            raise ConfigError(f"{where}[{i}] = {v!r} is invalid: expected a finite number")
        out.append(float(v))
    return tuple(out)


def _flag(value: Any, where: str) -> bool:
    if not isinstance(value, bool):
        raise ConfigError(f"{where} = {value!r} is invalid: expected true or false")
    return value


@dataclass(frozen=True)
class ObjectPose:
    """One object's pose: centre (x, y, z) and unit quaternion (w, x, y, z); checked when built
    (``where`` names it in errors, not part of the value)."""

    position: tuple[float, float, float] = (0.0, 0.0, 0.0)
    quaternion: tuple[float, float, float, float] = (1.0, 0.0, 0.0, 0.0)
    where: str = field(default="object", compare=False, repr=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "position", _floats(self.position, 3, f"{self.where}.position"))
        q = _floats(self.quaternion, 4, f"{self.where}.quaternion")
        norm = math.sqrt(sum(x * x for x in q))
        if abs(norm - 1.0) > _QUAT_TOL:
            raise ConfigError(f"{self.where}.quaternion {list(q)} is invalid: not a unit quaternion (norm {norm:.4f})")
        object.__setattr__(self, "quaternion", tuple(x / norm for x in q))

    def to_json(self) -> dict[str, list[float]]:
        return {"position": list(self.position), "quaternion": list(self.quaternion)}


def _pose(d: Any, where: str) -> ObjectPose:
    if not isinstance(d, Mapping) or set(d) != {"position", "quaternion"}:
        raise ConfigError(f"{where} must be an object with exactly the keys 'position' and 'quaternion'")
    return ObjectPose(_floats(d["position"], 3, f"{where}.position"), _floats(d["quaternion"], 4, f"{where}.quaternion"),
                      where=where)


def _object_pose(pose: Any, key: str) -> ObjectPose:
    if not isinstance(pose, ObjectPose):
        raise ConfigError(f"{key} must be an ObjectPose")
    return pose


def _by_name(d: Any, field_name: str, what: str, where: str, check: Any) -> dict[str, Any]:
    """``d`` as a dict of ``what`` name -> ``check(value, key)`` (a mapping with name keys)."""
    if not isinstance(d, Mapping):
        raise ConfigError(f"{where}: {field_name} must be a mapping of {what} name -> value")
    out = {}
    for name, v in d.items():
        if not isinstance(name, str) or not name:
            raise ConfigError(f"{where}: {field_name} has a key {name!r} that is not a {what} name")
        out[name] = check(v, f"{where}: {field_name}.{name}")
    return out


@dataclass(frozen=True)
class SceneState:
    """One copy's state (module docstring); checked when built."""

    base: tuple[float, float, float]
    joints: dict[str, float] = field(default_factory=dict)  # left out: the robot's rest pose
    gripper_closed: bool = False
    objects: dict[str, ObjectPose] = field(default_factory=dict)  # left out: the object's rest pose
    held: str | None = None
    source: str = ""

    def __post_init__(self) -> None:
        where = self.source or "state"
        object.__setattr__(self, "base", _floats(self.base, 3, f"{where}: base"))
        objects = _by_name(self.objects, "objects", "object", where, _object_pose)
        object.__setattr__(self, "objects", objects)
        object.__setattr__(self, "joints", _by_name(self.joints, "joints", "joint", where,
                                                    lambda v, key: _floats([v], 1, key)[0]))
        _flag(self.gripper_closed, f"{where}: gripper_closed")
        if self.held is not None:
            if not isinstance(self.held, str) or self.held not in objects:
                raise ConfigError(f"{where}: held = {self.held!r} is invalid: the held object must be one of the "
                                  f"state's objects {sorted(objects)}")
            if not self.gripper_closed:
                raise ConfigError(f"{where}: held is {self.held!r} but gripper_closed is false (a held object needs a "
                                  "closed gripper)")

    def to_json(self) -> dict[str, Any]:
        return {
            "format": STATE_FORMAT,
            "base": list(self.base),
            "joints": dict(self.joints),
            "gripper_closed": self.gripper_closed,
            "objects": {name: pose.to_json() for name, pose in self.objects.items()},
            "held": self.held,
            "source": self.source,
        }

    @classmethod
    def from_json(cls, d: Any, where: str = "state") -> SceneState:
        """A state from ``to_json``'s object (``where`` names the file in errors). Required:
        ``base``, ``objects`` (name -> ``position``, ``quaternion``); optional: ``joints`` (rest
        pose), ``gripper_closed`` (false), ``held`` (null), ``format``, ``source``. The first
        format's ``cube`` / ``cube_held`` read as the object ``cube``."""
        if not isinstance(d, Mapping):
            raise ConfigError(f"{where}: a scene state is a JSON object, got {type(d).__name__}")
        fmt = d.get("format", STATE_FORMAT if "objects" in d or "cube" not in d else _FORMAT_1)
        if fmt not in (STATE_FORMAT, _FORMAT_1):
            raise ConfigError(f"{where}: format = {fmt!r} is not {STATE_FORMAT!r} (or {_FORMAT_1!r})")
        keys, required = (_KEYS, ("base", "objects")) if fmt == STATE_FORMAT else (_KEYS_1, ("base", "cube"))
        check_unknown(d, list(keys), where)
        missing = [k for k in required if k not in d]
        if missing:
            raise ConfigError(f"{where}: missing key(s) {missing}")
        if fmt == STATE_FORMAT:
            objs = d["objects"]
            if not isinstance(objs, Mapping):
                raise ConfigError(f"{where}: objects must be an object of name -> {{position, quaternion}}")
            objects = {str(n): _pose(p, f"{where}: objects.{n}") for n, p in objs.items()}
            held = d.get("held")
            if held is not None and not isinstance(held, str):
                raise ConfigError(f"{where}: held = {held!r} is invalid: an object name or null")
        else:
            objects = {"cube": _pose(d["cube"], f"{where}: cube")}
            held = "cube" if _flag(d.get("cube_held", False), f"{where}: cube_held") else None
        source = d.get("source", "")
        # checked under the file's name (a message must say where to look), then given its own
        # free-text source
        state = cls(base=_floats(d["base"], 3, f"{where}: base"), joints=d.get("joints", {}),
                    gripper_closed=_flag(d.get("gripper_closed", False), f"{where}: gripper_closed"),
                    objects=objects, held=held, source=where)
        return dataclasses.replace(state, source=str(source)) if source else state


def save_state(state: SceneState, path: str | Path) -> Path:
    """Write ``state`` as JSON to ``path`` (directories created); returns the path."""
    p = Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    tmp = p.with_name(p.name + ".tmp")
    tmp.write_text(json.dumps(state.to_json(), indent=2) + "\n")
    tmp.replace(p)
    return p


def load_state(path: str | Path, key: str = "state") -> SceneState:
    """Read a state file; ``ConfigError`` naming ``key`` (the config key that gave the path) and
    the file for anything wrong with it."""
    p = Path(path)
    if not p.is_file():
        raise ConfigError(f"{key} = {str(path)!r}: no such file (a scene state JSON, see realize/world/state.py)")
    try:
        d = json.loads(p.read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as e:
        raise ConfigError(f"{key} = {str(path)!r}: not a readable JSON file ({e})") from None
    return SceneState.from_json(d, where=str(p))
