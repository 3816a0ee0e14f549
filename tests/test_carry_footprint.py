"""The carried arm's A* cells (realize/controllers/carry_footprint.py) against the fabric's own
sphere-to-box distance (an independent implementation), and what the filters leave out."""

from __future__ import annotations

import math

import pytest
import torch

from realize.controllers.carry_footprint import carry_blocked
from realize.controllers.obstacles import BOX_HALF, BoxDistance
from realize.controllers.occupancy import grid_from_bounds

GRID = grid_from_bounds((-3.0, -2.5, 3.0, 2.5), 0.05)
WALL = torch.tensor([[0.0, 0.0, 0.5, 0.8, 0.05, 0.5, 0.0, 0.0, 0.0]])  # 1.6 x 0.1 x 1.0 m at the origin
RAMP = torch.tensor([[0.2, -0.6, 0.9, 0.35, 0.2, 0.01, -math.pi / 2, 0.52, 0.0]])  # yawed and pitched


def oracle(boxes: torch.Tensor, offsets: torch.Tensor, heights: torch.Tensor, radii: torch.Tensor,
           margin: float) -> torch.Tensor:
    """(R, H, W): the fabric's BoxDistance < 0 for any sphere, the boxes widened by ``margin``."""
    wide = boxes.clone().double()
    wide[:, BOX_HALF.start:BOX_HALF.start + 2] += margin
    cells = GRID.cell_centers(dtype=torch.float64).reshape(-1, 2)
    r_n, k_n = heights.shape
    dist = BoxDistance(torch.ones(k_n, dtype=torch.bool), torch.ones(k_n, dtype=torch.bool))
    out = []
    for r in range(r_n):
        pts = torch.cat([cells[:, None, :] + offsets[r].double(), heights[r].double().expand(len(cells), -1)[..., None]], -1)
        d = dist(pts, radii.double().expand(len(cells), -1), wide.expand(len(cells), -1, -1))
        out.append((d < 0).any(-1).any(-1).reshape(GRID.shape))
    return torch.stack(out)


def test_cells_match_the_fabric_box_distance_for_a_wall_and_a_ramp():
    gen = torch.Generator().manual_seed(0)
    offsets = (torch.rand(3, 4, 2, generator=gen) - 0.5) * 1.8
    heights = 0.6 + torch.rand(3, 4, generator=gen) * 0.6
    radii = torch.tensor([0.08, 0.035, 0.09, 0.06])
    for boxes in (WALL, RAMP, torch.cat([WALL, RAMP])):
        got = carry_blocked(GRID, boxes, offsets, heights, radii, base_reach=0.0, margin=0.1)
        want = oracle(boxes, offsets, heights, radii, 0.1)
        assert got.shape == (3, *GRID.shape)
        # float32 here, float64 in the oracle: at most a boundary cell apart
        assert int((got != want).sum()) <= 3, int((got != want).sum())
        assert int(got.sum()) > 50


def test_the_arm_held_out_past_a_wall_blocks_the_cells_it_would_sweep_into_it():
    # one sphere 0.8 m ahead of the base (+x) at 0.8 m: a base at (-1.2, 0) puts it at (-0.4, 0), in
    # the wall; a base at (-1.9, 0) puts it at (-1.1, 0), 0.3 m past the wall's end (0.2 m past the
    # margin, more than its radius)
    blocked = carry_blocked(GRID, WALL, torch.tensor([[[0.8, 0.0]]]), torch.tensor([[0.8]]), torch.tensor([0.08]),
                            base_reach=0.52, margin=0.1)[0]

    def at(x: float, y: float) -> bool:
        c = ((torch.tensor([x, y]) - torch.tensor(GRID.origin)) / GRID.resolution).floor().long()
        return bool(blocked[c[1], c[0]])

    assert at(-1.2, 0.0) and at(0.0, 0.1) and at(-2.4, 0.0) is False
    assert not at(-1.9, 0.0) and not at(-1.2, 0.5) and not at(-1.2, -0.5)


def test_spheres_above_an_obstacle_or_inside_the_base_disc_block_nothing():
    off = torch.tensor([[[0.8, 0.0], [0.3, 0.0]]])
    # over the 1 m wall's top (1.2 - 0.09 > 1.0), and a sphere within the padded base disc
    assert not carry_blocked(GRID, WALL, off, torch.tensor([[1.2, 0.5]]), torch.tensor([0.09, 0.09]),
                             base_reach=0.52, margin=0.1).any()
    # a table-high box under a lifted gripper: no cell
    table = torch.tensor([[0.0, 1.2, 0.36, 0.3, 0.3, 0.36, 0.0, 0.0, 0.0]])
    assert not carry_blocked(GRID, table, off, torch.tensor([[0.81, 0.5]]), torch.tensor([0.08, 0.09]),
                             base_reach=0.52, margin=0.1).any()
    # no rows, no boxes
    assert carry_blocked(GRID, WALL, off[:0], torch.zeros(0, 2), torch.tensor([0.1, 0.1]), 0.52, 0.1).shape == (0, *GRID.shape)
    assert not carry_blocked(GRID, WALL[:0], off, torch.tensor([[0.8, 0.5]]), torch.tensor([0.1, 0.1]), 0.52, 0.1).any()


# the seed-paper run's best plan (seed 0, cost 445): it parks west of both tables and holds the
# cube 0.8 m ahead of the base (+x); in the wall world the base passes the wall's west end
SEED0_BEST = [-0.99539, 0.92603, -0.03445, 1.18966, 0.88812, -0.96596, -1.06226, -0.05093, -1.14599, 0.87784,
              1.91774, -0.07169]


@pytest.mark.slow
def test_the_cube_stays_in_hand_past_the_wall_only_with_the_carry_footprint() -> None:
    from helpers import compose_config

    from realize.realization.rollout import PlanRealizer
    from realize.spec.run_spec import build_run_spec
    from realize.scene import BatchedScene

    failures = {}
    for carry in (True, False):
        spec = build_run_spec(compose_config("experiment=seed_paper", "scene=wall",
                                             f"controller.astar.carry_footprint={str(carry).lower()}"))
        with BatchedScene(1, spec.geometry_cfg, spec.sim) as scene:
            res = PlanRealizer.from_spec(spec, None, scene).rollout(torch.tensor([SEED0_BEST]))
        failures[carry] = (bool(res.feasible[0]), res.failure[0])
    # planned with the arm: around the wall's end with the cube in hand, and on to the exit (the
    # padded map is split by the wall: the last leg takes the fallback grid between table 2 and the wall)
    assert failures[True] == (True, "")
    # planned with the base alone: the gripper hits the wall on the way to table 2, the cube falls
    assert failures[False] == (False, "3:place:not_holding")
