"""Generic VCM engine (docs/method.md): exactness of (14)/(11), (16) vs KKT, (17) vs lstsq, gradients."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from _craft import CRAFT

from vcjax.mechanics import (
    VCMGains,
    VirtualConstraints,
    constrained_acceleration,
    reaction_force,
    vcm_gains,
)
from vcjax.rollout import RolloutConfig, rollout
from vcjax.vehicles import design3dof as d3
from vcjax.vehicles.arm import TWO_LINK_ARM, arm_end_effector, arm_params

# ---------------------------------------------------------------- two-link arm on a circle
CENTER = jnp.array([1.0, 0.6])
RADIUS = 0.35


def circle_G(q, t, p):
    """End effector at distance RADIUS from CENTER (one holonomic constraint)."""
    d = arm_end_effector(q, p) - CENTER
    return jnp.atleast_1d(jnp.sqrt(d @ d) - RADIUS)


def tangential_K(q, qd, t, p):
    """Tangential end-effector speed equals v_d(t) (one velocity constraint)."""
    d = arm_end_effector(q, p) - CENTER
    tangent = jnp.stack([-d[1], d[0]]) / jnp.sqrt(d @ d)
    J_ee = jax.jacfwd(arm_end_effector)(q, p)
    v_d = 0.4 + 0.1 * jnp.sin(2.0 * t)
    return jnp.atleast_1d(tangent @ (J_ee @ qd) - v_d)


ARM_CONS = VirtualConstraints(holonomic=circle_G, velocity=tangential_K)
ARM_G_ONLY = VirtualConstraints(holonomic=circle_G)


def arm_plant(t, x, u, p):
    q, qd = x
    qdd = jnp.linalg.solve(TWO_LINK_ARM.mass_matrix(q, p), u - TWO_LINK_ARM.bias_force(q, qd, p))
    return (qd, qdd)


def make_arm_controller(cons, method="auto"):
    def controller(t, x, z, ctrl):
        gains, p = ctrl
        q, qd = x
        tau_c, _, diag = reaction_force(TWO_LINK_ARM, cons, gains, q, qd, t, None, p, method)
        return tau_c, z, diag

    return controller


ARM_Q0 = (jnp.array([0.35, 1.3]), jnp.array([0.2, -0.1]))


def _arm_run(cons, gains, num_steps, dt, method="auto"):
    p = arm_params()
    cfg = RolloutConfig(num_steps=num_steps, integrator="rk4")
    run = jax.jit(rollout, static_argnames=("plant", "controller", "config"))
    return run(
        arm_plant, make_arm_controller(cons, method), cfg, p, (gains, p), ARM_Q0, jnp.zeros(0), dt
    )


def _analytic_G(t, G0, PhiG0, pG, pPhi):
    """Solution of G' + pG G = PhiG0 exp(-pPhi t) (11), pG != pPhi."""
    return G0 * np.exp(-pG * t) + PhiG0 * (np.exp(-pPhi * t) - np.exp(-pG * t)) / (pG - pPhi)


@pytest.mark.parametrize("method", ["row", "column"])
def test_arm_circle_phi_decays_exactly(method):
    # m + k = n = 2: W square, so both (16) and (17) apply and must agree with the theory.
    pG, pPhi = 2.0, np.array([1.5, 3.0])
    gains = vcm_gains(P_G=[pG], P_Phi=pPhi)
    traj = _arm_run(ARM_CONS, gains, num_steps=3000, dt=1e-3, method=method)
    t = np.asarray(traj.t[:-1])
    Phi = np.asarray(traj.aux.Phi)
    G = np.asarray(traj.aux.G)[:, 0]
    assert np.all(np.asarray(traj.aux.full_rank))
    assert abs(Phi[0, 0]) > 0.1 and abs(Phi[0, 1]) > 0.1 and abs(G[0]) > 0.01
    Phi_exact = Phi[0] * np.exp(-np.outer(t, pPhi))
    rel = np.max(np.abs(Phi - Phi_exact)) / np.max(np.abs(Phi[0]))
    assert rel < 1e-6, rel
    G_exact = _analytic_G(t, G[0], Phi[0, 1], pG, pPhi[1])
    assert np.max(np.abs(G - G_exact)) / abs(G[0]) < 1e-6
    assert np.max(np.asarray(traj.aux.residual)) < 1e-9


def test_arm_holonomic_only_uses_row_branch():
    # k = 1 < n = 2: (16) with the Lagrange multiplier; the arm keeps one free DOF.
    pG, pPhi = 3.0, 1.0
    gains = vcm_gains(P_G=[pG], P_Phi=[pPhi])
    traj = _arm_run(ARM_G_ONLY, gains, num_steps=2000, dt=5e-4)  # the free DOF swings fast
    t = np.asarray(traj.t[:-1])
    Phi = np.asarray(traj.aux.Phi)[:, 0]
    G = np.asarray(traj.aux.G)[:, 0]
    assert np.max(np.abs(Phi - Phi[0] * np.exp(-pPhi * t))) / abs(Phi[0]) < 1e-6
    G_exact = _analytic_G(t, G[0], Phi[0], pG, pPhi)
    assert np.max(np.abs(G - G_exact)) / abs(G[0]) < 1e-6
    with pytest.raises(ValueError, match="method='column' needs"):
        _arm_run(ARM_G_ONLY, gains, num_steps=2, dt=1e-3, method="column")


def test_row_branch_matches_kkt_solve():
    """(16) against an independent saddle-point (KKT) solve of the constrained dynamics."""
    rng = np.random.default_rng(0)
    n, p = 5, 3
    A = rng.normal(size=(n, n))
    M = A @ A.T + n * np.eye(n)
    W = rng.normal(size=(p, n))
    h, nvec, tau = rng.normal(size=p), rng.normal(size=n), rng.normal(size=n)
    tau_c, qdd = constrained_acceleration(*map(jnp.asarray, (M, nvec, tau, W, h)), method="row")
    kkt = np.block([[M, W.T], [W, np.zeros((p, p))]])
    sol = np.linalg.solve(kkt, np.concatenate([tau - nvec, -h]))
    np.testing.assert_allclose(qdd, sol[:n], rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(tau_c, -W.T @ sol[n:], rtol=1e-10, atol=1e-12)


def test_column_branch_is_least_squares():
    """(17) against numpy.linalg.lstsq, and the normal equations that provably hold."""
    rng = np.random.default_rng(1)
    n, p = 3, 5
    A = rng.normal(size=(n, n))
    M = A @ A.T + n * np.eye(n)
    W = rng.normal(size=(p, n))
    h, nvec, tau = rng.normal(size=p), rng.normal(size=n), rng.normal(size=n)
    tau_c, qdd = constrained_acceleration(*map(jnp.asarray, (M, nvec, tau, W, h)), method="column")
    qdd_ls = -np.linalg.lstsq(W, h, rcond=None)[0]
    np.testing.assert_allclose(qdd, qdd_ls, rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(tau_c, nvec - tau + M @ qdd_ls, rtol=1e-10, atol=1e-12)
    # normal equations: the residual is orthogonal to range(W); it is not zero (inconsistent rows)
    res = W @ np.asarray(qdd) + h
    np.testing.assert_allclose(W.T @ res, 0.0, atol=1e-10)
    assert np.linalg.norm(res) > 0.1


def test_overdetermined_marine_constraints_residual_and_consistent_rows():
    """5 constraints on 3 DOF (17): where the rows are consistent (14) holds exactly."""
    p = d3.design3dof(
        m11=30.0, m22=60.0, m23=2.0, m33=8.0, d11=2.0, d22=5.0, d23=0.5, d32=0.3, d33=4.0
    )

    def K(q, qd, t, args):  # body-frame velocities: u - 1, v
        nu = d3.kinematics(q[2]).T @ qd
        return nu[:2] - jnp.array([1.0, 0.0])

    def G(q, t, args):  # heading and position (x, y) on the point (t, 0)
        return jnp.stack([q[2], q[0] - t, q[1]])

    cons = VirtualConstraints(holonomic=G, velocity=K)
    gains = vcm_gains(P_G=[1.0, 0.5, 0.5], P_Phi=[1.0, 1.0, 2.0, 0.5, 0.5])
    q, qd = jnp.array([0.0, 0.0, 0.0]), jnp.array([1.0, 0.0, 0.0])
    # consistent: on the trajectory x = t, u = 1 -> residual 0
    _, qdd, diag = reaction_force(d3.DESIGN3DOF_SYSTEM, cons, gains, q, qd, 0.0, None, p)
    assert float(diag.residual) < 1e-12 and bool(diag.full_rank) and int(diag.rank) == 3
    # inconsistent: off the path, velocity rows and position rows disagree -> lstsq compromise
    q = jnp.array([0.0, 2.0, 0.3])
    _, qdd, diag = reaction_force(d3.DESIGN3DOF_SYSTEM, cons, gains, q, qd, 0.0, None, p)
    assert float(diag.residual) > 1e-3
    from vcjax.mechanics import constraint_terms

    terms = constraint_terms(cons, gains, q, qd, 0.0, p)
    ls = -np.linalg.lstsq(np.asarray(terms.W), np.asarray(terms.h), rcond=None)[0]
    np.testing.assert_allclose(qdd, ls, rtol=1e-10)
    np.testing.assert_allclose(diag.residual, np.linalg.norm(terms.W @ ls + terms.h), rtol=1e-8)


# ---------------------------------------------------------------- 3-DOF marine craft


def craft_constraints():
    def K(q, qd, t, args):  # surge speed u = u_d(t)
        u = jnp.cos(q[2]) * qd[0] + jnp.sin(q[2]) * qd[1]
        return jnp.atleast_1d(u - (2.0 + 0.5 * jnp.sin(0.3 * t)))

    def G(q, t, args):  # heading psi = psi_d(t)
        return jnp.atleast_1d(q[2] - 0.8 * jnp.sin(0.2 * t))

    return VirtualConstraints(holonomic=G, velocity=K)


def craft_plant(t, x, tau_b, p):
    eta, nu = x
    return d3.vector_field(p, eta, nu, tau_b)


def craft_controller(cons):
    def controller(t, x, z, ctrl):
        gains, p = ctrl
        eta, nu = x
        qd = d3.kinematics(eta[2]) @ nu
        tau_c, _, diag = reaction_force(d3.DESIGN3DOF_SYSTEM, cons, gains, eta, qd, t, None, p)
        tau_b = d3.kinematics(eta[2]).T @ tau_c  # tau = J^{-T} tau_b
        return tau_b, z, diag

    return controller


def test_marine_surge_heading_decay():
    pG, pPhi = 0.8, np.array([1.2, 2.0])
    gains = vcm_gains(P_G=[pG], P_Phi=pPhi)
    cfg = RolloutConfig(num_steps=2000, integrator="rk4")
    x0 = (jnp.array([0.0, 0.0, 0.6]), jnp.array([0.5, 0.3, -0.1]))
    traj = jax.jit(rollout, static_argnames=("plant", "controller", "config"))(
        craft_plant,
        craft_controller(craft_constraints()),
        cfg,
        CRAFT,
        (gains, CRAFT),
        x0,
        jnp.zeros(0),
        5e-3,
    )
    t = np.asarray(traj.t[:-1])
    Phi = np.asarray(traj.aux.Phi)
    G = np.asarray(traj.aux.G)[:, 0]
    rel = np.max(np.abs(Phi - Phi[0] * np.exp(-np.outer(t, pPhi)))) / np.max(np.abs(Phi[0]))
    assert rel < 1e-6, rel
    G_exact = _analytic_G(t, G[0], Phi[0, 1], pG, pPhi[1])
    assert np.max(np.abs(G - G_exact)) / abs(G[0]) < 1e-6


# ---------------------------------------------------------------- diagnostics and errors
def test_rank_deficient_constraints_reported_as_data():
    def G(q, t, args):  # the same constraint twice: W has rank 1
        g = q[0] - 0.3
        return jnp.stack([g, 2.0 * g])

    cons = VirtualConstraints(holonomic=G)
    gains = vcm_gains(P_G=[1.0, 1.0], P_Phi=[1.0, 1.0])
    p = arm_params()
    f = jax.jit(lambda q, qd: reaction_force(TWO_LINK_ARM, cons, gains, q, qd, 0.0, None, p)[2])
    diag = f(jnp.array([0.1, 0.5]), jnp.array([0.0, 0.0]))
    assert int(diag.rank) == 1
    assert not bool(diag.full_rank)
    assert np.isinf(float(diag.cond))


def test_gain_validation_errors():
    with pytest.raises(ValueError, match="P_G"):
        vcm_gains(P_G=[-1.0], P_Phi=[1.0, 1.0])
    with pytest.raises(ValueError, match="P_Phi"):
        vcm_gains(P_G=[1.0], P_Phi=[1.0, 0.0])
    with pytest.raises(ValueError, match="P_Phi"):
        vcm_gains(P_G=[1.0], P_Phi=[[1.0, 2.0], [2.0, 1.0]])  # indefinite
    with pytest.raises(ValueError, match="P_G.*NaN"):
        vcm_gains(P_G=[np.nan], P_Phi=[1.0])
    with pytest.raises(ValueError, match="at least one"):
        VirtualConstraints()


def test_full_gain_matrices_equal_diagonal():
    p = arm_params()
    q, qd = jnp.array([0.4, 1.1]), jnp.array([0.3, -0.2])
    g_vec = vcm_gains(P_G=[2.0], P_Phi=[1.5, 3.0])
    g_mat = vcm_gains(P_G=[[2.0]], P_Phi=np.diag([1.5, 3.0]))
    a = reaction_force(TWO_LINK_ARM, ARM_CONS, g_vec, q, qd, 0.2, None, p)[0]
    b = reaction_force(TWO_LINK_ARM, ARM_CONS, g_mat, q, qd, 0.2, None, p)[0]
    np.testing.assert_allclose(a, b, rtol=1e-12)


def test_jit_vmap_match_plain_calls():
    p = arm_params()
    q, qd = jnp.array([0.4, 1.1]), jnp.array([0.3, -0.2])
    pGs = jnp.array([0.5, 1.0, 4.0])

    def force(pG):
        gains = vcm_gains(P_G=pG[None], P_Phi=jnp.array([1.5, 3.0]))
        return reaction_force(TWO_LINK_ARM, ARM_CONS, gains, q, qd, 0.2, None, p)[0]

    loop = np.stack([force(g) for g in pGs])
    np.testing.assert_allclose(jax.vmap(force)(pGs), loop, rtol=1e-12)
    np.testing.assert_allclose(jax.jit(force)(pGs[1]), loop[1], rtol=1e-12)


# ---------------------------------------------------------------- gradients
def _gradient_check(cons, theta0, modes):
    p = arm_params()
    cfg = RolloutConfig(num_steps=120, integrator="rk4")
    controller = make_arm_controller(cons)
    k = 1

    def cost(theta):
        gains = VCMGains(P_G=theta[:k], P_Phi=theta[k:])
        traj = rollout(arm_plant, controller, cfg, p, (gains, p), ARM_Q0, jnp.zeros(0), 0.01)
        ee = jax.vmap(arm_end_effector, in_axes=(0, None))(traj.x[0], p)
        err = jnp.sum((ee - CENTER) ** 2, axis=1)
        return 0.01 * jnp.sum(err) + 1e-4 * 0.01 * jnp.sum(traj.u**2)

    f = jax.jit(cost)
    eps = 1e-6
    g_fd = np.array(
        [
            (f(theta0.at[i].add(eps)) - f(theta0.at[i].add(-eps))) / (2 * eps)
            for i in range(theta0.shape[0])
        ]
    )
    assert np.all(np.abs(g_fd) > 1e-8)
    if "rev" in modes:
        np.testing.assert_allclose(jax.jit(jax.grad(cost))(theta0), g_fd, rtol=1e-6, atol=1e-10)
    if "fwd" in modes:
        g_fwd = jax.jit(jax.jacfwd(cost))(theta0)
        np.testing.assert_allclose(g_fwd, g_fd, rtol=1e-6, atol=1e-10)


def test_rollout_cost_gradient_matches_finite_differences():
    """Reverse-mode gradient of a rollout cost w.r.t. (p_G, p_Phi) vs central differences."""
    _gradient_check(ARM_G_ONLY, jnp.array([3.0, 1.0]), modes=("rev",))


@pytest.mark.slow
def test_rollout_cost_gradient_fwd_and_rev_full_constraint_set():
    _gradient_check(ARM_CONS, jnp.array([2.0, 1.5, 3.0]), modes=("rev", "fwd"))


def test_constraints_on_an_auxiliary_state_decay_exactly():
    """G depends on a particle z with z_dot = f(q, z): Φ still decays as exp(-P_Φ t)."""

    def target(z):
        return CENTER + RADIUS * jnp.stack([jnp.cos(z[0]), jnp.sin(z[0])])

    def G(q, t, p, z):
        return arm_end_effector(q, p) - target(z)

    def rate(q, t, z, p):  # depends on the arm's state and on z itself
        return jnp.atleast_1d(0.6 + 0.3 * jnp.sin(q[0]) * jnp.cos(z[0]))

    cons = VirtualConstraints(holonomic=G, state_rate=rate)
    pG, pPhi = np.array([2.0, 1.0]), np.array([1.5, 3.0])
    gains = vcm_gains(P_G=pG, P_Phi=pPhi)
    p = arm_params()

    def controller(t, x, z, ctrl):
        q, qd = x
        tau_c, _, diag = reaction_force(TWO_LINK_ARM, cons, ctrl, q, qd, t, None, p, z=z)
        return tau_c, rate(q, t, z, p), diag

    cfg = RolloutConfig(num_steps=2000, integrator="rk4")
    run = jax.jit(rollout, static_argnames=("plant", "controller", "config"))
    traj = run(arm_plant, controller, cfg, p, gains, ARM_Q0, jnp.array([0.3]), 1e-3)
    t = np.asarray(traj.t[:-1])
    Phi = np.asarray(traj.aux.Phi)
    assert np.all(np.abs(Phi[0]) > 0.05)
    rel = np.max(np.abs(Phi - Phi[0] * np.exp(-np.outer(t, pPhi)))) / np.max(np.abs(Phi[0]))
    assert rel < 1e-6, rel
    with pytest.raises(ValueError, match="auxiliary state"):
        reaction_force(TWO_LINK_ARM, cons, gains, ARM_Q0[0], ARM_Q0[1], 0.0, None, p)
