"""The controllers' settings (Hydra ``controller.pid``, ``controller.fabric``, ``controller.astar``'s
planner names): plain dataclasses with their defaults and bounds, in a module that imports no torch.

What it does: holds ``PIDConfig`` (the base's waypoint PID), ``FabricConfig`` (the fabric's
constants), ``WholeBodyConfig`` (the whole-body fabric's keys) and the names ``HEADING_MODES`` and
``PLANNERS``, so that the ``controller`` group's schema (``realize.spec.hydra_edge.register_schema``)
is registered from the classes without loading the controllers. The controllers' modules
(``pid``, ``fabrics``, ``whole_body``, ``astar``) import them from here.
What it doesn't: run a controller.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

from realize.config import ConfigError, Settings, setting

__all__ = ["HEADING_MODES", "PLANNERS", "PIDConfig", "FabricConfig", "WholeBodyConfig"]

HEADING_MODES = ("hold", "face_goal", "target")
PLANNERS = ("astar", "field")  # search engines of ``astar(planner=...)``


@dataclass
class PIDConfig(Settings):
    """Gains and limits (SI units: m, s, rad).

    kp, ki, kd: position gains (kp > 0; ki, kd >= 0).
    kp_yaw, ki_yaw, kd_yaw: yaw gains (kp_yaw > 0; others >= 0).
    max_lin_speed: m/s (> 0). max_yaw_rate: rad/s (> 0).
    max_lin_accel, max_yaw_accel: optional limits (> 0) on the command change per second.
    switch_radius: advance to the next waypoint once within this distance (> 0).
    goal_tolerance: final position tolerance (> 0). yaw_tolerance: final yaw tolerance (> 0).
    integral_limit: bound on the norm of the position error integral (>= 0, m s).
    heading: "hold" | "face_goal" | "target" (see module docstring).
    """

    config_key: ClassVar[str] = "controller.pid"

    kp: float = setting(1.5, gt=0)
    ki: float = setting(0.0, ge=0)
    kd: float = setting(0.05, ge=0)
    kp_yaw: float = setting(2.0, gt=0)
    ki_yaw: float = setting(0.0, ge=0)
    kd_yaw: float = setting(0.0, ge=0)
    max_lin_speed: float = setting(0.6, gt=0)
    max_yaw_rate: float = setting(1.0, gt=0)
    max_lin_accel: float | None = setting(None, gt=0)
    max_yaw_accel: float | None = setting(None, gt=0)
    switch_radius: float = setting(0.15, gt=0)
    goal_tolerance: float = setting(0.03, gt=0)
    yaw_tolerance: float = setting(0.05, gt=0)
    integral_limit: float = setting(0.5, ge=0)
    heading: str = setting("hold", choices=HEADING_MODES)


@dataclass
class FabricConfig(Settings):
    """Fabric constants; the defaults are the reference package's defaults."""

    config_key: ClassVar[str] = "controller.fabric"

    # base energy 0.5 * base_inertia * |qd|^2 (reference: "0.5 * 0.2 * ca.dot(xdot, xdot)")
    base_inertia: float = setting(0.2, gt=0)
    # obstacle collision geometry  h = -collision_lam / x^collision_exp * s(xd) * xd^2
    collision_lam: float = setting(0.5, ge=0)
    collision_exp: float = setting(5.0, ge=0)
    # obstacle collision Finsler energy  l = collision_metric_lam / x^collision_metric_exp * xd^2
    collision_metric_lam: float = setting(0.1, gt=0)
    collision_metric_exp: float = setting(1.0, ge=0)
    # joint-limit geometry  h = -limit_lam / x^limit_exp * xd^2
    limit_lam: float = setting(0.1, ge=0)
    limit_exp: float = setting(1.0, ge=0)
    # joint-limit energy  l = limit_metric_lam / x^limit_metric_exp * s(xd) * xd^2
    limit_metric_lam: float = setting(0.1, gt=0)
    limit_metric_exp: float = setting(1.0, ge=0)
    # attractor potential  psi = gamma * k_psi * (|x| + log(1 + exp(-2 a_psi |x|)) / a_psi)
    gamma: float = setting(1.0, gt=0)  # attractor weight ("weight_goal_0"); overridable per plan
    k_psi: float = setting(5.0, gt=0)
    a_psi: float = setting(10.0, gt=0)
    # attractor metric  ((m_max - m_min) exp(-(a_m |x|)^2) + m_min) * I
    m_min: float = setting(0.3, gt=0)
    m_max: float = setting(2.0, gt=0)
    a_m: float = setting(0.75, ge=0)
    # damper  beta = 0.5 (tanh(-alpha_b (|x| - radius_shift)) + 1) beta_close + beta_distant
    #                + max(0, alpha_geometry - alpha_execution)
    alpha_b: float = setting(0.5, ge=0)
    radius_shift: float = 0.02
    beta_close: float = setting(6.5, ge=0)
    beta_distant: float = setting(0.01, ge=0)
    # interpolation  eta = 0.5 (tanh(-alpha_eta * |qd|^2 * (1 - ex_factor) - 0.5) + 1)
    alpha_eta: float = setting(0.9, ge=0)
    ex_factor: float = 0.5
    # regularisation of inverses and alpha denominators; actions with norm < eps or
    # > 1 / eps are zeroed (set zero_extreme_actions=False to keep them)
    eps: float = setting(1e-6, gt=0)
    zero_extreme_actions: bool = True

    def check(self, where: str) -> None:
        if self.m_max < self.m_min:
            raise ConfigError(f"{where}.m_max = {self.m_max!r} is invalid: must be >= m_min ({self.m_min})")


@dataclass
class WholeBodyConfig(Settings):
    """Whole-body fabric settings (Hydra ``controller.fabric``). Every field is a config key."""

    config_key: ClassVar[str] = "controller.fabric"

    gamma: float = setting(3.0, gt=0)  # attractor weight
    beta_close: float = setting(6.5, ge=0)  # damping near the goal (reference default)
    beta_distant: float = setting(0.01, ge=0)  # damping far from the goal
    k_psi: float = setting(5.0, gt=0)  # attractor potential gain
    axis_length: float = setting(0.25, gt=0)  # m, orientation points behind / beside the TCP
    collision_lam: float = setting(0.5, ge=0)
    collision_margin: float = setting(0.02, ge=0)  # m added to every sphere radius
    collision_exclude: tuple[str, ...] | None = None  # spheres without box leaves (None: the robot's fabric_exclude)
    floor: bool = True
    # the spheres without box leaves lose their floor leaf too (a pick off the floor: the fingers must
    # reach an object lying on it); off by default, a re-sequence that picks from the floor turns it on
    floor_exclude: bool = False
    max_base_speed: float = setting(0.6, gt=0)  # m/s
    max_yaw_rate: float = setting(1.0, gt=0)  # rad/s
    max_joint_speed: float = setting(1.2, gt=0)  # rad/s, or m/s for a lift
    resync_tolerance: float = setting(0.08, gt=0)  # reference/measured drift that triggers a re-sync
    compiled: bool = False  # CPU: run the step built ahead of time into native code (realize/controllers/fabric_package.py)

    def fabric(self) -> FabricConfig:
        return FabricConfig(gamma=self.gamma, beta_close=self.beta_close, beta_distant=self.beta_distant,
                            k_psi=self.k_psi, collision_lam=self.collision_lam)
