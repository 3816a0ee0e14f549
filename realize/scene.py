"""The batched scene view: N realizations of the task simulated at once, seen as (N, ...) tensors.

What it does: builds the ManiSkill task of the scene variant (``RealizePickPlace-v1``, or
``RealizeMoveAndPush-v1`` for ``variant="push"``) for N plans and exposes one
interface whatever runs underneath:
  * CPU (``backend="cpu"``): N copies tiled in ONE PhysX CPU scene (``n_copies = N``), stepped
    by one call, with ``cpu_workers`` threads from the core count;
  * CUDA (``backend="gpu"``): ManiSkill's ``num_envs = N`` sub-scenes on PhysX GPU.
Everything it returns is expressed in a copy's local frame (the frame of ``envs.geometry``), so
the code above it never sees tile offsets.
It reads base pose, whole-body joint state, end-effector pose, cube pose and whether the gripper
holds the cube (from contact forces); it writes base velocity commands, torso/arm joint targets
and the gripper opening; it steps one control period.
What it doesn't: decide anything. Controllers compute the targets, the rollout runs actions.

Whole-body joint vector ``q`` (11): base x, base y, base yaw, torso, then the 7 arm joints
(shoulder_pan, shoulder_lift, upperarm_roll, elbow_flex, forearm_roll, wrist_flex, wrist_roll).
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from typing import Any

import numpy as np
import sapien
import torch

from envs.geometry import GeometryCfg, SceneGeometry, geometry_cfg_from_dict
from envs.fetch_omni import REST_QPOS
from realize.fetch_joints import WHOLE_BODY_JOINT_NAMES

BASE_JOINTS = WHOLE_BODY_JOINT_NAMES[:3]  # x, y, yaw
ARM_JOINTS = WHOLE_BODY_JOINT_NAMES[3:]  # torso + 7 arm joints
WHOLE_BODY_JOINTS = BASE_JOINTS + ARM_JOINTS
FINGER_JOINTS = ("l_gripper_finger_joint", "r_gripper_finger_joint")
FINGER_LINKS = ("l_gripper_finger_link", "r_gripper_finger_link")
EE_LINK = "gripper_link"
GRIPPER_OPEN, GRIPPER_CLOSED = 0.05, -0.01  # finger joint targets (m); closed < 0 squeezes


class SceneConfigError(ValueError):
    """A scene or physics setting is invalid; the message names the key."""


@dataclass
class SimSettings:
    """Physics settings (the Hydra ``sim`` group). Every field is a config key."""

    backend: str = "auto"  # auto | cpu | gpu
    sim_freq: int = 60
    control_freq: int = 20
    solver_position_iterations: int = 10
    solver_velocity_iterations: int = 1
    cpu_workers: int | None = None  # None: from the core count
    grasp_min_force: float = 0.5  # N, per finger, for "holds the cube"
    torch_threads_cpu: int | None = 1  # torch threads beside PhysX CPU workers (None: leave as is)

    def validate(self) -> None:
        if self.backend not in ("auto", "cpu", "gpu"):
            raise SceneConfigError(f"sim.backend = {self.backend!r} is invalid: allowed 'auto', 'cpu', 'gpu'")
        if self.sim_freq < 1 or self.control_freq < 1 or self.sim_freq % self.control_freq:
            raise SceneConfigError(
                f"sim.sim_freq = {self.sim_freq}, sim.control_freq = {self.control_freq}: both must be >= 1 "
                "and sim_freq a multiple of control_freq"
            )
        if self.solver_position_iterations < 1 or self.solver_velocity_iterations < 0:
            raise SceneConfigError(
                f"sim.solver_position_iterations = {self.solver_position_iterations} must be >= 1 and "
                f"sim.solver_velocity_iterations = {self.solver_velocity_iterations} >= 0"
            )
        if self.cpu_workers is not None and self.cpu_workers < 0:
            raise SceneConfigError(f"sim.cpu_workers = {self.cpu_workers} must be >= 0 (or null for auto)")
        if self.grasp_min_force <= 0:
            raise SceneConfigError(f"sim.grasp_min_force = {self.grasp_min_force} must be > 0")


def available_cores() -> int:
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # pragma: no cover - non-Linux
        return os.cpu_count() or 1


def resolve_backend(backend: str) -> str:
    if backend == "auto":
        return "gpu" if torch.cuda.is_available() else "cpu"
    if backend == "gpu" and not torch.cuda.is_available():
        raise SceneConfigError("sim.backend = 'gpu' but torch sees no CUDA device; use 'cpu' or 'auto'")
    return backend


def _quat_yaw(q: torch.Tensor) -> torch.Tensor:
    w, x, y, z = q.unbind(-1)
    return torch.atan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))


def quat_to_matrix(q: torch.Tensor) -> torch.Tensor:
    """(..., 4) wxyz unit quaternions -> (..., 3, 3) rotation matrices."""
    w, x, y, z = q.unbind(-1)
    return torch.stack(
        [
            1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y),
            2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x),
            2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y),
        ],
        dim=-1,
    ).reshape(q.shape[:-1] + (3, 3))


class BatchedScene:
    """N copies of the pick-and-place world, read and written as (N, ...) tensors.

    Args:
        n: number of parallel realizations (>= 1).
        geometry: world geometry config (``envs.geometry.GeometryCfg`` or a mapping).
        sim: physics settings.
    """

    def __init__(self, n: int, geometry: GeometryCfg | dict | None = None, sim: SimSettings | None = None):
        import gymnasium as gym

        import envs  # registers the tasks

        if isinstance(n, bool) or not isinstance(n, int) or n < 1:
            raise SceneConfigError(f"n = {n!r} is invalid: the number of parallel plans (ce.n_envs) must be an integer >= 1")
        self.sim = sim or SimSettings()
        self.sim.validate()
        self.backend = resolve_backend(self.sim.backend)
        self.n = n
        workers = self.sim.cpu_workers
        if workers is None:
            workers = 0 if n < 8 else min(available_cores(), 8)
        gcfg = geometry if isinstance(geometry, GeometryCfg) else geometry_cfg_from_dict(geometry)
        env_id = envs.env_id_for(gcfg.variant)
        common = dict(
            geometry=gcfg,
            obs_mode="none",
            sim_freq=self.sim.sim_freq,
            control_freq=self.sim.control_freq,
            solver_position_iterations=self.sim.solver_position_iterations,
            solver_velocity_iterations=self.sim.solver_velocity_iterations,
            render_mode="rgb_array",
        )
        if self.backend == "cpu":
            # PhysX's worker threads and torch's intra-op threads fight over the same cores; the
            # per-step tensors here are small, so torch runs single-threaded on the CPU backend
            # (measured: a 16-plan rollout took 12x longer with torch's default thread pool).
            if self.sim.torch_threads_cpu is not None:
                torch.set_num_threads(self.sim.torch_threads_cpu)
            self.env = gym.make(env_id, n_copies=n, sim_backend="physx_cpu", cpu_workers=workers, **common)
            self.device = torch.device("cpu")
        else:
            self.env = gym.make(env_id, num_envs=n, sim_backend="physx_cuda", **common)
            self.device = torch.device("cuda")
        self.u = self.env.unwrapped
        self.geometry: SceneGeometry = self.u.geometry
        self.substeps = self.sim.sim_freq // self.sim.control_freq
        self.control_dt = 1.0 / self.sim.control_freq
        self._start_xy = torch.tensor(self.geometry.robot_start[:2], dtype=torch.float32, device=self.device)
        self._offsets = torch.tensor(self.u.offsets, dtype=torch.float32, device=self.device)
        agent0 = self.u.agents[0]
        names = list(agent0.robot.active_joints_map.keys())
        self.joint_names = names
        self._wb_idx = torch.tensor([names.index(j) for j in WHOLE_BODY_JOINTS], device=self.device)
        self._finger_idx = torch.tensor([names.index(j) for j in FINGER_JOINTS], device=self.device)
        self._rest_qpos = torch.tensor(REST_QPOS, device=self.device)
        if self.backend == "cpu":
            self._setup_cpu()
        else:
            self._setup_gpu()
        self._base_cmd = torch.zeros(n, 3, device=self.device)
        self._arm_target = torch.zeros(n, len(ARM_JOINTS), device=self.device)
        self._arm_vel_target = torch.zeros(n, len(ARM_JOINTS), device=self.device)
        self._grip_target = torch.full((n,), GRIPPER_OPEN, device=self.device)
        self._frozen = torch.zeros(n, dtype=torch.bool, device=self.device)

    # ------------------------------------------------------------------ backends
    def _setup_cpu(self) -> None:
        self._arts = [a.robot._objs[0] for a in self.u.agents]
        joints_by_name = [{k: j._objs[0] for k, j in a.robot.active_joints_map.items()} for a in self.u.agents]
        self._base_joints = [[jm[j] for j in BASE_JOINTS] for jm in joints_by_name]
        self._arm_joints = [[jm[j] for j in ARM_JOINTS] for jm in joints_by_name]
        self._finger_joints = [[jm[j] for j in FINGER_JOINTS] for jm in joints_by_name]
        self._ee_links = [a.robot.links_map[EE_LINK]._objs[0] for a in self.u.agents]
        self._cube_bodies = [c._bodies[0] for c in self.u.cubes]
        self._dynamic_bodies = [a._bodies[0] for a in self.u.dynamic_actors]  # cubes (and sticks)
        # contact bookkeeping: physx component -> (copy index, role) with role 0/1 finger, 2 cube
        self._contact_role: dict[int, tuple[int, int]] = {}
        self._keep_alive = []  # id() keys stay valid while the wrappers live
        for c, a in enumerate(self.u.agents):
            for r, ln in enumerate(FINGER_LINKS):
                link = a.robot.links_map[ln]._objs[0]
                self._keep_alive.append(link)
                self._contact_role[id(link)] = (c, r)
        for c, body in enumerate(self._cube_bodies):
            self._keep_alive.append(body)
            self._contact_role[id(body)] = (c, 2)
        self._px = self.u.scene.px

    def _setup_gpu(self) -> None:  # pragma: no cover - exercised on CUDA machines only
        agent = self.u.agents[0]
        self._robot = agent.robot
        self._agent = agent
        self._cube = self.u.cubes[0]
        self._ee_link = agent.tcp
        self._joint_objs = {j.name: j for j in self._robot.get_active_joints()}

    # ------------------------------------------------------------------ reset
    def reset(self, seed: int = 0, randomize: bool = False) -> None:
        """Put every copy back in the task's initial state (same state for all unless randomize).

        On CPU the reset is history-free: PhysX keeps contact caches of shape pairs that touched
        in the previous rollout, so every dynamic actor (cube, and the push scene's stick) is taken
        out of the scene and put back in (which drops its pairs). A rollout in a used scene then
        equals one in a fresh scene bit for bit.
        """
        self._frozen.zero_()
        self.env.reset(seed=seed, options=dict(randomize=randomize))
        if self.backend == "cpu":
            for art in self._arts:
                art.root.wake_up()
            # all out in reverse build order, then all back in build order: PhysX hands out the
            # freed internal handles last-in first-out, so every body gets its own handle back
            # and the solver meets touching bodies (the cube on the stick) in the same order as
            # in a fresh scene. Out-and-in one by one permuted the handles from reset to reset
            # (measured in the push scene: 3e-6 m apart after 10 steps, ~1 cm after a push).
            entities = [body.entity for body in self._dynamic_bodies]
            px_scene = entities[0].scene
            for entity in reversed(entities):
                px_scene.remove_entity(entity)
            for entity in entities:
                px_scene.add_entity(entity)
        q = self.whole_body_q()
        self._base_cmd.zero_()
        self._arm_target = q[:, 3:].clone()
        self._arm_vel_target = torch.zeros_like(self._arm_target)
        self._grip_target.fill_(GRIPPER_OPEN)
        self._apply_targets()

    # ------------------------------------------------------------------ reads
    def qpos(self) -> torch.Tensor:
        """(N, 15) every active joint, in ManiSkill Fetch's joint order (``self.joint_names``)."""
        if self.backend == "cpu":
            return torch.from_numpy(np.stack([a.get_qpos() for a in self._arts])).to(torch.float32)
        return self._robot.get_qpos().clone()

    def qvel(self) -> torch.Tensor:
        if self.backend == "cpu":
            return torch.from_numpy(np.stack([a.get_qvel() for a in self._arts])).to(torch.float32)
        return self._robot.get_qvel().clone()

    def whole_body_q(self) -> torch.Tensor:
        """(N, 11) base x, y (local frame), yaw, torso, 7 arm joints."""
        q = self.qpos()[:, self._wb_idx]
        return torch.cat([q[:, :2] + self._start_xy, q[:, 2:]], dim=1)

    def whole_body_qd(self) -> torch.Tensor:
        return self.qvel()[:, self._wb_idx]

    def base_pose(self) -> torch.Tensor:
        """(N, 3) base x, y (local frame) and yaw."""
        return self.whole_body_q()[:, :3]

    def finger_width(self) -> torch.Tensor:
        """(N,) sum of the two finger joint positions (m): 0.1 fully open."""
        return self.qpos()[:, self._finger_idx].sum(dim=1)

    def ee_pose(self) -> torch.Tensor:
        """(N, 7) gripper_link position (local frame) and wxyz quaternion."""
        if self.backend == "cpu":
            poses = [l.get_entity_pose() for l in self._ee_links]
            raw = np.array([np.concatenate([p.p, p.q]) for p in poses], dtype=np.float32)
            raw = torch.from_numpy(raw)
        else:
            raw = self._ee_link.pose.raw_pose.clone()
        raw[:, :2] -= self._offsets if self.backend == "cpu" else 0.0
        return raw

    def cube_pose(self) -> torch.Tensor:
        """(N, 7) cube position (local frame) and wxyz quaternion."""
        if self.backend == "cpu":
            poses = [b.get_entity_pose() for b in self._cube_bodies]
            raw = torch.from_numpy(np.array([np.concatenate([p.p, p.q]) for p in poses], dtype=np.float32))
            raw[:, :2] -= self._offsets
            return raw
        return self._cube.pose.raw_pose.clone()

    def cube_velocity(self) -> torch.Tensor:
        """(N, 6) cube linear and angular velocity."""
        if self.backend == "cpu":
            v = [np.concatenate([b.get_linear_velocity(), b.get_angular_velocity()]) for b in self._cube_bodies]
            return torch.from_numpy(np.array(v, dtype=np.float32))
        return torch.cat([self._cube.linear_velocity, self._cube.angular_velocity], dim=1)

    def finger_cube_forces(self) -> torch.Tensor:
        """(N, 2) magnitude of the contact force (N) between each finger and the cube."""
        if self.backend == "cpu":
            impulse = np.zeros((self.n, 2), dtype=np.float64)
            role = self._contact_role
            for contact in self._px.get_contacts():
                b0, b1 = contact.bodies
                r0, r1 = role.get(id(b0)), role.get(id(b1))
                if r0 is None or r1 is None or r0[0] != r1[0]:
                    continue
                pair = {r0[1], r1[1]}
                if 2 not in pair or len(pair) != 2:
                    continue
                finger = (pair - {2}).pop()
                total = np.zeros(3)
                for pt in contact.points:
                    total += pt.impulse
                impulse[r0[0], finger] += np.linalg.norm(total)
            dt = 1.0 / self.sim.sim_freq
            return torch.from_numpy(impulse / dt).to(torch.float32)
        fingers = (self._agent.finger1_link, self._agent.finger2_link)
        return torch.stack(
            [self.u.scene.get_pairwise_contact_forces(f, self._cube).norm(dim=1) for f in fingers], dim=1
        )

    def holds_cube(self) -> torch.Tensor:
        """(N,) bool: both fingers press on the cube with at least ``sim.grasp_min_force``."""
        return (self.finger_cube_forces() >= self.sim.grasp_min_force).all(dim=1)

    # ------------------------------------------------------------------ writes
    def set_base_velocity(self, v_world: torch.Tensor) -> None:
        """(N, 3) base velocity in the local/world frame: vx, vy (m/s), yaw rate (rad/s)."""
        self._base_cmd = v_world.detach().to(self.device, torch.float32)

    def set_base_velocity_robot_frame(self, v_robot: torch.Tensor) -> None:
        """(N, 3) base velocity in the robot frame: forward, left (m/s), yaw rate (rad/s)."""
        yaw = self.base_pose()[:, 2]
        c, s = torch.cos(yaw), torch.sin(yaw)
        vx = c * v_robot[:, 0] - s * v_robot[:, 1]
        vy = s * v_robot[:, 0] + c * v_robot[:, 1]
        self.set_base_velocity(torch.stack([vx, vy, v_robot[:, 2]], dim=1))

    def set_arm_targets(self, q_target: torch.Tensor, qd_target: torch.Tensor | None = None) -> None:
        """(N, 8) torso + 7 arm joint position targets (rad, m), and optional velocity targets."""
        self._arm_target = q_target.detach().to(self.device, torch.float32)
        self._arm_vel_target = (torch.zeros_like(self._arm_target) if qd_target is None
                                else qd_target.detach().to(self.device, torch.float32))

    def set_gripper(self, closed: torch.Tensor) -> None:
        """(N,) bool: close (True) or open (False) the gripper."""
        c = closed.to(self.device, torch.bool)
        self._grip_target = torch.where(c, torch.tensor(GRIPPER_CLOSED, device=self.device),
                                        torch.tensor(GRIPPER_OPEN, device=self.device))

    def hold_still(self, mask: torch.Tensor | None = None) -> None:
        """Zero base velocity and freeze torso/arm at their current positions for masked copies."""
        q = self.whole_body_q()
        m = torch.ones(self.n, dtype=torch.bool, device=self.device) if mask is None else mask
        self._base_cmd = torch.where(m[:, None], torch.zeros_like(self._base_cmd), self._base_cmd)
        self._arm_target = torch.where(m[:, None], q[:, 3:], self._arm_target)
        self._arm_vel_target = torch.where(m[:, None], torch.zeros_like(self._arm_vel_target), self._arm_vel_target)

    def freeze(self, mask: torch.Tensor) -> None:
        """Stop simulating the robots of the masked copies (finished or failed plans): zero their
        velocities and put them to sleep until the next reset. On CPU a sleeping articulation
        costs almost nothing; on GPU this only holds them still."""
        new = mask.to(self.device, torch.bool) & ~self._frozen
        if not bool(new.any()):
            return
        self._frozen |= new
        idx = torch.nonzero(new).flatten().tolist()
        self._base_cmd[new] = 0.0
        if self.backend == "cpu":
            for c in idx:
                art = self._arts[c]
                for joint in self._base_joints[c]:  # a sleeping robot keeps its last targets
                    joint.set_drive_velocity_target(0.0)
                art.set_qvel(np.zeros(art.dof, dtype=np.float32))
                art.root.put_to_sleep()

    @property
    def frozen(self) -> torch.Tensor:
        return self._frozen.clone()

    def _apply_targets(self) -> None:
        base = self._base_cmd.numpy().astype(np.float64) if self.backend == "cpu" else self._base_cmd
        if self.backend == "cpu":
            arm = self._arm_target.numpy().astype(np.float64)
            arm_v = self._arm_vel_target.numpy().astype(np.float64)
            grip = self._grip_target.numpy().astype(np.float64)
            for c in torch.nonzero(~self._frozen).flatten().tolist():  # writing wakes a sleeping robot
                for j, joint in enumerate(self._base_joints[c]):
                    joint.set_drive_velocity_target(base[c, j])
                for j, joint in enumerate(self._arm_joints[c]):
                    joint.set_drive_target(arm[c, j])
                    joint.set_drive_velocity_target(arm_v[c, j])
                for joint in self._finger_joints[c]:
                    joint.set_drive_target(grip[c])
        else:  # pragma: no cover - CUDA only
            r = self._robot
            base_j = [self._joint_objs[j] for j in BASE_JOINTS]
            arm_j = [self._joint_objs[j] for j in ARM_JOINTS]
            fin_j = [self._joint_objs[j] for j in FINGER_JOINTS]
            r.set_joint_drive_velocity_targets(base, base_j)
            r.set_joint_drive_targets(self._arm_target, arm_j)
            r.set_joint_drive_velocity_targets(self._arm_vel_target, arm_j)
            r.set_joint_drive_targets(self._grip_target[:, None].repeat(1, 2), fin_j)
            px = self.u.scene.px
            px.gpu_apply_articulation_target_position()
            px.gpu_apply_articulation_target_velocity()

    def step(self) -> None:
        """Write the pending targets and advance physics by one control period."""
        self._apply_targets()
        for _ in range(self.substeps):
            self.u.scene.px.step()
        if self.backend != "cpu":  # pragma: no cover - CUDA only
            self.u.scene._gpu_fetch_all()

    # ------------------------------------------------------------------ pushing (tests, faults)
    def push_cube(self, copy: int, velocity: tuple[float, float, float]) -> None:
        """Give one copy's cube a linear velocity (used to check that copies are independent)."""
        if self.backend == "cpu":
            self._cube_bodies[copy].set_linear_velocity(np.asarray(velocity, dtype=np.float32))
        else:  # pragma: no cover
            v = self._cube.linear_velocity.clone()
            v[copy] = torch.tensor(velocity, device=self.device)
            self._cube.set_linear_velocity(v)

    def place_cube(self, positions: torch.Tensor) -> None:
        """Teleport every copy's cube to ``positions`` (N, 3) in its copy's local frame, axis-aligned
        and at rest (tests and what-if checks: where does a cube dropped here end up?)."""
        p = torch.as_tensor(positions, dtype=torch.float32).reshape(self.n, 3).cpu()
        if self.backend == "cpu":
            for c, body in enumerate(self._cube_bodies):
                xyz = p[c].numpy() + np.array([*self._offsets[c].tolist(), 0.0], dtype=np.float32)
                body.entity.set_pose(sapien.Pose(xyz))
                body.set_linear_velocity(np.zeros(3, dtype=np.float32))
                body.set_angular_velocity(np.zeros(3, dtype=np.float32))
        else:  # pragma: no cover - CUDA only
            pose = self._cube.pose.raw_pose.clone()
            pose[:, :3] = p.to(self.device)  # every GPU sub-scene has its own frame
            pose[:, 3:] = torch.tensor([1.0, 0.0, 0.0, 0.0], device=self.device)
            self._cube.set_pose(pose)
            self._cube.set_linear_velocity(torch.zeros(self.n, 3, device=self.device))
            self._cube.set_angular_velocity(torch.zeros(self.n, 3, device=self.device))

    # ------------------------------------------------------------------ rendering
    def render(self) -> np.ndarray:
        """(H, W, 3) uint8 frame of copy 0 from the task's render camera."""
        self.u.scene.update_render()
        frame = self.env.render()
        if isinstance(frame, torch.Tensor):
            frame = frame.cpu().numpy()
        frame = np.asarray(frame)
        return frame[0] if frame.ndim == 4 else frame

    def close(self) -> None:
        self.env.close()

    def __enter__(self) -> "BatchedScene":
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()
