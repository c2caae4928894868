"""3-DOF design model (20): Coriolis structure, energy, currents, generalised-coordinate form."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from _craft import CRAFT as P

from vcjax.environment import WaterMotion
from vcjax.integrators import rk4
from vcjax.vehicles import design3dof as d3

P_NODAMP = P._replace(
    d11=0.0 * P.d11, d22=0.0 * P.d22, d23=0.0 * P.d23, d32=0.0 * P.d32, d33=0.0 * P.d33
)


def test_coriolis_is_skew_and_does_no_work():
    nu = jnp.array([1.3, -0.4, 0.2])
    C = d3.coriolis(P, nu)
    np.testing.assert_allclose(C, -C.T, atol=0)
    assert abs(float(nu @ C @ nu)) < 1e-12


def test_kinetic_energy_conserved_without_damping():
    def f(t, y, a):
        return d3.vector_field(P_NODAMP, y[0], y[1], jnp.zeros(3)), None

    y = (jnp.zeros(3), jnp.array([2.0, 0.5, 0.3]))
    E0 = d3.kinetic_energy(P_NODAMP, y[1])
    step = jax.jit(lambda y: rk4(f, 0.0, y, 0.01, None)[0])
    for _ in range(1000):
        y = step(y)
    assert abs(float(d3.kinetic_energy(P_NODAMP, y[1]) / E0) - 1) < 1e-9


def test_drifting_with_current_stays_drifting():
    V_c = jnp.array([0.3, -0.5])
    psi0 = 0.7
    nu_c, _ = d3.current_in_body(jnp.array(psi0), jnp.array(0.0), V_c)

    def f(t, y, a):
        return d3.vector_field(
            P, y[0], y[1], jnp.zeros(3), WaterMotion(jnp.append(jnp.asarray(V_c), 0.0), None)
        ), None

    y = (jnp.array([0.0, 0.0, psi0]), nu_c)
    step = jax.jit(lambda y: rk4(f, 0.0, y, 0.05, None)[0])
    for _ in range(200):
        y = step(y)
    np.testing.assert_allclose(y[0][:2], V_c * 10.0, atol=1e-10)
    np.testing.assert_allclose(y[1], nu_c, atol=1e-12)


def test_rotating_frame_current_derivative():
    # nu_c(t) = R(psi(t))^T V_c with psi(t) = r t: compare the analytic rate with autodiff
    V_c = jnp.array([0.3, -0.5])
    r = 0.4
    nu_c_of_t = lambda t: d3.current_in_body(r * t, jnp.array(r), V_c)[0]
    _, rate = d3.current_in_body(jnp.array(0.3 * r), jnp.array(r), V_c)
    np.testing.assert_allclose(rate, jax.jacfwd(nu_c_of_t)(0.3), atol=1e-12)


def test_generalised_coordinate_form_matches_body_form():
    """from_body_frame: M(q) q_dd + n(q, q_d) = J^{-T} tau_b reproduces q_dd = J nu_dot + J_dot nu."""
    sys = d3.DESIGN3DOF_SYSTEM
    eta, nu, tau_b = (
        jnp.array([1.0, 2.0, 0.8]),
        jnp.array([1.5, -0.3, 0.25]),
        jnp.array([300.0, 50.0, -80.0]),
    )
    J = d3.kinematics(eta[2])
    qd = J @ nu
    qdd = jnp.linalg.solve(
        sys.mass_matrix(eta, P), J @ tau_b - sys.bias_force(eta, qd, P)
    )  # J^{-T} = J
    _, nu_dot = d3.vector_field(P, eta, nu, tau_b)
    J_dot = jax.jacfwd(d3.kinematics)(eta[2]) * nu[2]
    np.testing.assert_allclose(qdd, J @ nu_dot + J_dot @ nu, rtol=1e-10)


def test_validation_names_the_field():
    with pytest.raises(ValueError, match="not positive definite"):
        d3.design3dof(m11=1.0, m22=1.0, m23=5.0, m33=1.0)
    with pytest.raises(ValueError, match="m22.*NaN"):
        d3.design3dof(m11=1.0, m22=float("nan"), m23=0.0, m33=1.0)
    with pytest.raises(ValueError, match="d11.*shape"):
        d3.design3dof(m11=1.0, m22=1.0, m23=0.0, m33=1.0, d11=[1.0, 2.0])


def test_pose_rate_is_J_times_nu():
    # J(pi/2) maps surge to east and sway to (minus) north, by hand; and the matrix form.
    nu = jnp.array([1.5, -0.4, 0.2])
    np.testing.assert_allclose(d3.pose_rate(jnp.pi / 2, nu), [0.4, 1.5, 0.2], atol=1e-15)
    for psi in (-2.0, 0.0, 0.7, 3.0):
        np.testing.assert_allclose(
            d3.pose_rate(psi, nu), d3.kinematics(psi) @ nu, rtol=1e-15, atol=1e-15
        )
