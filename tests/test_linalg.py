"""Small numerical blocks: the closed-form surge-decoupled solve against LU, NaN-safe norms."""

import re

import jax
import jax.numpy as jnp
import numpy as np
import pytest

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


# ---------------------------------------------------------------- unrolled small solves


# compiled once per shape: running the unrolled routines op by op costs 3x more
solve_small = jax.jit(linalg.solve_small)
cholesky_small = jax.jit(linalg.cholesky_small)
cho_solve_small = jax.jit(linalg.cho_solve_small)
spd_solve_small = jax.jit(linalg.spd_solve_small)
lstsq_small = jax.jit(linalg.lstsq_small)


def _hard_matrix(rng, n):
    """A well-conditioned (n, n) matrix whose leading entry is tiny: no pivoting fails."""
    A = rng.normal(size=(n, n)) + n * np.eye(n)[::-1]
    A[0, 0] = 1e-14
    return A


def test_solve_small_matches_lapack_with_pivoting():
    rng = np.random.default_rng(7)
    for n in (1, 2, 3, 5, 6, 8, linalg.SMALL_MAX):
        A = _hard_matrix(rng, n)
        b, B = rng.normal(size=n), rng.normal(size=(n, 3))
        np.testing.assert_allclose(solve_small(A, b), np.linalg.solve(A, b), rtol=1e-10)
        np.testing.assert_allclose(solve_small(A, B), np.linalg.solve(A, B), rtol=1e-10)
    # beyond SMALL_MAX it is LAPACK's solve
    n = linalg.SMALL_MAX + 1
    A, b = _hard_matrix(rng, n), rng.normal(size=n)
    np.testing.assert_allclose(linalg.solve_small(A, b), np.linalg.solve(A, b), rtol=1e-10)


def test_solve_small_singular_gives_non_finite_and_bad_shapes_raise():
    A = np.array([[1.0, 2.0], [2.0, 4.0]])
    assert not np.all(np.isfinite(np.asarray(linalg.solve_small(A, np.ones(2)))))
    with pytest.raises(ValueError, match="square"):
        linalg.solve_small(np.ones((2, 3)), np.ones(2))
    with pytest.raises(ValueError, match="right-hand side"):
        linalg.solve_small(np.eye(3), np.ones(2))


def test_cholesky_small_and_spd_solve_match_lapack():
    rng = np.random.default_rng(8)
    for n in (1, 2, 4, 6, 9):
        X = rng.normal(size=(n, n))
        S = X @ X.T + 0.1 * np.eye(n)
        L = cholesky_small(S)
        np.testing.assert_allclose(L, np.linalg.cholesky(S), rtol=1e-10, atol=1e-13)
        assert np.all(np.triu(np.asarray(L), 1) == 0.0)
        b, B = rng.normal(size=n), rng.normal(size=(n, 2))
        np.testing.assert_allclose(spd_solve_small(S, b), np.linalg.solve(S, b), rtol=1e-9)
        np.testing.assert_allclose(cho_solve_small(L, B), np.linalg.solve(S, B), rtol=1e-9)
    # not positive definite: NaN entries (as jnp.linalg.cholesky), which the engine's
    # mass_spd health flag reads
    L = linalg.cholesky_small(np.diag([1.0, -1.0, 2.0]))
    assert not np.all(np.isfinite(np.asarray(L)))


def test_lstsq_small_matches_lapack_lstsq():
    rng = np.random.default_rng(9)
    for p, n in ((1, 1), (3, 3), (5, 3), (8, 5), (6, 6), (10, 4)):
        W, h = rng.normal(size=(p, n)), rng.normal(size=p)
        ref = np.linalg.lstsq(W, h, rcond=None)[0]
        np.testing.assert_allclose(lstsq_small(W, h), ref, rtol=1e-9, atol=1e-12)
        H = rng.normal(size=(p, 2))
        ref = np.linalg.lstsq(W, H, rcond=None)[0]
        np.testing.assert_allclose(lstsq_small(W, H), ref, rtol=1e-9, atol=1e-12)
    # a column that is already reduced (zeros below the diagonal) is left as it is
    W = np.array([[2.0, 1.0], [0.0, 3.0], [0.0, 4.0]])
    h = np.array([1.0, 2.0, 3.0])
    ref = np.linalg.lstsq(W, h, rcond=None)[0]
    np.testing.assert_allclose(lstsq_small(W, h), ref, rtol=1e-12)
    with pytest.raises(ValueError, match="p >= n"):
        linalg.lstsq_small(np.ones((2, 3)), np.ones(2))


def test_small_solves_gradients_match_finite_differences():
    rng = np.random.default_rng(10)
    n = 4
    A0 = _hard_matrix(rng, n)
    X = rng.normal(size=(n, n))
    S0 = X @ X.T + np.eye(n)
    W0 = rng.normal(size=(6, n))
    b = rng.normal(size=n)
    h = rng.normal(size=6)
    cases = [
        (lambda A: jnp.sum(linalg.solve_small(A, b) ** 2), A0),
        # perturb the symmetric matrix symmetrically: the routine reads its lower triangle
        (lambda S: jnp.sum(linalg.spd_solve_small(0.5 * (S + S.T), b) ** 2), S0),
        (lambda W: jnp.sum(linalg.lstsq_small(W, h) ** 2), W0),
    ]
    for f, x0 in cases:
        g = np.asarray(jax.jit(jax.grad(f))(jnp.asarray(x0)))
        f = jax.jit(f)
        d = rng.normal(size=x0.shape)
        step = 1e-6
        fd = (f(x0 + step * d) - f(x0 - step * d)) / (2 * step)
        np.testing.assert_allclose(np.sum(g * d), fd, rtol=1e-6)


def test_small_solves_batch_without_lapack_calls_and_in_float32():
    rng = np.random.default_rng(11)
    B, n = 16, 6
    A = rng.normal(size=(B, n, n)) + 3 * np.eye(n)
    b = rng.normal(size=(B, n))
    f = jax.jit(jax.vmap(linalg.solve_small))
    np.testing.assert_allclose(f(A, b), np.linalg.solve(A, b[..., None])[..., 0], rtol=1e-10)

    def custom_calls(fn):
        return re.findall(r'custom_call_target="([^"]+)"', fn.lower(A, b).compile().as_text())

    assert custom_calls(f) == []  # what the routine is for: no per-trajectory LAPACK call
    assert any("lapack" in c for c in custom_calls(jax.jit(jax.vmap(jnp.linalg.solve))))
    x32 = linalg.solve_small(A[0].astype(np.float32), b[0].astype(np.float32))
    assert x32.dtype == jnp.float32
    np.testing.assert_allclose(x32, np.linalg.solve(A[0], b[0]), rtol=1e-4, atol=1e-5)
