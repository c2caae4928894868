"""Edge cases of :mod:`vcjax.control` that the mutation run (``tools/mutation.py control``)
found untested. Eager checks on single numbers (milliseconds each)."""

import jax.numpy as jnp
import numpy as np
from _craft import CRAFT, K_RUDDER

from vcjax import paths
from vcjax.control.attitude import roll_pitch_pd
from vcjax.control.baselines import (
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
