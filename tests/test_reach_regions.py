"""Reach-aware grasp and place regions (issue 56): a hemisphere ``facing: robot`` samples only
tilts in the vertical plane through the arm's base axis, which a 5-joint arm reaches; a region
the arm reaches nowhere is refused in one line naming it, before anything simulates.

Reach is judged by the robot's own kinematics (``realize.robot.reach``: damped least squares from
random starts); the plane is a fact of the SO-100's URDF (its pan axis is its only vertical one).
"""

from __future__ import annotations

import math

import pytest
import torch

from helpers import compose_config
from realize.spec.run_spec import build_run_spec
from realize.config import ConfigError
from realize.realization.actions.manipulate import base_axis_xy, tcp_target
from realize.realization.reach_check import region_reach
from realize.robot.kinematics import RobotKinematics
from realize.robot.reach import reachable
from realize.tasks.hemisphere import Hemisphere

pytestmark = pytest.mark.usefixtures("torch_single_thread")


@pytest.fixture(scope="module")
def so100():
    spec = build_run_spec(compose_config("experiment=so100_pick_place"))
    return spec, RobotKinematics(spec.robot, dtype=torch.float64)


def _rest_q(spec) -> torch.Tensor:
    return torch.tensor([[*spec.geometry.robot_start, *(spec.robot.rest_value(j) for j in spec.robot.upper.joints)]],
                        dtype=torch.float64)


def test_the_so100_grasp_region_never_samples_a_tilt_it_cannot_reach(so100) -> None:
    """1,000 samples of the task's grasp region, turned toward the arm's pan axis as the grasp
    turns them: every approach lies within the band of the vertical plane through that axis, and
    the arm reaches every pre-pose and every TCP goal with it (position 1 cm, axis 0.1 rad)."""
    spec, kin = so100
    region = spec.task.layout.regions["Cube_g"]
    assert isinstance(region, Hemisphere) and region.facing == "robot"
    n = 1000
    pre = region.sample_uniform(n, torch.Generator().manual_seed(7), torch.float64)
    centre = torch.tensor(region.center, dtype=torch.float64).expand(n, 3)
    axis = base_axis_xy(kin, _rest_q(spec).expand(n, -1))
    pre = region.turn_toward(pre, centre, axis)
    approach = region.approach(pre)
    # the horizontal part of each tilted approach points straight away from the pan axis
    out = centre[:, :2] - axis
    out = out / out.norm(dim=1, keepdim=True)
    horiz = approach[:, :2]
    tilted = horiz.norm(dim=1) > 1e-6
    cross = (horiz[:, 0] * out[:, 1] - horiz[:, 1] * out[:, 0]).abs() / horiz.norm(dim=1).clamp(min=1e-12)
    assert float(cross[tilted].max()) <= math.sin(region.azimuth_half_width) + 1e-9
    assert bool(((horiz * out).sum(1)[tilted] > 0).all())  # away from the base, not toward it
    obj = spec.geometry.object("cube")
    goal = tcp_target(centre, approach, centre[:, 2] - obj.half_height, spec.robot.gripper,
                      spec.rollout.grasp_clearance, spec.rollout.grasp_offset)
    base = spec.geometry.robot_start
    ok = reachable(kin, base, torch.cat([pre, goal]), torch.cat([approach, approach]), seeds=8, iterations=60)
    assert bool(ok.all()), f"{int((~ok).sum())} of {2 * n} poses unreached"


def test_the_same_hemisphere_all_around_the_cube_is_mostly_out_of_reach(so100) -> None:
    """The contrast that makes the test above mean something: the grasp region without its band
    (azimuth all around) is reached in less than half of its samples, and the run says so."""
    spec, kin = so100
    from dataclasses import replace

    from realize.tasks.param_layout import ParamLayout

    regions = dict(spec.task.layout.regions)
    regions["Cube_g"] = replace(regions["Cube_g"], azimuth=None, azimuth_half_width=math.pi, facing=None)
    task = replace(spec.task, layout=ParamLayout(regions))
    share = region_reach(task, spec.geometry, spec.robot, spec.rollout, kin=kin)
    assert share["Cube_g"] < 0.5 and share["Cube_p"] > 0.9


def test_a_region_the_arm_never_reaches_is_refused_naming_it() -> None:
    with pytest.raises(ConfigError) as e:
        build_run_spec(compose_config("experiment=so100_pick_place", "scene.objects.cube.offset=[0.2,0.0]"))
    msg = str(e.value)
    assert msg.startswith("task:params.Cube_g: robot 'so100'") and "reaches no sample" in msg and "\n" not in msg


def test_an_azimuth_band_samples_projects_and_contains_alike() -> None:
    h = Hemisphere(center=(0.0, 0.0, 0.0), radius=0.1, polar_max=1.2, azimuth=2.5, azimuth_half_width=0.2)
    z = h.sample_uniform(500, torch.Generator().manual_seed(0), torch.float64)
    phi = torch.atan2(z[:, 1], z[:, 0])
    rel = torch.remainder(phi - 2.5 + math.pi, 2 * math.pi) - math.pi
    assert float(rel.abs().max()) <= 0.2 + 1e-9 and bool(h.contains(z).all())
    assert torch.allclose(h.project(z), z, atol=1e-12)
    far = torch.tensor([[0.1, 0.0, 0.02]], dtype=torch.float64)  # azimuth 0: outside the band
    assert not bool(h.contains(far)[0]) and bool(h.contains(h.project(far))[0])


def test_stopping_reached_poses_early_answers_as_every_step_would(so100) -> None:
    """``reachable`` stops the poses some start reaches every ``CHECK_EVERY`` steps: every pose the
    whole 60 steps of every start reach is reached, and the rest are the poses a start had
    reached at a check (a configuration within the limits at the pose: a witness), a few at most.
    Most of these poses (all around the cube) are out of the 5-joint arm's reach."""
    from realize.robot import reach

    spec, kin = so100
    from dataclasses import replace

    hemi = replace(spec.task.layout.regions["Cube_g"], azimuth=None, azimuth_half_width=math.pi, facing=None)
    gen = torch.Generator().manual_seed(1)
    pre = hemi.sample_uniform(64, gen, torch.float64)[:, :3]
    approach = hemi.approach(pre)
    base = tuple(float(v) for v in spec.geometry.robot_start)
    q = reach._solve(kin, base, pre, approach, None, 16, 60, 0.05, 0)
    pose = kin.ee_pose(q)
    near = (pose[:, :3, 3] - pre.repeat_interleave(16, 0)).norm(dim=1) <= 0.01
    along = ((pose[:, :3, :3] @ kin.approach_local) * approach.repeat_interleave(16, 0)).sum(1) >= math.cos(0.1)
    every_step = (near & along).reshape(64, 16).any(dim=1)
    early = reach._reached(kin, base, pre, approach, 0.01, 0.1, 16, 60, 0.05, 0)
    assert 0 < int(every_step.sum()) < 64, "the poses should be a mix of reached and not"
    assert bool((early | ~every_step).all())  # nothing the whole solve reaches is lost
    assert int((early & ~every_step).sum()) <= 3


def test_a_regions_share_is_solved_once_per_process(so100, monkeypatch: pytest.MonkeyPatch) -> None:
    """A run builds its spec several times (search, validation, replay, replans): the same region
    asks the kinematics once, and a region that differs (here: its radius) asks again."""
    from dataclasses import replace

    from realize.realization import reach_check
    from realize.tasks.param_layout import ParamLayout

    spec, _ = so100
    first = region_reach(spec.task, spec.geometry, spec.robot, spec.rollout)
    calls = []
    monkeypatch.setattr(reach_check, "reachable", lambda *a, **k: calls.append(1) or reachable(*a, **k))
    assert region_reach(spec.task, spec.geometry, spec.robot, spec.rollout) == first and calls == []
    regions = dict(spec.task.layout.regions)
    regions["Cube_p"] = replace(regions["Cube_p"], radius=regions["Cube_p"].radius * 0.9)
    region_reach(replace(spec.task, layout=ParamLayout(regions)), spec.geometry, spec.robot, spec.rollout)
    assert calls == [1]  # Cube_p only
