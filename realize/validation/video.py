"""Videos of a replayed plan that a person can read: a camera that follows the robot and what it
acts on, and the action and control step written on every frame.

What it does:
  * ``VideoRecorder``: renders copy 0 of a ``BatchedScene`` into an MP4 (H.264 through imageio's
    ffmpeg) as a step hook, frame by frame (nothing is kept in memory but the last frame);
    with a ``FollowCamera`` it moves the render camera before each frame, and with a ``Caption``
    it writes a label onto it;
  * ``FollowCamera``: per frame, looks at the robot's base and the point the current action
    works on (the object for a grasp, the place point, a move's goal, a push point), from the
    side of the line between them, 1.7-1.95 m away during grasp and place (with ``FOLLOW_FOVY``
    a 4.5 cm cube is then about 25 px wide in a 960 x 720 frame); eye and target are
    smoothed from frame to frame;
  * ``Caption``: the label ``2/5 grasp(cube, Cube_g)   step 412   20.6 s``, the current action
    following the rollout's ``action_hook`` (``Caption.on_action``).
What it doesn't: run the rollout (``realize.validation.replay``), or choose a fixed camera (the scene's
``EnvOptions.camera``; a fixed eye/target disables the follow camera).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:
    from realize.scene import BatchedScene
    from realize.tasks.spec import TaskSpec

__all__ = ["VideoRecorder", "VideoReport", "FollowCamera", "Caption", "focus_points", "FOLLOW_FOVY"]

FOLLOW_FOVY = 0.9  # rad, the follow camera's vertical field of view (the tasks' render camera has 1.0)


@dataclass
class VideoReport:
    path: str
    frames: int
    fps: float
    every: int
    seconds: float  # video length
    bytes: int
    width: int
    height: int
    first_render_s: float  # the first frame (on lavapipe it compiles the shaders)
    render_s_per_frame: float  # mean over the other frames
    hold_s: float


def focus_points(task: TaskSpec, z: np.ndarray) -> list[tuple[str, np.ndarray]]:
    """Per action of ``task``'s plan: its kind (``move`` or ``manipulate``) and the world point
    (x, y, z) it works on, from the plan's parameter vector ``z`` (D,)."""
    from realize.tasks.hemisphere import Hemisphere

    out = []
    for a in task.plan:
        name = a.params[0]
        region = task.layout.regions[name]
        v = np.asarray(z[task.layout.slices[name]], dtype=np.float64)
        if a.template == "move_to":
            out.append(("move", np.array([v[0], v[1], 0.0])))
        elif isinstance(region, Hemisphere):  # grasp/place: the object point is the centre
            out.append(("manipulate", np.asarray(region.center, dtype=np.float64)))
        else:  # a 3-D release or push point
            out.append(("manipulate", np.array([v[0], v[1], v[2] if len(v) > 2 else 0.5])))
    return out


class FollowCamera:
    """The render camera's pose per frame (module docstring). ``action`` is the current one."""

    def __init__(self, points: list[tuple[str, np.ndarray]], smoothing: float = 0.25,
                 objects: list[str | None] | None = None) -> None:
        self.points = points
        self.objects = list(objects or [])  # per action: the object it handles (None: none)
        self.smoothing = float(smoothing)
        self.action = 0
        self.eye: np.ndarray | None = None
        self.target: np.ndarray | None = None
        self.side = np.array([0.0, -1.0])  # the first view looks from -y

    def pose(self, base_xy: np.ndarray, held_or_target: np.ndarray | None, holding: bool) -> tuple[np.ndarray, np.ndarray]:
        """(eye, target) for a frame with the base at ``base_xy`` and the current action's object
        at ``held_or_target`` (None: the action handles none)."""
        kind, point = self.points[min(self.action, len(self.points) - 1)]
        # grasp: the object; place: where it goes
        obj = held_or_target if kind == "manipulate" and not holding and held_or_target is not None else point
        base = np.array([base_xy[0], base_xy[1], 0.8])  # the robot's middle: base to shoulder in view
        w = 0.6 if kind == "manipulate" else 0.5
        target = w * obj + (1 - w) * base
        line = obj[:2] - base[:2]
        span = float(np.linalg.norm(line))
        if span > 1e-3:
            perp = np.array([-line[1], line[0]]) / span
            self.side = perp if float(perp @ self.side) >= 0 else -perp  # keep the side it looked from
        if kind == "manipulate":
            dist = min(max(1.55 + 0.3 * span, 1.7), 1.95)
        else:
            dist = min(max(2.0 + 0.8 * span, 2.6), 4.5)
        elev = math.radians(38.0)
        eye = target + dist * np.array([math.cos(elev) * self.side[0], math.cos(elev) * self.side[1], math.sin(elev)])
        if self.eye is None or self.target is None:
            self.eye, self.target = eye, target
        else:
            a = self.smoothing
            self.eye = (1 - a) * self.eye + a * eye
            self.target = (1 - a) * self.target + a * target
        return self.eye, self.target


class Caption:
    """The label of each frame: the current action of ``plan`` (numbered from 1), the control
    step and its time at ``control_freq`` Hz. ``on_action`` is the rollout's ``action_hook``."""

    def __init__(self, plan: list[str], control_freq: float, height: int) -> None:
        from PIL import ImageFont
        import matplotlib

        self.plan, self.control_freq = plan, float(control_freq)
        self.action = 0
        self.final: str | None = None  # the text of the held last frames
        size = max(14, int(height / 26))
        font = Path(matplotlib.get_data_path()) / "fonts" / "ttf" / "DejaVuSans-Bold.ttf"
        self.font = ImageFont.truetype(str(font), size)

    def on_action(self, a: int, rows: Any) -> None:
        if bool((rows == 0).any()):
            self.action = a

    def text(self, step: int) -> str:
        a = min(self.action, len(self.plan) - 1)
        return f"{a + 1}/{len(self.plan)} {self.plan[a]}   step {step}   {step / self.control_freq:.1f} s"

    def draw(self, frame: np.ndarray, text: str) -> np.ndarray:
        """``frame`` with ``text`` on a dark band along its top."""
        from PIL import Image, ImageDraw

        img = Image.fromarray(frame)
        d = ImageDraw.Draw(img)
        x0, y0, x1, y1 = d.textbbox((0, 0), text, font=self.font)
        pad = max(4, (y1 - y0) // 3)
        d.rectangle([0, 0, img.width, (y1 - y0) + 2 * pad + y0], fill=(20, 20, 20))
        d.text((pad, pad), text, fill=(255, 255, 255), font=self.font)
        return np.asarray(img)


def _camera(scene: BatchedScene) -> Any:
    """The ManiSkill render camera of the scene's task (what ``BatchedScene.render`` shows)."""
    cams = getattr(scene.env.unwrapped, "_human_render_cameras", None) or {}
    if "render_camera" not in cams:
        raise RuntimeError("the scene's task has no 'render_camera' to move (a follow camera needs one)")
    return cams["render_camera"].camera


class VideoRecorder:
    """Renders copy 0 of a scene into an MP4 (module docstring).

    Use as ``recorder.attach(scene)`` (a step hook every ``every`` control steps)."""

    def __init__(self, path: str | Path, fps: float = 20.0, every: int = 1, quality: int = 7,
                 follow: FollowCamera | None = None, caption: Caption | None = None) -> None:
        import imageio.v2 as imageio

        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self.fps, self.every = float(fps), int(every)
        self.follow, self.caption = follow, caption
        self._writer = imageio.get_writer(str(self.path), format="FFMPEG", mode="I", fps=self.fps, codec="libx264",
                                          quality=quality, pixelformat="yuv420p", macro_block_size=1)
        self.scene: BatchedScene | None = None
        self.frames = 0
        self.render_times: list[float] = []
        self.last: np.ndarray | None = None
        self.shape: tuple[int, int] = (0, 0)

    def attach(self, scene: BatchedScene) -> None:
        self.scene = scene
        scene.add_step_hook(self, self.every)

    def _aim(self) -> None:
        import sapien
        from mani_skill.utils import sapien_utils

        assert self.scene is not None and self.follow is not None
        if self.caption is not None:
            self.follow.action = self.caption.action
        base = self.scene.base_pose()[0].cpu().numpy()
        objects = self.follow.objects
        name = objects[min(self.follow.action, len(objects) - 1)] if objects else None
        obj = None if name is None else self.scene.object_pose(name)[0, :3].cpu().numpy().astype(np.float64)
        holding = name is not None and bool(self.scene.holds(name)[0])
        eye, target = self.follow.pose(base[:2], obj, holding)
        pose = sapien_utils.look_at(eye=eye.tolist(), target=target.tolist())
        cam = _camera(self.scene)
        if self.frames == 0:
            cam.set_fovy(FOLLOW_FOVY)
        cam.set_local_pose(sapien.Pose(pose.raw_pose[0, :3].cpu().numpy(),
                                                        pose.raw_pose[0, 3:].cpu().numpy()))

    def __call__(self, step: int) -> None:
        assert self.scene is not None
        t0 = time.perf_counter()
        if self.follow is not None:
            self._aim()
        frame = np.ascontiguousarray(self.scene.render()[..., :3]).astype(np.uint8, copy=False)
        if self.caption is not None:
            frame = self.caption.draw(frame, self.caption.text(step))
        self.render_times.append(time.perf_counter() - t0)
        self._writer.append_data(frame)
        self.frames += 1
        self.last = frame
        self.shape = frame.shape[:2]

    def close(self, hold_s: float = 0.0, final_text: str | None = None) -> VideoReport:
        """Repeat the last frame for ``hold_s`` seconds (captioned ``final_text`` if given),
        finish the file and report."""
        held = 0
        if self.last is not None:
            held = int(round(hold_s * self.fps))
            last = self.last
            if final_text is not None and self.caption is not None:
                last = self.caption.draw(last, final_text)
            for _ in range(held):
                self._writer.append_data(last)
        self._writer.close()
        rt = self.render_times
        return VideoReport(
            path=str(self.path), frames=self.frames + held, fps=self.fps, every=self.every,
            seconds=(self.frames + held) / self.fps, bytes=self.path.stat().st_size if self.path.exists() else 0,
            width=int(self.shape[1]), height=int(self.shape[0]), first_render_s=rt[0] if rt else math.nan,
            render_s_per_frame=float(np.mean(rt[1:])) if len(rt) > 1 else math.nan, hold_s=held / self.fps,
        )
