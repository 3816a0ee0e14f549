"""Obstacle boxes of the whole-body fabric: the (M, 9) box tensor and its signed-distance leaves.

What it does:
  * names the columns of an obstacle-box row (``BOX_CENTER`` xyz, ``BOX_HALF`` half sizes xyz,
    ``BOX_YAW``, ``BOX_PITCH``, ``BOX_FLOOR`` flag) and builds the tensor from a scene geometry
    (``boxes_tensor``: every static box, plus the floor as one large box);
  * ``BoxDistance``: the collision leaf map of the fabric (sphere-to-box gap in units of the
    sphere radius) with closed-form jets (value, Jacobian, velocity, curvature).
What it doesn't: integrate anything or hold robot kinematics (``realize.controllers.whole_body``
wires these boxes into the fabric of ``realize.controllers.fabrics``).
"""

from __future__ import annotations

import math

import torch
from torch import Tensor

from realize.world.geometry import SceneGeometry
from realize.robot.chain import mat3, matvec3

# columns of one obstacle-box row
BOX_CENTER = slice(0, 3)  # centre x, y, z (m)
BOX_HALF = slice(3, 6)  # half sizes along the box's own axes (m)
BOX_YAW = 6  # rad about +z
BOX_PITCH = 7  # rad about the box's own y axis (a ramp)
BOX_FLOOR = 8  # 1.0 for the floor box, 0.0 otherwise
BOX_COLUMNS = 9
FLOOR_HALF = 50.0


def boxes_tensor(geometry: SceneGeometry, floor: bool = True) -> Tensor:
    """(M, BOX_COLUMNS) float64 obstacle boxes of ``geometry.static_obstacles`` (+ the floor)."""
    rows = [list(b.center) + list(b.half_size) + [b.yaw, b.pitch, 0.0] for b in geometry.static_obstacles]
    if floor:
        rows.append([0.0, 0.0, -FLOOR_HALF, FLOOR_HALF, FLOOR_HALF, FLOOR_HALF, 0.0, 0.0, 1.0])
    return torch.tensor(rows, dtype=torch.float64)


class BoxDistance:
    """Leaf map of the collision terms: sphere-to-box gap in units of the sphere radius.

    ``__call__(points (N,K,3), radii (N,K), boxes (N,M,BOX_COLUMNS)) -> (N,K,M)``. Pairs that
    must not interact (``box_ok[k]`` False for a box, ``floor_ok[k]`` False for the floor) get a
    constant far distance, hence no force. Per step, ``pair_ok`` (N, K, M) bool further leaves
    pairs out row by row (``controller.avoid_movable``: the objects a row handles, a held-object
    sphere where none is held). Pairs marked ``soft`` (N, K, M) bool (a movable object, or the
    held one) get no leaf farther apart than ``soft_range`` (leaf units): a leaf has no cut-off of
    its own, and the metrics of many far pairs add up and slow every motion; and their value is
    floored at ``SOFT_FLOOR``: a block knocked against the arm, or a held object whose sphere
    overlaps something when the carry begins, starts inside the leaf's barrier, where the value
    would be negative (a negative metric that pulls in and blows up); floored, such a pair brakes
    every motion further in, and the direction of its push stays the true one.
    """

    FAR = 10.0
    SOFT_FLOOR = 0.05

    def __init__(self, box_ok: Tensor, floor_ok: Tensor, pair_ok: Tensor | None = None,
                 soft: Tensor | None = None, soft_range: float = math.inf):
        self.box_ok, self.floor_ok = box_ok, floor_ok
        self.pair_ok, self.soft, self.soft_range = pair_ok, soft, soft_range

    def _local(self, points: Tensor, boxes: Tensor) -> tuple[Tensor, Tensor, Tensor]:
        c, h = boxes[..., BOX_CENTER], boxes[..., BOX_HALF]
        yaw, pitch = boxes[..., BOX_YAW], boxes[..., BOX_PITCH]
        cy, sy = torch.cos(yaw), torch.sin(yaw)
        cp, sp = torch.cos(pitch), torch.sin(pitch)
        zero, one = torch.zeros_like(cy), torch.ones_like(cy)
        rz = torch.stack([torch.stack([cy, -sy, zero], -1), torch.stack([sy, cy, zero], -1),
                          torch.stack([zero, zero, one], -1)], -2)
        ry = torch.stack([torch.stack([cp, zero, sp], -1), torch.stack([zero, one, zero], -1),
                          torch.stack([-sp, zero, cp], -1)], -2)
        rot = mat3(rz, ry)  # (N, M, 3, 3): box frame -> world
        u = points[:, :, None, :] - c[:, None, :, :]  # (N,K,M,3)
        return rot, _rt_vec(rot[:, None], u), h[:, None, :, :]

    def _ok(self, boxes: Tensor) -> Tensor:
        floor = boxes[..., BOX_FLOOR][:, None, :] > 0.5
        dev = boxes.device
        ok = torch.where(floor, self.floor_ok.to(dev)[None, :, None], self.box_ok.to(dev)[None, :, None])
        return ok if self.pair_ok is None else ok & self.pair_ok

    def _soft_off(self, ok: Tensor, val: Tensor) -> Tensor:
        """``ok`` without the ``soft`` pairs out of range now."""
        return ok if self.soft is None else ok & ~(self.soft & (val > self.soft_range))

    def _soft_floor(self, val: Tensor) -> Tensor:
        """``val`` with the ``soft`` pairs' values floored at ``SOFT_FLOOR``."""
        if self.soft is None:
            return val
        return torch.where(self.soft, val.clamp(min=self.SOFT_FLOOR), val)

    def __call__(self, points: Tensor, body_radii: Tensor, boxes: Tensor) -> Tensor:
        _, local, h = self._local(points, boxes)
        qv = local.abs() - h
        outside = torch.sqrt((torch.clamp(qv, min=0.0) ** 2).sum(-1) + 1e-12)
        inside = torch.clamp(qv.max(dim=-1).values, max=0.0)
        # dimensionless like the reference's sphere leaf (|p - c| / (r_o + r_b) - 1): the gap
        # in units of the body sphere's radius, which keeps the leaves well-conditioned at dt
        dist = (outside + inside) / body_radii[:, :, None] - 1.0
        return torch.where(self._soft_off(self._ok(boxes), dist), self._soft_floor(dist), torch.full_like(dist, self.FAR))

    def jets(self, p: Tensor, Jp: Tensor, pd: Tensor, ap: Tensor, radii: Tensor, boxes: Tensor
             ) -> tuple[Tensor, Tensor, Tensor, Tensor]:
        """Closed-form leaf jets (value, Jacobian, velocity, curvature), flattened (N, K*M, ...).

        Every sum over the 3 coordinates is written out (elementwise ops only): faster than
        tiny matrix products and reductions, and a row's bits never depend on its batch mates."""
        rot, local, h = self._local(p, boxes)
        s = torch.where(local >= 0, torch.ones_like(local), -torch.ones_like(local))
        qv = local.abs() - h
        act = (qv > 0).to(p.dtype)
        w = act * qv
        wn = torch.sqrt(_dot3(w, w) + 1e-12)
        q0, q1, q2 = qv.unbind(-1)
        qmax = torch.maximum(torch.maximum(q0, q1), q2)
        is_out = qmax > 0
        # one-hot of the first largest coordinate (argmax) for points inside the box
        k0 = (q0 >= q1) & (q0 >= q2)
        k1 = ~k0 & (q1 >= q2)
        e_k = torch.stack([k0, k1, ~k0 & ~k1], dim=-1).to(p.dtype)
        g_local = torch.where(is_out[..., None], act * s * w / wn[..., None], e_k * s)
        r = radii[:, :, None]
        ok = self._ok(boxes).expand_as(qmax)
        if self.soft is not None:
            ok = self._soft_off(ok, torch.where(is_out, wn, qmax) / r - 1.0)
        # d phi / d p (world); zero on pairs that must not interact
        g = torch.where(ok[..., None], matvec3(rot[:, None], g_local) / r[..., None], torch.zeros_like(g_local))
        val = torch.where(is_out, wn, qmax) / r - 1.0
        g0, g1, g2 = g.unsqueeze(-1).unbind(-2)  # (N,K,M,1)
        J0, J1, J2 = Jp[:, :, None].unbind(-2)  # (N,K,1,n)
        J = g0 * J0 + g1 * J1 + g2 * J2
        v = act * s * _rt_vec(rot[:, None], pd[:, :, None, :])  # local velocity of the active coordinates
        curv_out = (_dot3(v, v) - _dot3(w, v) ** 2 / wn ** 2) / wn
        a = _dot3(g, ap[:, :, None, :]) + torch.where(is_out & ok, curv_out, torch.zeros_like(curv_out)) / r
        phid = _dot3(g, pd[:, :, None, :])
        val = torch.where(ok, self._soft_floor(val), torch.full_like(val, self.FAR))
        return val.flatten(1), J.flatten(1, 2), phid.flatten(1), a.flatten(1)


def _dot3(a: Tensor, b: Tensor) -> Tensor:
    """Dot product over a last dim of size 3, written out (broadcasting)."""
    return a[..., 0] * b[..., 0] + a[..., 1] * b[..., 1] + a[..., 2] * b[..., 2]


def _rt_vec(rot: Tensor, u: Tensor) -> Tensor:
    """``rot^T @ u`` for ``(..., 3, 3)`` and ``(..., 3)`` (broadcasting), written out."""
    return rot[..., 0, :] * u[..., 0:1] + rot[..., 1, :] * u[..., 1:2] + rot[..., 2, :] * u[..., 2:3]
