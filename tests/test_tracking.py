"""Acting on where objects are, and the task's perturbation model (CPU simulator).

* a plan found in the nominal world (the hand-chosen seed-task vector) grasps a cube lying 3 cm
  from its config pose when objects are tracked (``controller.track_objects``), and closes on
  air with the switch off, or where the robot sees it elsewhere (an executor's belief);
* the perturbation model reads from the task config, refuses bad ranges, and its friction and
  mass factors reach every copy's object in the simulator.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import torch

from helpers import GOOD, compose_config
from realize.spec.run_spec import build_run_spec
from realize.config import ConfigError
from realize.realization.rollout import PlanRealizer
from realize.scene import BatchedScene
from realize.tasks.perturbation import Perturbation
from realize.tasks.worlds import draw_worlds
from realize.world.state import ObjectPose

pytestmark = pytest.mark.usefixtures("torch_single_thread")


@pytest.mark.parametrize("track", [True, False])
def test_a_cube_3cm_off_is_grasped_where_it_lies_when_tracked(track: bool) -> None:
    spec = build_run_spec(compose_config(f"controller.track_objects={str(track).lower()}"))
    with BatchedScene(1, spec.geometry_cfg, spec.sim) as scene:
        scene.reset()
        state = scene.capture_state(0, source="cube 3 cm off along x")
        x, y, z = state.objects["cube"].position
        # along x: the gripper's closing axis for this top-down grasp, the side a miss shows on
        state = dataclasses.replace(state, objects={"cube": ObjectPose((x + 0.03, y, z), (1.0, 0.0, 0.0, 0.0))})
        res = PlanRealizer(spec.task, scene, spec.rollout, seed=0, start=state).rollout(torch.tensor([GOOD]))
        cube = scene.object_pose("cube")[0, :3]
    if track:
        assert res.failure == [""] and bool(res.feasible[0])
        assert abs(float(cube[1]) + 1.2) < 0.3 and abs(float(cube[2]) - (0.72 + 0.0225)) < 5e-3  # on table 2
    else:
        assert res.failure == ["1:grasp:grasp_not_held"]  # the fingers closed where the cube was meant to be


def test_the_controllers_aim_where_the_robot_sees_the_cube() -> None:
    """An executor with perception hands the realizer its belief (``seen_objects``): the cube
    lies 3 cm off, but the robot sees it at its config pose, so the fingers close there."""
    spec = build_run_spec(compose_config("controller.track_objects=true"))
    with BatchedScene(1, spec.geometry_cfg, spec.sim) as scene:
        scene.reset()
        state = scene.capture_state(0, source="cube 3 cm off along x")
        x, y, z = state.objects["cube"].position
        state = dataclasses.replace(state, objects={"cube": ObjectPose((x + 0.03, y, z), (1.0, 0.0, 0.0, 0.0))})
        realizer = PlanRealizer(spec.task, scene, spec.rollout, seed=0, start=state)
        realizer.seen_objects = lambda: torch.tensor([[[x, y, z]]])
        res = realizer.rollout(torch.tensor([GOOD]))
    assert res.failure == ["1:grasp:grasp_not_held"]


def test_the_base_is_steered_where_the_localizer_has_it() -> None:
    """A localizer 8 cm off in x (``PlanRealizer.base_error``, an executor's belief): move_to
    parks the believed base on its goal, so the true base stops 8 cm short of it."""
    from realize.tasks.spec import task_for_plan
    from realize.tasks.suffix import part_columns

    spec = build_run_spec(compose_config())
    drive = task_for_plan(spec.task, spec.task.plan[:1])  # move_to(Table1)
    z = torch.tensor([[GOOD[c] for c in part_columns(spec.task, drive)]])
    ends = []
    with BatchedScene(1, spec.geometry_cfg, spec.sim) as scene:
        for err in (None, (0.08, 0.0, 0.0)):
            realizer = PlanRealizer(drive, scene, spec.rollout, seed=0)
            if err is not None:
                realizer.base_error = lambda: torch.tensor([err])
            res = realizer.rollout(z)
            assert bool(res.action_success[0, 0]), res.failure
            ends.append(scene.base_pose()[0, :2].clone())
    assert float(ends[1][0] - ends[0][0]) == pytest.approx(-0.08, abs=0.02)
    assert float(ends[1][1] - ends[0][1]) == pytest.approx(0.0, abs=0.02)


def test_perturbation_model_from_the_task_config() -> None:
    spec = build_run_spec(compose_config("+task.perturbation.mass=[0.5,1.5]", "task.perturbation.object_xy=0.03"))
    p = spec.task.perturbation
    assert p.object_xy == 0.03 and p.mass == (0.5, 1.5) and p.friction == (0.8, 1.2)
    assert build_run_spec(compose_config()).task.perturbation == Perturbation()  # the seed task states the defaults
    for bad, needle in [("task.perturbation.friction=[1.2,0.8]", "friction"),
                        ("task.perturbation.object_xy=-0.1", "object_xy"),
                        ("+task.perturbation.wind=1.0", "wind")]:
        with pytest.raises(ConfigError, match=needle) as ei:
            build_run_spec(compose_config(bad))
        assert "perturbation" in str(ei.value)


def test_friction_and_mass_factors_reach_each_copy() -> None:
    spec = build_run_spec(compose_config())
    model = Perturbation(friction=(0.5, 1.5), mass=(0.5, 2.0))
    w = draw_worlds(model, spec.geometry.objects, 3, seed=7)
    f_friction, f_mass = {"cube": w.friction[:, 0]}, {"cube": w.mass[:, 0]}
    with BatchedScene(3, spec.geometry_cfg, spec.sim) as scene:
        scene.set_object_friction("cube", f_friction["cube"])
        masses = scene.set_object_mass("cube", f_mass["cube"])
        friction, mass = scene.object_friction("cube").clone(), scene.object_mass("cube").clone()
        assert np.ptp(w.friction[:, 0]) > 0.05 and np.ptp(w.mass[:, 0]) > 0.05  # copies differ
        assert np.allclose(friction[:, 0].numpy(), 1.0 * f_friction["cube"], rtol=1e-6)
        assert np.allclose(mass.numpy(), 0.05 * f_mass["cube"], rtol=1e-6)
        assert np.allclose(masses.numpy(), 0.05 * f_mass["cube"])
        # a heavier cube falls as fast, but squeezes the table harder: all copies still rest
        scene.reset()
        for _ in range(5):
            scene.step()
        assert (scene.object_velocity("cube")[:, :3].norm(dim=1) < 0.01).all()
        # ... and reset() keeps each copy's own friction (static and dynamic) and mass
        assert torch.equal(scene.object_friction("cube"), friction)
        assert torch.equal(scene.object_mass("cube"), mass)
        assert np.allclose(scene.object_friction("cube").numpy(), np.stack([f_friction["cube"]] * 2, 1), rtol=1e-6)
        assert np.allclose(scene.object_mass("cube").numpy(), 0.05 * f_mass["cube"], rtol=1e-6)
