"""Small numerical blocks: the closed-form surge-decoupled solve against LU, NaN-safe norms."""

import jax
import jax.numpy as jnp
import numpy as np

from vcjax import linalg
from vcjax.linalg import safe_norm, solve_surge_decoupled, wrap_angle


def test_surge_decoupled_solve_matches_lu():
    rng = np.random.default_rng(3)
    for _ in range(20):
        B = rng.normal(size=(2, 2))
        M = np.zeros((3, 3))
        M[0, 0] = rng.uniform(0.5, 5.0)
        M[1:, 1:] = B @ B.T + 0.5 * np.eye(2)
        f = rng.normal(size=3)
        x = solve_surge_decoupled(jnp.asarray(M), jnp.asarray(f))
        np.testing.assert_allclose(x, np.linalg.solve(M, f), rtol=1e-12, atol=1e-12)
    # non-symmetric sway-yaw block too (the plant's M_A need not be symmetric)
    M = np.array([[2.0, 0, 0], [0, 3.0, 0.4], [0, -0.2, 1.5]])
    f = np.array([1.0, -2.0, 0.5])
    np.testing.assert_allclose(solve_surge_decoupled(M, f), np.linalg.solve(M, f), rtol=1e-13)


def test_safe_norm_gradient_at_zero_and_wrap():
    g = jax.grad(lambda x: safe_norm(x))(jnp.zeros(3))
    assert np.all(np.isfinite(np.asarray(g)))
    a = wrap_angle(jnp.array([np.pi + 0.1, -np.pi - 0.1, 7.0]))
    np.testing.assert_allclose(a, [-np.pi + 0.1, np.pi - 0.1, 7.0 - 2 * np.pi], atol=1e-12)


def test_matvec_equals_matmul_for_small_shapes():
    rng = np.random.default_rng(0)
    for m, n in ((2, 2), (3, 3), (2, 3), (6, 6)):
        A, x = rng.normal(size=(m, n)), rng.normal(size=n)
        np.testing.assert_allclose(linalg.matvec(jnp.asarray(A), jnp.asarray(x)), A @ x, rtol=1e-14)
