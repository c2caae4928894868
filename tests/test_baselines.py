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
    traj = _simulate("ilos", baseline_gains(), T=20.0)
    tau = np.asarray(traj.aux.tau)
    np.testing.assert_allclose(tau[:, 1], K_RUDDER * tau[:, 2], rtol=1e-12)


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
