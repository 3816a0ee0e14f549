"""The executed trajectory as a file a real robot's driver can follow (format: docs/execution_format.md).

What it does: ``TrajectoryLog`` collects, per control step, what the executor commanded: the
upper-joint position targets by name, the base velocity (vx, vy, yaw rate; the copy's local
frame) and the gripper command, with the index and text of the action that step belongs to.
``save(path)`` writes a compressed ``.npz`` (``TRAJECTORY_FORMAT``): arrays ``step``, ``t_s``,
``action``, ``plan_index``, ``joint_names``, ``joint_targets (T, J)``, ``base_velocity (T, 3)``, ``gripper (T,)``,
``action_boundaries (A, 2)`` (first and last row of each action, in order of execution),
``action_text (A,)``, ``control_freq`` and ``format``; where the log was given what the robot
measured at each step (its encoders and localization, once the step's command has run), also
``joint_positions (T, J)`` and ``base_pose (T, 3)`` (x, y, yaw). ``read_trajectory(path)`` reads
it back as a ``Trajectory`` and checks the format and the shapes.
``from_scene(scene, ...)`` is a convenience that appends the scene's current commanded
targets (``BatchedScene.commanded_targets``, copy 0) and its measured joints and base.
What it doesn't: simulate or drive anything; it keeps what it is given (units are the scene's).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from realize.config import ConfigError

if TYPE_CHECKING:
    from realize.scene import BatchedScene

__all__ = ["TRAJECTORY_FORMAT", "TrajectoryLog", "Trajectory", "read_trajectory"]

TRAJECTORY_FORMAT = "realize.trajectory/1"


@dataclass(frozen=True)
class Trajectory:
    """A read trajectory file (docs/execution_format.md); T control steps, J joints, A actions."""

    format: str
    control_freq: float
    step: np.ndarray  # (T,) int64 control step of the execution
    t_s: np.ndarray  # (T,) float64 s: step / control_freq
    action: np.ndarray  # (T,) int64 row of action_text the step belongs to
    plan_index: np.ndarray  # (T,) int64 index of that action in the plan being executed then
    joint_names: tuple[str, ...]
    joint_targets: np.ndarray  # (T, J) float64 position targets (rad; m for prismatic joints)
    base_velocity: np.ndarray  # (T, 3) float64 vx, vy (m/s), yaw rate (rad/s), world frame
    gripper: np.ndarray  # (T,) bool closed
    action_boundaries: np.ndarray  # (A, 2) int64 first and last row (inclusive) of each action
    action_text: tuple[str, ...]
    joint_positions: np.ndarray | None = None  # (T, J) float64 measured once the step's command has run
    base_pose: np.ndarray | None = None  # (T, 3) float64 x, y (m), yaw (rad), measured likewise

    def __len__(self) -> int:
        return len(self.step)


class TrajectoryLog:
    """Append per control step, then ``save`` (module docstring). ``control_freq``: Hz of the
    control steps (``sim.control_freq``)."""

    def __init__(self, control_freq: float):
        if not control_freq > 0:
            raise ConfigError(f"control_freq = {control_freq!r} is invalid: must be > 0")
        self.control_freq = float(control_freq)
        self.joint_names: tuple[str, ...] | None = None
        self._rows: list[tuple[int, int, list[float], tuple[float, float, float], bool]] = []
        self._texts: list[str] = []  # one per segment (a run of rows of one action)
        self._segments: list[list[int]] = []  # [first row, last row] per segment
        self._measured: list[list[float]] = []  # per row: joint positions, then base x, y, yaw

    def __len__(self) -> int:
        return len(self._rows)

    def append(self, step: int, action_index: int, action_text: str, joint_targets: Mapping[str, float],
               base_velocity: Sequence[float], gripper_closed: bool,
               measured: Sequence[float] | None = None) -> None:
        """One control step: ``step`` (increasing), the action being executed (its index in the
        plan being run and its text: a new segment starts whenever either changes), the joint
        position targets by name (the same names every step), (vx, vy, wz), the gripper command;
        ``measured``: the joint positions (the targets' order) then base x, y, yaw, as the robot
        read them once this command has run (given at every step or never)."""
        names = tuple(joint_targets)
        if self.joint_names is None:
            self.joint_names = names
        elif names != self.joint_names:
            raise ConfigError(f"joint_targets names {list(names)} differ from the first step's {list(self.joint_names)}")
        if self._rows and step <= self._rows[-1][0]:
            raise ConfigError(f"step = {step!r} is invalid: steps must increase (last {self._rows[-1][0]})")
        bv = tuple(float(v) for v in base_velocity)
        if len(bv) != 3:
            raise ConfigError(f"base_velocity = {base_velocity!r} is invalid: must be (vx, vy, wz)")
        if (measured is None) != (not self._measured) and self._rows:
            raise ConfigError("measured: give it at every step or never (a log has it for every row or none)")
        if measured is not None:
            m = [float(v) for v in measured]
            if len(m) != len(names) + 3:
                raise ConfigError(f"measured has {len(m)} values, expected {len(names) + 3} (joints, then x, y, yaw)")
            self._measured.append(m)
        row = len(self._rows)
        if not self._segments or self._texts[-1] != action_text or self._rows[-1][1] != action_index:
            self._texts.append(str(action_text))
            self._segments.append([row, row])
        else:
            self._segments[-1][1] = row
        self._rows.append((int(step), int(action_index), [float(joint_targets[n]) for n in names], bv,
                           bool(gripper_closed)))

    def from_scene(self, scene: BatchedScene, action_index: int, action_text: str, copy: int = 0) -> None:
        """Append the scene's commanded targets of ``copy`` at its current ``step_count``, with
        its measured joints and base."""
        from realize.robot.layout import BASE, UPPER

        base, arm, grip = scene.commanded_targets()
        targets = dict(zip(scene.robot.upper.joints, arm[copy].tolist()))
        q = scene.whole_body_q()[copy]
        self.append(scene.step_count, action_index, action_text, targets, base[copy].tolist(), bool(grip[copy]),
                    q[UPPER].tolist() + q[BASE].tolist())

    def arrays(self) -> dict[str, np.ndarray]:
        n = len(self._rows)
        names = self.joint_names or ()
        seg_of_row = np.empty(n, dtype=np.int64)
        for s, (a, b) in enumerate(self._segments):
            seg_of_row[a:b + 1] = s
        step = np.array([r[0] for r in self._rows], dtype=np.int64)
        return {
            "format": np.array(TRAJECTORY_FORMAT),
            "control_freq": np.array(self.control_freq),
            "step": step,
            "t_s": step / self.control_freq,
            "action": seg_of_row,
            "plan_index": np.array([r[1] for r in self._rows], dtype=np.int64),
            "joint_names": np.array(names, dtype=str),
            "joint_targets": np.array([r[2] for r in self._rows], dtype=np.float64).reshape(n, len(names)),
            "base_velocity": np.array([r[3] for r in self._rows], dtype=np.float64).reshape(n, 3),
            "gripper": np.array([r[4] for r in self._rows], dtype=bool),
            "action_boundaries": np.array(self._segments, dtype=np.int64).reshape(-1, 2),
            "action_text": np.array(self._texts, dtype=str),
            **({"joint_positions": np.array([m[:-3] for m in self._measured], dtype=np.float64).reshape(n, len(names)),
                "base_pose": np.array([m[-3:] for m in self._measured], dtype=np.float64).reshape(n, 3)}
               if self._measured else {}),
        }

    def save(self, path: str | Path) -> Path:
        """Write the compressed .npz (the suffix ``.npz`` is added where missing)."""
        path = Path(path)
        if path.suffix != ".npz":
            path = path.with_name(path.name + ".npz")
        path.parent.mkdir(parents=True, exist_ok=True)
        np.savez_compressed(path, **self.arrays())
        return path


def read_trajectory(path: str | Path) -> Trajectory:
    """Read a trajectory file; a wrong format or inconsistent shapes are one ``ConfigError``."""
    path = Path(path)
    try:
        with np.load(path, allow_pickle=False) as z:
            d: dict[str, Any] = {k: z[k] for k in z.files}
    except (OSError, ValueError) as e:
        raise ConfigError(f"{path}: not a trajectory file ({e})") from None
    need = ("format", "control_freq", "step", "t_s", "action", "plan_index", "joint_names", "joint_targets", "base_velocity",
            "gripper", "action_boundaries", "action_text")
    missing = [k for k in need if k not in d]
    if missing:
        raise ConfigError(f"{path}: arrays {missing} are missing")
    fmt = str(d["format"])
    if fmt != TRAJECTORY_FORMAT:
        raise ConfigError(f"{path}: format {fmt!r} is not {TRAJECTORY_FORMAT!r}")
    t = len(d["step"])
    j = len(d["joint_names"])
    shapes = {"t_s": (t,), "action": (t,), "plan_index": (t,), "joint_targets": (t, j), "base_velocity": (t, 3), "gripper": (t,),
              "action_boundaries": (len(d["action_text"]), 2)}
    if ("joint_positions" in d) != ("base_pose" in d):
        raise ConfigError(f"{path}: joint_positions and base_pose come together (one of them is missing)")
    if "joint_positions" in d:
        shapes.update({"joint_positions": (t, j), "base_pose": (t, 3)})
    for k, shape in shapes.items():
        if d[k].shape != shape:
            raise ConfigError(f"{path}: {k} has shape {d[k].shape}, expected {shape}")
    return Trajectory(fmt, float(d["control_freq"]), d["step"], d["t_s"], d["action"], d["plan_index"],
                      tuple(str(n) for n in d["joint_names"]), d["joint_targets"], d["base_velocity"],
                      d["gripper"].astype(bool), d["action_boundaries"], tuple(str(s) for s in d["action_text"]),
                      d.get("joint_positions"), d.get("base_pose"))
