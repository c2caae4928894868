"""Thruster allocation: exactness when attainable, limits, pseudo-inverse equivalence, baseline
comparison, closeness to the box-constrained optimum, gradients, jit/vmap, dtypes."""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from jax.test_util import check_grads
from scipy.optimize import lsq_linear

from vcjax.allocation import allocate, clip_allocate, pinv_allocate

S = 1 / math.sqrt(2)
RH, RV = 0.356, 0.252
# ODIN thruster configuration matrix (the vehicle data (docs/reference/vehicles.md)), typed in independently of vcjax.
T_ODIN = np.array(
    [
        [S, -S, -S, S, 0, 0, 0, 0],
        [S, S, -S, -S, 0, 0, 0, 0],
        [0, 0, 0, 0, -1, -1, -1, -1],
        [0, 0, 0, 0, RV * S, RV * S, -RV * S, -RV * S],
        [0, 0, 0, 0, RV * S, -RV * S, -RV * S, RV * S],
        [RH, -RH, RH, -RH, 0, 0, 0, 0],
    ]
)
F_MAX = np.full(8, 27.0)
RNG = np.random.default_rng(42)

BATCH = 512  # one batch shape (and one matrix shape) throughout: each function compiles once
_batch_allocate = jax.jit(jax.vmap(allocate, in_axes=(None, 0, None)))
_batch_clip = jax.jit(jax.vmap(clip_allocate, in_axes=(None, 0, None)))
alloc1 = jax.jit(allocate)
clip1 = jax.jit(clip_allocate)


def _batched(fn, T, taus, f_max):
    """Apply a batched allocation to any number of commands in chunks of BATCH."""
    n = taus.shape[0]
    pad = -n % BATCH
    taus = np.concatenate([taus, np.zeros((pad, taus.shape[1]))])
    outs = [fn(T, taus[i : i + BATCH], f_max) for i in range(0, taus.shape[0], BATCH)]
    return jax.tree_util.tree_map(lambda *a: np.concatenate(a)[:n], *outs)


def batch_allocate(T, taus, f_max):
    return _batched(_batch_allocate, T, taus, f_max)


def batch_clip(T, taus, f_max):
    return _batched(_batch_clip, T, taus, f_max)


def test_attainable_commands_are_met_exactly_within_limits():
    """tau = T f with |f| <= 27 N: RPI meets it (ODIN's blocks have 1-D null spaces)."""
    f_true = RNG.uniform(-27.0, 27.0, size=(2 * BATCH, 8))
    taus = f_true @ T_ODIN.T
    al = batch_allocate(T_ODIN, taus, F_MAX)
    assert np.all(np.asarray(al.feasible))
    assert float(np.max(al.residual)) < 1e-9
    np.testing.assert_allclose(al.tau, taus, atol=1e-9)
    assert float(np.max(np.abs(al.f))) <= 27.0 + 1e-12
    # the test is not vacuous: clipping the pseudo-inverse misses a large share of these
    cl = batch_clip(T_ODIN, taus, F_MAX)
    assert float(np.mean(~np.asarray(cl.feasible))) > 0.1


def test_limits_never_exceeded_generic_matrices():
    for _ in range(3):
        T = RNG.normal(size=(6, 8))
        f_max = RNG.uniform(0.5, 2.0, size=8)
        taus = RNG.normal(size=(BATCH, 6)) * 10.0  # mostly unattainable
        al = batch_allocate(T, taus, f_max)
        assert np.all(np.abs(np.asarray(al.f)) <= f_max * (1 + 1e-12))
        np.testing.assert_allclose(al.tau, np.asarray(al.f) @ T.T, atol=1e-12)
        np.testing.assert_allclose(
            al.residual, np.linalg.norm(np.asarray(al.tau) - taus, axis=1), atol=1e-12
        )


def test_equals_pseudo_inverse_when_nothing_saturates():
    taus = RNG.normal(size=(BATCH, 6)) * np.array([4.0, 4.0, 4.0, 0.8, 0.8, 1.6])
    pinv = taus @ np.linalg.pinv(T_ODIN).T
    assert np.max(np.abs(pinv)) < 27.0
    al = batch_allocate(T_ODIN, taus, F_MAX)
    np.testing.assert_allclose(al.f, pinv, atol=1e-10)
    np.testing.assert_allclose(jax.vmap(pinv_allocate, (None, 0))(T_ODIN, taus), pinv, atol=1e-10)
    assert not np.any(np.asarray(al.saturated))


def test_beats_clipped_pseudo_inverse_when_saturating():
    """Never worse than clip(pinv); strictly better in a known case; near-optimal when the
    command is unattainable (box-constrained least squares, BVLS)."""
    for T, f_max in ((T_ODIN, F_MAX), (RNG.normal(size=(6, 8)), RNG.uniform(0.5, 2, 8))):
        taus = RNG.normal(size=(BATCH, 6)) * float(np.max(np.abs(T) @ f_max))
        al = batch_allocate(T, taus, f_max)
        cl = batch_clip(T, taus, f_max)
        assert np.all(np.asarray(al.residual) <= np.asarray(cl.residual) + 1e-12)
    # surge 60 N and 6 N of sway with an 8 N m yaw moment: attainable, but pinv asks 28.9 N of H1
    tau = np.array([60.0, 6.0, 0.0, 0.0, 0.0, 8.0])
    f_pinv = np.linalg.pinv(T_ODIN) @ tau
    assert f_pinv.max() > 27.0
    al, cl = alloc1(T_ODIN, tau, F_MAX), clip1(T_ODIN, tau, F_MAX)
    assert bool(al.feasible) and float(al.residual) < 1e-10
    assert float(cl.residual) > 0.5
    # unattainable ODIN commands: within 1e-6 of the BVLS optimum
    taus = RNG.normal(size=(60, 6)) * np.array([80.0, 80.0, 120.0, 20.0, 20.0, 40.0])
    al = batch_allocate(T_ODIN, taus, F_MAX)
    for k in range(taus.shape[0]):
        opt = lsq_linear(T_ODIN, taus[k], bounds=(-F_MAX, F_MAX), method="bvls")
        best = np.linalg.norm(T_ODIN @ opt.x - taus[k])
        assert float(al.residual[k]) <= best + 1e-6
        assert bool(al.feasible[k]) == (best < 1e-8)


def test_gradients_match_finite_differences():
    """Piecewise smooth: exact derivatives inside a region of fixed active set (both modes)."""
    T = jnp.asarray(T_ODIN)
    fm = jnp.asarray(F_MAX)
    tau_free = jnp.array([10.0, -5.0, 20.0, 1.0, -0.5, 2.0])  # nothing saturates
    tau_sat = jnp.array([60.0, 6.0, 10.0, 0.0, 0.0, 8.0])  # H1 fixed at +27 N, still attainable
    assert not np.any(np.asarray(alloc1(T, tau_free, fm).saturated))
    assert np.sum(np.asarray(alloc1(T, tau_sat, fm).saturated)) == 1

    @jax.jit
    def fn(tau_, fm_, T_):
        return allocate(T_, tau_, fm_).f

    for tau in (tau_free, tau_sat):
        check_grads(fn, (tau, fm, T), order=1, modes=["fwd", "rev"], atol=1e-5, rtol=1e-5)
    # at the saturated point the fixed thruster moves with its limit only; the free ones make up
    J = jax.jacfwd(fn, argnums=1)(tau_sat, fm, T)
    assert float(J[0, 0]) == pytest.approx(1.0)
    np.testing.assert_allclose(T_ODIN @ np.asarray(J), 0.0, atol=1e-9)  # T f = tau held
    # unattainable command (polish steps active): gradients stay finite
    g = jax.jit(jax.grad(lambda t: allocate(T, t, fm).residual))(jnp.array([200.0, 0, 0, 0, 0, 0]))
    assert np.all(np.isfinite(np.asarray(g)))


def test_jit_vmap_and_no_jit_agree():
    """Attainable commands: the same thrusts; unattainable ones: the same residual (the closest
    force can be reached by several thrust vectors, and the polish steps stop short)."""
    attainable = RNG.uniform(-27.0, 27.0, size=(BATCH, 8)) @ T_ODIN.T
    unattainable = RNG.normal(size=(BATCH, 6)) * 100.0
    for taus, exact in ((attainable, True), (unattainable, False)):
        batched = batch_allocate(T_ODIN, taus, F_MAX)
        for k in (7,):
            eager = allocate(T_ODIN, taus[k], F_MAX)
            if exact:
                np.testing.assert_allclose(batched.f[k], eager.f, atol=1e-9)
            np.testing.assert_allclose(batched.residual[k], eager.residual, rtol=1e-6, atol=1e-9)
            assert bool(batched.feasible[k]) == bool(eager.feasible)
    # a scalar limit broadcasts
    np.testing.assert_allclose(
        alloc1(T_ODIN, attainable[0], 27.0).f, alloc1(T_ODIN, attainable[0], F_MAX).f, atol=1e-12
    )


def test_float32_preserves_dtype():
    T = jnp.asarray(T_ODIN, jnp.float32)
    al = allocate(T, jnp.array([60.0, 6.0, 0.0, 0.0, 0.0, 5.0], jnp.float32), jnp.float32(27.0))
    assert al.f.dtype == jnp.float32 and al.residual.dtype == jnp.float32
    assert bool(al.feasible) and float(jnp.max(jnp.abs(al.f))) <= 27.0
