"""Guidance (22)-(25), (28), (36): error rates against finite differences along a trajectory,
LOS-angle derivatives against autodiff, and heading-error wrapping across ±pi in closed loop."""

import functools

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from _craft import CRAFT as MODEL

from vcjax import paths
from vcjax.control.vcm import VCMConfig, pm_gains, vcm_law, vcm_params, vcm_state
from vcjax.guidance import alos_angle, los_angle, path_kinematics
from vcjax.integrators import rk4
from vcjax.rollout import RolloutConfig, rollout
from vcjax.vehicles import design3dof as d3

U_D, SIGMA = 1.5, 0.3


def _vehicle(t):
    """An arbitrary smooth planar motion: position (2,), heading."""
    p = jnp.stack([3.0 * t + 2.0 * jnp.sin(0.7 * t), 1.0 + 0.5 * t**2 - jnp.cos(t)])
    psi = 0.4 + 0.8 * jnp.sin(0.5 * t)
    return p, psi


def _eta_nu_nudot(t):
    """eta, body velocity nu = J^T eta_dot, and nu_dot, all by autodiff of _vehicle."""

    def eta(t_):
        p, psi = _vehicle(t_)
        return jnp.concatenate([p, psi[None]])

    def nu(t_):
        e, ed = jax.jvp(eta, (t_,), (jnp.ones_like(t_),))
        return d3.kinematics(e[2]).T @ ed

    n, nd = jax.jvp(nu, (t,), (jnp.ones_like(t),))
    return eta(t), n, nd


@pytest.mark.parametrize("make_path", [paths.paper_helix, lambda: paths.circle(radius=8.0)])
def test_error_rates_match_finite_differences(make_path):
    path, coeffs = make_path()

    def kin(t, w):
        eta, nu, _ = _eta_nu_nudot(t)
        return path_kinematics(paths.path_frame(path, coeffs, w), eta, nu, U_D, SIGMA)

    def f(t, w, args):  # particle (22) along the prescribed vehicle motion
        return kin(t, w).varpi_dot, None

    dt = 1e-3
    step = jax.jit(lambda t, w: rk4(f, t, w, dt, None)[0])
    ts = np.arange(0, 3001) * dt
    ws = [jnp.asarray(0.5)]
    for t in ts[:-1]:
        ws.append(step(jnp.asarray(t), ws[-1]))
    ws = jnp.stack(ws)
    k = jax.jit(jax.vmap(kin))(jnp.asarray(ts), ws)
    eps = np.asarray(k.eps)
    eps_dot_fd = (eps[2:] - eps[:-2]) / (2 * dt)
    eps_ddot_fd = (eps[2:] - 2 * eps[1:-1] + eps[:-2]) / dt**2
    nud = jax.vmap(lambda t: _eta_nu_nudot(t)[2])(jnp.asarray(ts))
    eps_ddot = np.einsum("nij,nj->ni", k.R_gamma, nud[:, :2]) + np.asarray(k.eps_ddot_drift)
    scale1 = np.max(np.abs(eps_dot_fd))
    scale2 = np.max(np.abs(eps_ddot_fd))
    assert np.max(np.abs(np.asarray(k.eps_dot)[1:-1] - eps_dot_fd)) < 1e-5 * scale1
    assert np.max(np.abs(eps_ddot[1:-1] - eps_ddot_fd)) < 1e-4 * scale2
    # psi_p rates along the particle's motion
    psi_p = np.unwrap(np.asarray(k.psi_p))
    np.testing.assert_allclose(
        np.asarray(k.psi_p_dot)[1:-1], (psi_p[2:] - psi_p[:-2]) / (2 * dt), atol=1e-5
    )
    np.testing.assert_allclose(
        np.asarray(k.psi_p_ddot)[1:-1],
        (psi_p[2:] - 2 * psi_p[1:-1] + psi_p[:-2]) / dt**2,
        atol=5e-4,
    )


def test_los_angle_derivatives_36():
    Delta = 4.0

    def e_of_t(t):
        return 3.0 * jnp.sin(0.9 * t) + t

    for t in (0.1, 1.3, 2.7):
        t = jnp.asarray(t)
        e, ed = jax.jvp(e_of_t, (t,), (1.0,))
        edd = jax.grad(jax.grad(e_of_t))(t)
        los = los_angle(e, ed, edd, Delta)
        psi_r = lambda t_: jnp.arctan(-e_of_t(t_) / Delta)
        assert float(los.psi_r) == pytest.approx(float(psi_r(t)))
        assert float(los.psi_r_dot) == pytest.approx(float(jax.grad(psi_r)(t)), rel=1e-12)
        assert float(los.psi_r_ddot) == pytest.approx(
            float(jax.grad(jax.grad(psi_r))(t)), rel=1e-10
        )


def test_alos_rates_match_finite_differences():
    """ALOS: integrate the crab-angle estimate's rate along a prescribed e(t) with a fine RK4, then
    compare the returned psi_r_dot with central differences of psi_r; and far from the path the
    adaptation rate saturates at gamma Delta (the bounded-rate property of Fossen's law)."""
    Delta, gamma = jnp.asarray(4.0), jnp.asarray(0.05)

    def e_of_t(t):
        return 6.0 * jnp.sin(0.9 * t) + t

    def f(t, b, args):
        e = e_of_t(t)
        return alos_angle(e, jnp.zeros_like(e), b, Delta, gamma).beta_hat_dot, None

    dt = 1e-3
    step = jax.jit(lambda t, b: rk4(f, t, b, dt, None)[0])
    ts = np.arange(0, 4001) * dt
    bs = [jnp.asarray(0.2)]
    for t in ts[:-1]:
        bs.append(step(jnp.asarray(t), bs[-1]))
    bs = jnp.stack(bs)

    def at(t, b):
        e, ed = jax.jvp(e_of_t, (t,), (jnp.ones_like(t),))
        return alos_angle(e, ed, b, Delta, gamma)

    a = jax.vmap(at)(jnp.asarray(ts), bs)
    psi_r = np.asarray(a.psi_r)
    fd = (psi_r[2:] - psi_r[:-2]) / (2 * dt)
    assert np.max(np.abs(np.asarray(a.psi_r_dot)[1:-1] - fd)) < 1e-5 * np.max(np.abs(fd))
    far = alos_angle(jnp.asarray(1e6), jnp.asarray(0.0), jnp.asarray(0.0), Delta, gamma)
    assert float(far.beta_hat_dot) == pytest.approx(float(gamma * Delta), rel=1e-9)


@functools.cache
def _loop(cfg):
    def plant(t, x, tau, args):
        eta, nu = x
        return d3.vector_field(MODEL, eta, nu, tau)

    def controller(t, x, z, params):
        return vcm_law(cfg, params, t, x[0], x[1], z)

    return plant, controller


_run = jax.jit(rollout, static_argnames=("plant", "controller", "config"))


def _simulate(path, coeffs, eta0, w0, T, dt=0.05, actuation="full"):
    cfg = VCMConfig(path=path, actuation=actuation, edd="implied")
    plant, controller = _loop(cfg)
    params = vcm_params(pm_gains(), MODEL, coeffs, u_d=1.5)
    x0 = (jnp.asarray(eta0), jnp.array([1.5, 0.0, 0.0]))
    conf = RolloutConfig(num_steps=int(round(T / dt)))
    return _run(plant, controller, conf, None, params, x0, vcm_state(varpi0=w0), dt)


def test_heading_error_wraps_across_pi_without_spinning():
    """Path heading south (psi_p = +pi); the vehicle starts at psi = -pi + 0.3 (= pi + 0.3): the
    heading error is 0.3 rad (plus the approach angle), not 2 pi - 0.3, and the craft turns the
    short way."""
    path, coeffs = paths.line(origin=(0.0, 0.0), direction=(-1.0, 0.0))
    traj = _simulate(path, coeffs, [0.0, 2.0, -np.pi + 0.3], 0.0, T=60.0)
    psit = np.asarray(traj.aux.psi_tilde)
    assert np.all(np.abs(psit) < 0.8)
    psi = np.asarray(traj.x[0][:, 2])
    assert np.ptp(psi) < 1.0  # no full turn
    assert np.max(np.abs(np.asarray(traj.aux.eps[-100:]))) < 1e-4


def test_many_laps_of_a_circle_without_heading_jumps():
    """psi_p from atan2 jumps by 2 pi once per lap; the errors and commands must not."""
    R = 15.0
    path, coeffs = paths.circle(radius=R, clockwise=True)
    traj = _simulate(path, coeffs, [R + 3.0, 0.0, np.pi / 2], 0.0, T=200.0, actuation="full")
    psi = np.asarray(traj.x[0][:, 2])
    assert psi[-1] - psi[0] > 2 * 2 * np.pi  # at least two laps (continuous heading state)
    psit = np.asarray(traj.aux.psi_tilde)
    assert np.all(np.abs(np.diff(psit)) < 0.05)
    r = np.asarray(traj.x[1][:, 2])
    k0 = len(r) // 2
    np.testing.assert_allclose(r[k0:], 1.5 / R, rtol=1e-3)  # settles on the curvature rate
    assert np.max(np.abs(np.asarray(traj.aux.eps[k0:]))) < 1e-3
