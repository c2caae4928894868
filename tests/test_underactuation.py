"""Generic underactuation solve (mechanics.underactuated_reaction_force): the horizontal 3-DOF
reduction equals the closed-form law (38) with Remark 4, the unactuated rows hold to round-off,
and a second independent check against an explicit (r+1)-point affine reconstruction."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from _craft import CRAFT as MODEL
from _craft import K_RUDDER

from vcjax import paths
from vcjax.control.vcm import VCMConfig, pm_gains, vcm_law, vcm_params, vcm_state
from vcjax.environment import WaterMotion
from vcjax.linalg import rot2, wrap_angle
from vcjax.mechanics import (
    Underactuation,
    VCMGains,
    VirtualConstraints,
    reaction_force,
    underactuated_reaction_force,
)
from vcjax.rollout import RolloutConfig, rollout
from vcjax.vehicles import design3dof as d3

LINE_PATH, LINE_COEFFS = paths.paper_line()
GAINS = pm_gains()
#: no two entries equal: a swap between the s/e or u/v gains changes the law
ASYMMETRIC = pm_gains(P_G=(1.1, 0.4, 0.7), P_Phi=(1.3, 0.8, 2.2, 0.6, 0.35), Delta=4.0, sigma=0.6)


def _closed_form_run(T=12.0, dt=0.05, gains=GAINS):
    cfg = VCMConfig(path=LINE_PATH, actuation="underactuated", edd="implied")
    params = vcm_params(gains, MODEL, LINE_COEFFS, u_d=2.0, k_rudder=K_RUDDER)

    def plant(t, x, tau, args):
        return d3.vector_field(MODEL, x[0], x[1], tau, WaterMotion(jnp.zeros(3), None))

    def controller(t, x, z, p):
        return vcm_law(cfg, p, t, x[0], x[1], z)

    x0 = (jnp.array([0.0, 0.0, np.pi / 2]), jnp.array([2.0, 0.0, 0.0]))
    run = jax.jit(rollout, static_argnames=("plant", "controller", "config"))
    conf = RolloutConfig(num_steps=int(round(T / dt)))
    return run(plant, controller, conf, None, params, x0, vcm_state(), dt), params


def _engine_problem(params):
    """The exact constraint set (26)-(27) with z = [varpi, v_d] and v_d free (sway unactuated)."""
    g = params.gains

    def frame(z):  # the pose: the engine differentiates these constraints twice
        return paths.path_pose(LINE_PATH, LINE_COEFFS, z[0])

    def eps_of(q, z):
        f = frame(z)
        return rot2(f.psi_p).T @ (q[:2] - f.p[:2])

    def G(q, t, args, z):
        eps = eps_of(q, z)
        psi_d = frame(z).psi_p + jnp.arctan(-eps[1] / g.Delta)
        return jnp.stack([wrap_angle(q[2] - psi_d), eps[0], eps[1]])

    def K(q, qd, t, args, z):
        nu = d3.kinematics(q[2]).T @ qd
        return nu[:2] - jnp.stack([params.u_d, z[1]])

    def rate(q, t, z, args):
        varpi_dot = (params.u_d + g.sigma * eps_of(q, z)[0]) / frame(z).speed_bar
        return jnp.stack([varpi_dot, jnp.zeros_like(varpi_dot)])

    def unactuated(q, qd, t, args):
        # body force tau_b = J^T tau; the rudder's own sway force: tau_v - k tau_r = 0
        a_b = jnp.array([[0.0, 1.0, -K_RUDDER]])
        return a_b @ d3.kinematics(q[2]).T, jnp.zeros(1)

    cons = VirtualConstraints(holonomic=G, velocity=K, state_rate=rate)
    return cons, Underactuation(unactuated=unactuated, free=(1,)), VCMGains(g.P_G, g.P_Phi)


@pytest.mark.parametrize("gains", [GAINS, ASYMMETRIC], ids=["paper", "asymmetric"])
def test_horizontal_reduction_equals_closed_form_38(gains):
    """Engine + Underactuation on the 3-DOF model == vcm_law (underactuated, implied), 1e-8."""
    traj, params = _closed_form_run(gains=gains)
    cons, under, gains = _engine_problem(params)

    def engine(eta, nu, varpi, v_d, t):
        qd = d3.kinematics(eta[2]) @ nu
        z = jnp.stack([varpi, v_d])
        tau_c, _, mu, diag = underactuated_reaction_force(
            d3.DESIGN3DOF_SYSTEM, cons, under, gains, eta, qd, t, None, MODEL, z=z
        )
        return d3.kinematics(eta[2]).T @ tau_c, mu[0], diag.residual

    eta, nu = traj.x[0][:-1], traj.x[1][:-1]
    z = traj.z
    tau_e, vdd_e, res = jax.jit(jax.vmap(engine))(eta, nu, z.varpi[:-1], z.v_d[:-1], traj.t[:-1])
    tau_law = np.asarray(traj.aux.tau)
    scale = np.max(np.abs(tau_law), axis=0)
    assert np.max(np.abs(tau_e - tau_law) / scale) <= 1e-8
    # the free rate is the closed form's v_d_dot (finite differences of the recorded v_d)
    vd = np.asarray(z.v_d)
    assert np.max(np.abs(vd)) > 1e-3
    vdd_law = jax.jit(jax.vmap(lambda e, n, zz, t: vcm_law(_cfg(), params, t, e, n, zz)[1].v_d))(
        eta, nu, jax.tree_util.tree_map(lambda a: a[:-1], z), traj.t[:-1]
    )
    np.testing.assert_allclose(vdd_e, vdd_law, rtol=1e-8, atol=1e-10 * np.abs(vdd_law).max())
    np.testing.assert_allclose(res, traj.aux.ls_residual, rtol=1e-6, atol=1e-9)
    # the unactuated row holds to round-off at every step
    gap = tau_e[:, 1] - K_RUDDER * tau_e[:, 2]
    assert np.max(np.abs(gap)) <= 1e-10 * np.max(np.abs(tau_e))


def _cfg():
    return VCMConfig(path=LINE_PATH, actuation="underactuated", edd="implied")


def test_solution_is_the_root_of_the_affine_condition():
    """Independent of the linearisation: evaluate the fully actuated engine at mu = 0 and at
    the r unit vectors (the state_rate carries mu explicitly); the affine interpolation's root
    gives the same force and the same free rate."""
    params = vcm_params(GAINS, MODEL, LINE_COEFFS, u_d=2.0, k_rudder=K_RUDDER)
    cons, under, gains = _engine_problem(params)
    q = jnp.array([1.0, 3.0, 1.2])
    qd = d3.kinematics(q[2]) @ jnp.array([1.6, 0.3, -0.2])
    z = jnp.array([2.0, 0.1])

    @jax.jit
    def full(mu):
        rate = lambda q_, t_, z_, a_: cons.state_rate(q_, t_, z_, a_) + jnp.stack([0.0 * mu, mu])
        c = VirtualConstraints(cons.holonomic, cons.velocity, rate)
        return reaction_force(d3.DESIGN3DOF_SYSTEM, c, gains, q, qd, 0.0, None, MODEL, z=z)[0]

    A, _ = under.unactuated(q, qd, 0.0, None)
    tau0, tau1 = full(jnp.asarray(0.0)), full(jnp.asarray(1.0))
    mu = -(A @ tau0)[0] / (A @ (tau1 - tau0))[0]
    tau_c, _, mu_e, _ = jax.jit(
        lambda q, qd, z: underactuated_reaction_force(
            d3.DESIGN3DOF_SYSTEM, cons, under, gains, q, qd, 0.0, None, MODEL, z=z
        )
    )(q, qd, z)
    np.testing.assert_allclose(mu_e[0], mu, rtol=1e-10)
    np.testing.assert_allclose(tau_c, full(mu), rtol=1e-10, atol=1e-9)
    np.testing.assert_allclose(A @ tau_c, 0.0, atol=1e-9)


def test_bad_declarations_raise_before_compilation():
    with pytest.raises(ValueError, match="free"):
        Underactuation(unactuated=lambda *a: None, free=())
    with pytest.raises(ValueError, match="free"):
        Underactuation(unactuated=lambda *a: None, free=(1, 1))
    params = vcm_params(GAINS, MODEL, LINE_COEFFS, u_d=2.0, k_rudder=K_RUDDER)
    cons, under, gains = _engine_problem(params)
    q, qd = jnp.zeros(3), jnp.array([1.0, 0.0, 0.0])
    with pytest.raises(ValueError, match="out of range"):
        underactuated_reaction_force(
            d3.DESIGN3DOF_SYSTEM, cons, under, gains, q, qd, 0.0, None, MODEL, z=jnp.zeros(1)
        )
    with pytest.raises(ValueError, match="auxiliary"):
        underactuated_reaction_force(d3.DESIGN3DOF_SYSTEM, cons, under, gains, q, qd, 0.0)
