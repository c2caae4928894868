"""LOS-PID (39), ILOS (40) and ALOS baselines on a perfect model: ILOS removes the cross-track
offset a cross current causes (Børhaug–Pettersen), LOS-PID's integral reduces it, the integrators'
roles are real (switching them off leaves the offset), ALOS's estimate converges to the crab angle
of the plant's steady-state force balance, and new gains do not recompile."""

import functools

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import scipy.optimize
from _craft import CRAFT as MODEL
from _craft import K_RUDDER

from vcjax import paths
from vcjax.control.baselines import (
    BaselineConfig,
    baseline_gains,
    baseline_law,
    baseline_params,
    baseline_state,
)
from vcjax.environment import WaterMotion
from vcjax.rollout import RolloutConfig, rollout
from vcjax.vehicles import design3dof as d3

PATH, COEFFS = paths.paper_line()
CROSS_CURRENT = jnp.array([0.5, 0.0])  # perpendicular to the path (which points east)


@functools.cache
def _loop(kind):
    cfg = BaselineConfig(path=PATH, kind=kind)

    def plant(t, x, tau, V_c):
        return d3.vector_field(
            MODEL, x[0], x[1], tau, WaterMotion(jnp.append(jnp.asarray(V_c), 0.0), None)
        )

    def controller(t, x, z, params):
        return baseline_law(cfg, params, t, x[0], x[1], z)

    return plant, controller


_run = jax.jit(rollout, static_argnames=("plant", "controller", "config"))


def _simulate(kind, gains, T=300.0, dt=0.1, V_c=CROSS_CURRENT):
    plant, controller = _loop(kind)
    params = baseline_params(gains, MODEL, COEFFS, u_d=2.0, k_rudder=K_RUDDER)
    x0 = (jnp.array([0.0, 0.0, np.pi / 2]), jnp.array([2.0, 0.0, 0.0]))
    cfg = RolloutConfig(num_steps=int(round(T / dt)))
    return _run(plant, controller, cfg, V_c, params, x0, baseline_state(), dt)


def _tail_abs_e(traj, frac=0.1):
    e = np.asarray(traj.aux.eps[:, 1])
    return float(np.max(np.abs(e[int((1 - frac) * len(e)) :])))


def test_ilos_rejects_a_cross_current():
    traj = _simulate("ilos", baseline_gains())
    assert bool(np.all(np.asarray(traj.finite)))
    assert _tail_abs_e(traj) < 1e-4
    # the craft crabs into the current: a steady heading offset remains while e -> 0
    assert abs(float(traj.aux.psi_tilde[-1])) > 0.05
    # without the integral (sigma_i = 0) plain LOS keeps a cross-track offset of ~ Delta tan(beta)
    plain = _simulate("ilos", baseline_gains(sigma_i=0.0))
    assert _tail_abs_e(plain) > 1.0


def test_los_pid_integral_reduces_the_offset():
    with_i = _simulate("los_pid", baseline_gains())
    without = _simulate("los_pid", baseline_gains(k_ei=0.0))
    assert _tail_abs_e(without) > 1.0
    assert _tail_abs_e(with_i) < 0.1 * _tail_abs_e(without)


def test_no_current_both_converge_to_the_path():
    # LOS-PID unwinds the integral charged during the approach with a slow pole (~80 s): longer
    for kind, T in (("ilos", 200.0), ("los_pid", 600.0)):
        traj = _simulate(kind, baseline_gains(), T=T, dt=0.2, V_c=jnp.zeros(2))
        assert _tail_abs_e(traj) < 1e-3, kind
        assert abs(float(traj.aux.u_tilde[-1])) < 1e-3


def _crab_equilibrium(gains, u_d=2.0, V_c=(0.5, 0.0), pi_h=np.pi / 2):
    """Steady straight-line motion of the plant under the baselines' surge loop and heading PD,
    found by root-finding, independently of any guidance law.

    Unknowns ``(psi, u, v, tau_u, tau_r)`` (``r = 0``); equations: the plant's accelerations
    vanish (3), the course over ground is the path's (cross-track rate 0), and the surge loop's
    algebraic steady state ``tau_u = n_b,u(nu) - m11 k_u (u - u_d)``. Returns the crab angle
    ``beta = pi_h - psi`` and the heading PD's steady error ``psi~ = (n_b,r(nu) - tau_r) /
    (m33 k_psi_p)`` (the design model's bias uses the measured velocity over ground, the plant's
    the velocity through the water, so a PD without integral keeps a small offset).
    """
    V_c = jnp.asarray(V_c)

    def residual(x):
        psi, u, v, tau_u, tau_r = (jnp.asarray(c) for c in x)
        eta = jnp.stack([jnp.zeros(()), jnp.zeros(()), psi])
        nu = jnp.stack([u, v, jnp.zeros(())])
        tau = jnp.stack([tau_u, K_RUDDER * tau_r, tau_r])
        eta_dot, nu_dot = d3.vector_field(
            MODEL, eta, nu, tau, WaterMotion(jnp.append(jnp.asarray(V_c), 0.0), None)
        )
        cross_rate = -jnp.sin(pi_h) * eta_dot[0] + jnp.cos(pi_h) * eta_dot[1]
        surge_loop = tau_u - d3.body_bias(MODEL, nu)[0] + MODEL.m11 * gains.k_u * (u - u_d)
        return np.array([*np.asarray(nu_dot), float(cross_rate), float(surge_loop) / MODEL.m11])

    sol = scipy.optimize.root(residual, [pi_h, u_d, 0.0, 0.0, 0.0], tol=1e-13)
    assert np.max(np.abs(residual(sol.x))) < 1e-12, sol.message
    psi, u, v, _, tau_r = sol.x
    nu = jnp.array([u, v, 0.0])
    psi_tilde = (float(d3.body_bias(MODEL, nu)[2]) - tau_r) / (
        float(MODEL.m33) * float(gains.k_psi_p)
    )
    return pi_h - psi, float(np.arctan2(v, u)), psi_tilde


def test_alos_estimate_converges_to_the_crab_angle():
    gains = baseline_gains()
    traj = _simulate("alos", gains, T=400.0)
    assert bool(np.all(np.asarray(traj.finite)))
    assert _tail_abs_e(traj) < 1e-6  # e -> 0 under the cross current
    beta, beta_vu, psi_tilde = _crab_equilibrium(gains)
    assert beta == pytest.approx(beta_vu, abs=1e-10)  # course along the path: psi + atan(v/u)
    assert abs(beta) > 0.1  # a real crab angle (the current is 25 % of the speed)
    # the closed loop sits at the root-found equilibrium ...
    psi_end = float(traj.x[0][-1, 2])
    assert np.pi / 2 - psi_end == pytest.approx(beta, abs=1e-6)
    assert float(traj.aux.psi_tilde[-1]) == pytest.approx(psi_tilde, abs=1e-6)
    # ... and psi_d = pi_h - beta_hat with psi = psi_d + psi~ gives beta_hat = beta + psi~: the
    # estimate is the crab angle plus the heading autopilot's own steady error (ALOS adapts away
    # any constant heading offset, whatever its cause)
    beta_hat = float(traj.z.beta_hat[-1])
    assert beta_hat == pytest.approx(beta + psi_tilde, abs=1e-6)
    # with a 100x stiffer heading loop the autopilot's error vanishes and beta_hat -> beta
    stiff = baseline_gains(k_psi_p=200.0, k_psi_d=30.0)
    traj = _simulate("alos", stiff, T=400.0)
    beta_s, _, psi_tilde_s = _crab_equilibrium(stiff)
    assert abs(psi_tilde_s) < 0.02 * abs(psi_tilde)
    assert float(traj.z.beta_hat[-1]) == pytest.approx(beta_s + psi_tilde_s, abs=1e-6)
    assert float(traj.z.beta_hat[-1]) == pytest.approx(beta_s, abs=0.01 * abs(beta_s))


def test_alos_without_adaptation_is_plain_los():
    """gamma = 0 freezes beta_hat at 0: plain LOS, which keeps the cross-current offset."""
    traj = _simulate("alos", baseline_gains(gamma=0.0))
    assert float(np.max(np.abs(np.asarray(traj.z.beta_hat)))) == 0.0
    assert _tail_abs_e(traj) > 1.0
    plain = _simulate("ilos", baseline_gains(sigma_i=0.0))
    np.testing.assert_allclose(
        np.asarray(traj.aux.eps), np.asarray(plain.aux.eps), rtol=1e-9, atol=1e-9
    )


def test_underactuated_sway_force_is_the_rudders():
    """The sway force the law commands (``tau_v = k_rudder tau_r``) is the force the INFANTE
    plant's rudder produces at the commanded angle: the rudder terms of the plant's force model
    (``body_forces``, a separate code path), whose sway/yaw ratio is npsauv.m's published
    ``Ydr / (Ndr L)`` (Healey & Lienard 1993: Ydr = 0.027, Ndr = -0.013; L = 4.5 m)."""
    from vcjax import experiments
    from vcjax.vehicles import infante

    sim1 = experiments.get("sim1")
    traj = sim1.simulate("ilos", sim1.setup(horizon=10.0, dt=0.05))
    p = infante.infante_params()
    nu = traj.x.nu[:-1]  # the (measured) velocity the controller used at each step
    delta = traj.u[:, 1]  # commanded rudder angle [rad]
    forces = jax.vmap(lambda nu, d: infante.body_forces(p, nu, jnp.stack([jnp.zeros_like(d), d])))
    rudder = np.asarray(forces(nu, delta) - forces(nu, jnp.zeros_like(delta)))  # (N, 3) [X, Y, N]
    tau = np.asarray(traj.aux.tau)
    assert np.max(np.abs(tau[:, 2])) > 100.0  # the rudder works hard in this manoeuvre
    np.testing.assert_allclose(rudder[:, 1], tau[:, 1], rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(rudder[:, 2], tau[:, 2], rtol=1e-9, atol=1e-9)
    big = np.abs(tau[:, 2]) > 1.0
    np.testing.assert_allclose(rudder[big, 1] / rudder[big, 2], 0.027 / (-0.013 * 4.5), rtol=1e-9)


def test_new_gains_reuse_the_compiled_rollout():
    _simulate("ilos", baseline_gains(), T=5.0)
    n = _run._cache_size()
    _simulate("ilos", baseline_gains(Delta=3.0, sigma_i=0.2, k_u=2.0), T=5.0)
    assert _run._cache_size() == n


def test_gain_validation():
    with pytest.raises(ValueError, match="Delta"):
        baseline_gains(Delta=-1.0)
    with pytest.raises(ValueError, match="k_ei"):
        baseline_gains(k_ei=-0.1)
    with pytest.raises(ValueError, match="gamma"):
        baseline_gains(gamma=-0.01)
    with pytest.raises(ValueError, match="kind"):
        BaselineConfig(path=PATH, kind="pid")
