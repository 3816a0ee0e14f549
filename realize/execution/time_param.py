"""Time-parameterize an executed arm path within the robot's joint limits (toppra).

What it does: ``joint_limits(urdf, names)`` reads each joint's velocity limit from the robot's
URDF (``realize.robot.urdf.parse_urdf_joints``); URDFs carry no acceleration limits, so one
scalar (rad/s^2, m/s^2 for prismatic joints) is given for every joint
(``DEFAULT_ACCELERATION_LIMIT``). ``parameterize(waypoints, limits)`` passes a joint path through
toppra (a cubic spline through the waypoints on their chord length, then the time-optimal
parameterization under the velocity and acceleration constraints, held at ``GRID_PER_WAYPOINT``
grid points per waypoint) and returns a ``TimedPath`` (samples of position and velocity
against time). ``segment_pieces(targets, gripper)`` cuts an executed action segment's rows into
pieces at the rows where the gripper command changes and where the arm starts or stops moving;
``timed_segment`` parameterizes every moving piece and,
where toppra's duration is shorter than the piece's executed duration, stretches its time
uniformly (velocities then scale down by the stretch, accelerations by its square, so the
limits still hold) so that each piece starts and ends when it did in the execution: the
arm stays in step with the base and gripper commands of the same clock. A piece that toppra
says needs longer than it had overruns (counted in ``TimedSegment.overrun_s``); a segment
where the arm does not move is one point at ``HOLD_DURATION_S``. Waypoints are
the control-rate targets with repeats (closer than ``MIN_STEP``) dropped, at most
``MAX_WAYPOINTS`` per piece (evenly thinned, the ends kept).
What it doesn't: write any file (``realize.execution.ros2_export``), check joint position limits
or collisions, or time the base (its velocity commands are exported as they were executed).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from realize.config import ConfigError

__all__ = ["DEFAULT_ACCELERATION_LIMIT", "GRID_PER_WAYPOINT", "MIN_STEP", "MAX_WAYPOINTS", "HOLD_DURATION_S", "JointLimits",
           "TimedPath", "TimedSegment", "joint_limits", "decimate", "parameterize", "segment_pieces", "timed_segment"]

DEFAULT_ACCELERATION_LIMIT = 1.5  # rad/s^2 (m/s^2 for prismatic joints), every joint: URDFs have none
MIN_STEP = 1e-4  # rad (m): a waypoint closer than this to the last kept one is a repeat
MAX_WAYPOINTS = 200  # per piece: toppra's spline through more adds nothing at 20 Hz
HOLD_DURATION_S = 0.05  # the one point of a segment where the arm does not move
# toppra holds the constraints at its grid points: 4 per waypoint (and the waypoints) keep the
# accelerations between them within a few per cent of the limit (its default grid: 9 % over)
GRID_PER_WAYPOINT = 4
_STILL = 1e-4  # rad (m) per control step: the arm counts as standing still below this


@dataclass(frozen=True)
class JointLimits:
    """Per joint (in ``names`` order): velocity limit (URDF) and acceleration limit."""

    names: tuple[str, ...]
    velocity: np.ndarray  # (J,) rad/s or m/s
    acceleration: np.ndarray  # (J,) rad/s^2 or m/s^2


@dataclass(frozen=True)
class TimedPath:
    """A parameterized path: K samples from t = 0 to ``duration_s``."""

    t_s: np.ndarray  # (K,)
    positions: np.ndarray  # (K, J)
    velocities: np.ndarray  # (K, J)
    duration_s: float
    waypoints: np.ndarray  # (W, J) the waypoints the spline passes through


@dataclass
class TimedSegment:
    """One action segment's arm trajectory: points relative to the segment's first row's time."""

    t_s: np.ndarray  # (K,) time from the segment's start, increasing
    positions: np.ndarray  # (K, J)
    velocities: np.ndarray  # (K, J)
    executed_s: float  # the segment's executed duration (rows / control_freq)
    optimal_s: list[float] = field(default_factory=list)  # toppra's duration of each moving piece
    overrun_s: float = 0.0  # how much longer than executed the pieces had to be (0: in step)


def joint_limits(urdf: str | Path, names: Sequence[str],
                 acceleration: float = DEFAULT_ACCELERATION_LIMIT) -> JointLimits:
    """Velocity limits of ``names`` from the URDF file, ``acceleration`` for every joint; a joint
    the URDF lacks or one without a finite velocity limit is a ``ConfigError``."""
    from realize.robot.urdf import parse_urdf_joints

    if not (acceleration > 0 and np.isfinite(acceleration)):
        raise ConfigError(f"acceleration limit = {acceleration!r} is invalid: must be a finite number > 0")
    by_name = {j.name: j for j in parse_urdf_joints(str(urdf)).values()}
    vel = []
    for n in names:
        if n not in by_name:
            raise ConfigError(f"joint {n!r} is not in {Path(urdf).name}")
        v = by_name[n].velocity
        if not (v > 0 and np.isfinite(v)):
            raise ConfigError(f"joint {n!r} of {Path(urdf).name} has no finite velocity limit ({v})")
        vel.append(v)
    return JointLimits(tuple(names), np.array(vel, dtype=np.float64), np.full(len(vel), float(acceleration)))


def decimate(points: np.ndarray, min_step: float = MIN_STEP, max_points: int = MAX_WAYPOINTS) -> np.ndarray:
    """The rows of ``points`` (N, J) without repeats (closer than ``min_step``, max-norm, to the
    last kept row), thinned evenly to at most ``max_points`` (first and last kept)."""
    points = np.asarray(points, dtype=np.float64)
    keep = [0]
    for i in range(1, len(points)):
        if np.abs(points[i] - points[keep[-1]]).max() >= min_step:
            keep.append(i)
    if len(keep) > 1 and keep[-1] != len(points) - 1:
        keep[-1] = len(points) - 1  # end exactly where the path ends
    if len(keep) > max_points:
        idx = np.unique(np.round(np.linspace(0, len(keep) - 1, max_points)).astype(int))
        keep = [keep[i] for i in idx]
    return points[keep]


def parameterize(waypoints: np.ndarray, limits: JointLimits, sample_dt: float = 0.05) -> TimedPath:
    """The time-optimal trajectory through ``waypoints`` (W >= 2 distinct rows) within ``limits``,
    sampled every ``sample_dt`` s and at its end; toppra's failure is a ``RuntimeError``."""
    import toppra
    import toppra.algorithm as algo
    import toppra.constraint as constraint

    w = np.asarray(waypoints, dtype=np.float64)
    if w.ndim != 2 or len(w) < 2 or w.shape[1] != len(limits.names):
        raise ValueError(f"waypoints of shape {w.shape}: need (W >= 2, {len(limits.names)})")
    chord = np.r_[0.0, np.cumsum(np.linalg.norm(np.diff(w, axis=0), axis=1))]
    if not np.all(np.diff(chord) > 0):
        raise ValueError("waypoints repeat: decimate them first")
    path = toppra.SplineInterpolator(chord / chord[-1], w)
    v, a = limits.velocity, limits.acceleration
    grid = np.unique(np.r_[np.linspace(0.0, 1.0, min(GRID_PER_WAYPOINT * len(w), 1000)), chord / chord[-1]])
    inst = algo.TOPPRA([constraint.JointVelocityConstraint(np.stack([-v, v], axis=1)),
                        constraint.JointAccelerationConstraint(np.stack([-a, a], axis=1))],
                       path, gridpoints=grid, parametrizer="ParametrizeConstAccel")
    traj = inst.compute_trajectory()
    if traj is None:
        raise RuntimeError(f"toppra found no parameterization of a path of {len(w)} waypoints")
    d = float(traj.duration)
    t = np.unique(np.r_[np.arange(0.0, d, sample_dt), d])
    return TimedPath(t, np.asarray(traj(t)), np.asarray(traj(t, 1)), d, w)


def segment_pieces(targets: np.ndarray, gripper: np.ndarray) -> list[tuple[int, int, bool]]:
    """Cut rows of one segment (``targets`` (N, J), ``gripper`` (N,)) into pieces
    ``(first, last, moving)``: consecutive pieces share their boundary row; a new piece starts
    where the arm starts or stops moving (a step of at least ``_STILL``) and where the gripper
    command changes."""
    n = len(targets)
    if n < 2:
        return [(0, max(n - 1, 0), False)]
    moving = np.abs(np.diff(targets, axis=0)).max(axis=1) >= _STILL  # step i -> i+1
    grip_change = np.r_[False, gripper[1:-1] != gripper[:-2]] if n > 2 else np.zeros(1, bool)
    pieces: list[tuple[int, int, bool]] = []
    start = 0
    for i in range(1, n - 1):  # boundary at row i: step i-1 -> i differs from step i -> i+1, or grip changes
        if moving[i] != moving[i - 1] or grip_change[i]:
            pieces.append((start, i, bool(moving[start:i].any())))
            start = i
    pieces.append((start, n - 1, bool(moving[start:n - 1].any())))
    return pieces


def timed_segment(targets: np.ndarray, gripper: np.ndarray, control_freq: float, limits: JointLimits,
                  sample_dt: float | None = None) -> TimedSegment:
    """One action segment's rows (module docstring): every moving piece parameterized by toppra
    and stretched to its executed duration where toppra is faster; still pieces hold."""
    targets = np.asarray(targets, dtype=np.float64)
    j = targets.shape[1]
    dt = 1.0 / control_freq
    sample_dt = dt if sample_dt is None else sample_dt
    executed = (len(targets) - 1) * dt
    pieces = [p for p in segment_pieces(targets, np.asarray(gripper, dtype=bool)) if p[2]]
    if not pieces or len(decimate(targets)) < 2:  # the arm does not move: one point, a minimal duration
        return TimedSegment(np.array([HOLD_DURATION_S]), targets[-1:].copy(), np.zeros((1, j)), executed)
    ts: list[np.ndarray] = [np.zeros(1)]
    qs: list[np.ndarray] = [targets[:1]]
    vs: list[np.ndarray] = [np.zeros((1, j))]
    optimal: list[float] = []
    clock = 0.0  # the time of the last point so far (>= the executed time of the next piece's first row)
    for first, last, _ in pieces:
        w = decimate(targets[first:last + 1])
        if len(w) < 2:
            continue
        start = max(first * dt, clock)
        tp = parameterize(w, limits, sample_dt)
        optimal.append(tp.duration_s)
        k = max((last - first) * dt / tp.duration_s, 1.0)  # stretched to the executed duration where faster
        keep = slice(0 if start > clock else 1, None)  # the piece's start point, where the arm held before it
        ts.append(start + tp.t_s[keep] * k)
        qs.append(tp.positions[keep])
        vs.append(tp.velocities[keep] / k)
        clock = start + tp.duration_s * k
    if clock < executed:  # hold the last point to the segment's executed end
        ts.append(np.array([executed]))
        qs.append(qs[-1][-1:])
        vs.append(np.zeros((1, j)))
    return TimedSegment(np.concatenate(ts), np.concatenate(qs), np.concatenate(vs), executed, optimal,
                        max(0.0, clock - executed))
