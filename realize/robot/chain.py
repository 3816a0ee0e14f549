"""A URDF joint tree folded into constant tensors, and its batched forward kinematics.

What it does
------------
:class:`KinematicChain` takes the joints of a URDF (``realize.robot.urdf.JointSpec``), the names
of the joints that are degrees of freedom (in the order of ``q``) and fixed values for the other
movable joints, orders the links parents-first and pre-folds every link's parent joint into
constants (held joints folded into their fixed transform):

* revolute: ``R_local(t) = cos(t) A + sin(t) B + (1 - cos(t)) C``, ``p_local = p0``;
* prismatic: ``R_local = A``, ``p_local = p0 + d * Aa``; fixed: ``R_local = A``, ``p_local = p0``.

:meth:`KinematicChain.forward` then gives rotation ``(..., 3, 3)`` and position ``(..., 3)`` of
any set of links for ``q`` of any leading batch shape, with out-of-place torch ops only (works
under autograd and ``torch.func``, on any device). It also checks that the degrees of freedom
form one serial chain in ``q`` order, which the closed-form Jacobians (``realize.robot.jacobians``)
rely on.

What it doesn't: read the URDF file (``realize.robot.urdf``), know a robot's TCP or spheres
(``realize.robot.kinematics``), or compute Jacobians.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Sequence

import torch
from torch import Tensor

from realize.robot.urdf import JointSpec, axis_rotation, rpy_matrix, skew

__all__ = ["ChainNode", "KinematicChain", "homogeneous", "mat3", "matvec3", "FIXED", "REVOLUTE", "PRISMATIC"]

FIXED, REVOLUTE, PRISMATIC = 0, 1, 2


@dataclass(frozen=True)
class ChainNode:
    """One link's parent joint, pre-folded into constants (see the module docstring)."""

    link: str
    parent: int  # index into the node list, -1 for the root
    kind: int  # 0 fixed, 1 revolute, 2 prismatic
    dof: int  # index into q, -1 if none


def mat3(a: Tensor, b: Tensor) -> Tensor:
    """``a @ b`` for ``(..., 3, 3)`` by ``(..., 3, k)`` (broadcasting), written out elementwise: unlike a
    batched matmul, a row's bits never depend on the other rows of the batch."""
    return a[..., :, 0:1] * b[..., 0:1, :] + a[..., :, 1:2] * b[..., 1:2, :] + a[..., :, 2:3] * b[..., 2:3, :]


def matvec3(a: Tensor, v: Tensor) -> Tensor:
    """``a @ v`` for ``(..., 3, 3)`` matrices and ``(..., 3)`` vectors (broadcasting), elementwise."""
    return a[..., 0] * v[..., 0:1] + a[..., 1] * v[..., 1:2] + a[..., 2] * v[..., 2:3]


def homogeneous(r: Tensor, p: Tensor) -> Tensor:
    """Rotations ``(..., 3, 3)`` and positions ``(..., 3)`` -> transforms ``(..., 4, 4)``."""
    bottom = torch.zeros(*r.shape[:-2], 1, 4, dtype=r.dtype, device=r.device)
    bottom = bottom + torch.tensor([0.0, 0.0, 0.0, 1.0], dtype=r.dtype, device=r.device)
    return torch.cat([torch.cat([r, p.unsqueeze(-1)], dim=-1), bottom], dim=-2)


class KinematicChain:
    """The joint tree of a URDF as constant tensors, with ``dof_names`` as the entries of ``q``.

    Args:
        joints: URDF joints keyed by child link (``realize.robot.urdf.parse_urdf_joints``).
        dof_names: the joints that are degrees of freedom, in ``q`` order; they must form one
            serial chain in that order.
        fixed_values: values of movable joints that are not in ``dof_names`` (0 if absent).
        device, dtype: where and in which precision the constant tensors live.
    """

    def __init__(
        self,
        joints: Mapping[str, JointSpec],
        dof_names: Sequence[str],
        fixed_values: Mapping[str, float],
        device: torch.device | str = "cpu",
        dtype: torch.dtype = torch.float32,
    ) -> None:
        self.device = torch.device(device)
        self.dtype = dtype
        self.dof_names: tuple[str, ...] = tuple(dof_names)
        dof_of = {n: i for i, n in enumerate(self.dof_names)}

        # Links in topological order (parents first); the root is the link with no parent joint.
        children: dict[str, list[str]] = {}
        for j in joints.values():
            children.setdefault(j.parent, []).append(j.child)
        roots = [lk for lk in children if lk not in joints]
        if len(roots) != 1:
            raise ValueError(f"expected one root link, found {roots}")
        self.root_link = roots[0]
        order: list[str] = []
        frontier = [self.root_link]
        while frontier:
            lk = frontier.pop(0)
            order.append(lk)
            frontier.extend(children.get(lk, []))

        self.link_names: tuple[str, ...] = tuple(order)
        self.index = {lk: i for i, lk in enumerate(order)}
        nodes: list[ChainNode] = []
        a_list, b_list, c_list, p_list, ax_list = [], [], [], [], []
        eye = torch.eye(3, dtype=torch.float64)
        for lk in order:
            if lk == self.root_link:
                nodes.append(ChainNode(lk, -1, FIXED, -1))
                a_list.append(eye)
                b_list.append(torch.zeros(3, 3, dtype=torch.float64))
                c_list.append(torch.zeros(3, 3, dtype=torch.float64))
                p_list.append(torch.zeros(3, dtype=torch.float64))
                ax_list.append(torch.zeros(3, dtype=torch.float64))
                continue
            j = joints[lk]
            r0 = rpy_matrix(j.rpy)
            p0 = torch.tensor(j.xyz, dtype=torch.float64)
            axis = torch.tensor(j.axis, dtype=torch.float64)
            axis = axis / axis.norm().clamp_min(1e-12)
            movable = j.type in ("revolute", "continuous", "prismatic")
            dof = dof_of.get(j.name, -1)
            if movable and dof < 0:
                # held fixed: fold its value into the constant transform
                v = fixed_values.get(j.name, 0.0)
                if j.type == "prismatic":
                    p0 = p0 + r0 @ axis * v
                else:
                    r0 = r0 @ axis_rotation(axis, v)
                kind = FIXED
            elif movable:
                kind = PRISMATIC if j.type == "prismatic" else REVOLUTE
            else:
                kind = FIXED
            k = skew(axis)
            nodes.append(ChainNode(lk, self.index[j.parent], kind, dof))
            if kind == REVOLUTE:
                a_list.append(r0)
                b_list.append(r0 @ k)
                c_list.append(r0 @ torch.outer(axis, axis))
            else:
                a_list.append(r0)
                b_list.append(torch.zeros(3, 3, dtype=torch.float64))
                c_list.append(torch.zeros(3, 3, dtype=torch.float64))
            p_list.append(p0)
            ax_list.append(axis)
        self.nodes: tuple[ChainNode, ...] = tuple(nodes)
        kw = dict(device=self.device, dtype=self.dtype)
        self.A = torch.stack(a_list).to(**kw)  # (n_links, 3, 3)
        self.B = torch.stack(b_list).to(**kw)
        self.C = torch.stack(c_list).to(**kw)
        self.p0 = torch.stack(p_list).to(**kw)  # (n_links, 3)
        self.Aa = (torch.stack(a_list) @ torch.stack(ax_list).unsqueeze(-1)).squeeze(-1).to(**kw)
        self.axis = torch.stack(ax_list).to(**kw)
        # per link, the constant columns W of r_par @ W that give the link's pose from its parent's
        # (revolute: [A - C | B | C | p0 | Aa], prismatic: [A | p0 | Aa], fixed: [A | p0]; Aa is the
        # joint axis in the parent frame)
        self._w: list[Tensor] = []
        for i, nd in enumerate(nodes):
            a64, p64 = torch.stack(a_list)[i], torch.stack(p_list)[i]
            if nd.kind == REVOLUTE:
                w = torch.cat([a64 - c_list[i], b_list[i], c_list[i], p64[:, None], (a64 @ ax_list[i])[:, None]], dim=1)
            elif nd.kind == PRISMATIC:
                w = torch.cat([a64, p64[:, None], (a64 @ ax_list[i])[:, None]], dim=1)
            else:
                w = torch.cat([a64, p64[:, None]], dim=1)
            self._w.append(w.to(**kw))

        # Actuated joints: the link each one moves, and which joints each link depends on.
        self.dof_link: list[int] = [0] * len(self.dof_names)
        for i, nd in enumerate(nodes):
            if nd.dof >= 0:
                self.dof_link[nd.dof] = i
        self.dof_kind = [nodes[i].kind for i in self.dof_link]
        for d in range(1, self.n_dof):  # the actuated joints must be one chain, in q order
            expected = torch.arange(self.n_dof) <= d
            if not torch.equal(self.ancestor_dof_mask(nodes[self.dof_link[d]].link) > 0, expected):
                raise ValueError("whole-body joints are not a serial chain in q order (base, then the upper joints from the root outwards)")
        self.rev_mask = torch.tensor([k_ == REVOLUTE for k_ in self.dof_kind], device=self.device)
        """(n_dof,) bool: which degrees of freedom are revolute (the rest prismatic)."""

    @property
    def n_dof(self) -> int:
        return len(self.dof_names)

    def ancestor_dof_mask(self, link: str) -> Tensor:
        """``(n_dof,)`` float64: 1 where joint j moves ``link``."""
        mask = torch.zeros(self.n_dof, dtype=torch.float64)
        i = self.index[link]
        while i >= 0:
            nd = self.nodes[i]
            if nd.dof >= 0:
                mask[nd.dof] = 1.0
            i = nd.parent
        return mask

    def needed(self, links: Sequence[str]) -> list[int]:
        """Node indices of ``links`` and all their ancestors, parents first."""
        need: set[int] = set()
        for lk in links:
            if lk not in self.index:
                raise KeyError(f"unknown link {lk!r}")
            i = self.index[lk]
            while i >= 0 and i not in need:
                need.add(i)
                i = self.nodes[i].parent
        return sorted(need)  # topological order == index order

    def forward(self, q: Tensor, links: Sequence[str], root_pose: Tensor | None) -> dict[str, tuple[Tensor, Tensor]]:
        """Rotation (..., 3, 3) and position (..., 3) of the given links (and their ancestors).

        In the root frame, or in the world frame when ``root_pose`` (a world-from-root 4x4
        transform, optionally batched) is given.
        """
        return self._forward(q, links, root_pose)[0]

    def _forward(self, q: Tensor, links: Sequence[str], root_pose: Tensor | None
                 ) -> tuple[dict[str, tuple[Tensor, Tensor]], dict[int, Tensor]]:
        """Rotation (..., 3, 3) and position (..., 3) of the given links (and their ancestors).

        In the root frame, or in the world frame when ``root_pose`` (a world-from-root 4x4
        transform, optionally batched) is given.
        """
        batch = q.shape[:-1]
        axes: dict[int, Tensor] = {}  # joint axis z of each dof's link, in the output frame
        cos, sin = torch.cos(q), torch.sin(q)
        out: dict[int, tuple[Tensor, Tensor]] = {}
        for i in self.needed(links):
            nd = self.nodes[i]
            w = self._w[i]
            if nd.parent < 0:
                if root_pose is None:
                    r = self.A[i].expand(*batch, 3, 3)
                    p = self.p0[i].expand(*batch, 3)
                else:
                    rp = root_pose.to(self.dtype)
                    r = rp[..., :3, :3].expand(*batch, 3, 3)
                    p = rp[..., :3, 3].expand(*batch, 3)
                out[i] = (r, p)
                continue
            if nd.parent == 0 and root_pose is None:  # the root frame itself: pose (I, 0)
                x, p_par = w, None
            else:
                r_par, p_par = out[nd.parent]
                # the one product per link; r_par @ constant is a 2D GEMM over the batch, whose
                # rows were checked (tests/test_batch_invariance.py) not to depend on each other
                x = r_par @ w  # (..., 3, k)
            if nd.kind == REVOLUTE:
                c, s = cos[..., nd.dof, None, None], sin[..., nd.dof, None, None]
                r = c * x[..., 0:3] + s * x[..., 3:6] + x[..., 6:9]
                p = x[..., 9]
                axes[i] = x[..., 10]
            elif nd.kind == PRISMATIC:
                r = x[..., 0:3]
                p = x[..., 3] + q[..., nd.dof, None] * x[..., 4]
                axes[i] = x[..., 4]
            else:
                r, p = x[..., 0:3], x[..., 3]
            if p_par is not None:
                p = p + p_par
            r, p = r.expand(*batch, 3, 3), p.expand(*batch, 3)
            out[i] = (r, p)
        return {self.nodes[i].link: v for i, v in out.items()}, axes

    def joint_frames(
        self, q: Tensor, links: Sequence[str], root_pose: Tensor | None
    ) -> tuple[dict[str, tuple[Tensor, Tensor]], Tensor, Tensor]:
        """:meth:`forward` of ``links`` plus every degree of freedom's axis ``z`` and origin ``o``
        in the output frame, each ``(..., n_dof, 3)``."""
        fk, axes = self._forward(q, [self.nodes[i].link for i in self.dof_link] + list(links), root_pose)
        z = torch.stack([axes[i].expand(*q.shape[:-1], 3) for i in self.dof_link], dim=-2)
        o = torch.stack([fk[self.nodes[i].link][1] for i in self.dof_link], dim=-2)
        return fk, z, o
