"""Integrators: observed convergence order against an analytic solution; pytree states."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from vcjax.integrators import ORDER, get_integrator


def field(t, y, args):
    """Driven damped oscillator (pytree state: (x, v))."""
    x, v = y
    return (v, -2.0 * x - 0.5 * v + jnp.cos(t)), None


def decay_exact(t):
    return np.exp(-t)


def run(name, dt, T):
    integ = get_integrator(name)

    def body(y, k):
        return integ(field, k * dt, y, dt, None)[0], None

    y, _ = jax.lax.scan(
        body, (jnp.array(1.0), jnp.array(0.0)), jnp.arange(int(round(T / dt)), dtype=float)
    )
    return np.array([float(y[0]), float(y[1])])


def test_rk4_matches_analytic_exponential():
    f = lambda t, y, a: (-y, None)
    y = jnp.array(1.0)
    for _ in range(100):
        y, _ = get_integrator("rk4")(f, 0.0, y, 0.01, None)
    assert abs(float(y) - decay_exact(1.0)) < 1e-10  # RK4 global error ~ dt^4 / 120


@pytest.mark.parametrize("name", ["euler", "heun", "rk4"])
def test_convergence_order(name):
    T = 2.0
    ref = run("rk4", 2.5e-4, T)  # reference: RK4 with a 40x finer step
    dts = [0.04, 0.02, 0.01]
    errs = [np.linalg.norm(run(name, dt, T) - ref) for dt in dts]
    orders = np.log2(np.array(errs[:-1]) / np.array(errs[1:]))
    assert np.all(np.abs(orders - ORDER[name]) < 0.25), (name, errs, orders)


def test_unknown_integrator_is_a_clear_error():
    with pytest.raises(ValueError, match="unknown integrator"):
        get_integrator("rk45")


def test_rk4_stage_loop_equals_the_unrolled_stages():
    """rk4 (the stages as a scan over the tableau) and rk4_unrolled (written out) are the same
    method: one step of a nonlinear pytree system agrees to round-off, aux from stage 1."""
    import jax
    import jax.numpy as jnp
    import numpy as np

    from vcjax.integrators import rk4, rk4_unrolled

    def f(t, y, args):
        a, b = y
        return (jnp.sin(t) * b - a**3, jnp.cos(a) + args * b), {"t": t, "a": a}

    y = (jnp.asarray([0.3, -1.2]), jnp.asarray([2.0, 0.5]))
    for dt in (0.01, 0.3):
        y1, aux1 = rk4(f, 0.7, y, dt, 0.25)
        y2, aux2 = rk4_unrolled(f, 0.7, y, dt, 0.25)
        for u, v in zip(jax.tree_util.tree_leaves(y1), jax.tree_util.tree_leaves(y2), strict=True):
            np.testing.assert_allclose(u, v, rtol=1e-14, atol=1e-15)
        np.testing.assert_array_equal(aux1["a"], y[0])
        np.testing.assert_allclose(aux1["t"], 0.7)
