"""Baselines for 3-D path following of a fin-controlled AUV, on the same path particle and plant.

All laws return the body force ``tau5 = [X, Y, Z, M, N]`` of the 5-DOF design model; the
vehicle's actuator map turns ``X, M, N`` into propeller rpm, stern-plane and rudder angles (so
every law sees the same speed-scheduled fin gains, and only guidance and control differ).
The errors ``eps = [s, e, h]`` are those of [`path_errors_3d`][vcjax.control.vcm3d.path_errors_3d]
at a
path particle moving as (22) with ``u_p = u_d + sigma s`` (for a straight line: Fossen's
along-, cross- and vertical-track errors).

* [`autopilot_law`][vcjax.control.baselines3d.autopilot_law], ``guidance="alos"``: ALOS3D guidance
(Fossen & Aguiar, 2024,
  Automatica 163, 111556; MSS ``ALOS3D.m``) in continuous time:

      psi_d   = psi_p - beta_hat  - atan(e / Delta_h)
      theta_d = theta_p + alpha_hat + atan(h / Delta_v)
      beta_hat_dot  = gamma_h Delta_h / sqrt(Delta_h^2 + e^2) Proj(beta_hat, e)
      alpha_hat_dot = gamma_v Delta_v / sqrt(Delta_v^2 + h^2) Proj(alpha_hat, h)

  (``Proj`` stops an estimate at ``|.| = M_theta`` while the error pushes it outwards), with PID
  heading and pitch autopilots (moments ``N = -m66 (w^2 psi~ + 2 zeta w r~ + w^3/10 int psi~)``,
  likewise ``M`` with ``m55``, ``r~ = r - psi_d_dot`` from the ALOS angle's kinematic rate) and a
  surge PI loop with the design model's drag as feed-forward. On the plant the path particle
  replaces MSS's waypoint switching (the mission path has turns, not polyline corners).
* [`autopilot_law`][vcjax.control.baselines3d.autopilot_law], ``guidance="los"``: the same
autopilots with plain LOS angles (no
  adaptation) — the structure of PythonVehicleSimulator's REMUS 100 depth/heading autopilot
  (heading and depth PID, constant propeller loop), as a sanity run.
* [`decoupled_law`][vcjax.control.baselines3d.decoupled_law]: the paper's decoupled design
(Simulation 2): the horizontal VCM law
  (31)/(38) on a 3-DOF design model (with its ILOS angle and integral action, as configured)
  plus a depth loop through pitch: ``theta_d = theta_p + atan((h + sigma_v h_int) / Delta_v)``
  and the PID pitch autopilot.

  The 3-DOF model's body bias. The structure (20) has a skew-symmetric ``C_b(nu)`` built from
  ``M_b``, hence the Munk yaw moment ``(m22 - m11) u v``. A vehicle model without it (PVS's
  REMUS 100 zeroes those ``C_A`` entries) can be matched by (20) only in slope at one speed
  (``d32`` cancels it at ``u = U_design``); the residue ``(m22 - m11)(u - U_design) v`` is
  second order at straight motion, but the law measures velocity over ground, and a vehicle
  crabbing into a cross current has ``v`` of the current's size. On REMUS under 0.3 m/s it is
  up to ~0.9 N m of phantom yaw moment while a 15 deg rudder gives 1.2 N m at 1.5 m/s: the
  heading row was enforced on the wrong model and the vehicle oscillated in heading along
  every leg. [`DecoupledConfig`][vcjax.control.baselines3d.DecoupledConfig] ``body_bias`` therefore
  lets the horizontal law use the
  surge, sway and yaw rows of the full design model's bias (``M_b`` stays the 3-DOF one); with
  ``None`` the 3-DOF model's own (20) bias is used.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from typing import Any, Literal, NamedTuple

import jax.numpy as jnp

from vcjax._checks import check_positive
from vcjax.control.vcm import VCMConfig, VCMState, vcm_law
from vcjax.control.vcm3d import path_errors_3d
from vcjax.linalg import Rzyx, wrap_angle

__all__ = [
    "AutopilotGains",
    "autopilot_gains",
    "Baseline3DParams",
    "baseline3d_params",
    "AutopilotConfig",
    "AutopilotState",
    "autopilot_state",
    "autopilot_law",
    "DecoupledConfig",
    "DecoupledState",
    "decoupled_state",
    "decoupled_law",
    "BaselineAux",
]


class AutopilotGains(NamedTuple):
    """Baseline gains (traced; scalars unless noted).

    Attributes:
        w_psi, zeta_psi: heading autopilot natural frequency [rad/s] and damping [-].
        w_theta, zeta_theta: pitch autopilot natural frequency [rad/s] and damping [-].
        k_u, k_ui: surge loop gains [1/s], [1/s^2].
        Delta: (2,) look-ahead distances ``[horizontal, vertical]`` [m].
        gamma: (2,) adaptation gains ``[gamma_h, gamma_v]`` [1/(m s)] (ALOS) or ILOS gains
            ``[sigma_h, sigma_v]`` of the decoupled depth loop [-].
        M_theta: () bound of the ALOS estimates [rad].
        sigma: () particle-speed gain [1/s].
    """

    w_psi: Any
    zeta_psi: Any
    w_theta: Any
    zeta_theta: Any
    k_u: Any
    k_ui: Any
    Delta: Any
    gamma: Any
    M_theta: Any
    sigma: Any


def autopilot_gains(
    w_psi=1.2,
    zeta_psi=1.0,
    w_theta=1.5,
    zeta_theta=1.0,
    k_u=0.5,
    k_ui=0.02,
    Delta=(8.0, 8.0),
    gamma=(0.004, 0.004),
    M_theta=0.35,
    sigma=0.3,
) -> AutopilotGains:
    """Validated [`AutopilotGains`][vcjax.control.baselines3d.AutopilotGains] (frequencies, damping,
    look-ahead, bound > 0).

    Defaults: at 1.5 m/s the heading stiffness ``m66 w_psi^2`` ≈ 11 N m/rad and the pitch
    stiffness ``m55 w_theta^2`` ≈ 17 N m/rad (about 3x the REMUS restoring moment
    ``W z_g``), the order of MSS's ``SIMremus100ALOS`` autopilots once its fin-angle gains are
    converted to moments; ALOS gains with the mission's 8 m look-ahead.
    """
    for name, v in dict(w_psi=w_psi, zeta_psi=zeta_psi, w_theta=w_theta, k_u=k_u).items():
        check_positive(name, v, ())
    check_positive("zeta_theta", zeta_theta, ())
    check_positive("k_ui", k_ui, (), strict=False)
    check_positive("Delta", Delta, (2,))
    check_positive("gamma", gamma, (2,), strict=False)
    check_positive("M_theta", M_theta, ())
    check_positive("sigma", sigma, ())
    vals = (w_psi, zeta_psi, w_theta, zeta_theta, k_u, k_ui, Delta, gamma, M_theta, sigma)
    return AutopilotGains(*(jnp.asarray(x, dtype=float) for x in vals))


class Baseline3DParams(NamedTuple):
    """Traced parameters of the baselines.

    Attributes:
        gains: [`AutopilotGains`][vcjax.control.baselines3d.AutopilotGains].
        inertia: (3,) ``[m11, m55, m66]`` surge mass and pitch/yaw inertia [kg, kg m^2].
        drag: callable-free feed-forward: () surge drag at ``u_d`` [N] (design model).
        u_d: () desired speed [m/s].
        path: path coefficients.
        horizontal: the 2-D VCM law's [`LawParams`][vcjax.control.params.LawParams]
            (``decoupled_law`` only; ``None`` otherwise).
        design: the design model's parameters passed to
            [`DecoupledConfig`][vcjax.control.baselines3d.DecoupledConfig] ``body_bias``
            (``decoupled_law`` with ``body_bias`` only; ``None`` otherwise).
    """

    gains: Any
    inertia: Any
    drag: Any
    u_d: Any
    path: Any
    horizontal: Any = None
    design: Any = None


def baseline3d_params(
    gains, inertia, drag, path, u_d=1.5, horizontal=None, design=None
) -> Baseline3DParams:
    """Validated [`Baseline3DParams`][vcjax.control.baselines3d.Baseline3DParams]."""
    if not isinstance(gains, AutopilotGains):
        raise ValueError(f"gains: expected AutopilotGains, got {type(gains).__name__}")
    check_positive("inertia", inertia, (3,))
    check_positive("u_d", u_d, ())
    f = lambda x: jnp.asarray(x, dtype=float)
    return Baseline3DParams(gains, f(inertia), f(drag), f(u_d), path, horizontal, design)


class BaselineAux(NamedTuple):
    """Signals common to the baselines: eps (3,) [m], psi_d, theta_d [rad], tau (5,)."""

    eps: Any
    psi_d: Any
    theta_d: Any
    tau: Any


@dataclasses.dataclass(frozen=True)
class AutopilotConfig:
    """Static: the path and the guidance, ``"alos"`` (ALOS3D) or ``"los"`` (PVS-like)."""

    path: Any
    guidance: Literal["alos", "los"] = "alos"

    def __post_init__(self):
        if self.guidance not in ("alos", "los"):
            raise ValueError(f"guidance: 'alos' or 'los', got {self.guidance!r}")


class AutopilotState(NamedTuple):
    """varpi; beta_hat, alpha_hat [rad]; integrals of psi~, theta~ [rad s] and u~ [m]."""

    varpi: Any
    beta_hat: Any
    alpha_hat: Any
    int_psi: Any
    int_theta: Any
    int_u: Any


def autopilot_state(varpi0=0.0) -> AutopilotState:
    z = jnp.asarray(0.0)
    return AutopilotState(jnp.asarray(varpi0, dtype=float), z, z, z, z, z)


def _particle(path, coeffs, varpi, p, u_d, sigma):
    f, eps = path_errors_3d(path, coeffs, varpi, p)
    varpi_dot = (u_d + sigma * eps[0]) * jnp.cos(f.theta_p) / f.speed_bar
    return f, eps, varpi_dot


def _proj(est, err, bound):
    """MSS's projection: stop the estimate at |est| > bound while err pushes outwards."""
    return jnp.where((jnp.abs(est) > bound) & (est * err > 0), 0.0 * err, err)


def _pid_moment(inertia, w, zeta, err, rate_err, integ):
    return -inertia * (w * w * err + 2.0 * zeta * w * rate_err + 0.1 * w**3 * integ)


def _surge(params, nu5, int_u):
    g = params.gains
    u_t = nu5[0] - params.u_d
    return params.drag - params.inertia[0] * (g.k_u * u_t + g.k_ui * int_u), u_t


def autopilot_law(cfg: AutopilotConfig, params: Baseline3DParams, t, q, qd, nu5, z):
    """ALOS3D / LOS guidance with PID heading and pitch autopilots and a surge PI loop.

    Args:
        q: (5,) ``[x, y, z, theta, psi]``; qd: (5,) its rate; nu5: (5,) ``[u, v, w, q, r]``;
        z: [`AutopilotState`][vcjax.control.baselines3d.AutopilotState].

    Returns:
        ``(tau5, z_dot, BaselineAux)``.
    """
    g = params.gains
    f, eps, varpi_dot = _particle(cfg.path, params.path, z.varpi, q[:3], params.u_d, g.sigma)
    e, h = eps[1], eps[2]
    Dh, Dv = g.Delta[0], g.Delta[1]
    if cfg.guidance == "alos":
        beta, alpha = z.beta_hat, z.alpha_hat
        beta_dot = g.gamma[0] * Dh / jnp.sqrt(Dh * Dh + e * e) * _proj(beta, e, g.M_theta)
        alpha_dot = g.gamma[1] * Dv / jnp.sqrt(Dv * Dv + h * h) * _proj(alpha, h, g.M_theta)
    else:
        beta = alpha = beta_dot = alpha_dot = jnp.zeros_like(e)
    psi_d = f.psi_p - beta - jnp.arctan(e / Dh)
    theta_d = f.theta_p + alpha + jnp.arctan(h / Dv)
    # rates of the commanded angles: path angles along the particle + the LOS terms' kinematics
    e_dot, h_dot = _eps_rate(f, eps, qd[:3], varpi_dot)
    psi_d_dot = f.dpsi_dw * varpi_dot - beta_dot - Dh * e_dot / (Dh * Dh + e * e)
    theta_d_dot = f.dtheta_dw * varpi_dot + alpha_dot + Dv * h_dot / (Dv * Dv + h * h)
    psi_t = wrap_angle(q[4] - psi_d)
    theta_t = q[3] - theta_d
    N = _pid_moment(params.inertia[2], g.w_psi, g.zeta_psi, psi_t, qd[4] - psi_d_dot, z.int_psi)
    M = _pid_moment(
        params.inertia[1], g.w_theta, g.zeta_theta, theta_t, qd[3] - theta_d_dot, z.int_theta
    )
    X, u_t = _surge(params, nu5, z.int_u)
    zero = jnp.zeros_like(X)
    tau = jnp.stack([X, zero, zero, M, N])
    z_dot = AutopilotState(varpi_dot, beta_dot, alpha_dot, psi_t, theta_t, u_t)
    return tau, z_dot, BaselineAux(eps, psi_d, theta_d, tau)


def _eps_rate(f, eps, p_dot, varpi_dot):
    """``(e_dot, h_dot)`` from ``eps = R_p^T (p - p_p)``: the velocity relative to the particle
    in the path frame (the frame's own rotation is neglected: exact on straight legs)."""
    R_p = Rzyx(jnp.zeros_like(f.psi_p), f.theta_p, f.psi_p)
    rel = R_p.T @ (p_dot - f.dp_dw * varpi_dot)
    return rel[1], rel[2]


@dataclasses.dataclass(frozen=True)
class DecoupledConfig:
    """Static: the horizontal [`VCMConfig`][vcjax.control.vcm.VCMConfig] (its path is the 3-D path;
    the 2-D law uses the projection) and ``body_bias``: ``None`` (the 3-DOF model's own bias
    of (20)) or ``body_bias(design, q5, nu5) -> (5,)``, the full design model's bias
    ``[X, Y, Z, M, N]`` at ``q5 = [x, y, z, theta, psi]``, ``nu5 = [u, v, w, q, r]``
    (``design`` is [`Baseline3DParams`][vcjax.control.baselines3d.Baseline3DParams] ``design``),
    whose ``X, Y, N`` rows the horizontal
    law then uses (module docstring)."""

    horizontal: VCMConfig
    body_bias: Callable | None = None


class DecoupledState(NamedTuple):
    """The horizontal law's [`VCMState`][vcjax.control.vcm.VCMState]; ``h_int`` [m s] of the depth
    loop's ILOS angle; ``int_theta`` [rad s] of the pitch PID."""

    horizontal: Any
    h_int: Any
    int_theta: Any


def decoupled_state(horizontal: VCMState) -> DecoupledState:
    z = jnp.zeros_like(horizontal.varpi)
    return DecoupledState(horizontal, z, z)


def decoupled_law(cfg: DecoupledConfig, params: Baseline3DParams, t, q, qd, nu5, z):
    """Horizontal VCM (31)/(38) + depth through pitch (module docstring).

    Returns:
        ``(tau5, z_dot, BaselineAux)``; ``tau5 = [tau_u, tau_v, 0, M, tau_r]``.
    """
    g = params.gains
    hp = params.horizontal
    eta3 = jnp.stack([q[0], q[1], q[4]])
    nu3 = jnp.stack([nu5[0], nu5[1], nu5[4]])
    if cfg.body_bias is None:
        n_b = None
    else:
        if params.design is None:
            raise ValueError("decoupled_law: body_bias needs Baseline3DParams.design")
        n5 = cfg.body_bias(params.design, q, nu5)
        n_b = jnp.stack([n5[0], n5[1], n5[4]])
    tau3, zh_dot, aux = vcm_law(cfg.horizontal, hp, t, eta3, nu3, z.horizontal, n_b=n_b)
    f, eps = path_errors_3d(cfg.horizontal.path, hp.path, z.horizontal.varpi, q[:3])
    h = eps[2]
    Dv = g.Delta[1]
    H = h + g.gamma[1] * z.h_int
    h_int_dot = Dv * h / (H * H + Dv * Dv)
    theta_d = f.theta_p + jnp.arctan(H / Dv)
    h_dot = _eps_rate(f, eps, qd[:3], zh_dot.varpi)[1]
    H_dot = h_dot + g.gamma[1] * h_int_dot
    theta_d_dot = f.dtheta_dw * zh_dot.varpi + Dv * H_dot / (Dv * Dv + H * H)
    theta_t = q[3] - theta_d
    M = _pid_moment(
        params.inertia[1], g.w_theta, g.zeta_theta, theta_t, qd[3] - theta_d_dot, z.int_theta
    )
    zero = jnp.zeros_like(M)
    tau = jnp.stack([tau3[0], tau3[1], zero, M, tau3[2]])
    z_dot = DecoupledState(zh_dot, h_int_dot, theta_t)
    return tau, z_dot, BaselineAux(eps, aux.psi_d, theta_d, tau)
