"""The whole-body fabric around movable objects and with the held one (``controller.avoid_movable``).

Checked against geometry worked out here, not against the code under test: the boxes built from
object poses hold every corner of the object (``realize.controllers.movable.object_boxes``); a
fabric driven to a goal behind a movable block keeps its spheres off the block, where without the
block it drives them through it; a sphere for the held object acts only while a place carries it;
the rows of a batch step as each would alone; and which objects a grasp and a place leave out of
the leaves in each phase (``Manipulate._avoid``, ``Place._avoid``). The physical fact (cube E
carried to the top of a four-block tower, which the plain fabric sweeps beside below its top)
is in ``tests/test_place_lift.py``'s scene, here with ``avoid_movable``.
"""

from __future__ import annotations

import math

import pytest
import torch

from helpers import compose_config
from realize.controllers.movable import MovableObstacles, bounding_radius, object_boxes
from realize.controllers.obstacles import BOX_CENTER, BOX_HALF, BOX_PITCH, BOX_YAW
from realize.controllers.settings import WholeBodyConfig
from realize.controllers.whole_body import WholeBodyFabric
from realize.realization.actions.grasp import Grasp
from realize.realization.actions.manipulate import APPROACH, DESCEND, GRIP, RETREAT
from realize.realization.actions.place import Place
from realize.robot.spec import load_robot_spec
from realize.scene.quaternion import quat_to_matrix
from realize.world.geometry import GeometryCfg, build_geometry

F64 = torch.float64


def _rot(axis: str, a: float) -> torch.Tensor:
    c, s = math.cos(a), math.sin(a)
    rows = {"x": [[1, 0, 0], [0, c, -s], [0, s, c]], "y": [[c, 0, s], [0, 1, 0], [-s, 0, c]],
            "z": [[c, -s, 0], [s, c, 0], [0, 0, 1]]}[axis]
    return torch.tensor(rows, dtype=F64)


def _box_frame(row: torch.Tensor) -> torch.Tensor:
    return _rot("z", float(row[BOX_YAW])) @ _rot("y", float(row[BOX_PITCH]))


def test_object_boxes_are_exact_for_a_turned_block_and_hold_every_corner_of_any_pose() -> None:
    h = torch.tensor([0.03, 0.02, 0.01], dtype=F64)
    # turned about z by 0.4 rad: the box is the block itself
    row = object_boxes(torch.zeros(1, 1, 3, dtype=F64), _rot("z", 0.4)[None, None], h[None])[0, 0]
    assert float(row[BOX_YAW]) == pytest.approx(0.4) and float(row[BOX_PITCH]) == pytest.approx(0.0, abs=1e-12)
    assert torch.allclose(row[BOX_HALF], h)
    # lying on its side (rolled 90 degrees about x): y and z extents swap
    row = object_boxes(torch.zeros(1, 1, 3, dtype=F64), (_rot("z", 0.2) @ _rot("x", math.pi / 2))[None, None], h[None])[0, 0]
    assert torch.allclose(row[BOX_HALF], torch.tensor([0.03, 0.01, 0.02], dtype=F64), atol=1e-12)
    # any rotation: every corner of the block lies in the box (and the box is no larger than the block's sphere)
    g = torch.Generator().manual_seed(0)
    quats = torch.randn(200, 4, generator=g, dtype=F64)
    rot = quat_to_matrix(quats / quats.norm(dim=1, keepdim=True))
    centre = torch.randn(200, 3, generator=g, dtype=F64)
    rows = object_boxes(centre[None], rot[None], h[None].expand(200, 3))[0]
    signs = torch.tensor([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)], dtype=F64)
    for k in range(200):
        corners = centre[k] + (signs * h) @ rot[k].T  # (8, 3) in the world
        local = (corners - rows[k, BOX_CENTER]) @ _box_frame(rows[k])  # in the box's frame
        assert bool((local.abs() <= rows[k, BOX_HALF] + 1e-9).all()), k
        assert float(rows[k, BOX_HALF].norm()) <= math.sqrt(3) * float(h.norm()) + 1e-9
    assert bounding_radius("box", (0.03, 0.02, 0.01)) == pytest.approx(math.sqrt(0.0014))
    assert bounding_radius("cylinder", (0.03, 0.03, 0.04)) == pytest.approx(0.05)


@pytest.fixture(scope="module")
def fabric() -> WholeBodyFabric:
    return WholeBodyFabric(build_geometry(GeometryCfg()), WholeBodyConfig(), robot=load_robot_spec("panda"), dtype=F64)


def _start(fab: WholeBodyFabric, n: int) -> torch.Tensor:
    """(n, n_dof) the robot's rest pose, its base 20 cm behind the origin."""
    q = torch.tensor(fab.robot.rest_q(), dtype=F64).repeat(n, 1)
    q[:, :3] = torch.tensor([-0.2, 0.0, 0.0], dtype=F64)
    return q


def _block(centre: torch.Tensor, half: float) -> torch.Tensor:
    """(n, 1, 9) upright blocks of half size ``half`` at ``centre`` (n, 3)."""
    n = centre.shape[0]
    return object_boxes(centre[:, None], torch.eye(3, dtype=F64).expand(n, 1, 3, 3), torch.full((1, 3), half, dtype=F64))


def _drive(fab: WholeBodyFabric, q0: torch.Tensor, goal_tcp: torch.Tensor, movable: MovableObstacles | None,
           steps: int) -> list[torch.Tensor]:
    """Integrate the fabric alone (its reference followed exactly) toward a TCP goal with the
    hand's current axes; the joints of every step."""
    tcp0, a, c = fab.kin.tcp_and_axes(q0)
    goal = fab.goal_points(goal_tcp, a, c)
    st = fab.start(q0, torch.zeros_like(q0))
    out = []
    for _ in range(steps):
        st, valid = fab.step(st, st.q, goal, movable=movable)
        assert bool(valid.all())
        out.append(st.q)
    return out


def _tcp(fab: WholeBodyFabric, qs: list[torch.Tensor]) -> torch.Tensor:
    return torch.stack([fab.kin.tcp_and_axes(q)[0] for q in qs])


def _gap(points: torch.Tensor, centre: torch.Tensor, half: float) -> torch.Tensor:
    """Distance from points (n, 3) to upright blocks (n, 3) of half size ``half`` (<= 0 inside)."""
    q = (points - centre).abs() - half
    return q.clamp(min=0).norm(dim=-1) + q.max(dim=-1).values.clamp(max=0)


def test_a_movable_block_in_the_way_keeps_the_hand_off_and_rows_step_as_alone(fabric: WholeBodyFabric) -> None:
    fab, half, steps = fabric, 0.05, 80
    q0 = _start(fab, 3)
    tcp0 = fab.kin.tcp_and_axes(q0)[0]
    goal = tcp0 + torch.tensor([0.0, 0.0, -0.3], dtype=F64)  # straight down
    centre = tcp0 + torch.tensor([0.0, 0.0, -0.15], dtype=F64)  # a block half way, on the way
    boxes = _block(centre, half)
    none_held = (torch.zeros(3, 3, dtype=F64), torch.zeros(3, dtype=F64))
    # row 0 sees the block, row 1 leaves it out, row 2 sees a block far away (2 m off)
    far = _block(centre + torch.tensor([2.0, 0.0, 0.0], dtype=F64), half)
    mixed = torch.cat([boxes[:1], boxes[1:2], far[2:]], dim=0)
    ignore = torch.tensor([[False], [True], [False]])
    mv = MovableObstacles(mixed, ignore, *none_held, range=1.0)
    qs, qs_plain = _drive(fab, q0, goal, mv, steps), _drive(fab, q0, goal, None, steps)
    tcps, plain = _tcp(fab, qs), _tcp(fab, qs_plain)  # (steps, 3, 3)

    def clearance(q: torch.Tensor) -> float:
        """The least gap between the block and a sphere with box leaves (not the fingers), less its radius."""
        centres, radii = fab.kin.collision_spheres(q[:1])
        on = fab.distance.box_ok
        return float((_gap(centres[0, on], centre[0], half) - radii[on]).min())

    assert min(clearance(q) for q in qs_plain) < -0.02  # without it the hand passes through where the block stands
    assert min(clearance(q) for q in qs) > 0.0  # with it every sphere of the hand stays off the block
    # a row that leaves the block out, or whose block is out of range, moves as the plain fabric
    assert torch.allclose(tcps[:, 1], plain[:, 1], atol=1e-9) and torch.allclose(tcps[:, 2], plain[:, 2], atol=1e-9)
    # batched equals per-sample
    for k in range(3):
        alone = MovableObstacles(mixed[k:k + 1], ignore[k:k + 1], none_held[0][:1], none_held[1][:1], range=1.0)
        one = torch.stack(_drive(fab, q0[k:k + 1], goal[k:k + 1], alone, steps))[:, 0]
        assert torch.allclose(one, torch.stack(qs)[:, k], atol=1e-10, rtol=0), k


def test_the_held_sphere_keeps_the_carried_object_off_a_block_and_acts_only_while_held(fabric: WholeBodyFabric) -> None:
    fab, half, steps = fabric, 0.03, 80
    q0 = _start(fab, 2)
    tcp0 = fab.kin.tcp_and_axes(q0)[0]
    goal = tcp0 + torch.tensor([0.25, 0.0, 0.0], dtype=F64)  # sideways
    # an object held 12 cm below the TCP (further than the hand's spheres reach), radius 3 cm
    below = torch.tensor([0.0, 0.0, -0.12], dtype=F64)
    # a block in the held object's way, at its height, 12 cm to the side
    centre = tcp0 + below + torch.tensor([0.12, 0.0, 0.0], dtype=F64)
    boxes = _block(centre, half)
    radius = torch.tensor([0.03, 0.0], dtype=F64)  # row 0 holds it, row 1 holds nothing
    tcp_a, a0, c0 = fab.kin.tcp_and_axes(q0)
    st = fab.start(q0, torch.zeros_like(q0))
    g = fab.goal_points(goal, a0, c0)
    r0 = fab.kin.ee_pose(q0)[:, :3, :3]
    local = (r0.transpose(1, 2) @ below.expand(2, 3)[:, :, None])[:, :, 0]  # held rigidly in the hand
    held, gaps, qs = tcp0 + below, [], []
    for _ in range(steps):
        # each step the fabric is told where the object is now, as the rollout reads it
        mv = MovableObstacles(boxes, torch.zeros(2, 1, dtype=torch.bool), held, radius, range=1.0)
        st, valid = fab.step(st, st.q, g, movable=mv)
        pose = fab.kin.ee_pose(st.q)
        held = pose[:, :3, 3] + (pose[:, :3, :3] @ local[:, :, None])[:, :, 0]
        gaps.append(_gap(held, centre, half))
        qs.append(st.q)
    gaps = torch.stack(gaps)  # (steps, 2)
    assert float(gaps[:, 1].min()) < 0.0  # nothing held: the point where it would be goes through the block
    assert float(gaps[:, 0].min()) > 0.03  # held, the object (radius 3 cm) stays off the block
    # a row that holds nothing steps as the plain fabric: its hand's own spheres never met the block
    plain = torch.stack(_drive(fab, q0, goal, None, steps))
    assert torch.allclose(torch.stack(qs)[:, 1], plain[:, 1], atol=1e-9)


class _Ctx:
    """What ``_avoid`` reads: the movable objects' poses (n, m, 7)."""

    def __init__(self, n: int, m: int):
        self.objects = torch.zeros(n, m, 7)


def test_which_objects_a_grasp_and_a_place_leave_out_in_each_phase() -> None:
    n, m = 4, 5
    ctx, rows = _Ctx(n, m), torch.arange(n)
    grasp = Grasp(n, torch.device("cpu"))
    grasp.obj[:] = 2
    grasp.phase[:] = torch.tensor([APPROACH, DESCEND, GRIP, RETREAT])
    ignore, held = grasp._avoid(ctx, rows)
    assert held is None  # a grasp carries nothing as a sphere, in any phase
    assert ignore.tolist() == [[k == 2 for k in range(m)]] * n  # only the object it closes on
    place = Place(n, torch.device("cpu"))
    place.obj[:] = 3
    place.support[:] = torch.tensor([1, 1, 1, -1])  # the last sets it down on a table
    place.phase[:] = torch.tensor([APPROACH, DESCEND, RETREAT, DESCEND])
    ignore, held = place._avoid(ctx, rows)
    assert held.tolist() == [3, -1, -1, -1]  # carried as a sphere in the carry only
    assert ignore.tolist() == [
        [False, False, False, True, False],  # the carry: the support is an obstacle
        [False, True, False, True, False],  # coming down onto it: left out
        [False, True, False, True, False],  # going back out: left out
        [False, False, False, True, False],  # onto a table: nothing else left out
    ]


@pytest.mark.parametrize("avoid", [True])
def test_a_block_carried_to_the_top_of_a_tower_with_avoid_movable_goes_over_it(avoid: bool) -> None:
    """``tests/test_place_lift.py``'s scene (cube E onto a four-block tower, the seed-0 plan's
    parameters, the arm 4 cm back): the plain fabric brings cube E in 7.5 cm below the tower's
    top; avoiding the tower, cube E comes in above the top, is never below it while over it,
    lands on cube D and the tower stands."""
    from helpers import CUBE as H, carry_onto_tower

    c = carry_onto_tower(f"controller.avoid_movable={avoid}")
    res, held, tower, e, pa = c.result, c.held, c.tower, c.cube_e, c.cube_a
    moved = max(math.dist(tower[k], (pa[0], pa[1], pa[2] + H * k)) for k in range(4))
    near = [gap for d, gap in held if d <= 2 * H]
    assert bool(res.feasible[0]) and bool(res.goal[0]), res.failure
    assert near[0] >= 0.0, near[0]  # it comes in above the top (the plain fabric: 7.5 cm below)
    assert min(gap for d, gap in held if d <= H) >= -0.002  # never below the top while over it
    assert moved <= 0.002, moved  # the tower stands
    assert math.dist(e[:2], tower[3][:2]) <= 0.015 and abs(e[2] - tower[3][2] - H) <= 0.003  # cube E on top


class _Scene:
    """What ``StepContext`` reads of a scene: two copies, a cube, a can lying on its side and a block."""

    n_envs, device, control_dt = 2, torch.device("cpu"), 0.05

    def __init__(self, fab: WholeBodyFabric):
        from types import SimpleNamespace
        self.n_dof = fab.kin.n_dof
        self.geometry = SimpleNamespace(objects=(
            SimpleNamespace(shape="box", half_size=(0.02, 0.02, 0.02)),
            SimpleNamespace(shape="cylinder", half_size=(0.03, 0.03, 0.04)),
            SimpleNamespace(shape="box", half_size=(0.05, 0.01, 0.01))))

    def whole_body_q(self) -> torch.Tensor:
        return torch.zeros(2, self.n_dof)

    whole_body_qd = whole_body_q

    def object_poses(self) -> torch.Tensor:
        poses = torch.zeros(2, 3, 7)
        poses[:, :, 3] = 1.0  # upright
        poses[:, :, :3] = torch.tensor([[0.5, 0.0, 0.8], [0.5, 0.2, 0.8], [0.5, -0.2, 0.8]])
        poses[1, 1, 3:7] = torch.tensor([math.cos(math.pi / 4), math.sin(math.pi / 4), 0.0, 0.0])  # the can on its side
        return poses

    def object_velocities(self) -> torch.Tensor:
        return torch.zeros(2, 3, 6)


def test_the_step_context_builds_the_boxes_leaves_out_the_held_object_and_sizes_its_sphere(fabric) -> None:
    from realize.realization.config import RolloutConfig
    from realize.realization.context import StepContext

    ctx = StepContext(_Scene(fabric), RolloutConfig(avoid_movable=True), fabric, None, torch.zeros(4, 4, dtype=torch.bool))
    ctx.read()
    ctx.begin_step()
    goal = torch.zeros(1, 3)
    ctx.fabric_goal(torch.tensor([1]), goal, goal, goal, torch.tensor([[True, False, False]]), torch.tensor([1]))
    ctx.fabric_goal(torch.tensor([0]), goal, goal, goal)  # a template that leaves nothing out
    mv = ctx._movable(torch.tensor([1, 0]))
    # row 1 (first): the cube left out by its template, the held can left out as a box too
    assert mv.ignore.tolist() == [[True, True, False], [False, False, False]]
    assert mv.held_radius.tolist() == pytest.approx([0.05, 0.0])  # hypot(3 cm, 4 cm); nothing held
    assert mv.held_centre[0].tolist() == pytest.approx([0.5, 0.2, 0.8])
    # the can lying on its side (turned 90 degrees about x): its height now lies along y
    assert mv.boxes[0, 1, BOX_HALF].tolist() == pytest.approx([0.03, 0.04, 0.03], abs=1e-6)
    assert mv.boxes[1, 1, BOX_HALF].tolist() == pytest.approx([0.03, 0.03, 0.04], abs=1e-6)
    assert mv.boxes[1, 2, BOX_HALF].tolist() == pytest.approx([0.05, 0.01, 0.01], abs=1e-6)
    ctx.run_fabric()  # and the step runs with them
    assert not bool(ctx.fab_invalid.any())
