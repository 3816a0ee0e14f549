"""The CUDA backend: ManiSkill's own batching, ``num_envs = N`` sub-scenes on PhysX GPU.

What it does: builds the task with ``num_envs = N`` on ``physx_cuda`` (no renderer unless a
camera is asked for: ManiSkill would build one per sub-scene); every read is one batched
ManiSkill tensor (each sub-scene has its own frame, so poses are local already). PhysX GPU
keeps its state in device buffers that ManiSkill's setters write and its getters read, so every
write is applied before the next step or fetch (a fetch overwrites what was not applied): drive
targets after the setters, an object after ``push_object`` / ``place_object``; ``set_state`` applies
joints and poses, updates the links' kinematics, then fetches (ManiSkill's own reset order);
after the substeps the buffers are fetched once. ``realize.scene.backends`` checks SAPIEN's
PhysX GPU library (``realize.physx_gpu``) before this backend is built.
What it doesn't: repeat bit for bit (PhysX GPU contacts are not deterministic), put finished
copies to sleep (it holds them still), or set friction or mass per copy (PhysX GPU fixes materials
and masses when the scene is built). It has not run on a GPU in this repository's CI: its test skips without CUDA
(nor has ``set_state``, the restore of a saved state, which no test runs on a GPU). Each
movable object is one batched ManiSkill actor over the sub-scenes; reads stack them on the m axis.
"""

from __future__ import annotations

import torch

from realize.config import ConfigError
from realize.world.geometry import GeometryCfg
from realize.robot.spec import RobotSpec
from realize.scene.physics import PhysicsBackend, make_task
from realize.scene.settings import EnvOptions, SimSettings

# ManiSkill builds a renderer per sub-scene wherever it has a render device: none without a camera
_NO_RENDER = {"render_backend": "none"}

__all__ = ["GpuBackend"]

_NO_FRICTION = ("per-copy object friction needs the CPU backend: PhysX GPU fixes materials when the scene is "
                "built (use sim.backend=cpu, or no friction range)")


class GpuBackend(PhysicsBackend):  # pragma: no cover - exercised on CUDA machines only
    """N ManiSkill sub-scenes on PhysX GPU (see the module docstring)."""

    name = "gpu"
    deterministic = False

    def __init__(self, n_envs: int, geometry: GeometryCfg, sim: SimSettings, options: EnvOptions, robot: RobotSpec):
        self.n_envs, self.sim, self.robot = n_envs, sim, robot
        self.env = make_task(geometry, sim, options, robot, num_envs=n_envs, sim_backend="physx_cuda",
                             **({} if options.camera is not None else _NO_RENDER))
        self.device = torch.device("cuda")
        self.u = self.env.unwrapped
        agent = self.u.agents[0]
        self._robot = agent.robot
        self._agent = agent
        self._objects = [self.u.object_actors[o.name][0] for o in self.u.geometry.objects]
        self._ee_link = agent.tcp
        joints = {j.name: j for j in self._robot.get_active_joints()}
        self._base_j = [joints[j] for j in robot.base.joints]
        self._arm_j = [joints[j] for j in robot.upper.joints]
        self._finger_j = [joints[j] for j in robot.gripper.joints]

    def after_reset(self) -> None:
        pass

    def qpos(self) -> torch.Tensor:
        return self._robot.get_qpos().clone()

    def qvel(self) -> torch.Tensor:
        return self._robot.get_qvel().clone()

    def ee_pose(self) -> torch.Tensor:
        return self._ee_link.pose.raw_pose.clone()

    def object_poses(self) -> torch.Tensor:
        return torch.stack([o.pose.raw_pose for o in self._objects], dim=1).clone()

    def object_velocities(self) -> torch.Tensor:
        return torch.stack([torch.cat([o.linear_velocity, o.angular_velocity], dim=1) for o in self._objects], dim=1)

    def finger_forces(self) -> torch.Tensor:
        fingers = self._agent.finger_links
        pair = self.u.scene.get_pairwise_contact_forces
        return torch.stack([torch.stack([pair(f, o).norm(dim=1) for f in fingers], dim=1) for o in self._objects],
                           dim=1)

    def apply_targets(self, base_vel: torch.Tensor, arm: torch.Tensor, arm_vel: torch.Tensor,
                      grip: torch.Tensor, frozen: torch.Tensor) -> None:
        r = self._robot
        if self._base_j:  # a fixed base has no joints
            r.set_joint_drive_velocity_targets(base_vel, self._base_j)
        r.set_joint_drive_targets(arm, self._arm_j)
        r.set_joint_drive_velocity_targets(arm_vel, self._arm_j)
        r.set_joint_drive_targets(grip[:, None].repeat(1, len(self._finger_j)), self._finger_j)
        px = self.u.scene.px
        px.gpu_apply_articulation_target_position()
        px.gpu_apply_articulation_target_velocity()

    def step(self, substeps: int) -> None:
        for _ in range(substeps):
            self.u.scene.px.step()
        self.u.scene._gpu_fetch_all()

    def freeze(self, copies: list[int]) -> None:
        """Nothing to do: the zeroed base targets and held arm targets keep them still."""

    def push_object(self, k: int, copy: int, velocity: tuple[float, float, float]) -> None:
        obj = self._objects[k]
        v = obj.linear_velocity.clone()
        v[copy] = torch.tensor(velocity, device=self.device)
        obj.set_linear_velocity(v)
        self.u.scene.px.gpu_apply_rigid_dynamic_data()

    def place_object(self, k: int, positions: torch.Tensor) -> None:
        obj = self._objects[k]
        pose = obj.pose.raw_pose.clone()
        pose[:, :3] = positions.to(self.device)  # every GPU sub-scene has its own frame
        pose[:, 3:] = torch.tensor([1.0, 0.0, 0.0, 0.0], device=self.device)
        obj.set_pose(pose)
        obj.set_linear_velocity(torch.zeros(self.n_envs, 3, device=self.device))
        obj.set_angular_velocity(torch.zeros(self.n_envs, 3, device=self.device))
        self.u.scene.px.gpu_apply_rigid_dynamic_data()

    def set_state(self, qpos: torch.Tensor, object_poses: torch.Tensor) -> None:
        """ManiSkill's batched setters, then apply, update the links' kinematics and fetch."""
        self._robot.set_qpos(qpos.to(self.device))
        self._robot.set_qvel(torch.zeros_like(qpos, device=self.device))
        for k, obj in enumerate(self._objects):
            obj.set_pose(object_poses[:, k].to(self.device))  # every GPU sub-scene has its own frame
            obj.set_linear_velocity(torch.zeros(self.n_envs, 3, device=self.device))
            obj.set_angular_velocity(torch.zeros(self.n_envs, 3, device=self.device))
        self.u.scene._gpu_apply_all()
        self.u.scene.px.gpu_update_articulation_kinematics()  # the links' poses from the new joints
        self.u.scene._gpu_fetch_all()

    def object_friction(self, k: int) -> torch.Tensor:
        raise ConfigError(_NO_FRICTION)

    def set_object_friction(self, k: int, values: torch.Tensor) -> None:
        raise ConfigError(_NO_FRICTION)

    def object_mass(self, k: int) -> torch.Tensor:
        raise ConfigError(_NO_FRICTION.replace("friction", "mass"))

    def set_object_mass(self, k: int, values: torch.Tensor) -> None:
        raise ConfigError(_NO_FRICTION.replace("friction", "mass"))
