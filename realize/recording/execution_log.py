"""The rerun recording of one executed world: the robot, the objects and the events on the
control-step timeline.

What it does: ``ExecutionRecorder(path, spec, name)`` opens ``path`` (an ``.rrd``), logs the
world's tables and fixtures once (``world/fixtures``: boxes), then ``step(k, scene)`` logs at
control step ``k`` (timeline ``control_step``, every ``every``-th step) the base (a point and
its heading), the end effector and every movable object (boxes at their poses), and
``event(k, text)`` a line in ``world/events`` (disturbances, deviations, replans: rerun's
text log, on the same timeline) and a ``world/replans`` scalar that counts the replans.
``close()`` writes the footer.
What it doesn't: decide what happened (``realize.repair.study``), or draw the robot's links (the
search's recording does, ``realize.recording.world3d``).
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import rerun as rr

__all__ = ["ExecutionRecorder", "EXECUTION_TIMELINE"]

EXECUTION_TIMELINE = "control_step"


class ExecutionRecorder:
    """One executed world's ``.rrd`` (module docstring)."""

    def __init__(self, path: str | Path, spec: Any, name: str, every: int = 2) -> None:
        self.path, self.every = Path(path), max(1, int(every))
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self.rec = rr.RecordingStream(f"realize-execution-{name}")
        self.rec.save(str(self.path))
        self.replans = 0
        g = spec.geometry
        boxes = list(g.static_obstacles)
        if boxes:
            self.rec.log("world/fixtures", rr.Boxes3D(centers=[list(b.center) for b in boxes],
                                                       half_sizes=[list(b.half_size) for b in boxes],
                                                       labels=[b.name for b in boxes]), static=True)
        self.halves = [list(o.half_size) for o in g.objects]
        self.names = list(g.object_names)

    def step(self, k: int, scene: Any) -> None:
        if k % self.every:
            return
        rec = self.rec
        rec.set_time(EXECUTION_TIMELINE, sequence=int(k))
        x, y, yaw = scene.base_pose()[0].tolist()
        rec.log("world/base", rr.Points3D([[x, y, 0.05]], radii=[0.08], colors=[[60, 110, 200]]))
        rec.log("world/base/heading", rr.Arrows3D(origins=[[x, y, 0.05]],
                                                   vectors=[[0.4 * math.cos(yaw), 0.4 * math.sin(yaw), 0.0]]))
        ee = scene.ee_pose()[0, :3].tolist()
        rec.log("world/ee", rr.Points3D([ee], radii=[0.03], colors=[[230, 120, 30]]))
        poses = scene.object_poses()[0]
        centers = poses[:, :3].tolist()
        quats = [[q[1], q[2], q[3], q[0]] for q in poses[:, 3:].tolist()]  # wxyz -> rerun's xyzw
        rec.log("world/objects", rr.Boxes3D(centers=centers, half_sizes=self.halves, quaternions=quats,
                                            labels=self.names))

    def event(self, k: int, text: str) -> None:
        self.rec.set_time(EXECUTION_TIMELINE, sequence=int(k))
        self.rec.log("world/events", rr.TextLog(text))
        if text.startswith("replan"):
            self.replans += 1
            self.rec.log("world/replans", rr.Scalars(float(self.replans)))

    def close(self) -> None:
        self.rec.disconnect()
