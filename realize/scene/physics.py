"""What a simulator backend gives the batched scene, and what both backends share.

What it does:
  * ``PhysicsBackend``: the contract of a backend (``realize.scene.cpu_tiled``,
    ``realize.scene.gpu``): raw per-copy reads in a copy's local frame (joint state, the TCP
    pose, every movable object's pose and velocity, finger-object contact forces; objects in the
    geometry's order, the m axis), drive-target writes, physics substeps, putting finished copies
    to sleep, history-free resets, teleporting every copy into a restored state (``set_state``),
    per-copy object friction and mass, and test-only object pushes. Everything is an (N, ...) tensor on
    the backend's device.
  * ``make_task``: builds the ManiSkill task of the scene's world (its env id from the geometry
    variant, ``task_id``; gym imports ``envs``, which registers them, by the id's ``envs:`` prefix:
    realize never imports ``envs``) with the physics settings and the ``EnvOptions`` (render camera,
    reset noise) as ``gym.make`` kwargs; each backend adds its own (tiles or ``num_envs``).
What it doesn't: pick a backend (``realize.scene.backends``), or hold the backend-independent
logic of the scene (whole-body vectors, target bookkeeping, step hooks: ``realize.scene.batched``).
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from typing import Any, ClassVar

import gymnasium as gym
import torch
from mani_skill.utils import sapien_utils

from realize.world.geometry import GeometryCfg
from realize.robot.spec import RobotSpec
from realize.scene.settings import EnvOptions, SimSettings

__all__ = ["PhysicsBackend", "make_task", "task_id"]


TASK_IDS = {"push": "RealizeMoveAndPush-v1"}  # world variant -> ManiSkill task id (envs.env_id_for agrees)
DEFAULT_TASK_ID = "RealizePickPlace-v1"  # plain, wall, ramp


def task_id(variant: str) -> str:
    """The ManiSkill task (``envs/``) that builds a world variant."""
    return TASK_IDS.get(variant, DEFAULT_TASK_ID)


def make_task(geometry: GeometryCfg, sim: SimSettings, options: EnvOptions, robot: RobotSpec,
              **backend_kwargs: Any) -> Any:
    """``gym.make`` the task that builds ``geometry``'s world with ``robot``, with ``sim``'s
    physics, the ``options`` that are set (the rest stays the task's) and the backend's own kwargs."""
    kwargs: dict[str, Any] = dict(
        geometry=geometry,
        robot_uids=robot.name,
        robot=robot,
        obs_mode="none",
        sim_freq=sim.sim_freq,
        control_freq=sim.control_freq,
        solver_position_iterations=sim.solver_position_iterations,
        solver_velocity_iterations=sim.solver_velocity_iterations,
        robot_solver_position_iterations=sim.solver_position_iterations_robot,
        lean_robot=sim.lean_robot,
        physx_scene=sim.physx_scene(),
        robot_collisions=sim.robot_collisions,
        render_mode="rgb_array",
    )
    cam = options.camera
    if cam is not None:
        render: dict[str, Any] = {}
        if cam.width is not None:
            render["width"] = int(cam.width)
        if cam.height is not None:
            render["height"] = int(cam.height)
        if cam.eye is not None and cam.target is not None:
            render["pose"] = sapien_utils.look_at(eye=list(map(float, cam.eye)), target=list(map(float, cam.target)))
        if render:
            kwargs["human_render_camera_configs"] = {"render_camera": render}
    if options.object_xy_noise is not None:
        kwargs["object_xy_noise"] = options.object_xy_noise
    if options.object_yaw_noise is not None:
        kwargs["object_yaw_noise"] = options.object_yaw_noise
    if options.robot_xy_noise is not None:
        kwargs["robot_xy_noise"] = options.robot_xy_noise
    return gym.make(f"envs:{task_id(geometry.variant)}", **backend_kwargs, **kwargs)


class PhysicsBackend(ABC):
    """One simulator backend under ``BatchedScene``: N copies of the task's world.

    Attributes every backend sets: ``env`` (the gym env), ``u`` (the unwrapped ManiSkill task),
    ``device`` (where its tensors live), ``n_envs``, ``robot`` (its ``RobotSpec``: the joints it
    reads and drives, the finger links, the TCP link). Poses are in a copy's local frame
    (``realize.world.geometry``'s), position then wxyz quaternion, float32."""

    name: ClassVar[str]  # "cpu" | "gpu": what run reports and logs call the backend
    deterministic: ClassVar[bool]  # same seed, same result, bit for bit

    env: Any
    u: Any
    device: torch.device
    n_envs: int
    sim: SimSettings
    robot: RobotSpec

    @abstractmethod
    def after_reset(self) -> None:
        """Called after the task's reset, before anything is read: backend book-keeping."""

    @abstractmethod
    def qpos(self) -> torch.Tensor:
        """(N, J) every active joint of the robot, in the articulation's order."""

    @abstractmethod
    def qvel(self) -> torch.Tensor:
        """(N, 15) joint velocities, same order."""

    @abstractmethod
    def ee_pose(self) -> torch.Tensor:
        """(N, 7) pose of the robot's TCP link (``robot.tcp.link``)."""

    @abstractmethod
    def object_poses(self) -> torch.Tensor:
        """(N, m, 7) pose of every movable object."""

    @abstractmethod
    def object_velocities(self) -> torch.Tensor:
        """(N, m, 6) linear and angular velocity of every movable object."""

    @abstractmethod
    def finger_forces(self) -> torch.Tensor:
        """(N, m, 2) magnitude of the contact force (N) between each object and each finger link
        (``robot.gripper.finger_links``)."""

    @abstractmethod
    def apply_targets(self, base_vel: torch.Tensor, arm: torch.Tensor, arm_vel: torch.Tensor,
                      grip: torch.Tensor, frozen: torch.Tensor) -> None:
        """Write drive targets: base velocities (N, 3), upper-joint positions and velocities
        (N, n_upper), finger positions (N,); copies in ``frozen`` (N,) may be skipped (asleep)."""

    @abstractmethod
    def step(self, substeps: int) -> None:
        """Advance physics by ``substeps`` simulation steps (one control period)."""

    @abstractmethod
    def freeze(self, copies: list[int]) -> None:
        """Stop simulating the robots of ``copies`` until the next reset (their base targets are
        already zero): sleep where the backend can, else nothing."""

    def wake(self) -> None:
        """Undo ``freeze`` without a reset: every copy simulated again (the next targets written)."""

    @abstractmethod
    def push_object(self, k: int, copy: int, velocity: tuple[float, float, float]) -> None:
        """Give object ``k`` of one copy a linear velocity (tests: copies are independent)."""

    @abstractmethod
    def place_object(self, k: int, positions: torch.Tensor) -> None:
        """Teleport object ``k`` of every copy to ``positions`` (N, 3, CPU float32), axis-aligned, at rest."""

    @abstractmethod
    def set_state(self, qpos: torch.Tensor, object_poses: torch.Tensor) -> None:
        """Teleport every copy, after a reset: robot joints to ``qpos`` (N, J, in the order of
        ``qpos()``, base joints relative to the task's robot start) at rest, every object to
        ``object_poses`` (N, m, 7, local frame, wxyz) at rest. Both CPU float32."""

    @abstractmethod
    def object_friction(self, k: int) -> torch.Tensor:
        """(N, 2) static and dynamic friction of object ``k`` in each copy (float64)."""

    @abstractmethod
    def set_object_friction(self, k: int, values: torch.Tensor) -> None:
        """Give object ``k`` of copy i the friction ``values[i]`` (static = dynamic; (N,) float64)."""

    @abstractmethod
    def object_mass(self, k: int) -> torch.Tensor:
        """(N,) mass (kg) of object ``k`` in each copy (float64)."""

    @abstractmethod
    def set_object_mass(self, k: int, values: torch.Tensor) -> None:
        """Give object ``k`` of copy i the mass ``values[i]`` (its inertia scaled alike; (N,) float64)."""

    def close(self) -> None:
        self.env.close()
