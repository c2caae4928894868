"""LOS-PID (39) and ILOS (40) baselines on a perfect model: ILOS removes the cross-track offset a
cross current causes (Børhaug–Pettersen), LOS-PID's integral reduces it, the integrators' roles
are real (switching them off leaves the offset), and new gains do not recompile."""

import functools

import jax
import jax.numpy as jnp
import numpy as np
import pytest
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
from vcjax.rollout import RolloutConfig, rollout
from vcjax.vehicles import design3dof as d3

PATH, COEFFS = paths.paper_line()
CROSS_CURRENT = jnp.array([0.5, 0.0])  # perpendicular to the path (which points east)


@functools.cache
def _loop(kind):
    cfg = BaselineConfig(path=PATH, kind=kind)

    def plant(t, x, tau, V_c):
        return d3.vector_field(MODEL, x[0], x[1], tau, V_c)

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


def test_underactuated_sway_force_is_the_rudders():
    """The sway force the law commands (``tau_v = k_rudder tau_r``) is the force the INFANTE
    plant's rudder produces at the commanded angle: the rudder terms of the plant's force model
    (``body_forces``, a separate code path), whose sway/yaw ratio is npsauv.m's published
    ``Ydr / (Ndr L)`` (Healey & Lienard 1993: Ydr = 0.027, Ndr = -0.013; L = 4.5 m)."""
    from vcjax import sim1
    from vcjax.vehicles import infante

    traj = sim1.run_variant("ilos", horizon=10.0, dt=0.05)
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
    with pytest.raises(ValueError, match="kind"):
        BaselineConfig(path=PATH, kind="pid")
