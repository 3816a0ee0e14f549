"""The state of one copy of the scene, to start a rollout from: robot, gripper, cube, grip.

What it does: ``SceneState`` holds what a plan's remaining actions need to begin where an
earlier execution left off, in one copy's local frame (the frame of ``realize.world.geometry``):

  * ``base``: the base pose (x, y, yaw) (m, m, rad);
  * ``joints``: the robot's other active joints by name (lift or torso, head, arm, fingers; the
    scene's ``state_joints``), in rad or m;
  * ``gripper_closed``: the gripper command (closed squeezes, open lets go);
  * ``cube_position`` (x, y, z) and ``cube_quaternion`` (w, x, y, z) of the cube;
  * ``cube_held``: whether the fingers hold the cube (needs ``gripper_closed``);
  * ``source``: free text saying where the state came from (a replay, a robot, a hand).

Velocities are not part of it: a restored copy starts at rest. ``save_state`` / ``load_state``
write and read it as JSON (``STATE_FORMAT``); every problem with a file (missing, not JSON,
unknown or missing keys, wrong lengths, non-finite numbers, an unnormalised quaternion, a
held cube with an open gripper) is one ``realize.config.ConfigError`` naming the file and the
key. A file written by hand may leave out joints: they take the robot's rest pose
(``RobotSpec.rest``) when the scene restores the state, as a fresh scene has them; which joint
names a robot has is checked there too (``BatchedScene.reset(state=...)``).

What it doesn't: read or write the simulator (``realize.scene.batched.BatchedScene``:
``capture_state`` and ``reset(state=...)``), or decide whether a plan can go on from a state
(``realize.tasks.suffix``).
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from realize.config import ConfigError

__all__ = ["SceneState", "STATE_FORMAT", "save_state", "load_state"]

STATE_FORMAT = "realize.scene_state/1"
_KEYS = ("format", "base", "joints", "gripper_closed", "cube", "cube_held", "source")
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
class SceneState:
    """One copy's state (module docstring); checked when built."""

    base: tuple[float, float, float]
    joints: dict[str, float] = field(default_factory=dict)  # left out: the robot's rest pose
    gripper_closed: bool = False
    cube_position: tuple[float, float, float] = (0.0, 0.0, 0.0)
    cube_quaternion: tuple[float, float, float, float] = (1.0, 0.0, 0.0, 0.0)
    cube_held: bool = False
    source: str = ""

    def __post_init__(self) -> None:
        where = self.source or "state"
        object.__setattr__(self, "base", _floats(self.base, 3, f"{where}: base"))
        object.__setattr__(self, "cube_position", _floats(self.cube_position, 3, f"{where}: cube.position"))
        q = _floats(self.cube_quaternion, 4, f"{where}: cube.quaternion")
        norm = math.sqrt(sum(x * x for x in q))
        if abs(norm - 1.0) > _QUAT_TOL:
            raise ConfigError(f"{where}: cube.quaternion {list(q)} is invalid: not a unit quaternion (norm {norm:.4f})")
        object.__setattr__(self, "cube_quaternion", tuple(x / norm for x in q))
        if not isinstance(self.joints, Mapping):
            raise ConfigError(f"{where}: joints must be a mapping of joint name -> position")
        joints = {}
        for name, v in self.joints.items():
            if not isinstance(name, str) or not name:
                raise ConfigError(f"{where}: joints has a key {name!r} that is not a joint name")
            joints[name] = _floats([v], 1, f"{where}: joints.{name}")[0]
        object.__setattr__(self, "joints", joints)
        _flag(self.gripper_closed, f"{where}: gripper_closed")
        _flag(self.cube_held, f"{where}: cube_held")
        if self.cube_held and not self.gripper_closed:
            raise ConfigError(f"{where}: cube_held is true but gripper_closed is false (a held cube needs a "
                              "closed gripper)")

    def to_json(self) -> dict[str, Any]:
        return {
            "format": STATE_FORMAT,
            "base": list(self.base),
            "joints": dict(self.joints),
            "gripper_closed": self.gripper_closed,
            "cube": {"position": list(self.cube_position), "quaternion": list(self.cube_quaternion)},
            "cube_held": self.cube_held,
            "source": self.source,
        }

    @classmethod
    def from_json(cls, d: Any, where: str = "state") -> SceneState:
        """A state from ``to_json``'s object (``where`` names the file in errors). Required:
        ``base``, ``cube`` (``position``, ``quaternion``); optional: ``joints`` (rest pose),
        ``gripper_closed`` and ``cube_held`` (false), ``format``, ``source``."""
        if not isinstance(d, Mapping):
            raise ConfigError(f"{where}: a scene state is a JSON object, got {type(d).__name__}")
        unknown = sorted(set(d) - set(_KEYS))
        if unknown:
            raise ConfigError(f"{where}: unknown key(s) {unknown}; allowed: {list(_KEYS)}")
        missing = [k for k in ("base", "cube") if k not in d]
        if missing:
            raise ConfigError(f"{where}: missing key(s) {missing}")
        fmt = d.get("format", STATE_FORMAT)
        if fmt != STATE_FORMAT:
            raise ConfigError(f"{where}: format = {fmt!r} is not {STATE_FORMAT!r}")
        cube = d["cube"]
        if not isinstance(cube, Mapping) or set(cube) != {"position", "quaternion"}:
            raise ConfigError(f"{where}: cube must be an object with exactly the keys 'position' and 'quaternion'")
        source = d.get("source", "")
        return cls(base=_floats(d["base"], 3, f"{where}: base"), joints=d.get("joints", {}),
                   gripper_closed=_flag(d.get("gripper_closed", False), f"{where}: gripper_closed"),
                   cube_position=_floats(cube["position"], 3, f"{where}: cube.position"),
                   cube_quaternion=_floats(cube["quaternion"], 4, f"{where}: cube.quaternion"),
                   cube_held=_flag(d.get("cube_held", False), f"{where}: cube_held"),
                   source=str(source) if source else where)


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
