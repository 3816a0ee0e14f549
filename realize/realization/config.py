"""Settings of a rollout (Hydra ``controller``): action tolerances, timeouts, controller settings.

What it does: ``RolloutConfig`` (the ``controller`` group, with the nested ``pid``, ``astar``
and ``fabric`` groups) and ``AStarConfig``, read and checked by ``realize.config.Settings``
(bounds are field metadata; a bad value raises ``ConfigError`` naming ``controller.<key>``).
They are checked once, when built; nothing on the control path checks them again.
What it doesn't: run anything (``realize.realization.rollout``).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING, ClassVar, Protocol

from realize.config import Settings, setting
from realize.controllers.settings import PLANNERS, PIDConfig, WholeBodyConfig

if TYPE_CHECKING:
    from realize.tasks.spec import TaskSpec
    from realize.world.state import SceneState


@dataclass
class AStarConfig(Settings):
    """Base path planning (Hydra ``controller.astar``)."""

    config_key: ClassVar[str] = "controller.astar"

    resolution: float = setting(0.05, gt=0)  # m per grid cell
    padding: float = setting(0.2, ge=0)  # m around every obstacle (paper: 20 cm), on top of the robot radius
    planner: str = setting("field", choices=PLANNERS)  # field (cached Dijkstra fields per start cell; a path does not depend on its batch) or astar (batched A*, same costs, other equal-cost paths)
    fallback_padding: float | None = setting(0.05, ge=0)  # m; a plan with no path on the padded grid retries with this padding (the gap between a table and a wall); null: no retry
    carry_footprint: bool = True  # plan around tall obstacles with the held arm's spheres too (realize/controllers/carry_footprint.py)
    carry_margin: float = setting(0.1, ge=0)  # m, how far the held arm's spheres stay from an obstacle sideways


@dataclass
class RolloutConfig(Settings):
    """Action tolerances, timeouts and controller settings (Hydra ``controller``)."""

    config_key: ClassVar[str] = "controller"

    move_tolerance: float = setting(0.1, gt=0)  # m, move_to success  ||x_base - x_loc|| <= eps
    move_timeout_s: float = setting(20.0, gt=0)
    reach_tolerance: float = setting(0.015, gt=0)  # m, ee_in(g_p): the TCP settled this close to the grasp point
    grip_tolerance: float = setting(0.005, gt=0)  # m, close at once when this close
    settle_s: float = setting(0.5, gt=0)  # s after the straight move before a settled TCP counts as arrived
    pregrasp_tolerance: float = setting(0.03, gt=0)  # m, pre-pose reached
    axis_tolerance: float = setting(0.1, gt=0)  # rad, approach axis alignment at the pre-pose
    grasp_offset: float = setting(0.0, ge=0)  # m, extra back-off of the TCP target along the approach
    grasp_clearance: float = setting(0.006, ge=0)  # m, fingertips stay this far above the supporting surface
    preshape_margin: float | None = setting(None, ge=0)  # m, grasp: fingers pre-shaped to the object's width across the closing axis plus this before the approach; null: fully open
    grasp_square_turn: float | None = setting(None, ge=0, le=1.5707963267948966)  # rad, grasp of a box: the sampled approach turns by at most this toward the plane of the face the fingers close on (the closing axis then stays that face's normal); null: as sampled
    place_align_yaw: bool = False  # place: turn the held box about the approach so it lands square on its support (the region's frame), modulo 90 degrees
    place_level: float | None = setting(None, ge=0, le=1.5707963267948966)  # rad, place of a box: the hand turns by at most this so the held box lands level (its face nearest horizontal flat) instead of on an edge; null: as held
    place_lift: bool = False  # place: the hand first rises straight up to the pre-place's height, then crosses to it, so the held object does not sweep through what stands on the way (a tower the fabric does not see)
    avoid_movable: bool = False  # the whole-body fabric also keeps off the movable objects where they stand (save those the action handles) and keeps the held object off everything (realize/controllers/movable.py)
    avoid_range: float = setting(1.0, gt=0)  # with avoid_movable: a sphere and a movable object (or the held one) interact in the fabric only within this gap, in units of the sphere's radius (a leaf has no cut-off; far pairs' metrics add up and slow every motion)
    place_drop: float = setting(0.004, ge=0)  # m, the held object is released this high above its place point
    place_pre_height: float = setting(0.12, gt=0)  # m, pre-place above a release point (place with a 3-D box region)
    retreat_share: float = setting(0.6, gt=0)  # retreat done once the TCP is this share of the way back out
    grip_s: float = setting(0.5, gt=0)  # s to close / open the gripper
    approach_speed: float = setting(0.15, gt=0)  # m/s of the straight moves in to and out from the object
    rest_speed: float = setting(0.05, gt=0)  # m/s, an object counts as resting below this
    manip_timeout_s: float = setting(15.0, gt=0)
    push_pre_distance: float = setting(0.15, gt=0)  # m, push: the straight move starts this far before the push point
    push_depth: float = setting(0.1, ge=0)  # m, push: and ends this far past it
    push_speed: float = setting(0.15, gt=0)  # m/s of the straight push (faster: the fabric lags behind the sliding goal)
    goal_settle_s: float = setting(1.5, ge=0)  # s of physics after a plan's last action before an object goal is read (uncounted)
    max_time_s: float = setting(120.0, gt=0)  # horizon of a whole plan
    record_every: int = setting(5, gt=0)  # control steps between recorded trajectory samples
    diverge_speed: float = setting(50.0, gt=0)  # joint speed that marks a plan as diverged
    base_feedback: float = setting(3.0, gt=0)  # 1/s, base position feedback onto the fabric's base velocity
    freeze_finished: bool = True  # put robots of finished / failed plans to sleep (saves physics)
    track_objects: bool = True  # a region framed by a movable object follows where it is seen when its action starts
    track_min_shift: float = setting(0.005, ge=0)  # m, seen this close to its config pose it counts as there
    pid: PIDConfig = field(default_factory=PIDConfig)
    astar: AStarConfig = field(default_factory=AStarConfig)
    fabric: WholeBodyConfig = field(default_factory=WholeBodyConfig)


class RealizerSpec(Protocol):
    """What ``PlanRealizer.from_spec`` reads from a run spec (``realize.spec.run_spec.RunSpec``)."""

    task: TaskSpec
    rollout: RolloutConfig
    seed: int
    start: SceneState | None
    keep_best: int | None
