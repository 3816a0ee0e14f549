"""Grasp approaches squared to the closing face (``controller.grasp_square_turn``).

Analytic: ``square_approach`` turns a unit approach in the plane it spans with the face normal,
by ``min(asin |a . n|, max_turn)``, so that when the bound allows it the face normal is
perpendicular to the approach (a closing axis with no tilt out of the face). In the simulator
(CPU), hand-chosen two-cubes plans with the 1 cm pre-shape of the preset: cube A turned by +-45
degrees and grasped 40 degrees off vertical from the west drops after closing with the approach
as sampled (the closing axis, a face normal projected across the tilted approach, stands out of
the horizontal and the pads press on edges); turned by up to 0.35 rad toward the face, both hold.
"""

from __future__ import annotations

import math

import pytest
import torch

from helpers import compose_config, turned_worlds
from realize.spec.run_spec import build_run_spec
from realize.config import ConfigError
from realize.realization.actions.manipulate import square_approach
from realize.realization.rollout import PlanRealizer
from realize.scene import BatchedScene

pytestmark = pytest.mark.usefixtures("torch_single_thread")


def _unit(x: torch.Tensor) -> torch.Tensor:
    return x / x.norm(dim=-1, keepdim=True)


def test_square_approach_turns_toward_the_face_plane_within_its_bound() -> None:
    g = torch.Generator().manual_seed(0)
    a = _unit(torch.randn(500, 3, generator=g, dtype=torch.float64))
    n = _unit(torch.randn(500, 3, generator=g, dtype=torch.float64))
    need = torch.asin((a * n).sum(-1).abs())  # the angle from the approach to the face's plane
    for bound in (0.2, 0.6, math.pi / 2):
        out = square_approach(a, n, bound)
        assert torch.allclose(out.norm(dim=-1), torch.ones(500, dtype=torch.float64), atol=1e-12)
        turned = torch.acos((out * a).sum(-1).clamp(-1.0, 1.0))
        assert torch.allclose(turned, need.clamp(max=bound), atol=1e-6)
        left = torch.asin((out * n).sum(-1).abs())  # what is left of the angle to the plane
        assert torch.allclose(left, (need - bound).clamp(min=0.0), atol=1e-6)
        normal = torch.linalg.cross(a, n, dim=-1)  # the turn stays in the plane of a and n
        assert torch.allclose((out * normal).sum(-1), torch.zeros(500, dtype=torch.float64), atol=1e-12)
    square = _unit(torch.tensor([[0.3, 0.0, -1.0]], dtype=torch.float64))  # already perpendicular to y
    assert torch.equal(square_approach(square, torch.tensor([[0.0, 1.0, 0.0]], dtype=torch.float64), 0.35), square)


CUBE_A = (0.0, 1.1, 0.7425)  # its centre on table 1
YAWS = [math.pi / 4, -math.pi / 4]
TILT = math.radians(40)


def _grasped(turn: str) -> tuple[list[int], list[str]]:
    spec = build_run_spec(compose_config("experiment=two_cubes", "controller.max_time_s=14",
                                         "controller.preshape_margin=0.01", f"controller.grasp_square_turn={turn}"))
    x, y, z = CUBE_A
    vals = {"Table1": [-0.85, 1.2], "CubeA_g": [x - 0.15 * math.sin(TILT), y, z + 0.15 * math.cos(TILT)],
            "CubeB_g": [0.0, 1.3, 0.8925], "Table2": [-0.85, -1.2], "CubeA_p": [0.0, -1.3, 0.8975],
            "CubeB_p": [0.0, -1.1, 0.8975], "Exit": [2.2, 0.0]}
    row = sum((vals[k] for k in spec.task.layout.names), [])
    n = len(YAWS)
    with BatchedScene(n, spec.geometry_cfg, spec.sim) as scene:
        scene.set_worlds(turned_worlds(tuple(spec.geometry.object_names), "cube_a", YAWS))
        res = PlanRealizer.from_spec(spec, None, scene).rollout(torch.tensor([row] * n, dtype=torch.float64))
    return [int(p) for p in res.progress.tolist()], list(res.failure)


@pytest.mark.parametrize("turn, held", [("null", False), ("0.35", True)])
def test_a_cube_turned_45_degrees_is_held_with_the_approach_squared(turn: str, held: bool) -> None:
    progress, failure = _grasped(turn)
    if held:  # both grasped (the rest of the plan runs into the short horizon)
        assert all(p >= 2 for p in progress), failure
    else:
        assert failure == ["1:grasp:object_dropped"] * 2, failure


def test_a_turn_past_a_right_angle_is_refused() -> None:
    with pytest.raises(ConfigError, match="controller.grasp_square_turn"):
        build_run_spec(compose_config("experiment=two_cubes", "controller.grasp_square_turn=2.0"))
