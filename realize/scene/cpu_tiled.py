"""The CPU backend: N copies of the world tiled in ONE PhysX CPU scene, stepped by one call.

What it does: ManiSkill allows one CPU env only, so the task is built with ``n_tiles = N``: N
robots (a ManiSkill multi-agent), tables and movable objects, laid out far enough apart never to touch,
with PhysX's enhanced determinism so that copies stay independent and runs repeat bit for bit.
Reads loop over the copies' SAPIEN objects (one bound getter call per copy and quantity, no
per-body numpy work; contacts other than finger-object pairs are dropped before their points are
read); positions are shifted back by each tile's offset into the copy's local frame. Writes set
only the drive targets that changed since the last write (all of them after a reset), and wake
the running robots that got nothing new, as a write would. Resets are history-free, restores
(``set_state``) included: every reset moves the bodies into a new PhysX system
(``_fresh_physx``, about 7 ms at 38 copies), so nothing PhysX kept from earlier rollouts decides
the order of a step's contacts; frozen robots sleep.
Threads: PhysX ``cpu_workers`` from the core count unless set; torch runs on
``sim.torch_threads_cpu`` threads beside them.
What it doesn't: decide anything, or keep state beyond the SAPIEN handles and the last targets
written (a step's targets live in ``realize.scene.batched``).
"""

from __future__ import annotations

import os
from math import sqrt

import numpy as np
import sapien
import sapien.physx as physx
import torch

from realize.config import ConfigError
from realize.world.geometry import GeometryCfg
from realize.robot.spec import RobotSpec
from realize.scene.physics import PhysicsBackend, make_task
from realize.scene.settings import EnvOptions, SimSettings

__all__ = ["CpuTiledBackend", "available_cores"]



def available_cores() -> int:
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # pragma: no cover - non-Linux
        return os.cpu_count() or 1


def _check_pose_layout(pose: sapien.Pose) -> None:
    """The reads take a pose's ``__getstate__`` as (p, q); refuse a SAPIEN where it is not."""
    if not np.array_equal(np.asarray(pose.__getstate__(), dtype=np.float32), np.concatenate([pose.p, pose.q])):
        raise RuntimeError("sapien.Pose.__getstate__ is not (p, q) in this SAPIEN version")


class CpuTiledBackend(PhysicsBackend):
    """N copies tiled in one PhysX CPU scene (see the module docstring)."""

    name = "cpu"
    deterministic = True
    rewrite_all_targets = False  # True: write every target every step, as before (tests compare)

    def __init__(self, n_envs: int, geometry: GeometryCfg, sim: SimSettings, options: EnvOptions, robot: RobotSpec):
        self.n_envs, self.sim, self.robot = n_envs, sim, robot
        workers = sim.cpu_workers
        if workers is None:
            workers = 0 if n_envs < 8 else min(available_cores(), 8)
        # PhysX's worker threads and torch's intra-op threads fight over the same cores; the
        # per-step tensors here are small, so torch runs single-threaded on the CPU backend
        # (measured: a 16-plan rollout took 12x longer with torch's default thread pool).
        if sim.torch_threads_cpu is not None:
            torch.set_num_threads(sim.torch_threads_cpu)
        self.env = make_task(geometry, sim, options, robot, n_tiles=n_envs, sim_backend="physx_cpu", cpu_workers=workers)
        self.device = torch.device("cpu")
        self.u = self.env.unwrapped
        self._offsets = torch.tensor(self.u.offsets, dtype=torch.float32, device=self.device)
        self._arts = [a.robot._objs[0] for a in self.u.agents]
        joints_by_name = [{k: j._objs[0] for k, j in a.robot.active_joints_map.items()} for a in self.u.agents]
        self._base_joints = [[jm[j] for j in robot.base.joints] for jm in joints_by_name]
        self._arm_joints = [[jm[j] for j in robot.upper.joints] for jm in joints_by_name]
        self._finger_joints = [[jm[j] for j in robot.gripper.joints] for jm in joints_by_name]
        self._ee_links = [a.robot.links_map[robot.tcp.link]._objs[0] for a in self.u.agents]
        # columns of the per-copy drive-target row: base velocities, upper-joint positions and
        # velocities, fingers
        nb, nu, nf = len(robot.base.joints), len(robot.upper.joints), len(robot.gripper.joints)
        self._cols = (slice(0, nb), slice(nb, nb + nu), slice(nb + nu, nb + 2 * nu), slice(nb + 2 * nu, nb + 2 * nu + nf))
        self._n_targets = nb + 2 * nu + nf
        # _object_bodies[k][c]: object k (the geometry's order) of copy c
        self._object_bodies = [[a._bodies[0] for a in self.u.object_actors[o.name]] for o in self.u.geometry.objects]
        self.n_objects = m = len(self._object_bodies)
        by_copy = [self._object_bodies[k][c] for c in range(n_envs) for k in range(m)]  # copy-major
        self._dynamic_bodies = [a._bodies[0] for a in self.u.dynamic_actors]  # every object, build order
        # contact bookkeeping: physx component -> (copy index, role) with role 0/1 finger, 2 + k object k
        self._contact_role: dict[int, tuple[int, int]] = {}
        self._keep_alive = []  # id() keys stay valid while the wrappers live
        for c, a in enumerate(self.u.agents):
            for r, ln in enumerate(robot.gripper.finger_links):
                link = a.robot.links_map[ln]._objs[0]
                self._keep_alive.append(link)
                self._contact_role[id(link)] = (c, r)
        for k, bodies in enumerate(self._object_bodies):
            for c, body in enumerate(bodies):
                self._keep_alive.append(body)
                self._contact_role[id(body)] = (c, 2 + k)
        self._px = self.u.scene.px
        # bound pybind methods, looked up once: the per-step loops only call them
        self._get_qpos = [a.get_qpos for a in self._arts]
        self._get_qvel = [a.get_qvel for a in self._arts]
        self._get_ee_pose = [link.get_entity_pose for link in self._ee_links]
        self._get_object_pose = [b.get_entity_pose for b in by_copy]
        self._get_object_lin_vel = [b.get_linear_velocity for b in by_copy]
        self._get_object_ang_vel = [b.get_angular_velocity for b in by_copy]
        _check_pose_layout(by_copy[0].get_entity_pose())
        self._setters = [
            [j.set_drive_velocity_target for j in self._base_joints[c]]
            + [j.set_drive_target for j in self._arm_joints[c]]
            + [j.set_drive_velocity_target for j in self._arm_joints[c]]
            + [j.set_drive_target for j in self._finger_joints[c]]
            for c in range(n_envs)
        ]
        assert all(len(row) == self._n_targets for row in self._setters)
        self._wake = [art.root.wake_up for art in self._arts]
        self._written = np.zeros((n_envs, self._n_targets), dtype=np.float64)  # last targets written
        self._write_all = True  # until the first write after a reset

    def after_reset(self) -> None:
        """History-free reset: a fresh PhysX system (``_fresh_physx``), then every dynamic
        actor out of it and back in, as the first reset of a built scene does. A rollout after
        any history, restores included, equals one in a fresh scene bit for bit."""
        self._write_all = True  # the task's reset may have set targets of its own
        self._fresh_physx()
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

    def _fresh_physx(self) -> None:
        """Move every entity into a new SAPIEN scene with a new PhysX CPU system (the old one's
        config and timestep), in the old scene's order.

        Why: PhysX keeps bookkeeping that outlives a rollout and that no reset clears (the
        broadphase's order, the pair manager's pairs of the robots, which stay in the scene).
        It decides the order in which contacts that appear in the same step are solved, and a
        state restored into contact (a cube teleported into closed fingers) settles in one of
        two grasps by that order: the seed plan's suffix from one captured state cost 265 or
        276 steps by what the scene had simulated before, and a plain rollout after a restore
        differed from one in a fresh scene too. A new system has no history. It costs about
        7 ms at 38 copies of the seed task (the bodies are moved, not built again)."""
        old_scene = self.u.scene.sub_scenes[0]
        old = old_scene.physx_system
        entities = list(old_scene.entities)
        for entity in reversed(entities):
            old_scene.remove_entity(entity)
        global_config = physx.get_scene_config()
        physx.set_scene_config(old.config)  # a new system takes the global config
        try:
            new = physx.PhysxCpuSystem()
        finally:
            physx.set_scene_config(global_config)
        new.timestep = old.timestep
        render = old_scene.render_system
        scene = sapien.Scene([new] if render is None else [new, render])
        for entity in entities:
            scene.add_entity(entity)
        self.u.scene.sub_scenes[0] = scene
        self.u.scene.px = self._px = new

    # ------------------------------------------------------------------ reads
    # One pybind call per copy and quantity, straight into one array: a pose's ``__getstate__``
    # is its (p, q) as 7 Python floats (checked against ``p``/``q`` in ``_check_pose_layout``),
    # exact copies of PhysX's float32s. ``PhysxCpuSystem.pack()`` holds every body's and
    # articulation's state in one buffer but took ~12x longer than these loops (measured at N=200).
    def qpos(self) -> torch.Tensor:
        return torch.from_numpy(np.array([get() for get in self._get_qpos]))

    def qvel(self) -> torch.Tensor:
        return torch.from_numpy(np.array([get() for get in self._get_qvel]))

    def _local_poses(self, getters: list) -> torch.Tensor:
        """(len(getters), 7) poses, shifted into their copy's frame (getters copy-major, as many per copy)."""
        raw = torch.from_numpy(np.array([get().__getstate__() for get in getters], dtype=np.float32))
        per = len(getters) // self.n_envs
        raw = raw.reshape(self.n_envs, per, 7)
        raw[:, :, :2] -= self._offsets[:, None, :]
        return raw.reshape(-1, 7)

    def ee_pose(self) -> torch.Tensor:
        return self._local_poses(self._get_ee_pose)

    def object_poses(self) -> torch.Tensor:
        return self._local_poses(self._get_object_pose).reshape(self.n_envs, self.n_objects, 7)

    def object_velocities(self) -> torch.Tensor:
        out = np.empty((self.n_envs * self.n_objects, 6), dtype=np.float32)
        out[:, :3] = [get() for get in self._get_object_lin_vel]
        out[:, 3:] = [get() for get in self._get_object_ang_vel]
        return torch.from_numpy(out).reshape(self.n_envs, self.n_objects, 6)

    def finger_forces(self) -> torch.Tensor:
        """Contacts of anything but a finger and an object of its own copy (objects on tables or
        on each other, the arm on the head, ...) are dropped after two dict look-ups, before any
        contact point is read. A contact's impulse is summed and its norm taken in Python
        floats: the same float64 operations as numpy's ``zeros(3) + p0 + p1 ...`` and
        ``linalg.norm`` (sqrt of the dot product), bit for bit, without an array per contact."""
        m = self.n_objects
        impulse = [0.0] * (2 * m * self.n_envs)  # (copy, object, finger) flattened
        role = self._contact_role.get
        for contact in self._px.get_contacts():
            b0, b1 = contact.bodies
            r0 = role(id(b0))
            if r0 is None:
                continue
            r1 = role(id(b1))
            if r1 is None or r0[0] != r1[0] or (r0[1] >= 2) == (r1[1] >= 2):
                continue  # other bodies, another copy's, finger-finger or object-object
            finger, obj = (r1[1], r0[1] - 2) if r0[1] >= 2 else (r0[1], r1[1] - 2)
            x = y = z = 0.0
            for pt in contact.points:
                px, py, pz = pt.impulse.tolist()
                x += px
                y += py
                z += pz
            impulse[2 * (r0[0] * m + obj) + finger] += sqrt(x * x + y * y + z * z)
        dt = 1.0 / self.sim.sim_freq
        return torch.from_numpy(np.array(impulse).reshape(self.n_envs, m, 2) / dt).to(torch.float32)

    # ------------------------------------------------------------------ writes
    def apply_targets(self, base_vel: torch.Tensor, arm: torch.Tensor, arm_vel: torch.Tensor,
                      grip: torch.Tensor, frozen: torch.Tensor) -> None:
        """Writes only the targets whose bits differ from the last ones written (after a reset:
        all of them); a running copy with nothing new is woken up, as a write would (PhysX's
        setters wake the articulation, and a robot left unwritten could fall asleep). Frozen
        copies are not touched: writing would wake them."""
        n = self.n_envs
        c_base, c_arm, c_arm_vel, c_grip = self._cols
        new = np.empty((n, self._n_targets), dtype=np.float64)
        new[:, c_base] = base_vel[:, :c_base.stop].numpy()  # a fixed base: no columns
        new[:, c_arm] = arm.numpy()
        new[:, c_arm_vel] = arm_vel.numpy()
        new[:, c_grip] = grip.numpy()[:, None]
        running = ~frozen.numpy()
        changed = new.view(np.int64) != self._written.view(np.int64)
        if self._write_all or self.rewrite_all_targets:
            changed[:] = True
            self._write_all = False
        changed &= running[:, None]
        rows, cols = np.nonzero(changed)
        setters, values = self._setters, new[rows, cols].tolist()
        for c, k, v in zip(rows.tolist(), cols.tolist(), values):
            setters[c][k](v)
        self._written[changed] = new[changed]
        for c in np.nonzero(running & ~changed.any(axis=1))[0].tolist():
            self._wake[c]()

    def step(self, substeps: int) -> None:
        for _ in range(substeps):
            self._px.step()

    def freeze(self, copies: list[int]) -> None:
        """A sleeping articulation costs almost nothing to simulate."""
        for c in copies:
            art = self._arts[c]
            for joint in self._base_joints[c]:  # a sleeping robot keeps its last targets
                joint.set_drive_velocity_target(0.0)
            self._written[c, self._cols[0]] = 0.0
            art.set_qvel(np.zeros(art.dof, dtype=np.float32))
            art.root.put_to_sleep()

    def wake(self) -> None:
        self._write_all = True
        for art in self._arts:
            art.root.wake_up()

    # ------------------------------------------------------------------ tests, what-ifs, perturbations
    def push_object(self, k: int, copy: int, velocity: tuple[float, float, float]) -> None:
        self._object_bodies[k][copy].set_linear_velocity(np.asarray(velocity, dtype=np.float32))

    def place_object(self, k: int, positions: torch.Tensor) -> None:
        for c, body in enumerate(self._object_bodies[k]):
            xyz = positions[c].numpy() + np.array([*self._offsets[c].tolist(), 0.0], dtype=np.float32)
            body.entity.set_pose(sapien.Pose(xyz))
            body.set_linear_velocity(np.zeros(3, dtype=np.float32))
            body.set_angular_velocity(np.zeros(3, dtype=np.float32))

    def set_state(self, qpos: torch.Tensor, object_poses: torch.Tensor) -> None:
        """Teleport every copy into its row (joints at rest, objects placed). One physics
        substep in the task's initial state comes first: it was the flush of the robots' contact
        caches before every reset got a fresh PhysX system (``after_reset``), which alone makes a
        restore history-free; it stays because the restores' numbers include it."""
        self._px.step()
        zeros = np.zeros(self._arts[0].dof, dtype=np.float32)
        for c, art in enumerate(self._arts):
            art.set_qpos(qpos[c].numpy().astype(np.float32))
            art.set_qvel(zeros)
        for k, bodies in enumerate(self._object_bodies):
            for c, body in enumerate(bodies):
                p = object_poses[c, k, :3].numpy() + np.array([*self._offsets[c].tolist(), 0.0], dtype=np.float32)
                body.entity.set_pose(sapien.Pose(p, object_poses[c, k, 3:].numpy()))
                body.set_linear_velocity(np.zeros(3, dtype=np.float32))
                body.set_angular_velocity(np.zeros(3, dtype=np.float32))
        self._write_all = True

    def _shapes(self, k: int) -> list:
        shapes = []
        for body in self._object_bodies[k]:
            (shape,) = body.get_collision_shapes()
            shapes.append(shape)
        return shapes

    def object_friction(self, k: int) -> torch.Tensor:
        mats = [s.get_physical_material() for s in self._shapes(k)]
        return torch.tensor([[m.static_friction, m.dynamic_friction] for m in mats], dtype=torch.float64)

    def set_object_friction(self, k: int, values: torch.Tensor) -> None:
        """One loop over the copies (SAPIEN has no batched material API on CPU); each copy gets
        its own material."""
        shapes = self._shapes(k)
        if len(values) != len(shapes):
            raise ConfigError(f"{len(values)} friction values for {len(shapes)} copies")
        for shape, mu in zip(shapes, values.tolist()):
            old = shape.get_physical_material()
            shape.set_physical_material(sapien.physx.PhysxMaterial(float(mu), float(mu), float(old.restitution)))

    def object_mass(self, k: int) -> torch.Tensor:
        return torch.tensor([body.get_mass() for body in self._object_bodies[k]], dtype=torch.float64)

    def set_object_mass(self, k: int, values: torch.Tensor) -> None:
        """One loop over the copies; the inertia scales with the mass (same shape, same density
        distribution)."""
        bodies = self._object_bodies[k]
        if len(values) != len(bodies):
            raise ConfigError(f"{len(values)} mass values for {len(bodies)} copies")
        for body, m in zip(bodies, values.tolist()):
            f = float(m) / body.get_mass()
            body.set_mass(float(m))
            body.set_inertia(np.asarray(body.get_inertia(), dtype=np.float32) * np.float32(f))
