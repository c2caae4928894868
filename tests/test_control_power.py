"""Edge cases of :mod:`vcjax.control` that the mutation run (``tools/mutation.py control``)
found untested. Eager checks on single numbers (milliseconds each)."""

import jax.numpy as jnp
import numpy as np

from vcjax.control.attitude import roll_pitch_pd


def test_roll_pitch_pd_is_the_documented_law():
    # tau_K = -k_p phi - k_d p, tau_M = -k_p theta - k_d q, with every input distinct
    gains = jnp.array([3.0, 0.5])
    eta = jnp.array([10.0, 20.0, 30.0, 0.2, -0.3, 40.0])
    nu = jnp.array([1.0, 2.0, 3.0, 0.7, 1.1, 5.0])
    tau = roll_pitch_pd(gains, eta, nu)
    np.testing.assert_allclose(tau, [-3.0 * 0.2 - 0.5 * 0.7, 3.0 * 0.3 - 0.5 * 1.1], rtol=1e-15)
