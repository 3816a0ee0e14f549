"""The batched scene: N realizations of the task simulated at once, seen as (N, ...) tensors.

What it does: ``BatchedScene(n_envs, geometry, sim, env=...)`` opens the backend ``sim.backend``
resolves to (``realize.scene.backends``: N copies tiled in one PhysX CPU scene, or ManiSkill's
``num_envs = N`` on PhysX GPU) and is the one interface the realizer sees, whatever runs:
  * reads: base pose, whole-body joint state, end-effector pose, every movable object's pose
    and velocity ((N, m, ...), ``object_names`` order, or one by name), which object the gripper
    holds (finger contact forces), all in one copy's local frame (the frame of
    ``realize.world.geometry``), so nothing above it sees tile offsets; each is read from the
    simulator once per state (cached until a step, reset, freeze or object move; ``state_changed``);
  * writes: base velocity commands, upper-joint targets, the gripper opening; ``step``
    advances one control period, ``freeze`` stops finished copies, ``reset`` starts all over;
  * step hooks (``add_step_hook``: a video writer renders there), per-copy object friction and
    mass, object pushes and teleports (``realize.scene.object_properties``), and the ``EnvOptions``
    the task is built with (camera, reset noise, randomization), for replay and validation.
What it doesn't: decide anything (controllers compute the targets, the rollout runs actions), or
ask which backend runs (``backend``/``deterministic`` only report it).

Whole-body joint vector ``q`` (n_dof): base x, base y, base yaw, then the robot's upper joints
(``RobotSpec.whole_body_joints``: a lift or torso, then the arm).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from typing import Any, Protocol

import numpy as np
import torch

from realize.config import ConfigError
from realize.robot.layout import BASE, BASE_XY, UPPER, YAW
from realize.world.geometry import GeometryCfg, SceneGeometry, build_geometry, check_robot_start
from realize.scene.backends import open_backend
from realize.scene.object_properties import ObjectProperties
from realize.robot.spec import DEFAULT_ROBOT, RobotSpec, load_robot_spec
from realize.scene.settings import EnvOptions, SimSettings
from realize.scene.state_rows import reset_offsets, state_row
from realize.world.state import ObjectPose, SceneState

__all__ = ["BatchedScene", "SceneSpec", "StepHook"]

StepHook = Callable[[int], None]
RESTORE_SETTLE_STEPS = 1  # control periods a restored held object is simulated before the first read


class SceneSpec(Protocol):
    """What ``BatchedScene.from_spec`` reads of a run spec."""

    geometry_cfg: GeometryCfg
    sim: SimSettings
    robot: RobotSpec


class BatchedScene(ObjectProperties):
    """N copies of the task's world, read and written as (N, ...) tensors.

    Args:
        n_envs: number of parallel realizations (>= 1).
        geometry: the world (a ``realize.world.geometry.GeometryCfg`` or a mapping of the ``scene``
            group's keys; None: the defaults).
        sim: physics settings (None: the defaults).
        env: what the task is built and reset with besides (render camera, reset noise, forced
            randomization; None: as registered).
        robot: the robot (None: the default robot, ``realize.robot.spec.DEFAULT_ROBOT``).
    """

    def __init__(self, n_envs: int, geometry: GeometryCfg | Mapping[str, Any] | None = None,
                 sim: SimSettings | None = None, *, env: EnvOptions | None = None,
                 robot: RobotSpec | None = None):
        if isinstance(n_envs, bool) or not isinstance(n_envs, int) or n_envs < 1:
            raise ConfigError(
                f"n_envs = {n_envs!r} is invalid: the number of parallel plans (ce.n_envs) must be an integer >= 1"
            )
        self.sim = sim or SimSettings()
        self.options = env or EnvOptions()
        self.robot: RobotSpec = robot or load_robot_spec(DEFAULT_ROBOT)
        gcfg = geometry if isinstance(geometry, GeometryCfg) else GeometryCfg.from_mapping(geometry)
        check_robot_start(build_geometry(gcfg), self.robot.base.footprint_radius)  # before any simulator
        self.n_envs = n_envs
        self._impl = open_backend(n_envs, gcfg, self.sim, self.options, self.robot)
        self.backend: str = self._impl.name
        self.deterministic: bool = self._impl.deterministic
        self.env, self.u, self.device = self._impl.env, self._impl.u, self._impl.device
        self.geometry: SceneGeometry = self.u.geometry
        self.object_names: tuple[str, ...] = self.geometry.object_names
        """The movable objects, in the order of the m axis of ``object_poses`` and friends."""
        self.substeps = self.sim.sim_freq // self.sim.control_freq
        self.control_dt = 1.0 / self.sim.control_freq
        self._start_xy = torch.tensor(self.geometry.robot_start[:2], dtype=torch.float32, device=self.device)
        names = list(self.u.agents[0].robot.active_joints_map.keys())
        self.joint_names = names
        self.state_joints: tuple[str, ...] = tuple(n for n in names if n not in self.robot.base.joints)
        """Every active joint but the base's: what a ``SceneState`` holds by name."""
        if set(self.state_joints) != set(self.robot.state_joints):  # the spec must name every joint it drives
            raise ConfigError(f"robot {self.robot.name!r}: its upper, held and gripper joints "
                              f"{sorted(self.robot.state_joints)} are not the simulated robot's other active joints "
                              f"{sorted(self.state_joints)}")
        self._fixed_base = self.robot.base.fixed
        wb = self.robot.upper.joints if self._fixed_base else self.robot.whole_body_joints
        self._wb_idx = torch.tensor([names.index(j) for j in wb], device=self.device)
        self._base_fixed_pose = torch.zeros(n_envs, 3, device=self.device)  # a fixed base's, read at each reset
        self._finger_idx = torch.tensor([names.index(j) for j in self.robot.gripper.joints], device=self.device)
        self._grip_open, self._grip_closed = self.robot.gripper.open, self.robot.gripper.closed
        self._base_cmd = torch.zeros(n_envs, 3, device=self.device)
        self._arm_target = torch.zeros(n_envs, self.robot.n_upper, device=self.device)
        self._arm_vel_target = torch.zeros(n_envs, self.robot.n_upper, device=self.device)
        self._grip_target = torch.full((n_envs,), self._grip_open, device=self.device)
        self._frozen = torch.zeros(n_envs, dtype=torch.bool, device=self.device)
        self._hooks: list[tuple[StepHook, int]] = []
        self.step_count = 0  # control steps since the last reset
        self._reads: dict[str, torch.Tensor] = {}  # this state's reads, until the state changes

    @classmethod
    def from_spec(cls, spec: SceneSpec, n_envs: int, env: EnvOptions | None = None) -> BatchedScene:
        """The scene of a run spec (its ``geometry_cfg``, ``sim`` and ``robot``) with ``n_envs`` copies."""
        return cls(n_envs, spec.geometry_cfg, spec.sim, env=env, robot=spec.robot)

    # ------------------------------------------------------------------ reset, hooks
    def add_step_hook(self, hook: StepHook, every: int = 1) -> None:
        """Call ``hook(step)`` after every ``reset`` (step 0) and after every ``every``-th control
        step since the last reset (the physics of that step already simulated)."""
        if isinstance(every, bool) or not isinstance(every, int) or every < 1:
            raise ConfigError(f"every = {every!r} is invalid: must be an integer >= 1")
        self._hooks.append((hook, every))

    # reset and freeze change tensors in place that a rollout (run in inference mode) may have
    # made: only inference mode may do that, so they run in it too
    @torch.inference_mode()
    def reset(self, seed: int = 0, randomize: bool = False,
              state: SceneState | Sequence[SceneState] | None = None) -> None:
        """Put every copy back in the task's initial state (same state for all unless randomize, or
        ``env.randomize_resets``), or, with ``state``, every copy in that state (robot joints, object
        poses, gripper command; at rest; a fixed base bolted where it has it); a sequence of states
        puts copy i in ``state[i]`` (copies past its end in its first). Resets are history-free on a
        deterministic backend: a rollout in a used scene equals one in a fresh scene bit for bit.
        A state that holds an object is simulated for ``RESTORE_SETTLE_STEPS`` control periods with
        every target holding (not counted in ``step_count``): the closed fingers then press on it,
        and the contact forces that ``holds`` reads exist before the first action asks."""
        self._frozen.zero_()
        states = [] if state is None else [state] if isinstance(state, SceneState) else list(state)
        options: dict[str, Any] = dict(randomize=randomize or self.options.randomize_resets,
                                       offsets=reset_offsets(self, states, self._reset_offsets))
        self.env.reset(seed=seed, options=options)
        self._impl.after_reset()
        if self._fixed_base:  # where this reset bolted every copy's base
            self._base_fixed_pose = self.u.base_poses().to(self.device, torch.float32)
        if states:
            self._restore(states)
        self.state_changed()
        q = self.whole_body_q()
        self._base_cmd.zero_()
        self._arm_target = q[:, UPPER].clone()
        self._arm_vel_target = torch.zeros_like(self._arm_target)
        closed = [s.gripper_closed for s in states] or [False]
        closed += closed[:1] * (self.n_envs - len(closed))
        self._grip_target.copy_(torch.where(torch.tensor(closed[:self.n_envs], device=self._grip_target.device),
                                            self._grip_closed, self._grip_open).to(self._grip_target.dtype))
        self._apply_targets()
        if any(s.held is not None for s in states):
            for _ in range(RESTORE_SETTLE_STEPS):
                self._impl.step(self.substeps)
        self.state_changed()  # a caller may move things through ``u`` before the first read
        self.step_count = 0
        for hook, _ in self._hooks:
            hook(0)

    @torch.inference_mode()
    def resume(self) -> None:
        """Go on from the scene as it is (an executed world after a hold), nothing restored: every
        copy awake and holding; ``step_count`` 0 and the step hooks called with 0, as a reset does."""
        self._frozen.zero_()
        self._impl.wake()
        self.hold_still()  # written by the next step
        self.step_count = 0
        for hook, _ in self._hooks:
            hook(0)

    def _restore(self, states: Sequence[SceneState]) -> None:
        if len(states) > self.n_envs:
            raise ValueError(f"{len(states)} states for {self.n_envs} copies")
        rows, poses = zip(*(state_row(self, s) for s in states))
        pad = self.n_envs - len(states)  # copies past the states' end take the first one
        self._impl.set_state(torch.stack([*rows, *rows[:1] * pad]), torch.stack([*poses, *poses[:1] * pad]))

    def capture_state(self, copy: int = 0, source: str = "") -> SceneState:
        """Copy ``copy``'s state now (no velocities; held only if the gripper is closed): ``reset(state=)`` restores it."""
        qpos = self._read("qpos", self._impl.qpos)[copy].tolist()
        base = self.base_pose()[copy].tolist()
        poses = self.object_poses()[copy].tolist()
        held = int(self.held_object()[copy])
        return SceneState(base=tuple(base), joints={n: qpos[self.joint_names.index(n)] for n in self.state_joints},
                          gripper_closed=(closed := bool(self._grip_target[copy] == self._grip_closed)),
                          objects={n: ObjectPose(tuple(p[:3]), tuple(p[3:]), where=f"objects.{n}")
                                   for n, p in zip(self.object_names, poses)},
                          held=self.object_names[held] if held >= 0 and closed else None, source=source)

    # ------------------------------------------------------------------ reads
    # Each quantity is read from the simulator once per state: the first read after a change
    # (step, reset, freeze, place_object, push_object) asks the backend, later ones get a copy.
    def state_changed(self) -> None:
        """Forget the reads of the old state. The scene calls it whenever it changes the
        simulator; a caller that changes it through ``u``/``env`` (tests teleporting a robot)
        must call it too."""
        self._reads.clear()

    def _read(self, key: str, fn: Callable[[], torch.Tensor]) -> torch.Tensor:
        value = self._reads.get(key)
        if value is None:
            value = self._reads[key] = fn()
        return value

    def qpos(self) -> torch.Tensor:
        """(N, J) every active joint of the robot, in the articulation's order (``self.joint_names``)."""
        return self._read("qpos", self._impl.qpos).clone()

    def qvel(self) -> torch.Tensor:
        return self._read("qvel", self._impl.qvel).clone()

    def _whole_body_q(self) -> torch.Tensor:
        q = self._read("qpos", self._impl.qpos)[:, self._wb_idx]
        if self._fixed_base:
            return torch.cat([self._base_fixed_pose, q], dim=1)
        return torch.cat([q[:, BASE_XY] + self._start_xy, q[:, YAW:]], dim=1)

    def _whole_body_qd(self) -> torch.Tensor:
        qd = self._read("qvel", self._impl.qvel)[:, self._wb_idx]
        return torch.cat([torch.zeros_like(self._base_fixed_pose), qd], dim=1) if self._fixed_base else qd

    def whole_body_q(self) -> torch.Tensor:
        """(N, n_dof) base x, y (local frame), yaw, then the upper joints (lift/torso, arm)."""
        return self._read("whole_body_q", self._whole_body_q).clone()

    def whole_body_qd(self) -> torch.Tensor:
        return self._read("whole_body_qd", self._whole_body_qd).clone()

    def base_pose(self) -> torch.Tensor:
        """(N, 3) base x, y (local frame) and yaw."""
        return self._read("whole_body_q", self._whole_body_q)[:, BASE].clone()

    def gripper_command(self) -> torch.Tensor:
        """(N,) bool: the gripper target is closed (the last ``set_gripper``, or the reset's)."""
        return self._grip_target == self._grip_closed

    def commanded_targets(self) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """Copies of the next step's targets: base velocity (N, 3), upper joints (N, n_upper), gripper closed (N,)."""
        return self._base_cmd.clone(), self._arm_target.clone(), self._grip_target == self._grip_closed

    def finger_width(self) -> torch.Tensor:
        """(N,) sum of the finger joint positions (the joints' unit: m or rad; the gap between the pads
        they leave is ``realize.robot.grip_geometry``'s)."""
        return self._read("qpos", self._impl.qpos)[:, self._finger_idx].sum(dim=1)

    def ee_pose(self) -> torch.Tensor:
        """(N, 7) the TCP link's (``robot.tcp.link``) position (local frame) and wxyz quaternion."""
        return self._read("ee_pose", self._impl.ee_pose).clone()

    def object_index(self, name: str) -> int:
        """Position of object ``name`` on the m axis (``ConfigError`` naming the known ones)."""
        if name not in self.object_names:
            raise ConfigError(f"object {name!r} is not in the scene; its objects: {list(self.object_names)}")
        return self.object_names.index(name)

    def object_poses(self) -> torch.Tensor:
        """(N, m, 7) every object's position (local frame) and wxyz quaternion."""
        return self._read("object_poses", self._impl.object_poses).clone()

    def object_pose(self, name: str) -> torch.Tensor:
        """(N, 7) object ``name``'s position (local frame) and wxyz quaternion."""
        return self._read("object_poses", self._impl.object_poses)[:, self.object_index(name)].clone()

    def object_velocities(self) -> torch.Tensor:
        """(N, m, 6) every object's linear and angular velocity."""
        return self._read("object_velocities", self._impl.object_velocities).clone()

    def object_velocity(self, name: str) -> torch.Tensor:
        """(N, 6) object ``name``'s linear and angular velocity."""
        return self._read("object_velocities", self._impl.object_velocities)[:, self.object_index(name)].clone()

    def finger_forces(self) -> torch.Tensor:
        """(N, m, 2) magnitude of the contact force (N) between each object and each finger."""
        return self._read("finger_forces", self._impl.finger_forces).clone()

    def holding(self) -> torch.Tensor:
        """(N, m) bool: both fingers press on the object with at least ``sim.grasp_min_force``."""
        return (self.finger_forces() >= self.sim.grasp_min_force).all(dim=2)

    def holds(self, name: str) -> torch.Tensor:
        """(N,) bool: the gripper holds object ``name`` (both fingers press on it)."""
        return self.holding()[:, self.object_index(name)]

    def held_object(self) -> torch.Tensor:
        """(N,) int64: index (m axis) of the object the gripper holds, -1 where none (the first
        where two are pressed at once)."""
        h = self.holding()
        first = h.to(torch.int8).argmax(dim=1)
        return torch.where(h.any(dim=1), first, torch.full_like(first, -1))

    @property
    def frozen(self) -> torch.Tensor:
        return self._frozen.clone()

    @property
    def object_xy_noise(self) -> float:
        """Amplitude (m) of the objects' xy noise of a randomized reset."""
        return float(self.u.object_xy_noise)

    @property
    def object_yaw_noise(self) -> float:
        """Amplitude (rad) of the objects' yaw noise of a randomized reset."""
        return float(self.u.object_yaw_noise)

    @property
    def robot_xy_noise(self) -> float:
        """Amplitude (m) of the robot start's xy noise of a randomized reset."""
        return float(self.u.robot_xy_noise)

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
        """(N, n_upper) upper-joint position targets (rad, m), and optional velocity targets."""
        self._arm_target = q_target.detach().to(self.device, torch.float32)
        self._arm_vel_target = (torch.zeros_like(self._arm_target) if qd_target is None
                                else qd_target.detach().to(self.device, torch.float32))

    def set_gripper(self, closed: torch.Tensor, opening: torch.Tensor | None = None) -> None:
        """(N,) bool: close (True) or open (False) the gripper; ``opening`` (N,): the finger joint
        target of the open ones (a grasp's pre-shape; default ``robot.gripper.open``)."""
        c = closed.to(self.device, torch.bool)
        open_ = (torch.tensor(self._grip_open, device=self.device) if opening is None
                 else opening.to(self.device, torch.float32))
        self._grip_target = torch.where(c, torch.tensor(self._grip_closed, device=self.device), open_)

    def hold_still(self, mask: torch.Tensor | None = None) -> None:
        """Zero base velocity and freeze the upper joints at their current positions for masked copies."""
        q = self.whole_body_q()
        m = torch.ones(self.n_envs, dtype=torch.bool, device=self.device) if mask is None else mask
        self._base_cmd = torch.where(m[:, None], torch.zeros_like(self._base_cmd), self._base_cmd)
        self._arm_target = torch.where(m[:, None], q[:, UPPER], self._arm_target)
        self._arm_vel_target = torch.where(m[:, None], torch.zeros_like(self._arm_vel_target), self._arm_vel_target)

    @torch.inference_mode()
    def freeze(self, mask: torch.Tensor) -> None:
        """Stop simulating the robots of the masked copies (finished or failed plans): zero their
        velocities and put them to sleep until the next reset where the backend can (CPU: a
        sleeping articulation costs almost nothing); elsewhere this only holds them still."""
        new = mask.to(self.device, torch.bool) & ~self._frozen
        if not bool(new.any()):
            return
        self._frozen |= new
        idx = torch.nonzero(new).flatten().tolist()
        self._base_cmd[new] = 0.0
        self._impl.freeze(idx)
        self.state_changed()

    def _apply_targets(self) -> None:
        self._impl.apply_targets(self._base_cmd, self._arm_target, self._arm_vel_target, self._grip_target,
                                 self._frozen)

    def step(self) -> None:
        """Write the pending targets and advance physics by one control period; then the step hooks."""
        self._apply_targets()
        self._impl.step(self.substeps)
        self.state_changed()
        self.step_count += 1
        for hook, every in self._hooks:
            if self.step_count % every == 0:
                hook(self.step_count)

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
        self._impl.close()

    def __enter__(self) -> BatchedScene:
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()
