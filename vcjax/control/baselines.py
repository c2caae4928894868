"""Baseline path-following controllers the paper compares against (Section 4.2), in the same
harness as the VCM law (same path particle (22), design model, plants and metrics).

* LOS-PID (39): LOS heading ``psi_d = psi_p + atan(-e / Delta)`` tracked by a model-based heading
  PD, plus cross-track PID terms in the yaw moment,
  ``tau_r = tau_n,r - m33 (k_ed e_dot + k_ep e + k_ei int e)``;
* ILOS (40): integral LOS, ``psi_r = atan(-(e + sigma_i e_int) / Delta)`` with the
  Børhaug–Pettersen integral law ``e_int_dot = Delta e / ((e + sigma_i e_int)^2 + Delta^2)``,
  tracked by the same heading PD;
* ALOS: Fossen's adaptive LOS (IEEE TCST 31(6), 2023; ``ALOSpsi`` of the MSS toolbox),
  ``psi_d = psi_p - beta_hat - atan(e / Delta)`` with the crab-angle estimate
  ``beta_hat_dot = gamma Delta e / sqrt(Delta^2 + e^2)``, tracked by the same heading PD. Near
  the path it linearises to ILOS with ``gamma = sigma_i / Delta^2`` (the default ``gamma`` is
  that of the default ILOS gains); far from it the adaptation rate saturates at ``gamma Delta``.

All three use a model-based surge-speed loop ``tau_u = n_u + m11 (u_d_dot - k_u (u - u_d))``, are
underactuated (``tau_v`` is the rudder's own sway force ``k_rudder tau_r``), and take every gain
as a traced parameter. The heading PD ``tau_n,r = n_r + m33 (psi_p_ddot - k_psi_d psi~_dot -
k_psi_p psi~)`` defaults to the same characteristic polynomial as the VCM heading error (37).
"""

from __future__ import annotations

import dataclasses
from typing import Any, Literal, NamedTuple

import jax.numpy as jnp
import numpy as np

from vcjax._checks import check_positive
from vcjax.control.params import LawParams, law_params
from vcjax.guidance import alos_angle, los_angle, path_kinematics
from vcjax.linalg import wrap_angle
from vcjax.paths import path_frame
from vcjax.vehicles import design3dof as d3

__all__ = [
    "KINDS",
    "MAX_CRAB",
    "BaselineGains",
    "baseline_gains",
    "BaselineParams",
    "baseline_params",
    "BaselineConfig",
    "BaselineState",
    "baseline_state",
    "BaselineAux",
    "baseline_law",
]


#: The baselines: LOS-PID (39), ILOS (40) and Fossen's ALOS.
KINDS = ("los_pid", "ilos", "alos")

#: Largest heading offset [rad] the LOS-PID cross-track integral may ask for (anti-windup).
MAX_CRAB = float(np.pi / 4)


class BaselineGains(NamedTuple):
    """Gains of the LOS-PID / ILOS / ALOS baselines (traced).

    Attributes:
        Delta: () look-ahead distance [m].
        sigma: () particle-speed gain [1/s] (as in the VCM law).
        k_u: () surge-speed gain [1/s].
        k_psi_p, k_psi_d: () heading PD gains [1/s^2, 1/s].
        k_ep, k_ed, k_ei: () cross-track PID gains of (39), normalised by m33
            [rad/(s^2 m), rad/(s m), rad/(s^3 m)] (LOS-PID only).
        sigma_i: () ILOS integral gain of (40) [-] (ILOS only).
        gamma: () ALOS adaptation gain [rad/(m s)] (ALOS only).
    """

    Delta: Any
    sigma: Any
    k_u: Any
    k_psi_p: Any
    k_psi_d: Any
    k_ep: Any
    k_ed: Any
    k_ei: Any
    sigma_i: Any
    gamma: Any


def baseline_gains(
    Delta=5.0,
    sigma=0.5,
    k_u=1.0,
    k_psi_p=2.0,
    k_psi_d=3.0,
    k_ep=0.02,
    k_ed=0.1,
    k_ei=0.005,
    sigma_i=0.4,
    gamma=0.016,
) -> BaselineGains:
    """Validated [`BaselineGains`][vcjax.control.baselines.BaselineGains]; every gain > 0 except the
    cross-track PID ones, ``sigma_i``
    and ``gamma`` (>= 0). The default ``gamma = sigma_i / Delta^2`` of the defaults, so ALOS and
    ILOS share their linearisation about the path."""
    vals = dict(Delta=Delta, sigma=sigma, k_u=k_u, k_psi_p=k_psi_p, k_psi_d=k_psi_d)
    for name, v in vals.items():
        check_positive(name, v, ())
    for name, v in dict(k_ep=k_ep, k_ed=k_ed, k_ei=k_ei, sigma_i=sigma_i, gamma=gamma).items():
        check_positive(name, v, (), strict=False)
    f = lambda x: jnp.asarray(x, dtype=float)
    return BaselineGains(
        *(f(x) for x in (Delta, sigma, k_u, k_psi_p, k_psi_d, k_ep, k_ed, k_ei, sigma_i, gamma))
    )


#: The baselines' traced parameters ([`LawParams`][vcjax.control.params.LawParams] with
#: [`BaselineGains`][vcjax.control.baselines.BaselineGains]);
#: [`baseline_params`][vcjax.control.params.law_params] validates them.
BaselineParams = LawParams
baseline_params = law_params


@dataclasses.dataclass(frozen=True)
class BaselineConfig:
    """Static: the path kind and which baseline (one of ``KINDS``)."""

    path: Any
    kind: Literal["los_pid", "ilos", "alos"] = "ilos"

    def __post_init__(self):
        if self.kind not in KINDS:
            raise ValueError(f"kind: one of {KINDS}, got {self.kind!r}")


class BaselineState(NamedTuple):
    """``varpi`` (path particle), ``e_int`` (the cross-track integral state of LOS-PID / ILOS)
    and ``beta_hat`` (ALOS's crab-angle estimate [rad]); a state a law does not use stays put."""

    varpi: Any
    e_int: Any
    beta_hat: Any


def baseline_state(varpi0=0.0, e_int0=0.0, beta_hat0=0.0) -> BaselineState:
    f = lambda x: jnp.asarray(x, dtype=float)
    return BaselineState(f(varpi0), f(e_int0), f(beta_hat0))


class BaselineAux(NamedTuple):
    """Recorded signals (same names as the VCM law's where they mean the same)."""

    eps: Any
    eps_dot: Any
    u_tilde: Any
    psi_tilde: Any
    psi_d: Any
    tau: Any


def baseline_law(cfg: BaselineConfig, params: BaselineParams, t, eta, nu, z: BaselineState):
    """LOS-PID (39), ILOS (40) or ALOS; returns ``(tau (3,), z_dot, aux)`` like the VCM law."""
    g = params.gains
    m = params.model
    frame = path_frame(cfg.path, params.path, z.varpi)
    u_d = params.u_d
    kin = path_kinematics(frame, eta, nu, u_d, g.sigma)
    e, e_dot = kin.eps[1], kin.eps_dot[1]
    zero = jnp.zeros_like(e)
    beta_hat_dot = zero
    if cfg.kind == "alos":
        alos = alos_angle(e, e_dot, z.beta_hat, g.Delta, g.gamma)
        psi_r, psi_r_dot, beta_hat_dot = alos
        e_int_dot = zero
        extra = zero
    elif cfg.kind == "ilos":
        E = e + g.sigma_i * z.e_int
        e_int_dot = g.Delta * e / (E**2 + g.Delta**2)
        E_dot = e_dot + g.sigma_i * e_int_dot
        psi_r = jnp.arctan(-E / g.Delta)
        psi_r_dot = -g.Delta * E_dot / (g.Delta**2 + E**2)
        extra = zero
    else:
        los = los_angle(e, e_dot, zero, g.Delta)
        psi_r, psi_r_dot = los.psi_r, los.psi_r_dot
        # Anti-windup in the units that matter: the integral term k_ei e_int acts like a heading
        # offset k_ei e_int / k_psi_p; it is clamped to a crab angle of at most MAX_CRAB (and to
        # int_limit when k_ei = 0), with back-calculation.
        lim = jnp.where(
            g.k_ei > 0, g.k_psi_p * MAX_CRAB / jnp.where(g.k_ei > 0, g.k_ei, 1.0), params.int_limit
        )
        clipped = jnp.clip(z.e_int, -lim, lim)
        e_int_dot = e - (z.e_int - clipped)
        extra = g.k_ed * e_dot + g.k_ep * e + g.k_ei * z.e_int
    psi_d = kin.psi_p + psi_r
    psi_tilde = wrap_angle(eta[2] - psi_d)
    psi_tilde_dot = nu[2] - (kin.psi_p_dot + psi_r_dot)
    n_b = d3.body_bias(m, nu)
    u_dot_cmd = -g.k_u * (nu[0] - u_d)
    r_dot_cmd = kin.psi_p_ddot - g.k_psi_d * psi_tilde_dot - g.k_psi_p * psi_tilde - extra
    tau_u = n_b[0] + m.m11 * u_dot_cmd
    tau_r = n_b[2] + m.m33 * r_dot_cmd
    tau = jnp.stack([tau_u, params.k_rudder * tau_r, tau_r])
    z_dot = BaselineState(varpi=kin.varpi_dot, e_int=e_int_dot, beta_hat=beta_hat_dot)
    aux = BaselineAux(
        eps=kin.eps,
        eps_dot=kin.eps_dot,
        u_tilde=nu[0] - u_d,
        psi_tilde=psi_tilde,
        psi_d=psi_d,
        tau=tau,
    )
    return tau, z_dot, aux
