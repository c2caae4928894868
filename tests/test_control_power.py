"""Edge cases of :mod:`vcjax.control` that the mutation run (``tools/mutation.py control``)
found untested. Eager checks on single numbers (milliseconds each)."""

import jax
import jax.numpy as jnp
import numpy as np
from _craft import CRAFT, K_RUDDER

from vcjax import paths
from vcjax.control.attitude import roll_pitch_pd
from vcjax.control.baselines import (
    MAX_CRAB,
    BaselineConfig,
    baseline_gains,
    baseline_law,
    baseline_params,
    baseline_state,
)


def test_roll_pitch_pd_is_the_documented_law():
    # tau_K = -k_p phi - k_d p, tau_M = -k_p theta - k_d q, with every input distinct
    gains = jnp.array([3.0, 0.5])
    eta = jnp.array([10.0, 20.0, 30.0, 0.2, -0.3, 40.0])
    nu = jnp.array([1.0, 2.0, 3.0, 0.7, 1.1, 5.0])
    tau = roll_pitch_pd(gains, eta, nu)
    np.testing.assert_allclose(tau, [-3.0 * 0.2 - 0.5 * 0.7, 3.0 * 0.3 - 0.5 * 1.1], rtol=1e-15)


def test_ilos_integral_rate_is_equation_40():
    # e_int' = Delta e / ((e + sigma_i e_int)^2 + Delta^2), off the path with a wound-up integral
    path, coeffs = paths.paper_line()
    gains = baseline_gains(Delta=4.0, sigma_i=0.7)
    params = baseline_params(gains, CRAFT, coeffs, u_d=2.0, k_rudder=K_RUDDER)
    eta, nu = jnp.array([3.0, 1.0, 1.4]), jnp.array([1.8, 0.1, 0.05])
    z = baseline_state(varpi0=0.1, e_int0=2.5)
    _, z_dot, aux = baseline_law(BaselineConfig(path=path, kind="ilos"), params, 0.0, eta, nu, z)
    e = float(aux.eps[1])
    assert abs(e) > 0.5
    big_e = e + 0.7 * 2.5
    np.testing.assert_allclose(z_dot.e_int, 4.0 * e / (big_e**2 + 16.0), rtol=1e-13)


_PATH, _COEFFS = paths.paper_line()
_ETA, _NU = jnp.array([3.0, 1.0, 1.4]), jnp.array([1.8, 0.1, 0.05])


def _los_pid(e_int0, **gains):
    params = baseline_params(baseline_gains(**gains), CRAFT, _COEFFS, u_d=2.0, k_rudder=K_RUDDER)
    z = baseline_state(varpi0=0.1, e_int0=e_int0)
    cfg = BaselineConfig(path=_PATH, kind="los_pid")
    return baseline_law(cfg, params, 0.0, _ETA, _NU, z)


def test_defaults_are_the_documented_ones_and_the_config_is_hashable():
    g = baseline_gains()
    assert [float(x) for x in g] == [5.0, 0.5, 1.0, 2.0, 3.0, 0.02, 0.1, 0.005, 0.4, 0.016]
    assert float(g.gamma) == float(g.sigma_i / g.Delta**2)  # ALOS shares ILOS's linearisation
    assert all(float(x) == 0.0 for x in baseline_state())
    cfg = BaselineConfig(path=_PATH, kind="ilos")
    assert hash(cfg) == hash(BaselineConfig(path=_PATH, kind="ilos"))  # a static argument


def test_los_pid_anti_windup_clamps_the_integral_to_a_crab_angle_of_max_crab():
    # k_ei e_int / k_psi_p <= MAX_CRAB (pi/4): beyond, back-calculation pulls e_int back
    _, z_dot, aux = _los_pid(1e4, k_ei=0.01, k_psi_p=2.0)
    lim = 2.0 * MAX_CRAB / 0.01
    assert MAX_CRAB == np.pi / 4
    np.testing.assert_allclose(z_dot.e_int, aux.eps[1] - (1e4 - lim), rtol=1e-13)
    _, z_dot, aux = _los_pid(-60.0, k_ei=0.0)  # no integral gain: int_limit (50) clamps
    np.testing.assert_allclose(z_dot.e_int, aux.eps[1] - (-60.0 + 50.0), rtol=1e-13)


def test_los_pid_cross_track_terms_enter_the_yaw_moment_as_equation_39():
    # tau_r = ... - m33 (k_ed e_dot + k_ep e + k_ei e_int): each gain's share, by differences
    base = dict(k_ep=0.0, k_ed=0.0, k_ei=0.0)
    tau0, _, aux = _los_pid(3.0, **base)
    e, e_dot = float(aux.eps[1]), float(aux.eps_dot[1])
    for name, signal in (("k_ep", e), ("k_ed", e_dot)):
        tau, _, _ = _los_pid(3.0, **(base | {name: 0.3}))
        np.testing.assert_allclose(tau[2] - tau0[2], -CRAFT.m33 * 0.3 * signal, rtol=1e-10)


def test_los_pid_without_an_integral_gain_has_finite_gradients():
    # k_ei = 0: int_limit clamps, and the crab-angle branch (a division by k_ei) stays NaN-free
    params = baseline_params(baseline_gains(k_ei=0.0), CRAFT, _COEFFS, u_d=2.0, k_rudder=K_RUDDER)
    cfg = BaselineConfig(path=_PATH, kind="los_pid")

    def out(k_ei):
        p = params._replace(gains=params.gains._replace(k_ei=k_ei))
        tau, z_dot, _ = baseline_law(cfg, p, 0.0, _ETA, _NU, baseline_state(0.1, -60.0))
        return tau[2] + z_dot.e_int

    assert np.isfinite(jax.grad(out)(0.0))


def test_ilos_heading_rate_feedback_is_the_derivative_of_equation_40():
    # on the straight line (psi_p constant) the yaw moment's k_psi_d share is
    # -m33 k_psi_d (r - psi_r_dot), psi_r_dot = -Delta E_dot / (Delta^2 + E^2),
    # E = e + sigma_i e_int, E_dot = e_dot + sigma_i e_int_dot
    def law(k_psi_d):
        gains = baseline_gains(Delta=4.0, sigma_i=0.7, k_psi_d=k_psi_d)
        params = baseline_params(gains, CRAFT, _COEFFS, u_d=2.0, k_rudder=K_RUDDER)
        cfg = BaselineConfig(path=_PATH, kind="ilos")
        return baseline_law(cfg, params, 0.0, _ETA, _NU, baseline_state(0.1, 2.5))

    tau1, z_dot, aux = law(1.0)
    tau2, _, _ = law(3.0)
    e, e_dot = float(aux.eps[1]), float(aux.eps_dot[1])
    big_e, big_e_dot = e + 0.7 * 2.5, e_dot + 0.7 * float(z_dot.e_int)
    psi_r_dot = -4.0 * big_e_dot / (16.0 + big_e**2)
    expected = -CRAFT.m33 * 2.0 * (float(_NU[2]) - psi_r_dot)
    np.testing.assert_allclose(tau2[2] - tau1[2], expected, rtol=1e-10)


def test_law_params_defaults_are_the_documented_ones():
    p = baseline_params(baseline_gains(), CRAFT, _COEFFS)  # u_d 2 m/s, no rudder, clamp 50 m s
    assert (float(p.u_d), float(p.k_rudder), float(p.int_limit)) == (2.0, 0.0, 50.0)
