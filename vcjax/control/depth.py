"""Depth loop of a craft following a 3-D path in the horizontal plane (Simulation 2, step 2):
a PID on ``z - z_p(w)`` evaluated at the *path particle* ``w``, with feed-forward of the path's
depth along the particle's motion.

The reference moves with the particle (22): ``z_p_dot = z_p' w_dot``,
``z_p_ddot = z_p'' w_dot^2 + z_p' w_ddot``
([`depth_reference`][vcjax.control.depth.depth_reference]). The law
([`depth_pid`][vcjax.control.depth.depth_pid]) asks for the vertical acceleration::

    a_z = z_p_ddot - k_d (z_dot - z_p_dot) - k_p (z - z_p) - k_i int(z - z_p)
    Z_ned = m_w a_z + d_w z_dot,      tau_Z = Z_ned / max(cos(phi) cos(theta), 1/2)

(``m_w``, ``d_w``: heave mass and design-point damping of the model; the division maps the NED
vertical force to the body heave axis of a tilted craft) with back-calculation anti-windup on the
integral: ``d/dt int = e_z - (int - clip(int, -limit, limit))``. With a perfect model the depth
error obeys ``e'' + k_d e' + k_p e + k_i int e = 0``: stable iff ``k_d k_p > k_i`` (Routh–Hurwitz).
"""

from __future__ import annotations

from typing import Any, NamedTuple

import jax.numpy as jnp

__all__ = ["DepthReference", "depth_reference", "depth_pid"]


class DepthReference(NamedTuple):
    """Depth of the path at the particle and its time derivatives [m, m/s, m/s^2]."""

    z: Any
    z_dot: Any
    z_ddot: Any


def depth_reference(frame, w_dot, w_ddot) -> DepthReference:
    """The path's depth at the particle (``frame``:
    [`vcjax.paths.PathFrame`][vcjax.paths.PathFrame]) moving at
    ``w_dot`` [1/s] with ``w_ddot`` [1/s^2]."""
    return DepthReference(
        z=frame.z_p,
        z_dot=frame.dz_dw * w_dot,
        z_ddot=frame.d2z_dw2 * w_dot**2 + frame.dz_dw * w_ddot,
    )


def depth_pid(gains, int_limit, ref: DepthReference, z, z_dot, int_z, m_w, d_w, tilt):
    """Heave force of the depth PID (module docstring).

    Args:
        gains: (3,) ``[k_p 1/s^2, k_d 1/s, k_i 1/s^3]``; int_limit: () clamp of the integral [m s].
        ref: [`DepthReference`][vcjax.control.depth.DepthReference]; z, z_dot: () depth [m] and its
            rate [m/s] (NED);
        int_z: () integral state [m s]; m_w: () heave mass [kg]; d_w: () heave damping [kg/s];
        tilt: () ``cos(phi) cos(theta)`` of the craft.

    Returns:
        ``(tau_Z, int_z_dot, e_z)``: body heave force [N], integral rate, depth error [m].
    """
    ez = z - ref.z
    kp, kd, ki = gains[0], gains[1], gains[2]
    a_z = ref.z_ddot - kd * (z_dot - ref.z_dot) - kp * ez - ki * int_z
    Z_ned = m_w * a_z + d_w * z_dot
    tau_Z = Z_ned / jnp.maximum(tilt, 0.5 * jnp.ones_like(ez))
    clipped = jnp.clip(int_z, -int_limit, int_limit)
    return tau_Z, ez - (int_z - clipped), ez
