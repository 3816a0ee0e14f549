"""What one control step knows: the scene's reads, the controllers, and the command buffers.

What it does: ``StepContext`` holds, for all N copies of the scene, the measured state of the
current control step (whole-body joints, base pose, tool centre point and gripper axes, every
movable object's pose and speed, which objects the fingers hold), the shared controllers (the whole-body
fabric, the A* grid and occupancy), and the commands the action templates write this step
(base velocity, upper-joint targets, gripper). Templates that want the fabric register a goal
for their rows (``fabric_goal``); ``run_fabric`` then runs ONE batched fabric step for all of
them and turns the fabric's reference into commands. With ``controller.avoid_movable`` that step
also avoids the movable objects where they stand now, save those each row's template leaves out,
and the object a row carries (``realize.controllers.movable``). Every field is declared below; templates
get everything else they need as arguments.
What it doesn't: decide which action a plan is in or when it ends (``realize.realization.rollout``
and the templates), or write to the simulator (the rollout does).
"""

from __future__ import annotations

from collections.abc import Callable

import torch
from torch import Tensor

from realize.robot.layout import BASE, N_BASE, UPPER
from realize.controllers.movable import MovableObstacles, bounding_radius, object_boxes
from realize.controllers.occupancy import GridSpec
from realize.controllers.whole_body import FabricState, WholeBodyFabric
from realize.realization.config import RolloutConfig
from realize.scene import BatchedScene, quat_to_matrix
from realize.world.geometry import SceneGeometry


class StepContext:
    """Per-step view shared by the templates: measured state and the command buffers.

    Constant for a rollout: ``scene``, ``cfg``, ``fabric``, ``grid``, ``occupancy`` (A*'s
    padded (H, W) grid), ``occupancy_tight`` (the grid padded by ``astar.fallback_padding``, for
    plans with no path on the padded one; None: no retry), ``n_envs``, ``device``, ``dt`` (control period, s).
    Measured by ``read()`` after every physics step, (N, ...) float32: ``q`` / ``qd`` (N, n_dof)
    whole-body joints (``realize.robot.layout``), ``base`` (N, 3) x, y, yaw, ``tcp`` (N, 3),
    ``approach`` / ``closing`` (N, 3) gripper axes, ``objects`` (N, m, 7) poses and
    ``object_speed`` (N, m) of the movable objects (``scene.object_names`` order);
    ``holds(rows, obj)`` reads finger contacts on demand (once per step).
    Commands, reset by ``begin_step()``: ``base_cmd`` (N, 3) world-frame base velocity,
    ``arm_cmd`` / ``arm_vel_cmd`` (N, n_upper) lift/torso + arm targets, ``grip_cmd`` (N,) closed;
    ``grip_open`` (N,) the finger joint target of an open gripper (``robot.gripper.open``, or a
    grasp's pre-shape; kept until a template changes it);
    ``arm_hold`` (N, n_upper) is where an arm not driven by the fabric stays.
    """

    scene: BatchedScene
    cfg: RolloutConfig
    fabric: WholeBodyFabric
    grid: GridSpec
    occupancy: Tensor
    occupancy_tight: Tensor | None
    n_envs: int
    device: torch.device
    dt: float
    q: Tensor
    qd: Tensor
    base: Tensor
    tcp: Tensor
    approach: Tensor
    closing: Tensor
    objects: Tensor
    object_speed: Tensor
    base_cmd: Tensor
    arm_cmd: Tensor
    arm_vel_cmd: Tensor
    grip_cmd: Tensor
    grip_open: Tensor
    arm_hold: Tensor
    fab_state: FabricState  # the fabric's reference state of every copy
    fab_invalid: Tensor  # (N,) the fabric flagged the copy's step invalid

    def __init__(self, scene: BatchedScene, cfg: RolloutConfig, fabric: WholeBodyFabric, grid: GridSpec,
                 occupancy: Tensor, occupancy_tight: Tensor | None = None, geometry: SceneGeometry | None = None):
        self.scene, self.cfg, self.fabric = scene, cfg, fabric
        self._geometry = geometry  # the map the controllers plan in (None: the scene's own)
        self.grid, self.occupancy, self.occupancy_tight = grid, occupancy, occupancy_tight
        self.n_envs, self.device = scene.n_envs, scene.device
        self.dt = scene.control_dt
        n, dev = self.n_envs, self.device
        n_dof = fabric.kin.n_dof
        n_upper = n_dof - N_BASE
        self.base_cmd = torch.zeros(n, N_BASE, device=dev)
        self.arm_cmd = torch.zeros(n, n_upper, device=dev)
        self.arm_vel_cmd = torch.zeros(n, n_upper, device=dev)
        self.grip_cmd = torch.zeros(n, dtype=torch.bool, device=dev)
        self.grip_open = torch.full((n,), float(fabric.robot.gripper.open), device=dev)
        self.arm_hold = torch.zeros(n, n_upper, device=dev)
        fab = dict(dtype=fabric.dtype, device=fabric.device)
        self.fab_state = FabricState(torch.zeros(n, n_dof, **fab), torch.zeros(n, n_dof, **fab))
        self._fab_rows: list[Tensor] = []
        self._fab_goals: list[Tensor] = []
        self._fab_approach: list[Tensor] = []
        self._fab_closing: list[Tensor] = []
        self._fab_ignore: list[Tensor | None] = []
        self._fab_held: list[Tensor | None] = []
        self.fab_invalid = torch.zeros(n, dtype=torch.bool, device=dev)
        self._holds: Tensor | None = None
        self._object_shape: tuple[Tensor, Tensor] | None = None  # half sizes (m, 3), bounding radii (m,)
        # where the robot's localization has its base, as an offset (N, 3: x, y, yaw) from where it
        # is; None: exact. Everything read below (q, the TCP, the base) is then the believed one
        self.base_offset: Callable[[], Tensor] | None = None


    @property
    def geometry(self) -> SceneGeometry:
        """The map the controllers plan in: the realizer's belief, or the scene's geometry."""
        return self.scene.geometry if self._geometry is None else self._geometry
    def steps(self, seconds: float) -> int:
        """Control steps in ``seconds`` (at least 1)."""
        return max(1, int(round(seconds / self.dt)))

    def read(self) -> None:
        """Read the scene's state after a physics step."""
        s = self.scene
        self.q = s.whole_body_q()
        if self.base_offset is not None:
            self.q = self.q.clone()
            self.q[:, BASE] += self.base_offset().to(self.q)
        self.qd = s.whole_body_qd()
        self.base = self.q[:, BASE]
        tcp, approach, closing = self.fabric.kin.tcp_and_axes(self.q.to(self.fabric.dtype))
        self.tcp, self.approach, self.closing = tcp.float(), approach.float(), closing.float()
        self.objects = s.object_poses()
        self.object_speed = s.object_velocities()[:, :, :3].norm(dim=2)
        self._holds = None

    def holds(self, rows: Tensor, obj: Tensor | int) -> Tensor:
        """(len(rows),) bool: both fingers press on object ``obj`` (an index on the m axis, one
        for all rows or one per row; read once per step)."""
        if self._holds is None:
            self._holds = self.scene.holding()
        return self._holds[rows, obj]

    def hold_arm(self, rows: Tensor) -> None:
        """Keep the upper joints (lift/torso, arm) of ``rows`` where they are now."""
        self.arm_hold[rows] = self.q[rows, UPPER]

    def start_fabric(self, rows: Tensor) -> None:
        """Restart the fabric's reference of ``rows`` from the measured joints, at rest."""
        st = self.fabric.start(self.q[rows], torch.zeros_like(self.qd[rows]))
        self.fab_state.q[rows] = st.q
        self.fab_state.qd[rows] = st.qd

    def fabric_goal(self, rows: Tensor, position: Tensor, approach: Tensor, closing: Tensor,
                    ignore: Tensor | None = None, held: Tensor | None = None) -> None:
        """Ask for a fabric step of ``rows`` towards a TCP position and gripper axes (len, 3).

        With ``controller.avoid_movable`` (else unused): ``ignore`` (len, m) bool, the movable
        objects the rows leave out (None: none); ``held`` (len,) long, the object each row carries
        as a collision sphere fixed to the hand, -1 none (None: none)."""
        self._fab_rows.append(rows)
        self._fab_goals.append(position)
        self._fab_approach.append(approach)
        self._fab_closing.append(closing)
        self._fab_ignore.append(ignore)
        self._fab_held.append(held)

    def _movable(self, rows: Tensor) -> MovableObstacles:
        """The movable objects the fabric step of ``rows`` (the requests' rows, in order) avoids."""
        n, m = len(rows), self.objects.shape[1]
        ignore = torch.cat([torch.zeros(len(r), m, dtype=torch.bool, device=self.device) if i is None else i
                            for r, i in zip(self._fab_rows, self._fab_ignore)])
        held = torch.cat([torch.full((len(r),), -1, dtype=torch.long, device=self.device) if h is None else h
                          for r, h in zip(self._fab_rows, self._fab_held)])
        if self._object_shape is None:
            objs = self.scene.geometry.objects
            self._object_shape = (torch.tensor([o.half_size for o in objs], device=self.device),
                                  torch.tensor([bounding_radius(o.shape, o.half_size) for o in objs], device=self.device))
        half, radius = self._object_shape
        poses = self.objects[rows]
        boxes = object_boxes(poses[..., :3], quat_to_matrix(poses[..., 3:7]), half)
        carried = held >= 0
        idx = held.clamp(min=0)
        ar = torch.arange(n, device=self.device)
        # the held object never avoids itself
        ignore = ignore | (torch.nn.functional.one_hot(idx, m).bool() & carried[:, None])
        centre = poses[ar, idx, :3]
        return MovableObstacles(boxes, ignore, centre, torch.where(carried, radius[idx], torch.zeros_like(radius[idx])),
                                self.cfg.avoid_range)

    def begin_step(self) -> None:
        """Reset the commands: base still, arm at ``arm_hold``, no fabric goals."""
        self.base_cmd.zero_()
        self.arm_cmd.copy_(self.arm_hold)
        self.arm_vel_cmd.zero_()
        self._fab_rows, self._fab_goals, self._fab_approach, self._fab_closing = [], [], [], []
        self._fab_ignore, self._fab_held = [], []
        self.fab_invalid.zero_()

    def run_fabric(self) -> None:
        """One batched fabric step for every plan that asked for it this step."""
        if not self._fab_rows:
            return
        rows = torch.cat(self._fab_rows)
        dt = self.fabric.dtype
        goal = self.fabric.goal_points(torch.cat(self._fab_goals).to(dt), torch.cat(self._fab_approach).to(dt),
                                       torch.cat(self._fab_closing).to(dt))
        st = FabricState(self.fab_state.q[rows], self.fab_state.qd[rows])
        movable = self._movable(rows) if self.cfg.avoid_movable else None
        new, valid = self.fabric.step(st, self.q[rows], goal, movable=movable)
        self.fab_state.q[rows] = new.q
        self.fab_state.qd[rows] = new.qd
        # the base is velocity-driven: feed back its position error to the fabric's reference
        base_err = (new.q[:, BASE] - self.q[rows, BASE].to(new.q)).float()
        self.base_cmd[rows] = new.qd[:, BASE].float() + self.cfg.base_feedback * base_err
        self.arm_cmd[rows] = new.q[:, UPPER].float()
        self.arm_vel_cmd[rows] = new.qd[:, UPPER].float()
        self.arm_hold[rows] = new.q[:, UPPER].float()
        self.fab_invalid[rows] = ~valid
