"""Batched, differentiable, pure-torch kinematics of a mobile manipulator's whole body.

What it does
------------
:class:`RobotKinematics` is the model of one robot's whole body ``q`` (base x, y, yaw, then the
upper joints: a lift or torso and the arm; ``RobotSpec.whole_body_joints``), built from its spec
(``realize.robot.spec``): its URDF (``realize.robot.urdf``) read once into constant tensors
(``realize.robot.chain``), the held joints (a head) and the fingers at values chosen at
construction, the TCP and the collision spheres of its sphere file. It gives

* link poses and the tool centre point (TCP) pose and axes (:meth:`~RobotKinematics.ee_pose`,
  :meth:`~RobotKinematics.tcp_and_axes`; the approach and closing axes are the spec's unit
  vectors in the TCP link's frame);
* collision-sphere centres (:meth:`~RobotKinematics.collision_spheres`);
* closed-form geometric Jacobians and curvature terms ``(dJ/dt) q'`` of the TCP and of the
  sphere centres (formulas in ``realize.robot.jacobians``), 10-30x faster on CPU than ``torch.func``
  forward-mode AD through the same FK, matching it to float64 precision;
* joint limits of ``q``;
* the ``realize.controllers.fabrics.FabricKinematics`` protocol: ``kin(q) -> (tcp, sphere
  centres)``, ``kin.body_radii`` and the fast path ``kin.jets(q, qd)``.

Every map is written with out-of-place torch ops only (no ``.item()``, no numpy, no Python
control flow on tensor values), so it works under ``torch.func.jacfwd`` / ``jvp`` / ``vmap``
and under autograd, on any device, for any leading batch shape ``(..., n_dof)``.

Frames: everything is expressed in the robot's *root* frame (the ``root`` link of the URDF,
the frame in which ``x = y = yaw = 0`` puts ``base_link``), unless a ``root_pose`` (a 4x4
world-from-root transform, optionally batched) is passed, in which case results are in the
world frame. In ManiSkill the root pose is ``robot.get_root_pose()``.

What it does not do: no inverse kinematics, no dynamics, no self-collision model (the spheres
are meant for robot-versus-environment distances); the finger joints are not degrees of freedom
(the finger spheres sit at the opening given at construction, default the open target).
"""

from __future__ import annotations

from typing import Sequence

import torch
from torch import Tensor

from realize.robot.jacobians import jdot_qdot, point_jacobian, point_jets, prefix_ends
from realize.robot.chain import KinematicChain, homogeneous, matvec3
from realize.robot.sphere_file import SphereSpec
from realize.robot.spec import RobotSpec
from realize.robot.urdf import fixed_base_joints, parse_urdf_joints, resolve_urdf

__all__ = ["RobotKinematics"]


class RobotKinematics:
    """Differentiable forward kinematics of a robot's whole body ``q`` (see module docstring).

    Args:
        spec: the robot (``realize.robot.spec.RobotSpec``): URDF, joints of ``q``, held joints,
            TCP, sphere file.
        device, dtype: where and in which precision the constant tensors live.
        finger_opening: fixed value of each finger joint (m; None: the gripper's open target);
            only the finger spheres depend on it.
        held: values of the held joints (None: the spec's ``held``).
        spheres: the collision-sphere model (None: the spec's sphere file).
        urdf_path: URDF to read (None: the spec's, ``realize.robot.urdf.resolve_urdf``).
    """

    def __init__(
        self,
        spec: RobotSpec,
        device: torch.device | str = "cpu",
        dtype: torch.dtype = torch.float32,
        finger_opening: float | None = None,
        held: dict[str, float] | None = None,
        spheres: Sequence[SphereSpec] | None = None,
        urdf_path: str | None = None,
    ) -> None:
        self.spec = spec
        self.device = torch.device(device)
        self.dtype = dtype
        self.urdf_path = urdf_path or resolve_urdf(spec.urdf, spec.visual_mesh_ext)
        self.joints = parse_urdf_joints(self.urdf_path)
        if spec.base.fixed:  # its base columns of q place the URDF's root (realize.robot.urdf.fixed_base_joints)
            self.joints = fixed_base_joints(self.joints, spec.whole_body_joints[:3], spec.base.height)
        self.ee_link: str = spec.tcp.link
        self.joint_names: tuple[str, ...] = spec.whole_body_joints
        opening = spec.gripper.open if finger_opening is None else float(finger_opening)
        self.fixed_values: dict[str, float] = {**dict(spec.held if held is None else held),
                                               **{j: opening for j in spec.gripper.joints}}
        self.spheres: tuple[SphereSpec, ...] = tuple(spec.spheres() if spheres is None else spheres)

        by_name = {j.name: j for j in self.joints.values()}
        for n in (*self.joint_names, *self.fixed_values):
            if n not in by_name:
                raise ValueError(f"robot {spec.name!r}: joint {n!r} not in {self.urdf_path}")
        self.chain = KinematicChain(self.joints, self.joint_names, self.fixed_values, self.device, self.dtype)
        self.root_link = self.chain.root_link
        self.link_names: tuple[str, ...] = self.chain.link_names
        if self.ee_link not in self.chain.index:
            raise ValueError(f"robot {spec.name!r}: tcp.link {self.ee_link!r} is not a link of {self.urdf_path}")
        self._rev_mask = self.chain.rev_mask
        kw = dict(device=self.device, dtype=self.dtype)

        # Joint limits of q.
        lower, upper, vel = [], [], []
        for n in self.joint_names:
            j = by_name[n]
            lower.append(j.lower)
            upper.append(j.upper)
            vel.append(j.velocity)
        self.lower = torch.tensor(lower, **kw)
        """(n_dof,) lower limits; -inf for continuous joints (yaw, arm rolls)."""
        self.upper = torch.tensor(upper, **kw)
        """(n_dof,) upper limits; +inf for continuous joints."""
        self.limited = torch.isfinite(self.lower) & torch.isfinite(self.upper)
        """(n_dof,) bool: which joints have finite limits."""
        self.velocity_limits = torch.tensor(vel, **kw)
        """(n_dof,) URDF velocity limits (inf where the URDF gives none)."""

        # TCP, its axes in the TCP link's frame, and spheres.
        self.tcp_offset = torch.tensor(tuple(spec.tcp.offset), **kw)
        self.approach_local = torch.tensor(tuple(spec.tcp.approach_axis), **kw)
        self.closing_local = torch.tensor(tuple(spec.tcp.closing_axis), **kw)
        self._approach_col = _basis_column(spec.tcp.approach_axis)
        self._closing_col = _basis_column(spec.tcp.closing_axis)
        for s in self.spheres:
            if s.link not in self.chain.index:
                raise ValueError(f"robot {spec.name!r}: sphere {s.name!r}: unknown link {s.link!r}")
        self.sphere_names: tuple[str, ...] = tuple(s.name for s in self.spheres)
        self.sphere_links: tuple[str, ...] = tuple(s.link for s in self.spheres)
        self.sphere_offsets = torch.tensor([s.offset for s in self.spheres], **kw).reshape(-1, 3)
        self.sphere_radii = torch.tensor([s.radius for s in self.spheres], **kw)
        """(K,) radii."""
        self.sphere_floor_mask = torch.tensor([s.check_floor for s in self.spheres], device=self.device)
        """(K,) bool: spheres to keep above the floor."""
        self.sphere_dof_mask = torch.stack(
            [self.chain.ancestor_dof_mask(s.link) for s in self.spheres]
        ).to(**kw).reshape(-1, len(self.joint_names))
        """(K, n_dof): 1 where joint j moves sphere k."""
        self._ee_dof_mask = self.chain.ancestor_dof_mask(self.ee_link).to(**kw)
        self._fk_links = [self.ee_link] + list(dict.fromkeys(self.sphere_links))
        self._jets_mask = torch.cat([self._ee_dof_mask.unsqueeze(0), self.sphere_dof_mask], dim=0)
        self._jets_ends = prefix_ends(self._jets_mask)

    @classmethod
    def for_robot(cls, name: str, **kwargs) -> RobotKinematics:
        """The model of the robot with config file ``configs/robot/<name>.yaml``."""
        from realize.robot.spec import load_robot_spec

        return cls(load_robot_spec(name), **kwargs)

    @property
    def n_dof(self) -> int:
        return len(self.joint_names)

    @property
    def n_spheres(self) -> int:
        return len(self.spheres)

    def _fk(self, q: Tensor, links: Sequence[str], root_pose: Tensor | None) -> dict[str, tuple[Tensor, Tensor]]:
        """Rotation (..., 3, 3) and position (..., 3) of the given links (and their ancestors)."""
        return self.chain.forward(q, links, root_pose)

    # ------------------------------------------------------------------ public maps

    def link_poses(self, q: Tensor, links: Sequence[str] | None = None, root_pose: Tensor | None = None) -> Tensor:
        """Poses of ``links`` (default: all URDF links, :attr:`link_names`): ``(..., L, 4, 4)``."""
        links = list(self.link_names if links is None else links)
        fk = self._fk(q, links, root_pose)
        r = torch.stack([fk[lk][0] for lk in links], dim=-3)
        p = torch.stack([fk[lk][1] for lk in links], dim=-2)
        return homogeneous(r, p)

    def link_positions(self, q: Tensor, links: Sequence[str], root_pose: Tensor | None = None) -> Tensor:
        """Origins of ``links``: ``(..., L, 3)``."""
        fk = self._fk(q, list(links), root_pose)
        return torch.stack([fk[lk][1] for lk in links], dim=-2)

    def tcp_and_axes(self, q: Tensor, root_pose: Tensor | None = None) -> tuple[Tensor, Tensor, Tensor]:
        """TCP position, unit approach axis and unit closing axis, each ``(..., 3)``."""
        r, tcp = self._tcp_from(self._fk(q, [self.ee_link], root_pose))
        return tcp, self._axis(r, self.approach_local, self._approach_col), self._axis(r, self.closing_local, self._closing_col)

    @staticmethod
    def _axis(r: Tensor, local: Tensor, col: tuple[int, float] | None) -> Tensor:
        """A unit axis fixed in the TCP link, in the output frame: a column of ``r`` where the
        axis is a basis vector (exact), else ``r @ local``."""
        if col is not None:
            k, sign = col
            return r[..., :, k] if sign > 0 else -r[..., :, k]
        return matvec3(r, local)

    def ee_pose(self, q: Tensor, root_pose: Tensor | None = None) -> Tensor:
        """TCP frame ``(..., 4, 4)``: position = TCP, rotation = the TCP link's (the approach and
        closing axes are ``spec.tcp``'s vectors in it)."""
        r, tcp = self._tcp_from(self._fk(q, [self.ee_link], root_pose))
        return homogeneous(r, tcp)

    def collision_spheres(self, q: Tensor, root_pose: Tensor | None = None) -> tuple[Tensor, Tensor]:
        """Sphere centres ``(..., K, 3)`` and radii ``(K,)`` (order: :attr:`sphere_names`)."""
        fk = self._fk(q, list(dict.fromkeys(self.sphere_links)), root_pose)
        return self._sphere_centres(fk), self.sphere_radii

    # ------------------------------------------------------------------ closed-form Jacobians
    # The actuated joints form one serial chain in q order (checked by KinematicChain); the
    # formulas are in realize.robot.jacobians.

    def _chain_terms(self, q: Tensor, links: Sequence[str], root_pose: Tensor | None):
        """FK of ``links`` plus every joint's axis and origin ``(..., n_dof, 3)`` in the output frame."""
        return self.chain.joint_frames(q, links, root_pose)

    def _point_jacobian(self, z: Tensor, o: Tensor, pts: Tensor, mask: Tensor) -> Tensor:
        """Jacobian ``(..., P, 3, n_dof)`` of points ``(..., P, 3)``, dof mask ``(P, n_dof)``."""
        return point_jacobian(z, o, pts, mask, self._rev_mask)

    def _jdot_qdot(self, z: Tensor, o: Tensor, pts: Tensor, mask: Tensor, qd: Tensor) -> Tensor:
        """(dJ/dt) q' of points ``(..., P, 3)`` with dof mask ``(P, n_dof)``: ``(..., P, 3)``."""
        return jdot_qdot(z, o, pts, mask, qd, self._rev_mask)

    def _tcp_from(self, fk: dict[str, tuple[Tensor, Tensor]]) -> tuple[Tensor, Tensor]:
        r, p = fk[self.ee_link]
        return r, p + matvec3(r, self.tcp_offset)

    def tcp_jacobian(self, q: Tensor, root_pose: Tensor | None = None) -> tuple[Tensor, Tensor]:
        """TCP pose ``(..., 4, 4)`` and geometric Jacobian ``(..., 6, n_dof)``.

        Rows 0-2: TCP linear velocity, rows 3-5: angular velocity ``w``, in the output frame.
        The approach axis ``a`` moves as ``a' = w x a``, so its Jacobian is ``-[a]x J[3:]``.
        """
        fk, z, o = self._chain_terms(q, [self.ee_link], root_pose)
        r, tcp = self._tcp_from(fk)
        mask = self._ee_dof_mask
        jv = self._point_jacobian(z, o, tcp.unsqueeze(-2), mask.unsqueeze(0)).squeeze(-3)
        jw = (z * (self._rev_mask.to(z.dtype) * mask).unsqueeze(-1)).transpose(-1, -2)
        return homogeneous(r, tcp), torch.cat([jv, jw], dim=-2)

    def tcp_jdot_qdot(self, q: Tensor, qd: Tensor, root_pose: Tensor | None = None) -> Tensor:
        """``(dJ/dt) q'`` of :meth:`tcp_jacobian`: ``(..., 6)`` (TCP and angular acceleration at q'' = 0)."""
        fk, z, o = self._chain_terms(q, [self.ee_link], root_pose)
        _, tcp = self._tcp_from(fk)
        mask = self._ee_dof_mask.unsqueeze(0)
        lin = self._jdot_qdot(z, o, tcp.unsqueeze(-2), mask, qd).squeeze(-2)
        rev = self._rev_mask.to(z.dtype) * self._ee_dof_mask
        w = torch.cumsum(z * (rev * qd).unsqueeze(-1), dim=-2)
        ang = (torch.linalg.cross(w, z, dim=-1) * (rev * qd).unsqueeze(-1)).sum(dim=-2)
        return torch.cat([lin, ang], dim=-1)

    def _sphere_centres(self, fk: dict[str, tuple[Tensor, Tensor]]) -> Tensor:
        r = torch.stack([fk[lk][0] for lk in self.sphere_links], dim=-3)
        p = torch.stack([fk[lk][1] for lk in self.sphere_links], dim=-2)
        return matvec3(r, self.sphere_offsets) + p

    def sphere_jacobians(self, q: Tensor, root_pose: Tensor | None = None) -> tuple[Tensor, Tensor, Tensor]:
        """Sphere centres ``(..., K, 3)``, radii ``(K,)`` and centre Jacobians ``(..., K, 3, n_dof)``."""
        fk, z, o = self._chain_terms(q, list(dict.fromkeys(self.sphere_links)), root_pose)
        centres = self._sphere_centres(fk)
        jac = self._point_jacobian(z, o, centres, self.sphere_dof_mask)
        return centres, self.sphere_radii, jac

    def sphere_jdot_qdot(self, q: Tensor, qd: Tensor, root_pose: Tensor | None = None) -> Tensor:
        """``(dJ/dt) q'`` of the sphere centres: ``(..., K, 3)`` (centre acceleration at q'' = 0)."""
        fk, z, o = self._chain_terms(q, list(dict.fromkeys(self.sphere_links)), root_pose)
        return self._jdot_qdot(z, o, self._sphere_centres(fk), self.sphere_dof_mask, qd)

    # ------------------------------------------------------------------ fabrics protocol

    @property
    def body_radii(self) -> Tensor:
        """(K,) sphere radii (``realize.controllers.fabrics.FabricKinematics`` protocol)."""
        return self.sphere_radii

    def __call__(self, q: Tensor, root_pose: Tensor | None = None) -> tuple[Tensor, Tensor]:
        """TCP position ``(..., 3)`` and sphere centres ``(..., K, 3)`` from one FK pass."""
        fk = self._fk(q, [self.ee_link] + list(dict.fromkeys(self.sphere_links)), root_pose)
        return self._tcp_from(fk)[1], self._sphere_centres(fk)

    def jets(
        self, q: Tensor, qd: Tensor, root_pose: Tensor | None = None
    ) -> tuple[tuple[Tensor, Tensor, Tensor, Tensor], tuple[Tensor, Tensor, Tensor, Tensor]]:
        """Closed-form jets of :meth:`__call__`, as ``fabrics.kinematic_jets`` returns them:
        ``((x, J, J q', (dJ/dt) q') of the TCP, (same) of the sphere centres)``, shapes
        ``(..., 3), (..., 3, n_dof), (..., 3), (..., 3)`` and ``(..., K, 3), (..., K, 3, 11), ...``.
        ``(dJ/dt) q' = q'^T (d^2 x / dq^2) q'`` (the true curvature term, sign +1)."""
        fk, z, o = self._chain_terms(q, self._fk_links, root_pose)
        pts = torch.cat([self._tcp_from(fk)[1].unsqueeze(-2), self._sphere_centres(fk)], dim=-2)
        jac, vel, acc = point_jets(z, o, pts, self._jets_mask, self._jets_ends, qd, self._rev_mask)
        ee = (pts[..., 0, :], jac[..., 0, :, :], vel[..., 0, :], acc[..., 0, :])
        sph = (pts[..., 1:, :], jac[..., 1:, :, :], vel[..., 1:, :], acc[..., 1:, :])
        return ee, sph


def _basis_column(axis: Sequence[float]) -> tuple[int, float] | None:
    """(k, +-1) where ``axis`` is +-e_k exactly, else None."""
    nz = [(i, v) for i, v in enumerate(axis) if v != 0.0]
    if len(nz) == 1 and abs(nz[0][1]) == 1.0:
        return nz[0][0], float(nz[0][1])
    return None
