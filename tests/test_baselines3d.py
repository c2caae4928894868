"""3-D baselines (control.baselines3d): ALOS3D angles and adaptation against an independent
NumPy transcription of Fossen & Aguiar (2024) on a straight line; projection; autopilot signs."""

import jax.numpy as jnp
import numpy as np
import pytest

from vcjax import paths
from vcjax.control.baselines3d import (
    AutopilotConfig,
    AutopilotState,
    autopilot_gains,
    autopilot_law,
    baseline3d_params,
)

A_H, A_V = 0.6, -0.15  # azimuth and elevation of the line [rad]
DIRECTION = (np.cos(A_V) * np.cos(A_H), np.cos(A_V) * np.sin(A_H), -np.sin(A_V))
LINE, COEFFS = paths.line(origin=(1.0, 2.0, 3.0), direction=DIRECTION)


def _alos_numpy(p, beta, alpha, Dh, Dv, gh, gv):
    """ALOS3D for a line through (1, 2, 3) with azimuth A_H, elevation A_V (Fossen & Aguiar)."""
    Rz = np.array([[np.cos(A_H), -np.sin(A_H), 0], [np.sin(A_H), np.cos(A_H), 0], [0, 0, 1]])
    Ry = np.array([[np.cos(A_V), 0, np.sin(A_V)], [0, 1, 0], [-np.sin(A_V), 0, np.cos(A_V)]])
    e = Ry.T @ Rz.T @ (p - np.array([1.0, 2.0, 3.0]))
    y_e, z_e = e[1], e[2]
    psi = A_H - beta - np.arctan(y_e / Dh)
    theta = A_V + alpha + np.arctan(z_e / Dv)
    beta_dot = gh * Dh / np.sqrt(Dh**2 + y_e**2) * y_e
    alpha_dot = gv * Dv / np.sqrt(Dv**2 + z_e**2) * z_e
    return psi, theta, beta_dot, alpha_dot, e


def _params(**kw):
    g = autopilot_gains(**kw)
    return baseline3d_params(g, (30.0, 7.5, 7.5), 10.0, COEFFS, u_d=1.5)


@pytest.mark.parametrize("p", [(5.0, 9.0, 2.0), (-3.0, 1.0, 6.5)])
def test_alos3d_angles_and_adaptation_match_the_paper(p):
    params = _params(Delta=(8.0, 12.0), gamma=(0.004, 0.002), M_theta=0.35)
    p = np.asarray(p)
    f = paths.path_frame(LINE, COEFFS, 0.0)
    # put the particle at the orthogonal projection (s = 0), as the particle law converges to
    w = float(np.dot(p - np.array([1.0, 2.0, 3.0]), np.asarray(f.dp_dw))) / float(
        np.dot(f.dp_dw, f.dp_dw)
    )
    z = AutopilotState(*(jnp.asarray(x) for x in (w, 0.1, -0.05, 0.0, 0.0, 0.0)))
    q = jnp.asarray([*p, 0.0, 0.0])
    qd = jnp.asarray([1.0, 0.2, 0.1, 0.0, 0.0])
    nu5 = jnp.asarray([1.5, 0.0, 0.0, 0.0, 0.0])
    tau, z_dot, aux = autopilot_law(AutopilotConfig(LINE, "alos"), params, 0.0, q, qd, nu5, z)
    psi, theta, bd, ad, e = _alos_numpy(p, 0.1, -0.05, 8.0, 12.0, 0.004, 0.002)
    np.testing.assert_allclose(aux.eps[1:], e[1:], atol=1e-9)  # MSS's x_e is from the waypoint
    assert abs(float(aux.eps[0])) < 1e-9  # ours from the particle, here at the projection
    np.testing.assert_allclose(aux.psi_d, psi, atol=1e-12)
    np.testing.assert_allclose(aux.theta_d, theta, atol=1e-12)
    np.testing.assert_allclose(z_dot.beta_hat, bd, rtol=1e-10)
    np.testing.assert_allclose(z_dot.alpha_hat, ad, rtol=1e-10)
    # the autopilots turn towards the commanded angles: psi = theta = 0 here
    assert np.sign(tau[4]) == np.sign(psi) and np.sign(tau[3]) == np.sign(theta)


def test_alos_projection_stops_the_estimate_at_the_bound():
    params = _params(M_theta=0.2)
    z = AutopilotState(*(jnp.asarray(x) for x in (0.0, 0.25, -0.25, 0.0, 0.0, 0.0)))
    # a point to the right (e > 0) and below (h > 0): both push the estimates outwards
    f = paths.path_frame(LINE, COEFFS, 0.0)
    right = np.array([-np.sin(A_H), np.cos(A_H), 0.0])
    p = np.asarray(f.p) + 2.0 * right
    q = jnp.asarray([*p, 0.0, 0.0])
    zero = jnp.zeros(5)
    _, z_dot, aux = autopilot_law(AutopilotConfig(LINE, "alos"), params, 0.0, q, zero, zero, z)
    assert float(aux.eps[1]) > 1.0
    assert float(z_dot.beta_hat) == 0.0  # beta_hat = 0.25 > 0.2 and e > 0 pushes outwards
    z_in = z._replace(beta_hat=jnp.asarray(0.1))
    _, z_dot, _ = autopilot_law(AutopilotConfig(LINE, "alos"), params, 0.0, q, zero, zero, z_in)
    assert float(z_dot.beta_hat) > 0.0


def test_plain_los_has_no_adaptation_and_validation():
    params = _params()
    z = AutopilotState(*(jnp.asarray(x) for x in (0.0, 0.3, 0.3, 0.0, 0.0, 0.0)))
    q = jnp.asarray([0.0, 3.0, 1.0, 0.0, 0.0])
    zero = jnp.zeros(5)
    _, z_dot, aux = autopilot_law(AutopilotConfig(LINE, "los"), params, 0.0, q, zero, zero, z)
    assert float(z_dot.beta_hat) == 0.0 and float(z_dot.alpha_hat) == 0.0
    with pytest.raises(ValueError, match="guidance"):
        AutopilotConfig(LINE, "pid")
    with pytest.raises(ValueError, match="Delta"):
        autopilot_gains(Delta=(0.0, 1.0))
