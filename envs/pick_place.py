"""RealizePickPlace-v1: the seed paper's mobile pick-and-place world, for plan realization.

**Task description.** A mobile manipulator (omnidirectional planar base, a lift or torso, an
arm and a parallel gripper; ``robot_uids``: any robot of ``configs/robot/``, default Fetch's
``fetch_omni``) starts in a free area. Movable objects (``scene.objects``, by name; the seed
world: one small cube, ``cube``) rest on ``table1``. The robot must carry them to ``table2`` and
then drive into the exit (rest) area. Between the tables there
is room to drive; variants add a wall between them (``variant="wall"``) or a ramp from
table 1's side down onto table 2 (``variant="ramp"``) down which a released cube can slide.
All geometry comes from a ``realize.world.geometry.GeometryCfg`` (the Hydra ``scene`` config group),
the ``geometry`` kwarg (a ``GeometryCfg`` or a mapping of its keys; default: the plain world).
This task builds the ``plain``, ``wall`` and ``ramp`` variants; ``push`` is
``RealizeMoveAndPush-v1``'s (``envs.env_id_for`` maps a variant to its task).

**Parallelism.** ``num_envs = N`` with the PhysX GPU backend gives ManiSkill's usual batched
sub-scenes. On CPU, ManiSkill allows one env only, so ``n_tiles = N`` tiles N copies of the
whole world (robot, tables, objects) in ONE PhysX CPU scene, spaced so they can never touch, and
stepped by one call. ``realize.scene.BatchedScene`` hides which of the two is used.

**Randomizations** (``reset(options=dict(randomize=...))``, off by default: plan realization
wants the same initial state for every sample): each object's xy offset by up to
``object_xy_noise`` m and its yaw by up to ``object_yaw_noise`` rad (objects standing on the floor keep their pose; an object on
another object stays above its top), and the robot's start xy by up to ``robot_xy_noise`` m.
``reset(options=dict(offsets=...))`` gives each copy its own offsets instead of random ones
(``robot_xy`` (N, 2); ``object_xy`` {name: (N, 2)}, ``object_yaw`` {name: (N,)}, copies in
``BatchedScene`` order): the perturbed worlds of ``realize.tasks.worlds``; an optional
``robot_yaw`` (N,) turns a fixed base (a restored state's, ``realize.scene.state_rows``).

**Success conditions** (``evaluate``): the ``goal`` kwarg, a task config's goal
(``realize.tasks.goal_spec``) whose ``base_in`` names one of the ``goal_regions`` (a task's
regions; default: the default task's ``Exit``; ``goal_frames``, the regions' frames: a spot
framed by a movable object is read where that object stands). By default every object that starts on a table
rests on table 2 (within 2 cm of resting height above its top, nearly still) AND the base is in
``Exit``: the goal of ``configs/task/pick_place.yaml``, whose region is the one exit.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import numpy as np
import sapien
import torch

from mani_skill.envs.sapien_env import BaseEnv
from mani_skill.sensors.camera import CameraConfig
from mani_skill.utils import sapien_utils
from mani_skill.utils.registration import register_env
from mani_skill.utils.structs.pose import Pose
from mani_skill.utils.structs.types import SceneConfig, SimConfig

from envs import robot_agent, robot_base
from envs.tiling import TILE_MARGIN, gpu_memory_config, tile_offsets, yaw_pitch_quat
from envs.goal_check import EXIT, default_goal_regions, goal_info
from realize.config import ConfigError
from realize.world.geometry import Box, GeometryCfg, SceneGeometry, build_geometry
from realize.world.objects import FLOOR, SceneObject
from realize.tasks.goal_spec import GoalSpec, goal_from_dict
from realize.tasks.regions import Region
from realize.robot.spec import RobotSpec

ENV_ID = "RealizePickPlace-v1"


@register_env(ENV_ID, max_episode_steps=2000)
class RealizePickPlaceEnv(BaseEnv):
    SUPPORTED_ROBOTS: list = []  # any robot of configs/robot/ (or a RobotSpec): set per instance
    TASK_ID = ENV_ID  # the gym id (for messages)
    VARIANTS: tuple[str, ...] = ("plain", "wall", "ramp")  # the geometry variants this task builds

    @classmethod
    def default_geometry(cls) -> GeometryCfg:
        """The world ``gym.make`` builds without a ``geometry`` kwarg."""
        return GeometryCfg()

    @classmethod
    def checked_geometry(cls, geometry: GeometryCfg | Mapping[str, Any] | None) -> GeometryCfg:
        """The ``geometry`` kwarg as a checked ``GeometryCfg`` (None: ``default_geometry()``); a
        variant this task does not build is refused here, before any scene is built."""
        if geometry is None:
            return cls.default_geometry()
        cfg = geometry if isinstance(geometry, GeometryCfg) else GeometryCfg.from_mapping(geometry, "geometry")
        if cfg.variant not in cls.VARIANTS:
            raise ConfigError(
                f"{cls.TASK_ID}: geometry.variant = {cfg.variant!r} is invalid: this task builds "
                f"{list(cls.VARIANTS)} (leave geometry unset for its default world)"
            )
        return cfg

    @classmethod
    def default_goal(cls, geometry: SceneGeometry) -> dict[str, Any]:
        """The goal ``gym.make`` evaluates without a ``goal`` kwarg: every object resting on a
        table at the start ends on table 2 (else the last table), and the base in ``Exit``."""
        goal_table = "table2" if any(t.name == "table2" for t in geometry.tables) else geometry.tables[-1].name
        tables = {t.name for t in geometry.tables}
        return {"rests_on": {o.name: goal_table for o in geometry.objects if o.rests_on in tables}, "base_in": EXIT}

    def checked_goal(self, goal: GoalSpec | Mapping[str, Any] | None) -> GoalSpec:
        """The ``goal`` kwarg as a checked ``GoalSpec`` (``realize.tasks.goal_spec``; its
        ``base_in`` names one of ``self.goal_regions``)."""
        if isinstance(goal, GoalSpec):
            return goal
        d = self.default_goal(self.geometry) if goal is None else goal
        return goal_from_dict(d, self.geometry, self.goal_regions, source=self.TASK_ID)

    def __init__(
        self,
        *args: Any,
        geometry: GeometryCfg | Mapping[str, Any] | None = None,
        n_tiles: int = 1,
        solver_position_iterations: int = 15,
        solver_velocity_iterations: int = 1,
        cpu_workers: int = 0,
        sim_freq: int = 100,
        control_freq: int = 20,
        object_xy_noise: float = 0.02,
        object_yaw_noise: float = math.pi / 4,
        goal: GoalSpec | Mapping[str, Any] | None = None,
        goal_regions: Mapping[str, Region] | None = None,
        goal_frames: Mapping[str, str] | None = None,
        robot_xy_noise: float = 0.05,
        robot_uids: str = "fetch_omni",
        robot: RobotSpec | Mapping[str, Any] | None = None,
        lean_robot: bool = False,
        robot_solver_position_iterations: int | None = None,
        physx_scene: Mapping[str, Any] | None = None,
        robot_collisions: str = "all",
        **kwargs: Any,
    ):
        if isinstance(n_tiles, bool) or not isinstance(n_tiles, int) or n_tiles < 1:
            raise ConfigError(f"n_tiles = {n_tiles!r} is invalid: must be an integer >= 1")
        gcfg = self.checked_geometry(geometry)
        self.geometry: SceneGeometry = build_geometry(gcfg)
        self.n_tiles = n_tiles
        self.offsets = tile_offsets(n_tiles, self.geometry.extent)
        self.object_xy_noise = object_xy_noise
        self.object_yaw_noise = object_yaw_noise
        self.goal_regions = dict(default_goal_regions() if goal_regions is None else goal_regions)
        self.goal_frames = dict(goal_frames or {})  # region -> frame: a spot framed by an object follows it
        self.goal: GoalSpec = self.checked_goal(goal)
        self.robot_xy_noise = robot_xy_noise
        self._sim_settings = dict(
            sim_freq=sim_freq,
            control_freq=control_freq,
            scene_config=dict(
                solver_position_iterations=solver_position_iterations,
                solver_velocity_iterations=solver_velocity_iterations,
                cpu_workers=cpu_workers,
                # far-apart copies must not influence each other's solver results
                enable_enhanced_determinism=True,
                **(physx_scene or {}),
            ),
        )
        # the robot: a spec given as data, else the robot of configs/robot/<robot_uids>.yaml
        if robot is None:
            if not isinstance(robot_uids, str):
                raise ConfigError(f"robot_uids = {robot_uids!r} is invalid: name one robot (tiled copies: n_tiles)")
            try:
                spec = robot_agent.robot_spec_for_uid(robot_uids)
            except ValueError as err:
                raise ConfigError(str(err)) from None
        else:
            spec = robot if isinstance(robot, RobotSpec) else RobotSpec.from_mapping(robot, "robot")
        self.robot_spec: RobotSpec = spec
        uid = robot_agent.agent_uid(spec, lean=lean_robot)  # lean: no links nothing touches
        self.robot_solver_position_iterations = robot_solver_position_iterations
        if robot_collisions not in robot_agent.ROBOT_COLLISIONS:
            raise ConfigError(f"robot_collisions = {robot_collisions!r}: must be one of {robot_agent.ROBOT_COLLISIONS}")
        self.robot_collisions = robot_collisions
        uids = uid if n_tiles == 1 else tuple([uid] * n_tiles)
        # the tiled copies' robots are supported as a whole (no warning listing N names)
        self.SUPPORTED_ROBOTS = [uid, uids]
        if kwargs.get("render_backend") == "none":  # nothing renders, so no render mode (ManiSkill would warn)
            kwargs["render_mode"] = None
        kwargs.setdefault("control_mode", "pd_joint_pos_base_vel")
        super().__init__(*args, robot_uids=uids, **kwargs)

    # ------------------------------------------------------------------ configuration
    @property
    def _default_sim_config(self) -> SimConfig:
        s = self._sim_settings
        scene = dict(s["scene_config"])
        if self.device.type == "cuda":  # enhanced determinism is for the CPU's one scene of tiled copies
            scene["enable_enhanced_determinism"] = False
        return SimConfig(
            sim_freq=s["sim_freq"],
            control_freq=s["control_freq"],
            spacing=max(self.geometry.extent) + TILE_MARGIN,
            scene_config=SceneConfig(**scene),
            gpu_memory_config=gpu_memory_config(self.num_envs),
        )

    @property
    def _default_sensor_configs(self):
        return []

    @property
    def _default_human_render_camera_configs(self):
        g = self.geometry
        cx = (g.bounds_low[0] + g.bounds_high[0]) / 2
        cy = (g.bounds_low[1] + g.bounds_high[1]) / 2
        # from beyond table 2's side, high: start, both tables and the exit stay in frame
        pose = sapien_utils.look_at(eye=[cx + 0.2, cy - 3.6, 3.5], target=[cx + 0.2, cy + 0.1, 0.3])
        return CameraConfig("render_camera", pose=pose, width=512, height=512, fov=1.0, near=0.01, far=100)

    # ------------------------------------------------------------------ building
    def _load_agent(self, options: dict):
        poses = robot_base.load_poses(self.robot_spec, self.geometry.robot_start, self.offsets)
        self.scene.__dict__[robot_agent.ROBOT_COLLISIONS_KEY] = self.robot_collisions  # read where the robot is parsed
        super()._load_agent(options, poses if self.n_tiles > 1 else poses[0])
        # The robot's joint controllers compensate gravity; the objects keep it.
        # Robots may run their own solver iteration count (PhysX solves a touching robot and
        # object with the larger of their counts; the objects keep the scene's).
        for agent in self.agents:
            if self.robot_solver_position_iterations is not None:
                for art in agent.robot._objs:
                    art.set_solver_position_iterations(self.robot_solver_position_iterations)
            for link in agent.robot.get_links():
                for body in link._objs:
                    body.disable_gravity = True

    @property
    def agents(self) -> list:
        """The robot agents of every tiled copy (one on GPU: it is batched itself)."""
        return list(self.agent.agents) if self.n_tiles > 1 else [self.agent]

    def _build_box(self, box: Box, offset: np.ndarray, copy: int):
        b = self.scene.create_actor_builder()
        mat = None if box.friction is None else sapien.physx.PhysxMaterial(box.friction, box.friction, 0.0)
        b.add_box_collision(half_size=list(box.half_size), material=mat)
        b.add_box_visual(half_size=list(box.half_size), material=sapien.render.RenderMaterial(base_color=list(box.color)))
        b.initial_pose = sapien.Pose(
            p=[box.center[0] + offset[0], box.center[1] + offset[1], box.center[2]],
            q=yaw_pitch_quat(box.yaw, box.pitch),
        )
        return b.build_static(name=f"{box.name}_{copy}")

    def _load_scene(self, options: dict):
        g = self.geometry
        ground = self.scene.create_actor_builder()
        ground.add_plane_collision(sapien.Pose(p=[0, 0, 0], q=[0.7071068, 0, -0.7071068, 0]))
        extent = self.offsets.max(axis=0) + np.array(g.extent) + 2 * TILE_MARGIN
        ground.add_box_visual(
            sapien.Pose(p=[extent[0] / 2 - TILE_MARGIN + g.bounds_low[0], extent[1] / 2 - TILE_MARGIN + g.bounds_low[1], -0.005]),
            half_size=[extent[0] / 2, extent[1] / 2, 0.005],
            material=sapien.render.RenderMaterial(base_color=[0.86, 0.86, 0.84, 1]),
        )
        ground.initial_pose = sapien.Pose()
        self.ground = ground.build_static(name="ground")
        # the base is driven through its planar joints: the robot's no_floor_links never touch the floor
        self.ground.set_collision_group_bit(group=2, bit_idx=robot_agent.FLOOR_BIT, bit=1)

        self.obstacles: list[list] = []
        # object_actors[name][copy]. Objects resting on a table or another object are built with
        # their copy's fixtures; objects standing on the floor (the stick) after every copy's:
        # PhysX solves bodies in build order, and this is the order the push world had before
        # its objects were data (the golden runs pin it).
        self.object_actors: dict[str, list] = {o.name: [] for o in g.objects}
        later = [o for o in g.objects if o.rests_on == FLOOR]
        for c, off in enumerate(self.offsets):
            self.obstacles.append([self._build_box(box, off, c) for box in g.static_obstacles])
            for o in g.objects:
                if o.rests_on != FLOOR:
                    self.object_actors[o.name].append(self._build_object(o, off, c))
        for o in later:
            for c, off in enumerate(self.offsets):
                self.object_actors[o.name].append(self._build_object(o, off, c))

    def _build_object(self, o: SceneObject, offset: np.ndarray, copy: int):
        """One copy of a movable object at its rest pose (a cylinder's axis vertical)."""
        b = self.scene.create_actor_builder()
        mat = sapien.physx.PhysxMaterial(o.friction, o.friction, 0.0)
        density = o.mass / o.volume()
        look = sapien.render.RenderMaterial(base_color=list(o.color))
        if o.shape == "cylinder":
            up = sapien.Pose(q=[0.7071068, 0.0, -0.7071068, 0.0])  # SAPIEN's cylinder axis is x: turn it to z
            b.add_cylinder_collision(up, radius=o.half_size[0], half_length=o.half_size[2], material=mat,
                                     density=density)
            b.add_cylinder_visual(up, radius=o.half_size[0], half_length=o.half_size[2], material=look)
        else:
            b.add_box_collision(half_size=list(o.half_size), material=mat, density=density)
            b.add_box_visual(half_size=list(o.half_size), material=look)
        b.initial_pose = sapien.Pose(p=[o.position[0] + offset[0], o.position[1] + offset[1], o.position[2]],
                                     q=yaw_pitch_quat(o.yaw, 0.0))
        return b.build(name=f"{o.name}_{copy}")

    @property
    def dynamic_actors(self) -> list:
        """Every dynamic actor (the movable objects of every copy) in build order:
        the CPU backend takes them out of the (new) PhysX system and back in on reset, in
        this order, as the first reset of a built scene does (``realize.scene.cpu_tiled``)."""
        g = self.geometry
        first = [self.object_actors[o.name][c] for c in range(self.n_tiles) for o in g.objects if o.rests_on != FLOOR]
        return first + [a for o in g.objects if o.rests_on == FLOOR for a in self.object_actors[o.name]]

    # ------------------------------------------------------------------ episodes
    def _initialize_episode(self, env_idx: torch.Tensor, options: dict):
        g = self.geometry
        randomize = bool(options.get("randomize", False))
        # explicit per-copy offsets (realize.tasks.worlds via BatchedScene.set_worlds) replace the random draws
        offsets = options.get("offsets")
        names = list(self.agents[0].robot.active_joints_map.keys())
        rest = [self.robot_spec.rest_value(n) for n in names]
        held = list(self.robot_spec.held)
        held_targets = torch.tensor([[float(v) for v in self.robot_spec.held.values()]])
        with torch.device(self.device):
            b = len(env_idx)
            for c, agent in enumerate(self.agents):
                off = torch.tensor(self.offsets[c], dtype=torch.float32)
                copies = env_idx.cpu() * self.n_tiles + c  # this tile's copies (CPU: tile c; GPU: env_idx)
                qpos = torch.tensor(rest, dtype=torch.float32).repeat(b, 1)
                start = torch.tensor(g.robot_start[:2], dtype=torch.float32).repeat(b, 1)
                if offsets is not None:
                    start = start + offsets["robot_xy"][copies].to(start)
                elif randomize:
                    start = start + (torch.rand(b, 2) * 2 - 1) * self.robot_xy_noise
                poses = {}
                for o in g.objects:  # objects on the floor (a stick) always start at their configured pose
                    xy = torch.tensor(o.position[:2], dtype=torch.float32).repeat(b, 1) + off
                    yaw = torch.full((b,), o.yaw)
                    if offsets is not None:
                        xy = xy + offsets["object_xy"][o.name][copies].to(xy)
                        yaw = yaw + offsets["object_yaw"][o.name][copies].to(yaw)
                    elif randomize and o.rests_on != FLOOR:
                        xy = xy + (torch.rand(b, 2) * 2 - 1) * self.object_xy_noise
                        yaw = yaw + (torch.rand(b) * 2 - 1) * self.object_yaw_noise
                    poses[o.name] = (xy, yaw)
                turn = offsets["robot_yaw"][copies] if offsets is not None and "robot_yaw" in offsets else None
                robot_base.place(agent, self.robot_spec, qpos, names, start, g.robot_start, off, turn)
                agent.reset(qpos)
                agent.robot.set_qvel(torch.zeros_like(qpos))
                if held:  # held joints (a head) go to their held values, wherever the rest pose starts them
                    agent.robot.set_joint_drive_targets(held_targets.repeat(b, 1), [agent.robot.active_joints_map[n] for n in held])
                for o in g.objects:
                    xy, yaw = poses[o.name]
                    if o.rests_on in poses and o.rests_on != FLOOR:  # keep the centre above the supporting object's top
                        sup = g.object(o.rests_on)
                        lo = torch.tensor([sup.position[0] - sup.half_size[0], sup.position[1] - sup.half_size[1]]) + off
                        hi = torch.tensor([sup.position[0] + sup.half_size[0], sup.position[1] + sup.half_size[1]]) + off
                        xy = torch.maximum(torch.minimum(xy, hi), lo)
                    q = torch.stack([torch.cos(yaw / 2), 0 * yaw, 0 * yaw, torch.sin(yaw / 2)], dim=1)
                    actor = self.object_actors[o.name][c]
                    z = torch.full((b, 1), o.position[2])
                    actor.set_pose(Pose.create_from_pq(torch.cat([xy, z], dim=1), q))
                    actor.set_linear_velocity(torch.zeros(b, 3))
                    actor.set_angular_velocity(torch.zeros(b, 3))

    # ------------------------------------------------------------------ success
    def object_states(self) -> tuple[torch.Tensor, torch.Tensor]:
        """(N, m, 3) centres (each copy's local frame) and (N, m) speeds of every object, in the
        geometry's object order."""
        off = torch.as_tensor(self.offsets, dtype=torch.float32, device=self.device)
        pos, speed = [], []
        for o in self.geometry.objects:
            actors = self.object_actors[o.name]
            pos.append(torch.cat([a.pose.p - torch.cat([off[i], off.new_zeros(1)]) for i, a in enumerate(actors)]))
            speed.append(torch.cat([a.linear_velocity for a in actors]).norm(dim=1))
        return torch.stack(pos, dim=1), torch.stack(speed, dim=1)

    def evaluate(self) -> dict:
        """The task's goal (the ``goal`` kwarg, default ``default_goal``) for every copy (tiled
        or not), by ``realize.tasks.goals.goal_reached``, in the ``goal_regions``."""
        g = self.geometry
        pos, speed = self.object_states()
        base = self.base_poses()[:, :2]
        return goal_info(self.goal, g, self.goal_regions, pos, speed, base, self.goal_frames)

    def base_poses(self) -> torch.Tensor:
        """(N, 3) every copy's base x, y (its local frame) and yaw (``envs.robot_base``)."""
        off = torch.as_tensor(self.offsets, dtype=torch.float32, device=self.device)
        return robot_base.base_poses(self.agents, self.robot_spec, off, self.geometry.robot_start)

    def _get_obs_extra(self, info: dict):
        return dict()

    def compute_dense_reward(self, obs: Any, action: torch.Tensor, info: dict):
        return info["success"].float()

    def compute_normalized_dense_reward(self, obs: Any, action: torch.Tensor, info: dict):
        return self.compute_dense_reward(obs, action, info)
