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

import torch
from torch import Tensor

from realize.geometry import SceneGeometry

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
    constant far distance, hence no force.
    """

    FAR = 10.0

    def __init__(self, box_ok: Tensor, floor_ok: Tensor):
        self.box_ok, self.floor_ok = box_ok, floor_ok

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
        rot = rz @ ry  # (N, M, 3, 3): box frame -> world
        u = points[:, :, None, :] - c[:, None, :, :]  # (N,K,M,3)
        local = torch.einsum("nmji,nkmj->nkmi", rot, u)  # R^T u
        return rot, local, h[:, None, :, :]

    def _ok(self, boxes: Tensor) -> Tensor:
        floor = boxes[..., BOX_FLOOR][:, None, :] > 0.5
        dev = boxes.device
        return torch.where(floor, self.floor_ok.to(dev)[None, :, None], self.box_ok.to(dev)[None, :, None])

    def __call__(self, points: Tensor, body_radii: Tensor, boxes: Tensor) -> Tensor:
        _, local, h = self._local(points, boxes)
        qv = local.abs() - h
        outside = torch.sqrt((torch.clamp(qv, min=0.0) ** 2).sum(-1) + 1e-12)
        inside = torch.clamp(qv.max(dim=-1).values, max=0.0)
        # dimensionless like the reference's sphere leaf (|p - c| / (r_o + r_b) - 1): the gap
        # in units of the body sphere's radius, which keeps the leaves well-conditioned at dt
        dist = (outside + inside) / body_radii[:, :, None] - 1.0
        return torch.where(self._ok(boxes), dist, torch.full_like(dist, self.FAR))

    def jets(self, p: Tensor, Jp: Tensor, pd: Tensor, ap: Tensor, radii: Tensor, boxes: Tensor
             ) -> tuple[Tensor, Tensor, Tensor, Tensor]:
        """Closed-form leaf jets (value, Jacobian, velocity, curvature), flattened (N, K*M, ...)."""
        rot, local, h = self._local(p, boxes)
        s = torch.where(local >= 0, torch.ones_like(local), -torch.ones_like(local))
        qv = local.abs() - h
        act = (qv > 0).to(p.dtype)
        w = act * qv
        wn = torch.sqrt((w * w).sum(-1) + 1e-12)
        is_out = (qv > 0).any(-1)
        k = qv.argmax(dim=-1, keepdim=True)
        e_k = torch.zeros_like(qv).scatter(-1, k, 1.0)
        g_local = torch.where(is_out[..., None], act * s * w / wn[..., None], e_k * s)
        r = radii[:, :, None]
        g = torch.einsum("nmij,nkmj->nkmi", rot, g_local) / r[..., None]  # d phi / d p (world)
        val = torch.where(is_out, wn, qv.max(-1).values) / r - 1.0
        J = torch.einsum("nkmd,nkdj->nkmj", g, Jp)
        pdl = torch.einsum("nmji,nkj->nkmi", rot, pd)  # local velocity
        v = act * s * pdl
        curv_out = ((v * v).sum(-1) - (w * v).sum(-1) ** 2 / wn ** 2) / wn
        a = (g * ap[:, :, None, :]).sum(-1) + torch.where(is_out, curv_out, torch.zeros_like(curv_out)) / r
        phid = (g * pd[:, :, None, :]).sum(-1)
        ok = self._ok(boxes).expand_as(val)
        val = torch.where(ok, val, torch.full_like(val, self.FAR))
        J = torch.where(ok[..., None], J, torch.zeros_like(J))
        phid = torch.where(ok, phid, torch.zeros_like(phid))
        a = torch.where(ok, a, torch.zeros_like(a))
        return val.flatten(1), J.flatten(1, 2), phid.flatten(1), a.flatten(1)
