"""VCM path-maneuvering law (docs/method.md): (32) structure, generic-engine cross-check, (37),
exponential convergence, underactuation (38), integral action (41)."""

import functools

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
from vcjax.mechanics import VCMGains, VirtualConstraints, reaction_force
from vcjax.rollout import RolloutConfig, rollout
from vcjax.vehicles import design3dof as d3

LINE_PATH, LINE_COEFFS = paths.paper_line()  # p_p(w) = [10, w, 0] (Simulation 1)
GAINS = pm_gains()  # docs/method.md order-one gains
Q0 = jnp.array([0.0, 0.0, np.pi / 2])
NU0 = jnp.array([2.0, 0.0, 0.0])

run = jax.jit(rollout, static_argnames=("plant", "controller", "config"))


@functools.cache
def make_loop(cfg):
    """Perfect-model closed loop: the plant is the design model itself."""

    def plant(t, x, tau, args):
        eta, nu = x
        V_c = args
        return d3.vector_field(
            MODEL, eta, nu, tau, WaterMotion(jnp.append(jnp.asarray(V_c), 0.0), None)
        )

    def controller(t, x, z, params):
        eta, nu = x
        return vcm_law(cfg, params, t, eta, nu, z)

    return plant, controller


def simulate(cfg, T, dt=0.02, k_rudder=0.0, V_c=(0.0, 0.0), gains=GAINS, x0=(Q0, NU0)):
    plant, controller = make_loop(cfg)
    params = vcm_params(gains, MODEL, LINE_COEFFS, u_d=2.0, k_rudder=k_rudder)
    conf = RolloutConfig(num_steps=int(round(T / dt)))
    return run(plant, controller, conf, jnp.asarray(V_c), params, x0, vcm_state(), dt), params


def _two_pole(t, x0, xdot0, a, b):
    """Solution of x'' + (a + b) x' + a b x = 0 written as (x' + a x) = c e^{-b t}."""
    c0 = xdot0 + a * x0
    return x0 * np.exp(-a * t) + c0 * (np.exp(-b * t) - np.exp(-a * t)) / (a - b)


def test_pseudo_inverse_structure_32():
    """W_b^+ = [[I/2, 0, R(gamma)^T/2], [0, 1, 0]]: the transpose of what (32) prints."""
    for gamma in (0.0, 0.4, -2.2):
        R = np.asarray(rot2(gamma))
        W_b = np.zeros((5, 3))
        W_b[:2, :2] = np.eye(2)
        W_b[2, 2] = 1.0
        W_b[3:, :2] = R
        expected = np.zeros((3, 5))
        expected[:2, :2] = 0.5 * np.eye(2)
        expected[:2, 3:] = 0.5 * R.T
        expected[2, 2] = 1.0
        np.testing.assert_allclose(np.linalg.pinv(W_b), expected, atol=1e-12)
        np.testing.assert_allclose(W_b.T @ W_b, np.diag([2.0, 2.0, 1.0]), atol=1e-12)
        if gamma != 0.0:
            assert not np.allclose(np.linalg.pinv(W_b)[:2, 3:], 0.5 * R)


#: gains with no two entries equal, so a row or index swap between two gains of the same kind
#: (p_G of s vs e, p_Phi of u vs v or s vs e) changes the law and is caught by a cross-check
ASYMMETRIC = pm_gains(P_G=(1.1, 0.4, 0.7), P_Phi=(1.3, 0.8, 2.2, 0.6, 0.35), Delta=4.0, sigma=0.6)


@pytest.mark.parametrize("gains", [GAINS, ASYMMETRIC], ids=["paper", "asymmetric"])
def test_closed_form_matches_generic_engine(gains):
    """Implied mode == generic engine fed the exact constraint set (26)-(27), rel. diff <= 1e-8."""
    cfg = VCMConfig(path=LINE_PATH, actuation="full", edd="implied")
    traj, params = simulate(cfg, T=20.0, dt=0.05, gains=gains)
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
        return nu[:2] - jnp.stack([params.u_d, jnp.zeros_like(params.u_d)])

    def rate(q, t, z, args):
        return jnp.atleast_1d((params.u_d + g.sigma * eps_of(q, z)[0]) / frame(z).speed_bar)

    cons = VirtualConstraints(holonomic=G, velocity=K, state_rate=rate)
    gains = VCMGains(P_G=g.P_G, P_Phi=g.P_Phi)

    def engine_tau(eta, nu, varpi, t):
        qd = d3.kinematics(eta[2]) @ nu
        tau_c, _, diag = reaction_force(
            d3.DESIGN3DOF_SYSTEM, cons, gains, eta, qd, t, None, MODEL, z=varpi[None]
        )
        return d3.kinematics(eta[2]).T @ tau_c, diag.residual

    eta, nu = traj.x[0][:-1], traj.x[1][:-1]
    tau_engine, residual = jax.jit(jax.vmap(engine_tau))(eta, nu, traj.z.varpi[:-1], traj.t[:-1])
    tau_law = traj.aux.tau
    scale = np.max(np.abs(tau_law), axis=0)
    assert np.max(np.abs(tau_engine - tau_law) / scale) <= 1e-8
    np.testing.assert_allclose(residual, traj.aux.ls_residual, rtol=1e-6, atol=1e-9)
    assert float(traj.aux.ls_residual[0]) > 1.0  # the rows really are inconsistent at first


@pytest.mark.parametrize("actuation", ["full", "underactuated"])
def test_heading_error_obeys_37_in_implied_mode(actuation):
    k = K_RUDDER if actuation == "underactuated" else 0.0
    cfg = VCMConfig(path=LINE_PATH, actuation=actuation, edd="implied")
    traj, params = simulate(cfg, T=15.0, dt=0.01, k_rudder=k)
    t = np.asarray(traj.t[:-1])
    psit = np.asarray(traj.aux.psi_tilde)
    pG1, pPhi3 = float(GAINS.P_G[0]), float(GAINS.P_Phi[2])
    exact = _two_pole(t, psit[0], float(traj.aux.psi_tilde_dot[0]), pG1, pPhi3)
    assert abs(psit[0]) > 1.0
    assert np.max(np.abs(psit - exact)) / abs(psit[0]) < 1e-6
    if actuation == "underactuated":  # tau_v is exactly the rudder's sway force (Remark 4)
        tau = np.asarray(traj.aux.tau)
        np.testing.assert_allclose(tau[:, 1], k * tau[:, 2], atol=1e-9 * np.abs(tau).max())
        assert np.max(np.abs(np.asarray(traj.z.v_d))) > 1e-3


def test_paper_mode_deviates_slightly_from_37():
    cfg = VCMConfig(path=LINE_PATH, actuation="full", edd="paper")
    traj, _ = simulate(cfg, T=15.0, dt=0.01)
    t = np.asarray(traj.t[:-1])
    psit = np.asarray(traj.aux.psi_tilde)
    exact = _two_pole(t, psit[0], float(traj.aux.psi_tilde_dot[0]), 1.0, 2.0)
    dev = np.max(np.abs(psit - exact)) / abs(psit[0])
    assert 1e-4 < dev < 0.02, dev  # SPEC: ~0.6 % of the initial heading error


@pytest.mark.parametrize("edd", ["paper", "implied"])
def test_full_actuation_converges_exponentially(edd):
    cfg = VCMConfig(path=LINE_PATH, actuation="full", edd=edd)
    traj, _ = simulate(cfg, T=60.0, dt=0.05)
    eps = np.linalg.norm(np.asarray(traj.aux.eps), axis=1)
    t = np.asarray(traj.t[:-1])
    assert eps[0] > 5.0
    assert eps[-1] < 1e-6
    assert abs(float(traj.aux.u_tilde[-1])) < 1e-6 and abs(float(traj.aux.psi_tilde[-1])) < 1e-6
    # exponential phase: |eps| decreases by orders of magnitude between 20 s and 40 s and 60 s
    e20, e40 = eps[np.searchsorted(t, 20.0)], eps[np.searchsorted(t, 40.0)]
    assert e40 < 1e-2 * e20 and eps[-1] < 1e-2 * e40


def test_integral_action_removes_current_induced_offset():
    """Perfect model but an unknown constant current: only (41) drives eps to zero."""
    V_c = (0.3, 0.4)
    res = {}
    for integral in (False, True):
        cfg = VCMConfig(path=LINE_PATH, actuation="full", edd="paper", integral=integral)
        traj, _ = simulate(cfg, T=100.0, dt=0.05, V_c=V_c)
        res[integral] = np.abs(np.asarray(traj.aux.eps[-200:])).max()
    assert res[False] > 1e-2
    assert res[True] < 1e-3


def test_new_gains_do_not_recompile():
    cfg = VCMConfig(path=LINE_PATH, actuation="underactuated")
    simulate(cfg, T=1.0, k_rudder=K_RUDDER)
    before = run._cache_size()
    simulate(cfg, T=1.0, k_rudder=0.1, gains=pm_gains(Delta=3.0, sigma=0.2, P_G=(2.0, 1.0, 1.0)))
    assert run._cache_size() == before


def test_gain_validation():
    with pytest.raises(ValueError, match="Delta"):
        pm_gains(Delta=0.0)
    with pytest.raises(ValueError, match="P_Phi"):
        pm_gains(P_Phi=(1.0, 1.0, 2.0, 0.5))
    with pytest.raises(ValueError, match="unstable"):
        pm_gains(P_int=(0.5, 0.5))
    with pytest.raises(ValueError, match="actuation"):
        VCMConfig(path=LINE_PATH, actuation="sway")


def test_integral_gain_bound_per_row_with_asymmetric_gains():
    """Routh-Hurwitz of (41) row by row, (p_G + p_Phi) p_G p_Phi: s row (0.4 + 0.3) 0.4 0.3 =
    0.084, e row (0.8 + 0.9) 0.8 0.9 = 1.224 (hand-computed; no two gains equal)."""
    g = dict(P_G=(1.0, 0.4, 0.8), P_Phi=(1.0, 1.0, 2.0, 0.3, 0.9))
    pm_gains(**g, P_int=(0.083, 1.223))
    for bad in [(0.085, 0.5), (0.05, 1.225)]:
        with pytest.raises(ValueError, match="P_int.*unstable"):
            pm_gains(**g, P_int=bad)


def test_ilos_guidance_keeps_37_exact_and_removes_the_cross_current_offset():
    """Extension: the ILOS approach angle inside the VCM heading row. (37) still holds exactly
    (implied mode, perfect model) for the new psi_d; under a cross current the underactuated
    craft crabs with e -> 0, where the paper's LOS angle needs e = Delta tan(crab)."""
    cfg = VCMConfig(path=LINE_PATH, actuation="underactuated", edd="implied", guidance="ilos")
    traj, _ = simulate(cfg, T=15.0, dt=0.01, k_rudder=K_RUDDER)  # perfect model: no current
    t = np.asarray(traj.t[:-1])
    psit = np.asarray(traj.aux.psi_tilde)
    exact = _two_pole(t, psit[0], float(traj.aux.psi_tilde_dot[0]), 1.0, 2.0)
    assert np.max(np.abs(psit - exact)) / abs(psit[0]) < 1e-6
    assert np.max(np.abs(np.asarray(traj.z.e_int))) > 0.1  # the integral is really in the loop

    V_c = (0.5, 0.0)  # perpendicular to the path, which points east
    tails = {}
    for guidance in ("los", "ilos"):
        cfg = VCMConfig(path=LINE_PATH, actuation="underactuated", edd="paper", guidance=guidance)
        traj, _ = simulate(cfg, T=300.0, dt=0.1, k_rudder=K_RUDDER, V_c=V_c)
        tails[guidance] = np.max(np.abs(np.asarray(traj.aux.eps[-300:, 1])))
    assert tails["los"] > 0.5
    assert tails["ilos"] < 1e-3
    with pytest.raises(ValueError, match="guidance"):
        VCMConfig(path=LINE_PATH, guidance="pure-pursuit")
    with pytest.raises(ValueError, match="sigma_i"):
        pm_gains(sigma_i=-0.1)
