"""Rollout: no retrace on new traced values, sampled vs continuous timing, health flags,
checkpointing, float32."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from vcjax.rollout import Reduction, RolloutConfig, rollout, rollout_reduce

TRACES = {"n": 0}


def plant(t, x, u, p):
    """Mass-spring-damper, force input; p = (k, c)."""
    TRACES["n"] += 1  # side effect runs at trace time only
    return jnp.stack([x[1], -p[0] * x[0] - p[1] * x[1] + u])


def pd_controller(t, x, z, gains):
    """PD with an integral state z (z_dot = position error)."""
    kp, kd, ki = gains
    u = -kp * x[0] - kd * x[1] - ki * z
    return u, x[0], {"u": u}


run = jax.jit(rollout, static_argnames=("plant", "controller", "config"))


def test_new_gains_and_dt_reuse_the_compiled_function():
    cfg = RolloutConfig(num_steps=50)
    x0 = jnp.array([1.0, 0.0])
    run(
        plant,
        pd_controller,
        cfg,
        jnp.array([1.0, 0.1]),
        jnp.array([2.0, 1.0, 0.1]),
        x0,
        jnp.array(0.0),
        0.01,
    )
    n = TRACES["n"]
    assert n > 0
    for k in range(3):
        traj = run(
            plant,
            pd_controller,
            cfg,
            jnp.array([1.0 + k, 0.2]),
            jnp.array([3.0 + k, 1.0, 0.2]),
            x0 + k,
            jnp.array(0.5),
            0.02 + 0.01 * k,
        )
        traj.t.block_until_ready()
    assert TRACES["n"] == n, "new traced values must not retrace"
    assert np.isclose(float(traj.t[-1]), 50 * 0.04)


def test_linear_closed_loop_matches_matrix_exponential():
    # continuous PD on a linear plant: x(t) = expm(A t) x0 exactly (to RK4 accuracy)
    k, c, kp, kd = 2.0, 0.3, 1.5, 0.8
    cfg = RolloutConfig(num_steps=200)
    traj = run(
        plant,
        pd_controller,
        cfg,
        jnp.array([k, c]),
        jnp.array([kp, kd, 0.0]),
        jnp.array([1.0, -0.5]),
        jnp.array(0.0),
        0.01,
    )
    A = np.array([[0.0, 1.0], [-(k + kp), -(c + kd)]])
    w, V = np.linalg.eig(A)
    x_T = (V @ np.diag(np.exp(w * 2.0)) @ np.linalg.solve(V, [1.0, -0.5])).real
    np.testing.assert_allclose(traj.x[-1], x_T, atol=1e-9)
    assert traj.x.shape == (201, 2) and traj.u.shape == (200,) and traj.aux["u"].shape == (200,)


def test_sampled_controller_converges_to_continuous_first_order():
    x0, z0 = jnp.array([1.0, 0.0]), jnp.array(0.0)
    pp, gg = jnp.array([2.0, 0.3]), jnp.array([1.5, 0.8, 0.4])
    T = 2.0
    ref = run(plant, pd_controller, RolloutConfig(num_steps=400), pp, gg, x0, z0, T / 400).x[-1]
    errs = []
    for n in (50, 100, 200):
        cfg = RolloutConfig(num_steps=n, timing="sampled")
        errs.append(
            float(
                jnp.linalg.norm(run(plant, pd_controller, cfg, pp, gg, x0, z0, T / n).x[-1] - ref)
            )
        )
    ratios = np.array(errs[:-1]) / np.array(errs[1:])
    assert errs[0] > 1e-4  # sampling is visible
    assert np.all(np.abs(ratios - 2.0) < 0.3), (errs, ratios)  # zero-order hold: O(dt)


def test_divergence_is_flagged_and_state_frozen():
    blow = lambda t, x, u, p: x**2  # x(t) = 1/(1 - t): blows up at t = 1
    ctrl = lambda t, x, z, p: (jnp.zeros(()), z, None)
    traj = run(
        blow,
        ctrl,
        RolloutConfig(num_steps=200, integrator="euler"),
        None,
        None,
        jnp.array([1.0]),
        jnp.zeros(0),
        0.01,
    )
    finite = np.asarray(traj.finite)
    assert not finite.all() and finite[:50].all()
    assert np.all(np.isfinite(traj.x))


@pytest.mark.parametrize("every", [1, 7, 100, 250])
def test_checkpoint_gives_same_trajectory_and_gradient(every):
    """Per-step and segment checkpointing (7 does not divide 100: a remainder segment) change
    memory, not results."""

    def loss(gains, checkpoint):
        cfg = RolloutConfig(num_steps=100, checkpoint=checkpoint, checkpoint_every=every)
        traj = rollout(
            plant,
            pd_controller,
            cfg,
            jnp.array([2.0, 0.3]),
            gains,
            jnp.array([1.0, 0.0]),
            jnp.array(0.0),
            0.02,
        )
        return jnp.sum(traj.x[:, 0] ** 2)

    g = jnp.array([1.5, 0.8, 0.4])
    a = jax.jit(jax.value_and_grad(loss), static_argnums=1)(g, False)
    b = jax.jit(jax.value_and_grad(loss), static_argnums=1)(g, True)
    np.testing.assert_allclose(a[0], b[0], rtol=1e-13)
    np.testing.assert_allclose(a[1], b[1], rtol=1e-12)
    with pytest.raises(ValueError, match="checkpoint_every"):
        RolloutConfig(num_steps=10, checkpoint=True, checkpoint_every=0)
    with pytest.raises(ValueError, match="unroll"):
        RolloutConfig(num_steps=10, unroll=0)


def test_float32_rollout_close_to_float64():
    args = dict(plant_params=jnp.array([2.0, 0.3]), ctrl_params=jnp.array([1.5, 0.8, 0.4]))
    cfg = RolloutConfig(num_steps=100)
    t64 = run(
        plant,
        pd_controller,
        cfg,
        args["plant_params"],
        args["ctrl_params"],
        jnp.array([1.0, 0.0]),
        jnp.array(0.0),
        0.02,
    )
    f32 = lambda a: jnp.asarray(a, jnp.float32)
    t32 = run(
        plant,
        pd_controller,
        cfg,
        f32(args["plant_params"]),
        f32(args["ctrl_params"]),
        f32([1.0, 0.0]),
        f32(0.0),
        0.02,
    )
    assert t32.x.dtype == jnp.float32 and t32.t.dtype == jnp.float32
    np.testing.assert_allclose(t32.x, t64.x, atol=1e-5)


def test_config_validation():
    with pytest.raises(ValueError, match="num_steps"):
        RolloutConfig(num_steps=0)
    with pytest.raises(ValueError, match="timing"):
        RolloutConfig(num_steps=10, timing="discrete")
    with pytest.raises(ValueError, match="unknown integrator"):
        RolloutConfig(num_steps=10, integrator="dopri5")


def test_unrolled_loop_gives_the_same_trajectory():
    args = (jnp.array([2.0, 0.3]), jnp.array([1.5, 0.8, 0.4]), jnp.array([1.0, 0.0]))
    a = run(plant, pd_controller, RolloutConfig(num_steps=37), *args, jnp.array(0.0), 0.02)
    b = run(
        plant, pd_controller, RolloutConfig(num_steps=37, unroll=4), *args, jnp.array(0.0), 0.02
    )
    np.testing.assert_allclose(a.x, b.x, rtol=1e-14)


@pytest.mark.parametrize("segment", [7, 50, 200])
def test_rollout_reduce_samples_the_analytic_solution(segment):
    """The streamed record is the same closed loop: the sum of x over the 200 steps' start
    states and every segment's first state match expm(A t) x0; 7 does not divide 200 (a
    remainder segment), 200 > N/1 is one segment."""
    k, c, kp, kd, dt, n = 2.0, 0.3, 1.5, 0.8, 0.01, 200
    A = np.array([[0.0, 1.0], [-(k + kp), -(c + kd)]])
    w, V = np.linalg.eig(A)
    x0 = np.array([1.0, -0.5])
    exact = lambda t: (V @ np.diag(np.exp(w * t)) @ np.linalg.solve(V, x0)).real

    def update(acc, seg, ks):
        # seg.x holds the L + 1 states of the segment; the L step starts are seg.x[:-1]
        assert seg.x.shape[0] == ks.shape[0] + 1 and seg.t.shape[0] == ks.shape[0] + 1
        return acc + jnp.sum(seg.x[:-1], axis=0), (seg.t[0], seg.x[0], seg.x[-1])

    red = Reduction(jnp.zeros(2), update, segment)
    acc, (t_first, x_first, x_last) = jax.jit(
        lambda *a: rollout_reduce(*a, red), static_argnums=(0, 1, 2)
    )(
        plant,
        pd_controller,
        RolloutConfig(num_steps=n),
        jnp.array([k, c]),
        jnp.array([kp, kd, 0.0]),
        jnp.asarray(x0),
        jnp.array(0.0),
        dt,
    )
    starts = np.arange(0, n, min(segment, n))
    np.testing.assert_allclose(t_first, starts * dt, atol=1e-12)
    np.testing.assert_allclose(x_first, np.stack([exact(t) for t in starts * dt]), atol=1e-9)
    np.testing.assert_allclose(x_last[-1], exact(n * dt), atol=1e-9)
    np.testing.assert_allclose(acc, sum(exact(i * dt) for i in range(n)), atol=1e-8)


def test_rollout_reduce_gradient_matches_finite_differences():
    """Gradients flow through the segment scan (with and without per-segment checkpointing)."""

    def loss(gains, checkpoint):
        red = Reduction(
            jnp.zeros(()), lambda a, seg, ks: (a + jnp.sum(seg.x[:-1, 0] ** 2), None), 9
        )
        cfg = RolloutConfig(num_steps=100, checkpoint=checkpoint)
        acc, _ = rollout_reduce(
            plant,
            pd_controller,
            cfg,
            jnp.array([2.0, 0.3]),
            gains,
            jnp.array([1.0, 0.0]),
            jnp.array(0.0),
            0.02,
            red,
        )
        return acc

    g = jnp.array([1.5, 0.8, 0.4])
    for ckpt in (False, True):
        grad = jax.jit(jax.grad(loss), static_argnums=1)(g, ckpt)
        h = 1e-6
        fd = [
            (loss(g.at[i].add(h), ckpt) - loss(g.at[i].add(-h), ckpt)) / (2 * h) for i in range(3)
        ]
        np.testing.assert_allclose(grad, fd, rtol=1e-6)
    with pytest.raises(ValueError, match="segment"):
        rollout_reduce(
            plant,
            pd_controller,
            RolloutConfig(num_steps=5),
            jnp.array([2.0, 0.3]),
            g,
            jnp.array([1.0, 0.0]),
            jnp.array(0.0),
            0.02,
            Reduction(0.0, None, 0),
        )


def test_batch_gradients_in_shared_and_per_scenario_parameters_match_finite_differences():
    """A vmapped batch of rollouts (the tuner's and the sweep's shape): the gradient in gains
    shared by the batch, in per-scenario plant parameters and in per-scenario gains, forward
    and reverse mode, equal to central differences. (The rollout marks its initial carry and
    RK4 its stage accumulators so that linearising the scans settles in one round; this checks
    that marking under vmap, where the carry and the parameters are batched differently.)"""

    def plant(t, x, u, p):
        return jnp.stack([x[1], -p[0] * x[0] - 0.2 * x[1] ** 3 + u[0]])

    def controller(t, x, z, c):
        return jnp.stack([-c[0] * x[1] - c[1] * z[0]]), jnp.stack([x[0]]), ()

    cfg = RolloutConfig(num_steps=6)  # continuous: RK4's stage scan inside the step scan

    def loss(c, x0, p):
        tr = rollout(plant, controller, cfg, p, c, x0, jnp.zeros(1), 0.1)
        return jnp.sum(tr.x**2)

    x0s = jnp.asarray([[1.0, 0.0], [0.5, -0.3], [-0.7, 0.2]])
    ps = jnp.asarray([[1.0], [1.5], [0.8]])
    c = jnp.asarray([0.5, 0.1])
    cs = jnp.stack([c, 1.2 * c, 0.9 * c])
    shared = lambda c, p: jnp.mean(jax.vmap(loss, in_axes=(None, 0, 0))(c, x0s, p))
    tiled = lambda cs: jnp.mean(jax.vmap(loss)(cs, x0s, ps))

    def fd(f, a, h=1e-6):
        flat = np.asarray(a).ravel()
        out = []
        for i in range(flat.size):
            e = np.zeros_like(flat)
            e[i] = h
            up, dn = (jnp.asarray((flat + s * e).reshape(np.shape(a))) for s in (1, -1))
            out.append((float(f(up)) - float(f(dn))) / (2 * h))
        return np.asarray(out).reshape(np.shape(a))

    checks = [
        (lambda a: shared(a, ps), c),
        (lambda a: shared(c, a), ps),
        (tiled, cs),
    ]
    for i, (f, a) in enumerate(checks):
        ref = fd(jax.jit(f), a)
        np.testing.assert_allclose(jax.jit(jax.grad(f))(a), ref, rtol=1e-6, atol=1e-9)
        if i == 0:
            np.testing.assert_allclose(jax.jit(jax.jacfwd(f))(a), ref, rtol=1e-6, atol=1e-9)


def chain_plant(t, x, u, p):
    """Six masses on nonlinear springs (12 states: a 6-DOF vehicle's size), force on the last."""
    q, v = x[:6], x[6:]
    stretch = jnp.diff(jnp.concatenate([jnp.zeros(1, x.dtype), q]))
    spring = p[0] * jnp.sin(stretch) + 0.1 * stretch**3
    force = spring - jnp.concatenate([spring[1:], jnp.zeros(1, x.dtype)]) - p[1] * v
    return jnp.concatenate([v, -force + jnp.zeros(6, x.dtype).at[5].set(u)])


def chain_pd(t, x, z, gains):
    kp, kd, ki = gains
    u = -kp * x[5] - kd * x[11] - ki * z
    return u, x[5], {"u": u}


def test_checkpoint_recomputes_the_stages_of_a_six_dof_sized_plant_only():
    """With ``checkpoint`` (the default), a plant of LOOP_STATE state entries or more has its
    RK4 stages rematerialised (they stack only their inputs for the backward pass) instead of
    its step (under a continuous law); the 2-state plant keeps its stage tape inside a
    checkpointed step. The gradient is the stored tape's to round-off either way."""
    from tests.reference.programs import program_eqns, stage_stacks
    from vcjax.rollout import LOOP_STATE

    assert LOOP_STATE == 12

    def loss(gains, checkpoint, chain):
        cfg = RolloutConfig(num_steps=40, checkpoint=checkpoint)
        pl, ctrl = (chain_plant, chain_pd) if chain else (plant, pd_controller)
        x0 = jnp.linspace(0.1, 0.6, 12) if chain else jnp.array([1.0, 0.0])
        traj = rollout(pl, ctrl, cfg, jnp.array([2.0, 0.3]), gains, x0, jnp.array(0.0), 0.02)
        return jnp.sum(traj.x**2)

    g = jnp.array([1.5, 0.8, 0.4])
    for chain in (False, True):
        a = jax.jit(jax.value_and_grad(loss), static_argnums=(1, 2))(g, False, chain)
        b = jax.jit(jax.value_and_grad(loss), static_argnums=(1, 2))(g, True, chain)
        np.testing.assert_allclose(a[0], b[0], rtol=1e-13)
        np.testing.assert_allclose(a[1], b[1], rtol=1e-11, atol=1e-13)
    stacks = lambda checkpoint, chain: stage_stacks(
        jax.grad(lambda g_: loss(g_, checkpoint, chain)), g
    )
    assert stacks(True, True) < stacks(False, True)  # the chain's stages recomputed
    assert stacks(True, False) >= 4  # the small plant's stages keep their (few) values

    def checkpoints(chain):  # jax.checkpoint calls: (around a stage, elsewhere: the step)
        from jax._src.ad_checkpoint import remat_p

        eqns = program_eqns(lambda g_: loss(g_, True, chain), g)
        inside = [in_stage for e, in_stage in eqns if e.primitive is remat_p]
        return sum(inside), len(inside) - sum(inside)

    # the chain's stages are checkpointed (the whole step is its stage loop: not the step
    # again); the small plant's step is checkpointed
    assert (checkpoints(True), checkpoints(False)) == ((1, 0), (0, 1))
