"""Settings of the batched scene: physics (the Hydra ``sim`` group) and what the task env is built with.

What it does:
  * ``SimSettings``: backend, physics and control rates, solver iterations, CPU threads, the
    contact force that counts as holding an object. Bounds and choices are field metadata
    (``realize.config.setting``); ``sim_freq`` must be a multiple of ``control_freq`` (``check``).
  * ``EnvOptions``: what the ManiSkill task is built and reset with besides geometry and physics:
    the render ``Camera`` (videos), the task's own reset noise amplitudes and whether every
    reset randomizes (the perturbed worlds of validation and robust search are given per copy
    instead: ``BatchedScene.set_worlds``). Defaults leave the task as registered.
What it doesn't: build anything (``realize.scene.backends`` does), or know which backend runs.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

from realize.config import ConfigError, Settings, setting

__all__ = ["BACKENDS", "SimSettings", "Camera", "EnvOptions"]

BACKENDS = ("auto", "cpu", "gpu")
SOLVERS = ("tgs", "pgs")
ROBOT_COLLISIONS = ("all", "no_self", "hand")  # envs.robot_agent.ROBOT_COLLISIONS


@dataclass
class SimSettings(Settings):
    """Physics settings (the Hydra ``sim`` group: this class's defaults are its one option,
    ``realize.spec.hydra_edge.register_schema``). Every field is a config key."""

    config_key: ClassVar[str] = "sim"

    # auto | cpu | gpu. auto: cpu (gpu, not verified on a GPU yet, only where asked for; see also the
    # top-level `device`)
    backend: str = setting("auto", choices=BACKENDS)
    sim_freq: int = setting(60, ge=1)  # physics steps per second
    control_freq: int = setting(20, ge=1)  # controller updates per second (sim_freq must be a multiple)
    solver_position_iterations: int = setting(10, ge=1)
    solver_velocity_iterations: int = setting(1, ge=0)
    # robots' own count (None: as above); breaks copy independence (a woken cube in one copy
    # changes the others' robots), so off by default
    solver_position_iterations_robot: int | None = setting(None, ge=1)
    # the robot without its collision.lean_drop_links (envs.robot_agent; Fetch: the 11 links nothing
    # touches: wheels, laser, e-stop, bellows, head camera frames)
    lean_robot: bool = True
    # all | no_self (robot links never touch each other) | hand (only the gripper link and the
    # fingers have collision shapes: 0.84-0.87x PhysX time, seed-task fidelity held; off by
    # default: with no base shape the base would drive through walls and tables)
    robot_collisions: str = setting("all", choices=ROBOT_COLLISIONS)
    cpu_workers: int | None = setting(None, ge=0)  # PhysX CPU threads of each scene (every worker's); None: a worker's share of the cores
    grasp_min_force: float = setting(0.5, gt=0)  # N, per finger, for "holds the object"
    torch_threads_cpu: int | None = setting(1, ge=1)  # torch intra-op threads beside PhysX CPU workers (None: leave as is)
    # CPU: at most this many copies per PhysX scene (a shard; realize.scene.shards): a run's
    # numbers depend on it, never on workers.n
    shard_rows: int = setting(100, ge=1)
    # PhysX scene settings (ManiSkill's SceneConfig; defaults are ManiSkill's)
    # m: shapes closer than the sum of their offsets get (speculative) contacts. 0.005: 0.905x PhysX
    # time and equal seed-task fidelity, but push-scene rollouts then stop being reset-deterministic
    # and batch-invariant (tests/test_push.py), so it stays 0.02
    contact_offset: float = setting(0.02, gt=0)
    # tgs: temporal Gauss-Seidel; pgs: projected Gauss-Seidel (0.73x PhysX time, but late-batch
    # feasible 0.925 -> 0.065: grasps slip)
    solver: str = setting("tgs", choices=SOLVERS)
    friction_every_iteration: bool = True  # friction solved in every position iteration (False: the last ones only)
    # persistent contact manifolds (False: ~0.94x PhysX time; with hand collisions late-batch
    # feasible fell to 0.285)
    enable_pcm: bool = True
    sleep_threshold: float = setting(0.005, ge=0)  # mass-normalised kinetic energy below which a body may sleep
    bounce_threshold: float = setting(2.0, ge=0)  # m/s: slower impacts do not bounce

    def physx_scene(self) -> dict[str, object]:
        """The PhysX scene settings as ManiSkill ``SceneConfig`` keys."""
        return dict(
            contact_offset=self.contact_offset, enable_tgs=self.solver == "tgs",
            enable_friction_every_iteration=self.friction_every_iteration, enable_pcm=self.enable_pcm,
            sleep_threshold=self.sleep_threshold, bounce_threshold=self.bounce_threshold,
        )

    def check(self, where: str) -> None:
        if self.sim_freq % self.control_freq:
            raise ConfigError(
                f"{where}.sim_freq = {self.sim_freq}, {where}.control_freq = {self.control_freq}: both must be "
                ">= 1 and sim_freq a multiple of control_freq"
            )


@dataclass
class Camera(Settings):
    """The task's render camera (videos): frame size (None: the task camera's), and a pose
    looking from ``eye`` at ``target`` (both None: the task camera's own pose)."""

    config_key: ClassVar[str] = "camera"

    width: int | None = setting(640, ge=16)
    height: int | None = setting(480, ge=16)
    eye: tuple[float, float, float] | None = None
    target: tuple[float, float, float] | None = None

    def check(self, where: str) -> None:
        if (self.eye is None) != (self.target is None):
            raise ConfigError(f"{where}.eye = {self.eye!r}, {where}.target = {self.target!r}: a camera pose "
                              "needs both eye and target")


@dataclass
class EnvOptions(Settings):
    """What the ManiSkill task is built and reset with besides geometry and physics.

    ``camera``: the render camera (None: the task's). ``object_xy_noise`` / ``robot_xy_noise`` (m) and
    ``object_yaw_noise`` (rad): reset noise amplitudes (None: the task's defaults). ``randomize_resets``: every
    ``reset`` applies the task's randomization (object xy/yaw, robot start xy), whatever the
    caller asks (the realizer resets without it)."""

    config_key: ClassVar[str] = "env"

    camera: Camera | None = None
    object_xy_noise: float | None = setting(None, ge=0)
    object_yaw_noise: float | None = setting(None, ge=0)
    robot_xy_noise: float | None = setting(None, ge=0)
    randomize_resets: bool = False
