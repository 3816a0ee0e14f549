"""Grasp and place regions against a fixed-base arm's reach, before anything simulates.

What it does: ``region_reach(task, geometry, robot, rollout)`` draws ``n`` samples (a seeded
generator) of every ``grasp`` and ``place`` hemisphere region of the plan and asks the robot's own
kinematics (``realize.robot.reach``) whether the arm, bolted where the scene puts it, reaches
both the pre-pose (the sample) and the TCP goal (the object's centre backed off as the grasp
computes it, ``tcp_target``; a place's region centre) with the approach the sample implies. It
returns each region's reachable share. ``check_reach`` refuses, in one line naming the region, a
region none of whose samples the arm reaches, and returns a warning line for each region of which
less than ``warn_below`` is reachable (a hemisphere all around an object, for a 5-joint arm
that tilts only in the vertical plane through its base: use ``facing: robot``); ``check_reach_all``
does it for a run's candidate plans and logs the warnings (``realize.spec.run_spec``).
What it doesn't: check mobile robots (the base moves during a grasp), collisions, or the
samples the search draws later (``ce.screen`` rejects those it can).
"""

from __future__ import annotations

import logging
from collections.abc import Sequence

import torch

from realize.config import ConfigError
from realize.realization.actions.manipulate import base_axis_xy, tcp_target
from realize.realization.config import RolloutConfig
from realize.robot.kinematics import RobotKinematics
from realize.robot.reach import reachable
from realize.robot.spec import RobotSpec
from realize.tasks.hemisphere import Hemisphere
from realize.tasks.spec import TaskSpec
from realize.world.geometry import SceneGeometry

__all__ = ["region_reach", "check_reach", "check_reach_all"]

log = logging.getLogger("realize")


# (robot, base, region, action, goal terms, n) -> share: a run builds its spec more than once (the
# search, validation, replay, each replan) and the answer is a pure function of these
_SHARES: dict[tuple[object, ...], float] = {}


def region_reach(task: TaskSpec, geometry: SceneGeometry, robot: RobotSpec, rollout: RolloutConfig,
                 n: int = 48, kin: RobotKinematics | None = None) -> dict[str, float]:
    """Region name -> the share of ``n`` samples the fixed-base arm reaches (module docstring);
    each region's answer is kept for this process (``_SHARES``)."""
    base = tuple(float(v) for v in geometry.robot_start)
    out: dict[str, float] = {}
    for action in task.plan:
        if action.template not in ("grasp", "place") or not action.params:
            continue
        name = action.params[0]
        region = task.layout.regions[name]
        if not isinstance(region, Hemisphere) or name in out:
            continue
        grasped = action.template == "grasp" and action.obj is not None
        key = (repr(robot), base, repr(region), action.template,
               geometry.object(action.obj).half_height if grasped else None,
               rollout.grasp_clearance, rollout.grasp_offset, n)
        if key not in _SHARES:
            kin = kin or RobotKinematics(robot, dtype=torch.float64)
            _SHARES[key] = _share(region, action.template, action.obj, geometry, robot, rollout, n, kin, base)
        out[name] = _SHARES[key]
    return out


def _share(region: Hemisphere, template: str, obj: str | None, geometry: SceneGeometry, robot: RobotSpec,
           rollout: RolloutConfig, n: int, kin: RobotKinematics, base: tuple[float, ...]) -> float:
    """The share of ``n`` samples of one grasp or place region whose pre-pose and goal the arm reaches."""
    q0 = torch.tensor([[*base, *(robot.rest_value(j) for j in robot.upper.joints)]], dtype=kin.dtype)
    gen = torch.Generator().manual_seed(0)
    pre = region.sample_uniform(n, gen, torch.float64)[:, :3]
    centre = torch.tensor(region.center, dtype=torch.float64).expand(n, 3)
    if region.facing == "robot":  # turned toward the arm's base axis, as the grasp and place turn it
        pre = region.turn_toward(pre, centre, base_axis_xy(kin, q0.expand(n, -1)).to(pre.dtype))
    approach = region.approach(pre)
    if template == "grasp" and obj is not None:
        support = centre[:, 2] - geometry.object(obj).half_height
        goal = tcp_target(centre, approach, support, robot.gripper, rollout.grasp_clearance, rollout.grasp_offset)
    else:
        goal = centre
    ok = reachable(kin, base, torch.cat([pre, goal]), torch.cat([approach, approach]))
    return float((ok[:n] & ok[n:]).double().mean())


def check_reach(task: TaskSpec, geometry: SceneGeometry, robot: RobotSpec, rollout: RolloutConfig,
                source: str = "task", warn_below: float = 0.5) -> list[str]:
    """Refuse a region the fixed-base arm never reaches (one ``ConfigError`` line naming it); the
    warning lines of the regions it reaches less than ``warn_below`` of. A mobile robot: no check."""
    if not robot.base.fixed:
        return []
    x, y, _ = geometry.robot_start
    warnings = []
    for name, share in region_reach(task, geometry, robot, rollout).items():
        where = f"{source}:params.{name}"
        if share == 0.0:
            raise ConfigError(f"{where}: robot {robot.name!r}, bolted at ({x:.3f}, {y:.3f}), reaches no sample of this "
                              "region (pre-pose and goal, by its kinematics): move the object or the robot closer, "
                              "or narrow the region (facing: robot, polar_max, radius)")
        if share < warn_below:
            warnings.append(f"{where}: robot {robot.name!r} reaches {share:.0%} of this region's samples (pre-pose "
                            "and goal, by its kinematics); the rest time out")
    return warnings


def check_reach_all(tasks: Sequence[TaskSpec], geometry: SceneGeometry, robot: RobotSpec, rollout: RolloutConfig,
                    source: str = "task") -> None:
    """``check_reach`` on every candidate plan of a run (the planner's top k), its warnings logged."""
    for i, task in enumerate(tasks):
        for line in check_reach(task, geometry, robot, rollout, source if len(tasks) == 1 else f"{source}[{i}]"):
            log.warning(line)
