"""Grasp pre-shaping (``controller.preshape_margin``), in the simulator (CPU), hand-chosen plans.

The two-cubes plan with cube A turned by +-pi/4 and grasped 50 deg off vertical: with the fingers
fully open (null, today's default) the closing axis tilts with the turned cube, an open finger
meets the table in the move in and the grasp times out; pre-shaped to the cube's width across the
closing axis plus 1 cm, both grasps hold. Straight down on an upright 4.5 cm cube the fingers
stand 4.5 + 1 cm apart before they close (fully open: the finger joints at ``robot.gripper.open``).
"""

from __future__ import annotations

import math

import pytest
import torch

from helpers import compose_config, turned_worlds
from realize.spec.run_spec import build_run_spec
from realize.config import ConfigError
from realize.realization.rollout import PlanRealizer
from realize.scene import BatchedScene

pytestmark = pytest.mark.usefixtures("torch_single_thread")

CUBE_A = (0.0, 1.1, 0.7425)  # its centre on table 1
TILT = math.radians(50)
# rows: cube A turned -pi/4 and +pi/4, grasped 50 deg off vertical from the west; upright, from above
YAWS = [-math.pi / 4, math.pi / 4, 0.0]
TILTS = [TILT, TILT, 0.0]


def _rollout(margin: str) -> tuple[list[str], list[int], list[float], float]:
    """(failures, actions completed, finger width 1.5 s into the grasp, width_open) of the rows."""
    spec = build_run_spec(compose_config("experiment=two_cubes", "controller.max_time_s=14",
                                         f"controller.preshape_margin={margin}",
                                         "controller.grasp_square_turn=null"))  # the pre-shape alone
    base = {"Table1": [-0.85, 1.2], "CubeB_g": [0.0, 1.3, 0.8925], "Table2": [-0.85, -1.2],
            "CubeA_p": [0.0, -1.3, 0.8975], "CubeB_p": [0.0, -1.1, 0.8975], "Exit": [2.2, 0.0]}
    rows = []
    for t in TILTS:
        x, y, z = CUBE_A
        vals = {**base, "CubeA_g": [x - 0.15 * math.sin(t), y, z + 0.15 * math.cos(t)]}
        rows.append(sum((vals[k] for k in spec.task.layout.names), []))
    n = len(rows)
    with BatchedScene(n, spec.geometry_cfg, spec.sim) as scene:
        scene.set_worlds(turned_worlds(tuple(spec.geometry.object_names), "cube_a", YAWS))
        realizer = PlanRealizer.from_spec(spec, None, scene)
        seen = {"a": -1, "t": 0, "w": None}

        def on_action(a: int, rows_: torch.Tensor) -> None:
            if a == 1:
                seen["a"], seen["t"] = 1, 0

        def on_step(step: int) -> None:
            if seen["a"] == 1:
                seen["t"] += 1
                if seen["t"] == int(1.5 / scene.control_dt):
                    seen["w"] = scene.finger_width().tolist()

        realizer.action_hook = on_action
        scene.add_step_hook(on_step)
        res = realizer.rollout(torch.tensor(rows, dtype=torch.float64))
    return list(res.failure), [int(p) for p in res.progress.tolist()], seen["w"], spec.robot.gripper.open * len(spec.robot.gripper.joints)


@pytest.mark.parametrize("margin, held", [("null", False), ("0.01", True)])
def test_turned_cube_grasp(margin: str, held: bool) -> None:
    failure, progress, width, width_open = _rollout(margin)
    turned = slice(0, 2)
    if held:  # both turned cubes grasped (the rest of the plan runs into the short horizon)
        assert all(p >= 2 for p in progress[turned]), failure
        assert width[2] == pytest.approx(0.045 + 0.01, abs=0.002)  # pre-shaped before the approach
    else:  # the open finger stalls on the table in the move in
        assert failure[turned] == ["1:grasp:timeout"] * 2, failure
        assert width[2] == pytest.approx(width_open, abs=0.002)
    assert progress[2] >= 2, failure  # the upright cube straight from above: held either way


def test_negative_margin_refused() -> None:
    with pytest.raises(ConfigError, match="controller.preshape_margin"):
        build_run_spec(compose_config("experiment=two_cubes", "controller.preshape_margin=-0.01"))
