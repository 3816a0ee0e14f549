"""Hand an executed world to a robot stack: the export formats and the one call the executor makes.

What it does: ``export_formats("ros2,lerobot")`` parses and checks the formats asked for (a bad
name is one ``ConfigError`` line, before anything runs); ``ExportOptions`` holds what the
export needs beyond the files (the acceleration limit of the arm's time parameterization,
the gripper's open/closed targets and force); ``ExportOptions.for_robot(spec)`` takes them from
a robot config. ``export_world(trajectory_npz, world_json, out_dir, formats, robot, ...)``
writes, for one executed world:
  * ``ros2``: ``<stem>.mcap`` beside nothing else (``realize.execution.ros2_export``);
  * ``lerobot``: the world's episode in the LeRobot dataset ``out_dir/lerobot/<mode>/``
    (``realize.execution.lerobot_export``), rewritten from every ``world-*-<mode>.npz`` in
    ``out_dir`` so that episode k is world k and a killed study's dataset stays whole.
It returns an ``ExportResult`` (files written, seconds per format, the bag's timing report).
What it doesn't: execute anything, or read the robot's acceleration limits from its config
(URDFs have none and ``RobotSpec`` has no such key: adding one changes every robot config's
hash, the compiled fabric's cache key among them; the limit is ``ExportOptions.acceleration_limit``,
``--accel-limit`` of scripts/execute.py).
"""

from __future__ import annotations

import json
import re
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

from realize.config import ConfigError, did_you_mean
from realize.execution.time_param import DEFAULT_ACCELERATION_LIMIT

if TYPE_CHECKING:
    from realize.execution.ros2_export import BagReport, Observations
    from realize.robot.spec import RobotSpec

__all__ = ["DEFAULT_ACCELERATION_LIMIT", "FORMATS", "LEROBOT_DIR", "ExportOptions", "ExportResult", "export_formats", "export_world"]

FORMATS = ("ros2", "lerobot")
LEROBOT_DIR = "lerobot"
_WORLD_FILE = re.compile(r"world-(\d+)-(\w+)\.npz$")


def export_formats(text: str | Sequence[str] | None) -> tuple[str, ...]:
    """``"ros2,lerobot"`` (or a sequence of names; empty or None: none) -> the formats in the
    order given, once each; an unknown name is a one-line ``ConfigError``."""
    if text is None:
        return ()
    parts = [p.strip() for p in (text.split(",") if isinstance(text, str) else text)]
    out: list[str] = []
    for p in parts:
        if not p:
            continue
        if p not in FORMATS:
            raise ConfigError(f"export format {p!r} is unknown{did_you_mean(p, list(FORMATS))}; "
                              f"allowed: {', '.join(FORMATS)} (comma-separated)")
        if p not in out:
            out.append(p)
    return tuple(out)


@dataclass(frozen=True)
class ExportOptions:
    """What an export needs beyond the files: the arm's acceleration limit (rad/s^2, m/s^2 for
    prismatic joints; every joint), and the gripper's targets (m) and force (N)."""

    acceleration_limit: float = DEFAULT_ACCELERATION_LIMIT
    gripper_open: float = 0.05
    gripper_closed: float = -0.01
    gripper_force: float = 100.0

    def __post_init__(self) -> None:
        a = self.acceleration_limit
        if isinstance(a, bool) or not isinstance(a, (int, float)) or not (0 < a < float("inf")):
            raise ConfigError(f"export acceleration limit = {a!r} is invalid: must be a finite number > 0 (rad/s^2)")

    @classmethod
    def for_robot(cls, robot: RobotSpec, acceleration_limit: float = DEFAULT_ACCELERATION_LIMIT) -> ExportOptions:
        g = robot.gripper
        return cls(float(acceleration_limit), float(g.open), float(g.closed), float(g.force))


@dataclass
class ExportResult:
    """What ``export_world`` wrote: files (relative to ``out_dir``), seconds per format, the bag's report."""

    files: list[str] = field(default_factory=list)
    seconds: dict[str, float] = field(default_factory=dict)
    bag: BagReport | None = None


def export_world(trajectory_npz: str | Path, world_json: str | Path | None, out_dir: str | Path,
                 formats: Sequence[str], robot: RobotSpec, *, options: ExportOptions | None = None,
                 observations: Observations | None = None) -> ExportResult:
    """Export one executed world (module docstring); ``world_json`` (its ``WorldLog``, None: no
    events), ``robot`` the run's robot config (its URDF's velocity limits, its gripper)."""
    from realize.execution.trajectory import read_trajectory
    from realize.robot.urdf import source_urdf

    formats = export_formats(list(formats))
    npz, out = Path(trajectory_npz), Path(out_dir)
    opts = options or ExportOptions.for_robot(robot)
    result = ExportResult()
    traj = read_trajectory(npz)
    if "ros2" in formats:
        from realize.execution.ros2_export import GripperValues, write_ros2_bag
        from realize.execution.time_param import joint_limits

        t0 = time.perf_counter()
        world = json.loads(Path(world_json).read_text()) if world_json is not None else {}
        limits = joint_limits(source_urdf(robot.urdf), traj.joint_names, opts.acceleration_limit)
        bag = out / (npz.stem + ".mcap")
        result.bag = write_ros2_bag(bag, traj, world, limits,
                                    GripperValues(opts.gripper_open, opts.gripper_closed, opts.gripper_force),
                                    observations)
        result.files.append(bag.name)
        result.seconds["ros2"] = time.perf_counter() - t0
    if "lerobot" in formats:
        from realize.execution.lerobot_export import episode_from_trajectory, write_lerobot_dataset

        t0 = time.perf_counter()
        m = _WORLD_FILE.search(npz.name)
        mode = m.group(2) if m else "episodes"
        files = sorted(out.glob(f"world-*-{mode}.npz"), key=lambda p: int(_WORLD_FILE.search(p.name).group(1))) \
            if m else [npz]  # type: ignore[union-attr]
        episodes = [episode_from_trajectory(traj if f.resolve() == npz.resolve() else read_trajectory(f)) for f in files]
        root = write_lerobot_dataset(out / LEROBOT_DIR / mode, episodes, traj.control_freq, robot.name)
        result.files.append(str(root.relative_to(out)))
        result.seconds["lerobot"] = time.perf_counter() - t0
    return result
