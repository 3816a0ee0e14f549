"""What the executing robot perceives: noisy, late and dropped readings of its world, and the
filtered belief it decides from.

What it does:
  * ``Noise`` (``execute.noise``, presets ``configs/noise/*.yaml``): Gaussian noise on each
    object's position (``object_m`` per axis) and yaw (``object_deg``), on each table's and
    new box's centre (``table_m``); a base pose that drifts (``base_m``, ``base_deg``: the
    stationary spread of a first-order Gauss-Markov error with correlation time ``drift_s``,
    as odometry drifts and a localizer pulls it back); readings every ``every`` control steps
    that arrive ``latency_s`` late and of which a share ``drop`` is lost; the belief averages
    the last ``window`` readings of each thing and starts over when a reading lies more than
    ``jump_m`` from it (the thing moved). All zero: ``Noise.off``, the belief is the world.
  * ``Sensor(noise, control_dt, seed)``: ``read(truth)`` takes one reading of an exact
    ``Observation`` (``realize.execution.world``) at its step and queues it;
    ``deliver(step)`` returns the readings that have arrived by ``step``. Its random numbers
    come from one seeded generator, so the same seed gives the same readings.
  * ``Belief(noise)``: ``update(reading)`` folds an arrived reading in; ``observation(truth)``
    is the believed ``Observation``: the joints, the gripper and what the hand holds as the
    robot's own sensors give them (exact: encoders, the gripper's force); the base where
    odometry has it now, off by the drift of the newest arrived reading (odometry has no
    latency, the localizer's correction does); the objects not in hand, the tables and the
    boxes as filtered; an object in the hand where the hand holds it, moved with the base's
    error (its pose comes from the arm's kinematics, not the camera).
What it doesn't: move anything, decide whether a deviation needs a repair
(``realize.execution.monitor``, the executor), or model occlusion or misdetection (a dropped
reading loses everything it would have seen at once).
"""

from __future__ import annotations

import dataclasses
import math
from collections import deque
from dataclasses import dataclass
from pathlib import Path
from typing import ClassVar

import numpy as np
from realize.config import ConfigError, Settings, read_preset, setting
from realize.paths import CONFIG_DIR
from realize.world.state import ObjectPose

from realize.execution.world import BoxSeen, Observation, TablePose

__all__ = ["Noise", "Reading", "Sensor", "Belief", "NOISE_DIR", "noise_presets", "load_noise"]

NOISE_DIR = CONFIG_DIR / "noise"


@dataclass
class Noise(Settings):
    """The observation model (module docstring); units in the names (m, deg, s)."""

    config_key: ClassVar[str] = "execute.noise"

    object_m: float = setting(0.0, ge=0, le=0.1, help="std of each object position reading, per axis (m)")
    object_deg: float = setting(0.0, ge=0, le=45, help="std of each object yaw reading (deg)")
    table_m: float = setting(0.0, ge=0, le=0.1, help="std of each table or box centre reading, per axis (m)")
    base_m: float = setting(0.0, ge=0, le=0.5, help="stationary std of the base position error, per axis (m)")
    base_deg: float = setting(0.0, ge=0, le=45, help="stationary std of the base heading error (deg)")
    drift_s: float = setting(5.0, gt=0, help="correlation time of the base error (s)")
    latency_s: float = setting(0.0, ge=0, le=5, help="every reading arrives this late (s)")
    drop: float = setting(0.0, ge=0, lt=1, help="share of readings lost")
    every: int = setting(2, ge=1, help="control steps between readings")
    window: int = setting(5, ge=1, help="readings the belief averages")
    jump_m: float = setting(0.05, gt=0, help="a reading this far from the belief starts its average over (m)")

    @property
    def off(self) -> bool:
        """No noise, no drift, no latency, nothing dropped: the belief is the world itself."""
        return not any((self.object_m, self.object_deg, self.table_m, self.base_m, self.base_deg, self.latency_s,
                        self.drop))


def noise_presets() -> list[str]:
    """The preset names of ``configs/noise/``."""
    return sorted(p.stem for p in NOISE_DIR.glob("*.yaml"))


def load_noise(name: str | Path) -> Noise:
    """``configs/noise/<name>.yaml`` (or the YAML file ``name``) as ``Noise``; an unknown name,
    a missing file, bad YAML or a bad key is one ``ConfigError``."""
    d, stem = read_preset(name, NOISE_DIR, "noise preset")
    return Noise.from_mapping(d, f"noise[{stem}]")


@dataclass(frozen=True)
class Reading:
    """One noisy reading taken at ``step``: base (x, y, yaw), objects not in hand (position,
    yaw), tables and boxes (centre); ``base_error`` is the drift it carried (to shift what the
    hand holds along)."""

    step: int
    base: tuple[float, float, float]
    base_error: tuple[float, float, float]
    objects: dict[str, tuple[tuple[float, float, float], float]]
    tables: dict[str, tuple[float, float]]
    boxes: dict[str, tuple[float, float]]


def _yaw_of(q: tuple[float, ...]) -> float:
    w, x, y, z = q
    return math.atan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))


def _turn(q: tuple[float, ...], dyaw: float) -> tuple[float, float, float, float]:
    """The quaternion ``q`` (wxyz) turned by ``dyaw`` about the world's z."""
    c, s = math.cos(dyaw / 2), math.sin(dyaw / 2)
    w, x, y, z = q
    out = (c * w - s * z, c * x - s * y, c * y + s * x, c * z + s * w)
    n = math.sqrt(sum(v * v for v in out))
    return tuple(v / n for v in out)  # type: ignore[return-value]


class Sensor:
    """Noisy, late, dropped readings of exact observations (module docstring)."""

    def __init__(self, noise: Noise, control_dt: float, seed: int) -> None:
        self.noise, self.dt = noise, float(control_dt)
        self.rng = np.random.default_rng([int(seed), 55])
        self.latency_steps = int(round(noise.latency_s / self.dt))
        self._error = np.zeros(3)  # the base's drift (x, y, yaw)
        self._last_step: int | None = None
        self._queue: deque[Reading] = deque()

    def _drift(self, step: int) -> np.ndarray:
        n = self.noise
        sigma = np.array([n.base_m, n.base_m, math.radians(n.base_deg)])
        if self._last_step is None:
            self._error = sigma * self.rng.standard_normal(3)
        else:
            a = math.exp(-(step - self._last_step) * self.dt / n.drift_s)
            self._error = a * self._error + sigma * math.sqrt(1 - a * a) * self.rng.standard_normal(3)
        self._last_step = step
        return self._error

    def read(self, truth: Observation) -> Reading | None:
        """One reading of ``truth`` (queued; None where it was dropped). Every reading draws
        the same random numbers, dropped or not, so a drop changes no later reading."""
        n, s = self.noise, truth.state
        err = self._drift(truth.step).copy()
        objects = {}
        for name, pose in s.objects.items():
            d = self.rng.standard_normal(4)
            p = tuple(float(v) for v in np.asarray(pose.position) + n.object_m * d[:3])
            objects[name] = (p, _yaw_of(pose.quaternion) + math.radians(n.object_deg) * float(d[3]))
        tables = {name: (t.x + n.table_m * float(a), t.y + n.table_m * float(b))
                  for (name, t), (a, b) in zip(truth.tables.items(), self.rng.standard_normal((len(truth.tables), 2)))}
        boxes = {b.name: (b.center[0] + n.table_m * float(u), b.center[1] + n.table_m * float(v))
                 for b, (u, v) in zip(truth.boxes, self.rng.standard_normal((len(truth.boxes), 2)))}
        lost = bool(self.rng.random() < n.drop)
        if s.held is not None:
            objects.pop(s.held, None)
        if lost:
            return None
        base = (s.base[0] + err[0], s.base[1] + err[1], s.base[2] + err[2])
        r = Reading(truth.step, tuple(float(v) for v in base), tuple(float(v) for v in err), objects, tables,  # type: ignore[arg-type]
                    boxes)
        self._queue.append(r)
        return r

    def deliver(self, step: int) -> list[Reading]:
        """The queued readings taken at least ``latency_s`` before ``step``, oldest first."""
        out = []
        while self._queue and self._queue[0].step + self.latency_steps <= step:
            out.append(self._queue.popleft())
        return out


class _Average:
    """The mean of the last ``window`` values of one thing, started over on a jump."""

    def __init__(self, window: int, jump: float) -> None:
        self.values: deque[np.ndarray] = deque(maxlen=window)
        self.jump = jump

    def add(self, v: np.ndarray, spatial: int) -> None:
        if self.values and float(np.linalg.norm(v[:spatial] - self.mean()[:spatial])) > self.jump:
            self.values.clear()
        self.values.append(v)

    def mean(self) -> np.ndarray:
        a = np.stack(self.values)
        m = a.mean(axis=0)
        if a.shape[1] == 4:  # position and yaw: the yaw's circular mean
            m[3] = math.atan2(float(np.sin(a[:, 3]).mean()), float(np.cos(a[:, 3]).mean()))
        return m


class Belief:
    """The filtered belief (module docstring). Before its first reading it knows nothing: the
    executor feeds it a reading taken at the world's start, before the robot moves."""

    def __init__(self, noise: Noise) -> None:
        self.noise = noise
        self._objects: dict[str, _Average] = {}
        self._tables: dict[str, _Average] = {}
        self._boxes: dict[str, _Average] = {}
        self._base_error = np.zeros(3)
        self.readings = 0
        self.last_step = -1

    def _fold(self, into: dict[str, _Average], name: str, v: np.ndarray, spatial: int) -> None:
        if name not in into:
            into[name] = _Average(self.noise.window, self.noise.jump_m)
        into[name].add(v, spatial)

    def update(self, r: Reading) -> None:
        self.readings += 1
        self.last_step = r.step
        for name, (p, yaw) in r.objects.items():
            self._fold(self._objects, name, np.array([*p, yaw]), 3)
        for name, c in r.tables.items():
            self._fold(self._tables, name, np.array(c), 2)
        for name, c in r.boxes.items():
            self._fold(self._boxes, name, np.array(c), 2)
        self._base_error = np.array(r.base_error)  # the localizer's newest correction

    @property
    def base_error(self) -> tuple[float, float, float]:
        """How far off (x, y, yaw) the localizer has the base now: believed minus true."""
        return (float(self._base_error[0]), float(self._base_error[1]), float(self._base_error[2]))

    def observation(self, truth: Observation) -> Observation:
        """The believed ``Observation`` at ``truth``'s step (module docstring)."""
        if self.readings == 0:
            raise ConfigError("the belief has no reading yet: feed it one taken at the world's start")
        s = truth.state
        ex, ey, eyaw = (float(v) for v in self._base_error)
        bx, by, byaw = s.base[0] + ex, s.base[1] + ey, s.base[2] + eyaw
        objects = {}
        if s.held is not None:  # the camera's readings of it are stale now: the hand knows where it is
            self._objects.pop(s.held, None)
        c, si = math.cos(eyaw), math.sin(eyaw)
        for name, pose in s.objects.items():
            if name == s.held or name not in self._objects:  # where the hand holds it: moved with the base's error
                dx, dy = pose.position[0] - s.base[0], pose.position[1] - s.base[1]
                p = (s.base[0] + ex + c * dx - si * dy, s.base[1] + ey + si * dx + c * dy, pose.position[2])
                objects[name] = ObjectPose(p, _turn(pose.quaternion, eyaw), where=f"objects.{name}")
                continue
            m = self._objects[name].mean()
            dyaw = float(m[3]) - _yaw_of(pose.quaternion)
            objects[name] = ObjectPose(tuple(float(v) for v in m[:3]), _turn(pose.quaternion, dyaw),  # type: ignore[arg-type]
                                       where=f"objects.{name}")
        state = dataclasses.replace(s, base=(bx, by, byaw), objects=objects,
                                    source=f"belief at step {truth.step} ({self.readings} readings, last of step "
                                           f"{self.last_step})")
        tables = {name: TablePose(*(float(v) for v in self._tables[name].mean()), t.yaw) if name in self._tables else t
                  for name, t in truth.tables.items()}
        boxes = tuple(BoxSeen(b.name, tuple(float(v) for v in self._boxes[b.name].mean()), b.size)  # type: ignore[arg-type]
                      for b in truth.boxes if b.name in self._boxes)
        hand = None
        if truth.hand is not None:  # the arm's kinematics from the believed base: moved with its error
            h = truth.hand
            dx, dy = h[0] - s.base[0], h[1] - s.base[1]
            hand = (s.base[0] + ex + c * dx - si * dy, s.base[1] + ey + si * dx + c * dy, h[2],
                    *_turn(tuple(h[3:]), eyaw))
        return Observation(truth.step, truth.time_s, state, tables, boxes, hand)
