"""RealizeMoveAndPush-v1: the journal paper's move-and-push world, for plan realization.

**Task description.** A mobile manipulator (any robot of ``configs/robot/``, default
``fetch_omni``: omnidirectional planar base, lift or torso, arm, parallel gripper) starts in a free area. A thin stick stands upright on the floor with a
small cube resting on its top; an open box (floor and four low walls, open top) stands on the
floor nearby. The cube must end up in the box. The intended way is to drive to the right side of
the stick and push its upper part over towards the box, so that the cube falls in; the cube can
also be picked off the stick top and placed into the box. Tables, if the scene config lists any,
are plain obstacles. All geometry comes from a ``realize.world.geometry.GeometryCfg`` with
``variant="push"`` (the Hydra ``scene=push`` config), the ``geometry`` kwarg; without it the task
builds its default push world (stick, cube and box of ``GeometryCfg``'s defaults, no tables). A
geometry of another variant is refused before anything is built.

**Parallelism.** As ``RealizePickPlace-v1`` (this task extends it): ``num_envs = N`` on PhysX
GPU, or ``n_tiles = N`` copies tiled in one PhysX CPU scene.

**Randomizations** (``reset(options=dict(randomize=...))``, off by default): those of
``RealizePickPlace-v1`` (the cube's xy offset on the stick top by up to ``cube_xy_noise`` m,
clipped to the stick's top, its yaw, and the robot's start xy). The stick always starts upright
at its configured pose.

**Success conditions** (``evaluate``): the cube's centre lies inside the box's inner
footprint, below the top of its walls, and the cube is nearly still.
"""

from __future__ import annotations


import sapien
import torch

from mani_skill.utils.registration import register_env
from mani_skill.utils.structs.pose import Pose

from envs.pick_place import RealizePickPlaceEnv
from realize.world.geometry import GeometryCfg
from realize.tasks.goals import cube_in_container

ENV_ID = "RealizeMoveAndPush-v1"


@register_env(ENV_ID, max_episode_steps=2000)
class RealizeMoveAndPushEnv(RealizePickPlaceEnv):
    TASK_ID = ENV_ID
    VARIANTS = ("push",)

    @classmethod
    def default_geometry(cls) -> GeometryCfg:
        return GeometryCfg(variant="push", tables=[])

    def _load_scene(self, options: dict):
        super()._load_scene(options)
        g = self.geometry
        st = g.stick
        self.sticks: list = []
        for c, off in enumerate(self.offsets):
            b = self.scene.create_actor_builder()
            mat = sapien.physx.PhysxMaterial(g.stick_friction, g.stick_friction, 0.0)
            hx, hy, hz = st.half_size
            b.add_box_collision(half_size=[hx, hy, hz], material=mat, density=g.stick_mass / (8 * hx * hy * hz))
            b.add_box_visual(half_size=[hx, hy, hz], material=sapien.render.RenderMaterial(base_color=list(st.color)))
            b.initial_pose = sapien.Pose(p=[st.center[0] + off[0], st.center[1] + off[1], st.center[2]])
            self.sticks.append(b.build(name=f"stick_{c}"))

    @property
    def dynamic_actors(self) -> list:
        return list(self.cubes) + list(self.sticks)

    def _initialize_episode(self, env_idx: torch.Tensor, options: dict):
        super()._initialize_episode(env_idx, options)
        st = self.geometry.stick
        with torch.device(self.device):
            b = len(env_idx)
            for c, stick in enumerate(self.sticks):
                off = torch.tensor(self.offsets[c], dtype=torch.float32)
                p = torch.tensor(st.center, dtype=torch.float32).repeat(b, 1)
                p[:, :2] += off
                stick.set_pose(Pose.create_from_pq(p, torch.tensor([[1.0, 0, 0, 0]]).repeat(b, 1)))
                stick.set_linear_velocity(torch.zeros(b, 3))
                stick.set_angular_velocity(torch.zeros(b, 3))
            if bool(options.get("randomize", False)):
                # keep the cube's centre above the stick's top
                hx, hy, _ = st.half_size
                for c, cube in enumerate(self.cubes):
                    p = cube.pose.p[env_idx].clone()
                    lo = torch.tensor([st.center[0] - hx + self.offsets[c][0], st.center[1] - hy + self.offsets[c][1]])
                    hi = torch.tensor([st.center[0] + hx + self.offsets[c][0], st.center[1] + hy + self.offsets[c][1]])
                    p[:, :2] = torch.maximum(torch.minimum(p[:, :2], hi), lo)
                    cube.set_pose(Pose.create_from_pq(p, cube.pose.q[env_idx]))

    def evaluate(self) -> dict:
        """Goal for every copy (tiled or not), by ``realize.tasks.goals.cube_in_container``:
        the cube rests inside the first container."""
        off = torch.as_tensor(self.offsets, dtype=torch.float32, device=self.device)
        p = torch.cat([c.pose.p - torch.cat([off[i], off.new_zeros(1)]) for i, c in enumerate(self.cubes)])
        speed = torch.cat([c.linear_velocity for c in self.cubes]).norm(dim=1)
        ok = cube_in_container(p, speed, self.geometry, self.geometry.containers[0].name)
        return dict(success=ok, cube_in_box=ok)
