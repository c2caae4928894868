"""Roll/pitch loop (Simulation 2, step 3): a PD on top of the hydrostatic restoring moment,
``tau_K = -k_p phi - k_d p``, ``tau_M = -k_p theta - k_d q``.

With restoring stiffness ``k_r`` (``W z_g`` for a bottom-heavy craft) and inertia ``I`` the roll
(pitch) error obeys ``I phi'' + k_d phi' + (k_r + k_p) phi = 0``: stable for any ``k_p, k_d > 0``.
"""

from __future__ import annotations

import jax.numpy as jnp

__all__ = ["roll_pitch_pd"]


def roll_pitch_pd(gains, eta, nu):
    """(2,) ``[tau_K, tau_M]`` [N m] of the PD ``gains`` (2,) ``[k_p N m/rad, k_d N m s/rad]``
    on the pose ``eta`` (6,) and body velocity ``nu`` (6,) of a 6-DOF craft."""
    tau_K = -gains[0] * eta[3] - gains[1] * nu[3]
    tau_M = -gains[0] * eta[4] - gains[1] * nu[4]
    return jnp.stack([tau_K, tau_M])
