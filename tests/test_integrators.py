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


def test_dense_tangent_is_the_identity_in_value_and_derivatives():
    """dense_tangent only changes how a scan's linearisation starts, never a number: its
    value, forward and reverse derivatives are the identity's, also when the marked value
    does not depend on what is differentiated (then its derivative is exactly zero)."""
    from vcjax.integrators import dense_tangent

    x = (jnp.array([1.0, -2.0]), jnp.array(3, dtype=jnp.int32))

    def f(p):  # x depends on p through its first leaf only after marking
        y = dense_tangent(x, (p, jnp.array(7, dtype=jnp.int32)))
        return y[0] * p[0] + p[1] ** 2, y[1]

    p = jnp.array([0.5, -1.5])
    val, ints = f(p)
    np.testing.assert_array_equal(val, x[0] * p[0] + p[1] ** 2)
    assert int(ints) == 3
    J = jax.jacrev(lambda p: f(p)[0])(p)
    J_fwd = jax.jacfwd(lambda p: f(p)[0])(p)
    want = np.array([[1.0, 2 * -1.5], [-2.0, 2 * -1.5]])
    np.testing.assert_array_equal(J, want)
    np.testing.assert_array_equal(J_fwd, want)
    # differentiating the marked value itself: the identity's Jacobian
    g = jax.jacrev(lambda a: dense_tangent(a, p))(x[0])
    np.testing.assert_array_equal(g, np.eye(2))


def test_sampled_rk4_stages_loop_or_unrolled_match_the_exact_discrete_map():
    """A sampled (zero-order-hold) rollout of a linear 12-state plant, x' = A x + B u with
    u = -K x held over each step: RK4's discrete map is x+ = T(hA) x + h S(hA) B u with
    T = sum_{i<=4} (hA)^i / i!, S = sum_{i<=3} (hA)^i / (i+1)!. The stage loop and the
    unrolled stages both follow it to round-off; ``"auto"`` picks the loop for 12 states and
    the unrolled stages for 6 (and always the loop with a continuous controller)."""
    import math

    import numpy as np

    from vcjax.rollout import LOOP_STATE, RolloutConfig, _rk4_loop, rollout

    rng = np.random.default_rng(3)
    n, h, steps = LOOP_STATE, 0.05, 40
    A = rng.normal(size=(n, n)) * 0.3 - np.eye(n)
    B = rng.normal(size=(n, 2))
    K = rng.normal(size=(2, n)) * 0.2
    x0 = rng.normal(size=n)

    def plant(t, x, u, p):
        return p[0] @ x + p[1] @ u

    def controller(t, x, z, k):
        return -k @ x, jnp.zeros(0), ()

    hA = h * A
    T = sum(np.linalg.matrix_power(hA, i) / math.factorial(i) for i in range(5))
    S = sum(np.linalg.matrix_power(hA, i) / math.factorial(i + 1) for i in range(4))
    x, want = x0, [x0]
    for _ in range(steps):
        x = T @ x + h * S @ B @ (-K @ x)
        want.append(x)
    got = {}
    for stages in ("loop", "unrolled"):
        cfg = RolloutConfig(num_steps=steps, timing="sampled", stages=stages)
        tr = rollout(plant, controller, cfg, (A, B), K, jnp.asarray(x0), jnp.zeros(0), h)
        got[stages] = np.asarray(tr.x)
        np.testing.assert_allclose(got[stages], np.asarray(want), rtol=1e-12, atol=1e-13)
    np.testing.assert_allclose(got["loop"], got["unrolled"], rtol=1e-14, atol=1e-15)
    sampled = RolloutConfig(num_steps=1, timing="sampled")
    assert _rk4_loop(sampled, jnp.zeros(n)) and not _rk4_loop(sampled, jnp.zeros(6))
    assert _rk4_loop(RolloutConfig(num_steps=1), jnp.zeros(6))
    with pytest.raises(ValueError, match="stages"):
        RolloutConfig(num_steps=1, stages="fused")


def test_rk4_remat_gives_the_same_gradient_and_keeps_no_stage_intermediates():
    """rk4(remat=True) checkpoints each stage: reverse mode through it gives the gradient of
    the plain stage loop (and of the unrolled stages, and a central difference), and its
    program no longer stacks the vector field's intermediates of the four stages for the
    backward pass (the stage loop's stacked outputs: 28 without, 5 with)."""
    import jax
    import jax.numpy as jnp
    import numpy as np

    from tests.reference.programs import stage_stacks
    from vcjax.integrators import rk4, rk4_unrolled

    def f(t, y, k):  # a field with many intermediate values
        a, b = y
        s = a
        for i in range(12):
            s = jnp.sin(s * k[i % 3] + t) + 0.1 * b
        return (s - a, jnp.cos(a) * k[0] - 0.5 * b), {"s": s}

    y0 = (jnp.asarray([0.3, -1.2]), jnp.asarray([2.0, 0.5]))
    k0 = jnp.asarray([0.9, 1.1, -0.7])

    def loss(k, step, **kw):
        y = y0
        for n in range(3):
            y, _ = step(f, 0.1 * n, y, 0.1, k, **kw)
        return jnp.sum(y[0] ** 2) + jnp.sum(y[1] ** 3)

    plain = jax.grad(lambda k: loss(k, rk4))(k0)
    remat = jax.grad(lambda k: loss(k, rk4, remat=True))(k0)
    unrolled = jax.grad(lambda k: loss(k, rk4_unrolled))(k0)
    np.testing.assert_allclose(remat, plain, rtol=1e-13, atol=1e-15)
    np.testing.assert_allclose(remat, unrolled, rtol=1e-13, atol=1e-15)
    h = 1e-6
    fd = [(loss(k0 + h * e, rk4) - loss(k0 - h * e, rk4)) / (2 * h) for e in np.eye(3)]
    np.testing.assert_allclose(remat, fd, rtol=1e-7)
    # forward values are the same bits (remat only changes what reverse mode stores)
    np.testing.assert_array_equal(loss(k0, rk4, remat=True), loss(k0, rk4))

    def stacked(**kw):
        return stage_stacks(jax.grad(lambda k: loss(k, rk4, **kw)), k0)

    assert stacked() > 20  # sin chain: every intermediate of the field, for four stages
    assert stacked(remat=True) <= 6  # the stage's inputs (and the field's aux output)
