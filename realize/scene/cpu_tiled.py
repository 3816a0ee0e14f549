"""The CPU backend: N copies of the world tiled in ONE PhysX CPU scene, stepped by one call.

What it does: ManiSkill allows one CPU env only, so the task is built with ``n_tiles = N``: N
robots (a ManiSkill multi-agent), tables and cubes, laid out far enough apart never to touch,
with PhysX's enhanced determinism so that copies stay independent and runs repeat bit for bit.
Reads and writes loop over the copies' SAPIEN objects (poses, joints, contacts); positions are
shifted back by each tile's offset into the copy's local frame. Resets are history-free (every
dynamic body leaves the PhysX scene and comes back, see ``after_reset``); frozen robots sleep.
Threads: PhysX ``cpu_workers`` from the core count unless set; torch runs on
``sim.torch_threads_cpu`` threads beside them.
What it doesn't: decide anything, or keep state beyond the SAPIEN handles (the targets live in
``realize.scene.batched``).
"""

from __future__ import annotations

import os

import numpy as np
import sapien
import torch

from realize.config import ConfigError
from realize.geometry import GeometryCfg
from realize.scene.physics import ARM_JOINTS, BASE_JOINTS, FINGER_JOINTS, FINGER_LINKS, EE_LINK, PhysicsBackend, make_task
from realize.scene.settings import EnvOptions, SimSettings

__all__ = ["CpuTiledBackend", "available_cores"]


def available_cores() -> int:
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # pragma: no cover - non-Linux
        return os.cpu_count() or 1


class CpuTiledBackend(PhysicsBackend):
    """N copies tiled in one PhysX CPU scene (see the module docstring)."""

    name = "cpu"
    deterministic = True

    def __init__(self, n_envs: int, geometry: GeometryCfg, sim: SimSettings, options: EnvOptions):
        self.n_envs, self.sim = n_envs, sim
        workers = sim.cpu_workers
        if workers is None:
            workers = 0 if n_envs < 8 else min(available_cores(), 8)
        # PhysX's worker threads and torch's intra-op threads fight over the same cores; the
        # per-step tensors here are small, so torch runs single-threaded on the CPU backend
        # (measured: a 16-plan rollout took 12x longer with torch's default thread pool).
        if sim.torch_threads_cpu is not None:
            torch.set_num_threads(sim.torch_threads_cpu)
        self.env = make_task(geometry, sim, options, n_tiles=n_envs, sim_backend="physx_cpu", cpu_workers=workers)
        self.device = torch.device("cpu")
        self.u = self.env.unwrapped
        self._offsets = torch.tensor(self.u.offsets, dtype=torch.float32, device=self.device)
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

    def after_reset(self) -> None:
        """History-free reset: PhysX keeps contact caches of shape pairs that touched in the
        previous rollout, so every dynamic actor (cube, and the push scene's stick) is taken out
        of the scene and put back in (which drops its pairs). A rollout in a used scene then
        equals one in a fresh scene bit for bit."""
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

    # ------------------------------------------------------------------ reads
    def qpos(self) -> torch.Tensor:
        return torch.from_numpy(np.stack([a.get_qpos() for a in self._arts])).to(torch.float32)

    def qvel(self) -> torch.Tensor:
        return torch.from_numpy(np.stack([a.get_qvel() for a in self._arts])).to(torch.float32)

    def ee_pose(self) -> torch.Tensor:
        poses = [l.get_entity_pose() for l in self._ee_links]
        raw = np.array([np.concatenate([p.p, p.q]) for p in poses], dtype=np.float32)
        raw = torch.from_numpy(raw)
        raw[:, :2] -= self._offsets
        return raw

    def cube_pose(self) -> torch.Tensor:
        poses = [b.get_entity_pose() for b in self._cube_bodies]
        raw = torch.from_numpy(np.array([np.concatenate([p.p, p.q]) for p in poses], dtype=np.float32))
        raw[:, :2] -= self._offsets
        return raw

    def cube_velocity(self) -> torch.Tensor:
        v = [np.concatenate([b.get_linear_velocity(), b.get_angular_velocity()]) for b in self._cube_bodies]
        return torch.from_numpy(np.array(v, dtype=np.float32))

    def finger_cube_forces(self) -> torch.Tensor:
        impulse = np.zeros((self.n_envs, 2), dtype=np.float64)
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

    # ------------------------------------------------------------------ writes
    def apply_targets(self, base_vel: torch.Tensor, arm: torch.Tensor, arm_vel: torch.Tensor,
                      grip: torch.Tensor, frozen: torch.Tensor) -> None:
        base = base_vel.numpy().astype(np.float64)
        arm_ = arm.numpy().astype(np.float64)
        arm_v = arm_vel.numpy().astype(np.float64)
        grip_ = grip.numpy().astype(np.float64)
        for c in torch.nonzero(~frozen).flatten().tolist():  # writing wakes a sleeping robot
            for j, joint in enumerate(self._base_joints[c]):
                joint.set_drive_velocity_target(base[c, j])
            for j, joint in enumerate(self._arm_joints[c]):
                joint.set_drive_target(arm_[c, j])
                joint.set_drive_velocity_target(arm_v[c, j])
            for joint in self._finger_joints[c]:
                joint.set_drive_target(grip_[c])

    def step(self, substeps: int) -> None:
        for _ in range(substeps):
            self.u.scene.px.step()

    def freeze(self, copies: list[int]) -> None:
        """A sleeping articulation costs almost nothing to simulate."""
        for c in copies:
            art = self._arts[c]
            for joint in self._base_joints[c]:  # a sleeping robot keeps its last targets
                joint.set_drive_velocity_target(0.0)
            art.set_qvel(np.zeros(art.dof, dtype=np.float32))
            art.root.put_to_sleep()

    # ------------------------------------------------------------------ tests, what-ifs, perturbations
    def push_cube(self, copy: int, velocity: tuple[float, float, float]) -> None:
        self._cube_bodies[copy].set_linear_velocity(np.asarray(velocity, dtype=np.float32))

    def place_cube(self, positions: torch.Tensor) -> None:
        for c, body in enumerate(self._cube_bodies):
            xyz = positions[c].numpy() + np.array([*self._offsets[c].tolist(), 0.0], dtype=np.float32)
            body.entity.set_pose(sapien.Pose(xyz))
            body.set_linear_velocity(np.zeros(3, dtype=np.float32))
            body.set_angular_velocity(np.zeros(3, dtype=np.float32))

    def _cube_shapes(self) -> list:
        shapes = []
        for body in self._cube_bodies:
            (shape,) = body.get_collision_shapes()
            shapes.append(shape)
        return shapes

    def cube_friction(self) -> torch.Tensor:
        mats = [s.get_physical_material() for s in self._cube_shapes()]
        return torch.tensor([[m.static_friction, m.dynamic_friction] for m in mats], dtype=torch.float64)

    def set_cube_friction(self, values: torch.Tensor) -> None:
        """One loop over the copies (SAPIEN has no batched material API on CPU); each copy gets
        its own material."""
        shapes = self._cube_shapes()
        if len(values) != len(shapes):
            raise ConfigError(f"{len(values)} friction values for {len(shapes)} copies")
        for shape, mu in zip(shapes, values.tolist()):
            old = shape.get_physical_material()
            shape.set_physical_material(sapien.physx.PhysxMaterial(float(mu), float(mu), float(old.restitution)))
