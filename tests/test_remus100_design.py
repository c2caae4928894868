"""REMUS 100 design model and actuator map: the design model is the plant's 5 rows at phi = p = 0
and zero current; the actuator map inverts the plant's fin and propeller models; limits."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from vcjax.vehicles import remus100 as r100
from vcjax.vehicles import remus100_design as rd

P = r100.remus100_params()
IDX = np.asarray(rd.IDX5)


def test_design_model_is_the_plants_five_rows():
    """M[IDX5, :] nu_dot + n5 = (tau_ctrl + crossflow)[IDX5] on the 6-DOF plant (phi = p = 0,
    no current): the design model is the plant without roll and cross-flow drag."""
    nu5 = jnp.array([1.4, 0.12, -0.08, 0.05, -0.11])
    q5 = jnp.array([3.0, -2.0, 12.0, 0.15, 0.7])
    eta, nu = rd.to_six(q5, nu5)
    dm = rd.design_model(P, U_design=float(jnp.linalg.norm(nu[:3])))
    act = jnp.array([0.1, -0.05, 1100.0])
    x = r100.remus100_state(eta, nu, act)
    args = r100.remus100_args(P)
    nu_dot = r100.remus100_plant(0.0, x, act, args).nu
    tau = r100.control_forces(P, nu, nu, act) + r100.crossflow_drag(P, nu)
    lhs = r100.mass_matrix(P)[IDX] @ nu_dot + rd.body_bias5(dm, q5, nu5)
    np.testing.assert_allclose(lhs, tau[IDX], rtol=1e-10, atol=1e-10)
    # the mechanics form: M(q) qdd + n(q, qd) = J^-T tau_b with qdd = d/dt (J nu)
    sys = rd.design_system()
    J = rd.kinematics5(q5)
    qd = J @ nu5
    nu5_dot = jnp.linalg.solve(rd.mass_matrix5(dm), tau[IDX] - rd.body_bias5(dm, q5, nu5))
    J_dot = jax.jvp(rd.kinematics5, (q5,), (qd,))[1]
    qdd = J @ nu5_dot + J_dot @ nu5
    gen = sys.mass_matrix(q5, dm) @ qdd + sys.bias_force(q5, qd, dm)
    np.testing.assert_allclose(gen, jnp.linalg.solve(J.T, tau[IDX]), rtol=1e-9, atol=1e-9)


def test_kinematics5_is_fossen_J_at_zero_roll():
    q5 = jnp.array([0.0, 0.0, 0.0, 0.3, -1.1])
    nu5 = jnp.array([1.0, 0.2, 0.1, 0.05, 0.2])
    eta, nu = rd.to_six(q5, nu5)
    from vcjax.vehicles.sixdof import kinematics

    np.testing.assert_allclose(rd.kinematics5(q5) @ nu5, (kinematics(eta) @ nu)[IDX], atol=1e-14)


@pytest.mark.parametrize("act", [(0.1, -0.2, 1200.0), (-0.25, 0.05, 400.0), (0.0, 0.0, 1500.0)])
def test_actuator_map_inverts_the_plants_forces(act):
    """Round trip: act -> plant control forces -> actuator_map -> act (no current, U > U_min)."""
    act = jnp.array(act)
    nu = jnp.array([1.5, 0.1, -0.05, 0.0, 0.02, 0.03])
    dm = rd.design_model(P)
    tau5 = r100.control_forces(P, nu, nu, act)[IDX]
    out = rd.actuator_map(dm, tau5, nu)
    np.testing.assert_allclose(out.cmd, act, rtol=1e-10, atol=1e-10)
    np.testing.assert_allclose(out.raw, act, rtol=1e-10, atol=1e-10)
    # fin forces come with their moments: the tied rows vanish for any fin force
    np.testing.assert_allclose(rd.unactuated_rows(dm) @ tau5, 0.0, atol=1e-12)


def test_actuator_map_limits_and_floor():
    dm = rd.design_model(P)
    nu = jnp.array([1.5, 0.0, 0.0, 0.0, 0.0, 0.0])
    big = jnp.array([1e4, 0.0, 0.0, -1e3, 1e3])
    out = rd.actuator_map(dm, big, nu)
    np.testing.assert_allclose(np.abs(out.cmd), P.act_max)
    assert np.all(np.abs(out.raw) > P.act_max)
    # strong braking: the propeller stays on its forward branch (never reverses)
    brake = rd.actuator_map(dm, jnp.array([-1e3, 0.0, 0.0, 0.0, 0.0]), nu)
    assert float(brake.cmd[2]) > 0.0
    # at rest the fin gain is floored: finite commands and finite gradients
    rest = jnp.zeros(6)
    out0 = rd.actuator_map(dm, jnp.array([1.0, 0.0, 0.0, 0.1, 0.1]), rest)
    assert np.all(np.isfinite(out0.raw))
    g = jax.grad(lambda t: jnp.sum(rd.actuator_map(dm, t, rest).cmd))(jnp.ones(5))
    assert np.all(np.isfinite(g))


def test_design_model_validation():
    with pytest.raises(ValueError, match="U_design"):
        rd.design_model(P, U_design=0.0)
    with pytest.raises(ValueError, match="vehicle"):
        rd.design_model(object())


def test_horizontal_design_matches_slopes_but_carries_a_munk_moment_the_model_lacks():
    """(20)'s C_b has the Munk yaw moment (m22 - m11) u v; the design model (PVS) has none, and
    d32 cancels it at u = U_design only. The residue is exactly (m22 - m11)(u - U) v: what made
    the decoupled baseline's heading row wrong when crabbing (so it uses body_bias5's rows)."""
    from vcjax.vehicles import design3dof as d3

    dm = rd.design_model(r100.remus100_params(), U_design=1.5)
    h = rd.horizontal_design(dm)
    for u, v, r in [(1.5, 0.0, 0.02), (1.5, 0.3, 0.0), (1.37, 0.2, 0.0), (1.6, -0.3, 0.01)]:
        n3 = np.asarray(d3.body_bias(h, jnp.asarray([u, v, r])))
        n5 = np.asarray(rd.body_bias5(dm, jnp.zeros(5), jnp.asarray([u, v, 0.0, 0.0, r])))
        munk = (float(h.m22) - float(h.m11)) * (u - 1.5) * v
        np.testing.assert_allclose(n3[2] - n5[4], munk, atol=1e-9)
    # crabbing into 0.3 m/s with u 0.1 m/s off the design speed: over half the rudder's moment
    k_r, _ = rd.fin_gains(dm, jnp.asarray([1.5, 0.0, 0.0, 0.0, 0.0, 0.0]))
    N_max = float(k_r * abs(P.x_r) * P.act_max[0])  # ~1.2 N m
    assert (float(h.m22) - float(h.m11)) * 0.1 * 0.3 > 0.5 * N_max
