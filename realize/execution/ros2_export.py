"""An executed trajectory as a ROS 2 bag in MCAP storage (written with ``rosbags``; no ROS install).

What it does: ``write_ros2_bag(path, trajectory, world, ...)`` writes one ``.mcap`` file
(topics and message types in docs/execution_format.md, "ROS 2 bag"):
  * ``/realize/arm/joint_trajectory`` ``trajectory_msgs/msg/JointTrajectory``: one per action
    segment, stamped (bag time and ``header.stamp``) at the segment's first control step;
    points from ``realize.execution.time_param.timed_segment`` (positions, velocities,
    ``time_from_start``; within the URDF's velocity limits and the given acceleration limit);
  * ``/realize/base/cmd_vel`` ``geometry_msgs/msg/Twist``: every control step, the base velocity
    command as executed, in the WORLD frame (x, y on the floor, z up), not REP 103's body frame;
  * ``/realize/gripper/command`` ``control_msgs/msg/GripperCommand`` (position, max_effort;
    registered from its message definition, the type is not in rosbags' standard store): at
    the first step and at every change of the command;
  * ``/realize/events`` ``std_msgs/msg/String``: JSON, one per action segment's start
    (``{"event": "action", ...}``), disturbance, deviation and replan of the world's log;
  * ``/realize/observed/<name>`` ``geometry_msgs/msg/PoseStamped`` (frame ``world``): the
    optional observations ``(time_s, {name: (x, y, z, qw, qx, qy, qz)})`` (``observed_topic``).
Every message's bag time is the execution's control time (``t_s`` of its step) in nanoseconds.
The bag is written as a rosbag2 directory and its one ``.mcap`` moved to ``path`` (a single
file, for ``ros2 bag play PATH -s mcap``; not played here: there is no ROS 2 install).
What it doesn't: read bags back (tests use the ``mcap`` reader), convert the base command to
the robot's frame (the executed yaw is not in the trajectory file), or export fingers, head
or other held joints (the gripper command stands for the fingers).
"""

from __future__ import annotations

import json
import re
import shutil
import tempfile
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from realize.execution.time_param import JointLimits, TimedSegment, timed_segment
from realize.execution.trajectory import Trajectory

__all__ = ["ARM_TOPIC", "BASE_TOPIC", "GRIPPER_TOPIC", "EVENTS_TOPIC", "OBSERVED_PREFIX", "GRIPPER_COMMAND_MSG",
           "TYPESTORE", "Observations", "observed_topic", "GripperValues", "BagReport", "typestore", "write_ros2_bag"]

ARM_TOPIC = "/realize/arm/joint_trajectory"
BASE_TOPIC = "/realize/base/cmd_vel"
GRIPPER_TOPIC = "/realize/gripper/command"
EVENTS_TOPIC = "/realize/events"
OBSERVED_PREFIX = "/realize/observed/"
TYPESTORE = "ROS2_JAZZY"  # rosbags' message store the standard types come from
# control_msgs/msg/GripperCommand as control_msgs defines it (the goal of control_msgs/action/GripperCommand)
GRIPPER_COMMAND_MSG = "float64 position\nfloat64 max_effort\n"

Observations = Sequence[tuple[float, Mapping[str, Sequence[float]]]]  # (time_s, name -> x, y, z, qw, qx, qy, qz)


@dataclass(frozen=True)
class GripperValues:
    """What the gripper command's bool becomes: the finger joint target (m) open and closed, and
    the most force the fingers may push with (N) (the robot config's ``gripper.open``,
    ``gripper.closed``, ``gripper.force``)."""

    open: float
    closed: float
    max_effort: float


@dataclass
class BagReport:
    """What a bag holds: messages per topic, and each segment's timing (time_param)."""

    path: str
    messages: dict[str, int] = field(default_factory=dict)
    segments: list[TimedSegment] = field(default_factory=list)

    @property
    def overrun_s(self) -> float:
        """Sum over segments of the time their arm motion needed beyond the executed one."""
        return float(sum(s.overrun_s for s in self.segments))


def typestore() -> Any:
    """rosbags' ROS 2 store (``TYPESTORE``) with ``control_msgs/msg/GripperCommand`` registered."""
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    store = get_typestore(getattr(Stores, TYPESTORE))
    store.register(get_types_from_msg(GRIPPER_COMMAND_MSG, "control_msgs/msg/GripperCommand"))
    return store


def observed_topic(name: str) -> str:
    """``/realize/observed/<name>``, characters a ROS 2 topic name cannot hold as ``_`` (and a
    leading digit behind one)."""
    token = re.sub(r"[^A-Za-z0-9_]", "_", name) or "_"
    return OBSERVED_PREFIX + ("_" + token if token[0].isdigit() else token)


def _ns(t_s: float) -> int:
    return int(round(t_s * 1e9))


def write_ros2_bag(path: str | Path, trajectory: Trajectory, world: Mapping[str, Any], limits: JointLimits,
                   gripper: GripperValues, observations: Observations | None = None) -> BagReport:
    """Write ``trajectory`` (and the events of ``world``, a ``WorldLog`` as a mapping) to the MCAP
    file ``path`` (module docstring); the arm's joints are ``limits.names`` (the trajectory's)."""
    from rosbags.rosbag2 import StoragePlugin, Writer

    if tuple(limits.names) != tuple(trajectory.joint_names):
        raise ValueError(f"limits name {list(limits.names)}, the trajectory {list(trajectory.joint_names)}")
    path = Path(path)
    store = typestore()
    T = store.types
    Time, Duration = T["builtin_interfaces/msg/Time"], T["builtin_interfaces/msg/Duration"]
    Header = T["std_msgs/msg/Header"]

    def stamp(t_s: float) -> Any:
        ns = _ns(t_s)
        return Time(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)

    report = BagReport(str(path))
    freq = trajectory.control_freq
    with tempfile.TemporaryDirectory(dir=path.parent if path.parent.exists() else None) as tmp:
        bag_dir = Path(tmp) / path.stem
        with Writer(bag_dir, version=9, storage_plugin=StoragePlugin.MCAP) as w:
            conns: dict[str, Any] = {}

            def put(topic: str, msgtype: str, t_s: float, msg: Any) -> None:
                if topic not in conns:
                    conns[topic] = w.add_connection(topic, msgtype, typestore=store)
                w.write(conns[topic], _ns(t_s), store.serialize_cdr(msg, msgtype))
                report.messages[topic] = report.messages.get(topic, 0) + 1

            events: list[tuple[float, dict[str, Any]]] = []
            names = list(trajectory.joint_names)
            for s, ((first, last), text) in enumerate(zip(trajectory.action_boundaries, trajectory.action_text)):
                t0 = float(trajectory.t_s[first])
                seg = timed_segment(trajectory.joint_targets[first:last + 1], trajectory.gripper[first:last + 1],
                                    freq, limits)
                report.segments.append(seg)
                points = [T["trajectory_msgs/msg/JointTrajectoryPoint"](
                    positions=np.asarray(q, dtype=np.float64), velocities=np.asarray(v, dtype=np.float64),
                    accelerations=np.zeros(0), effort=np.zeros(0),
                    time_from_start=Duration(sec=_ns(t) // 1_000_000_000, nanosec=_ns(t) % 1_000_000_000))
                    for t, q, v in zip(seg.t_s, seg.positions, seg.velocities)]
                msg = T["trajectory_msgs/msg/JointTrajectory"](header=Header(stamp=stamp(t0), frame_id=""),
                                                               joint_names=names, points=points)
                put(ARM_TOPIC, "trajectory_msgs/msg/JointTrajectory", t0, msg)
                events.append((t0, {"event": "action", "segment": s, "text": text,
                                    "plan_index": int(trajectory.plan_index[first]),
                                    "executed_s": seg.executed_s, "overrun_s": seg.overrun_s}))
            Vector3, Twist = T["geometry_msgs/msg/Vector3"], T["geometry_msgs/msg/Twist"]
            for t, (vx, vy, wz) in zip(trajectory.t_s, trajectory.base_velocity):
                put(BASE_TOPIC, "geometry_msgs/msg/Twist", float(t),
                    Twist(linear=Vector3(x=float(vx), y=float(vy), z=0.0), angular=Vector3(x=0.0, y=0.0, z=float(wz))))
            Grip = T["control_msgs/msg/GripperCommand"]
            last: bool | None = None
            for t, closed in zip(trajectory.t_s, trajectory.gripper):
                if last is None or bool(closed) != last:
                    put(GRIPPER_TOPIC, "control_msgs/msg/GripperCommand", float(t),
                        Grip(position=gripper.closed if closed else gripper.open, max_effort=gripper.max_effort))
                    last = bool(closed)
            for kind in ("disturbances", "deviations", "replans"):
                for e in world.get(kind, []):
                    events.append((int(e.get("step", 0)) / freq, {"event": kind[:-1], **e}))
            String = T["std_msgs/msg/String"]
            for t, e in sorted(events, key=lambda te: te[0]):
                put(EVENTS_TOPIC, "std_msgs/msg/String", t, String(data=json.dumps(e, default=str)))
            Pose, PoseStamped = T["geometry_msgs/msg/Pose"], T["geometry_msgs/msg/PoseStamped"]
            Point, Quaternion = T["geometry_msgs/msg/Point"], T["geometry_msgs/msg/Quaternion"]
            for t, poses in observations or ():
                for name, p in poses.items():
                    x, y, z, qw, qx, qy, qz = (float(v) for v in p)
                    put(observed_topic(name), "geometry_msgs/msg/PoseStamped", float(t), PoseStamped(
                        header=Header(stamp=stamp(float(t)), frame_id="world"),
                        pose=Pose(position=Point(x=x, y=y, z=z), orientation=Quaternion(x=qx, y=qy, z=qz, w=qw))))
        mcaps = sorted(bag_dir.glob("*.mcap"))
        if len(mcaps) != 1:
            raise RuntimeError(f"rosbags wrote {len(mcaps)} .mcap files in {bag_dir}, expected one")
        path.parent.mkdir(parents=True, exist_ok=True)
        shutil.move(str(mcaps[0]), path)
    return report
