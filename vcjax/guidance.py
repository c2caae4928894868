"""Path-particle guidance (paper eqs. (21)–(25), (28), (36)).

Given the path frame at the particle's parameter ``varpi`` (from [`vcjax.paths`][vcjax.paths]) and
the
vehicle's horizontal pose and body velocity, [`path_kinematics`][vcjax.guidance.path_kinematics]
returns the path-following
errors ``eps = [s, e]`` (23) (along-track, cross-track, in the projected path frame {p'}), their
first derivative (28), the particle's rate (22) with ``ubar_p = u_d + sigma s``, and every term of
``eps_ddot`` that does not depend on the body accelerations — what the VCM law and the LOS
baselines need. [`los_angle`][vcjax.guidance.los_angle] gives the approach angle (24) and its
derivatives (36);
[`alos_angle`][vcjax.guidance.alos_angle] Fossen's adaptive LOS angle (ALOS, 2023) with its
crab-angle estimate.

Conventions: NED, ``eta = [x, y, psi]``, ``nu = [u, v, r]``; ``e > 0`` means the vehicle is to the
right (starboard side) of the path, so the approach angle ``psi_r = atan(-e / Delta)`` steers
left.
"""

from __future__ import annotations

from typing import Any, NamedTuple

import jax.numpy as jnp

from vcjax.linalg import rot2

__all__ = [
    "PathKinematics",
    "path_kinematics",
    "LOSAngle",
    "los_angle",
    "ALOSAngle",
    "alos_angle",
]


class PathKinematics(NamedTuple):
    """Path-following kinematics at one instant (all scalars unless noted).

    Attributes:
        eps: (2,) ``[s, e]`` along/cross-track error [m] (23).
        eps_dot: (2,) time derivative (28) [m/s].
        eps_ddot_drift: (2,) ``eps_ddot - R(gamma) [u_dot, v_dot]`` [m/s^2]: the part of the
            second derivative that does not depend on the body accelerations.
        R_gamma: (2, 2) ``R(gamma)``, ``gamma = psi - psi_p``: ``eps_ddot = R_gamma w_dot + drift``.
        varpi_dot: particle parameter rate (22) [1/s].
        ubar_p: particle speed along the projected path ``u_d + sigma s`` [m/s].
        psi_p, psi_p_dot, psi_p_ddot: path azimuth at the particle and its time derivatives.
    """

    eps: Any
    eps_dot: Any
    eps_ddot_drift: Any
    R_gamma: Any
    varpi_dot: Any
    ubar_p: Any
    psi_p: Any
    psi_p_dot: Any
    psi_p_ddot: Any


def path_kinematics(frame, eta, nu, u_d, sigma, u_d_dot=0.0) -> PathKinematics:
    """Errors (23), their rate (28) and the particle's motion (22).

    Args:
        frame: a [`vcjax.paths.PathFrame`][vcjax.paths.PathFrame] at the particle (``p_bar``,
            ``psi_p``,
            ``dpsi_dw``, ``d2psi_dw2``, ``speed_bar``, ``dspeed_bar_dw``).
        eta: (3,) ``[x, y, psi]``; nu: (3,) ``[u, v, r]`` (velocity over ground).
        u_d: () desired surge speed [m/s]; u_d_dot: () its rate [m/s^2].
        sigma: () particle-speed gain of ``ubar_p = u_d + sigma s`` [1/s].
    """
    psi_p = frame.psi_p
    R_p = rot2(psi_p)
    eps = R_p.T @ (eta[:2] - frame.p_bar)
    s, e = eps[0], eps[1]
    ubar_p = u_d + sigma * s
    varpi_dot = ubar_p / frame.speed_bar
    psi_p_dot = frame.dpsi_dw * varpi_dot
    gamma = eta[2] - psi_p
    R_g = rot2(gamma)
    w = nu[:2]
    zero = jnp.zeros_like(s)
    eps_dot = R_g @ w + psi_p_dot * jnp.stack([e, -s]) - jnp.stack([ubar_p, zero])
    s_dot, e_dot = eps_dot[0], eps_dot[1]
    ubar_p_dot = u_d_dot + sigma * s_dot
    varpi_ddot = (ubar_p_dot - frame.dspeed_bar_dw * varpi_dot**2) / frame.speed_bar
    psi_p_ddot = frame.d2psi_dw2 * varpi_dot**2 + frame.dpsi_dw * varpi_ddot
    gamma_dot = nu[2] - psi_p_dot
    J2w = jnp.stack([-w[1], w[0]])  # d/dgamma R(gamma) w = R(gamma) J2 w
    drift = (
        gamma_dot * (R_g @ J2w)
        + psi_p_ddot * jnp.stack([e, -s])
        + psi_p_dot * jnp.stack([e_dot, -s_dot])
        - jnp.stack([ubar_p_dot, zero])
    )
    return PathKinematics(
        eps=eps,
        eps_dot=eps_dot,
        eps_ddot_drift=drift,
        R_gamma=R_g,
        varpi_dot=varpi_dot,
        ubar_p=ubar_p,
        psi_p=psi_p,
        psi_p_dot=psi_p_dot,
        psi_p_ddot=psi_p_ddot,
    )


class LOSAngle(NamedTuple):
    """Approach angle ``psi_r = atan(-e / Delta)`` (24) and its time derivatives (36)."""

    psi_r: Any
    psi_r_dot: Any
    psi_r_ddot: Any


def los_angle(e, e_dot, e_ddot, Delta) -> LOSAngle:
    """(24) and (36): ``psi_r_dot = -kappa e_dot``,
    ``psi_r_ddot = -kappa e_ddot + 2 kappa^2 e_dot^2 e / Delta``, ``kappa = Delta/(Delta^2+e^2)``.
    """
    kappa = Delta / (Delta**2 + e**2)
    return LOSAngle(
        psi_r=jnp.arctan(-e / Delta),
        psi_r_dot=-kappa * e_dot,
        psi_r_ddot=-kappa * e_ddot + 2 * kappa**2 * e_dot**2 * e / Delta,
    )


class ALOSAngle(NamedTuple):
    """Adaptive LOS approach angle and the crab-angle estimate's rate (all scalars).

    Attributes:
        psi_r: ``-beta_hat - atan(e / Delta)`` [rad]: the heading relative to the path azimuth,
            so ``psi_d = pi_h + psi_r``.
        psi_r_dot: its time derivative [rad/s].
        beta_hat_dot: rate of the crab-angle estimate [rad/s].
    """

    psi_r: Any
    psi_r_dot: Any
    beta_hat_dot: Any


def alos_angle(e, e_dot, beta_hat, Delta, gamma) -> ALOSAngle:
    """Fossen's adaptive LOS (T. I. Fossen, IEEE TCST 31(6), 2023):
    ``psi_d = pi_h - beta_hat - atan(e / Delta)`` with the crab-angle estimate
    ``beta_hat_dot = gamma Delta e / sqrt(Delta^2 + e^2)``.

    Near the path ``beta_hat_dot ~ gamma e``; far from it the rate saturates at ``gamma Delta``
    (the adaptation is bounded, unlike a plain integral of ``e``). At equilibrium (``e = 0``,
    ``e_dot = 0``) ``beta_hat`` is the crab angle ``beta = pi_h - psi``: the angle between the
    heading and the course over ground that keeps the craft on the line.

    Args:
        e: () cross-track error [m] (``> 0`` starboard of the path); e_dot: () its rate [m/s].
        beta_hat: () crab-angle estimate [rad].
        Delta: () look-ahead distance [m] (> 0); gamma: () adaptation gain [rad/(m s)] (>= 0).
    """
    root = jnp.sqrt(Delta**2 + e**2)  # >= Delta > 0: no singular point
    beta_hat_dot = gamma * Delta * e / root
    return ALOSAngle(
        psi_r=-beta_hat - jnp.arctan(e / Delta),
        psi_r_dot=-beta_hat_dot - Delta * e_dot / (Delta**2 + e**2),
        beta_hat_dot=beta_hat_dot,
    )
