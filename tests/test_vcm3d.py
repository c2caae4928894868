"""3-D VCM law (control.vcm3d) on the REMUS 100 design model: Theorem 1 on a perfect model,
exact heading/pitch rows, unactuated (fin-tied) forces to round-off on the PVS plant, gradients
against finite differences."""

import functools

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.linalg import expm

from vcjax import paths
from vcjax.control.vcm3d import VCM3DConfig, vcm3d_gains, vcm3d_law, vcm3d_params, vcm3d_state
from vcjax.linalg import Rzyx
from vcjax.rollout import RolloutConfig, rollout
from vcjax.vehicles import remus100 as r100
from vcjax.vehicles import remus100_design as rd

P = r100.remus100_params()
DM = rd.design_model(P)
SYSTEM = rd.design_system()
# an inclined straight line: azimuth 30 deg, descending at elevation atan(-0.2) ~ -11 deg
LINE, LINE_C = paths.line(origin=(0.0, 0.0, 5.0), direction=(np.cos(0.5), np.sin(0.5), 0.2))
run = jax.jit(rollout, static_argnames=("plant", "controller", "config"))


def cfg_of(actuation="full", integral=False, guidance="los", path=LINE):
    return VCM3DConfig(
        path=path,
        system=SYSTEM,
        kinematics=rd.kinematics5,
        tied_rows=rd.unactuated_rows,
        actuation=actuation,
        integral=integral,
        guidance=guidance,
    )


@functools.cache
def design_loop(cfg):
    """Perfect model: the plant is the design model in body coordinates."""

    def plant(t, x, tau_b, dm):
        q, nu = x
        nu_dot = jnp.linalg.solve(rd.mass_matrix5(dm), tau_b - rd.body_bias5(dm, q, nu))
        return (rd.kinematics5(q) @ nu, nu_dot)

    def controller(t, x, z, params):
        q, nu = x
        return vcm3d_law(cfg, params, t, q, rd.kinematics5(q) @ nu, z)

    return plant, controller


def _simulate(cfg, gains, x0, T, dt, z0=None):
    plant, controller = design_loop(cfg)
    params = vcm3d_params(gains, DM, LINE_C, u_d=1.5)
    conf = RolloutConfig(num_steps=int(round(T / dt)))
    return run(plant, controller, conf, DM, params, x0, z0 or vcm3d_state(), dt)


def test_theorem1_consistent_rows_decay_exactly():
    """On the path, aligned with it, speed off by delta: with p_G,s = sigma and p_Phi,u = p_Phi,s
    the rows are consistent, and all 8 obey Phi(t) = exp(-P_Phi t) Phi(0)."""
    gains = vcm3d_gains(
        P_G=(1.0, 1.0, 0.3, 0.3, 0.3), P_Phi=(0.6, 0.5, 0.5, 2.0, 2.0, 0.6, 0.5, 0.5), sigma=0.3
    )
    f = paths.path_frame(LINE, LINE_C, 4.0)
    s0 = 0.7
    p0 = f.p + s0 * f.dp_dw / jnp.linalg.norm(f.dp_dw)
    q0 = jnp.concatenate([p0, jnp.stack([f.theta_p, f.psi_p])])
    nu0 = jnp.array([1.5 + 0.4, 0.0, 0.0, 0.0, 0.0])
    traj = _simulate(cfg_of(), gains, (q0, nu0), T=6.0, dt=0.01, z0=vcm3d_state(varpi0=4.0))
    t = np.asarray(traj.t[:-1])
    Phi = np.asarray(traj.aux.Phi)
    expected = Phi[0] * np.exp(-np.outer(t, np.asarray(gains.P_Phi)))
    assert abs(Phi[0, 0]) > 0.3 and abs(Phi[0, 5]) > 0.3
    assert np.max(np.abs(Phi - expected)) < 1e-8
    assert np.max(np.asarray(traj.aux.ls_residual)) < 1e-8


def test_errors_angles_and_state_rates_by_hand():
    """One evaluation off the path: the errors (23), the approach angles (24) or their ILOS
    form (40), the particle rate (22), the ILOS and the integral states' rates (anti-windup
    beyond int_limit), each against the formula written out here with its own rotation
    matrices; Delta and sigma_i differ per channel, so a swapped index fails. (The LOS angles
    (24) are the ILOS ones at sigma_i = 0: the closed-loop tests above and the REMUS channel
    tests run them.)"""
    gains = vcm3d_gains(Delta=(6.0, 11.0), sigma=0.35, sigma_i=(0.4, 0.7), k_int=(0.02, 0.03, 0.05))
    params = vcm3d_params(gains, DM, LINE_C, u_d=1.5, int_limit=2.0)
    psi_p, theta_p = 0.5, -np.arctan(0.2)  # LINE: azimuth 0.5 rad, 0.2 m deeper per m
    c, s = np.cos(psi_p), np.sin(psi_p)
    Rz = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    c, s = np.cos(theta_p), np.sin(theta_p)
    Ry = np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])
    d = np.array([np.cos(0.5), np.sin(0.5), 0.2]) / np.linalg.norm([np.cos(0.5), np.sin(0.5), 0.2])
    varpi, eps = 3.0, np.array([0.4, -1.3, 0.8])
    p = np.array([0.0, 0.0, 5.0]) + varpi * d + Rz @ Ry @ eps
    q = jnp.asarray(np.concatenate([p, [0.1, 0.6]]))
    qd = jnp.array([1.2, 0.4, -0.1, 0.02, -0.03])
    zeta, e_int, h_int = np.array([0.5, -3.0, 1.0]), -2.0, 1.5
    z = vcm3d_state(varpi0=varpi, zeta0=zeta, e_int0=e_int, h_int0=h_int)
    law = jax.jit(vcm3d_law, static_argnums=0)
    _, z_dot, aux = law(cfg_of("full", True, "ilos"), params, 0.0, q, qd, z)
    np.testing.assert_allclose(aux.eps, eps, atol=1e-12)
    E, H = eps[1] + 0.4 * e_int, eps[2] + 0.7 * h_int
    np.testing.assert_allclose(aux.psi_d, psi_p + np.arctan(-E / 6.0), atol=1e-12)
    np.testing.assert_allclose(aux.theta_d, theta_p + np.arctan(H / 11.0), atol=1e-12)
    np.testing.assert_allclose(aux.psi_tilde, 0.6 - float(aux.psi_d), atol=1e-12)
    np.testing.assert_allclose(aux.theta_tilde, 0.1 - float(aux.theta_d), atol=1e-12)
    np.testing.assert_allclose(z_dot.e_int, 6.0 * eps[1] / (E**2 + 36.0), rtol=1e-12)
    np.testing.assert_allclose(z_dot.h_int, 11.0 * eps[2] / (H**2 + 121.0), rtol=1e-12)
    # the particle runs at u_d + sigma s along the (unit-speed) line
    np.testing.assert_allclose(z_dot.varpi, 1.5 + 0.35 * eps[0], rtol=1e-12)
    # zeta' = eps, less the excess beyond int_limit = 2 (zeta[1] = -3 is 1 beyond)
    np.testing.assert_allclose(z_dot.zeta, eps - np.array([0.0, -1.0, 0.0]), atol=1e-12)
    assert float(z_dot.v_d) == 0.0 and float(z_dot.w_d) == 0.0  # full actuation
    # the position rows of Phi = G' + P_G G with the integral: G = eps + k_I zeta, and on the
    # line eps' = R_p^T (p' - d varpi')
    eps_dot = (Rz @ Ry).T @ (np.asarray(qd[:3]) - d * (1.5 + 0.35 * eps[0]))
    k_int, zeta_dot = np.array([0.02, 0.03, 0.05]), np.asarray(z_dot.zeta)
    G_pos = eps + k_int * zeta
    np.testing.assert_allclose(aux.Phi[5:], eps_dot + k_int * zeta_dot + 0.3 * G_pos, atol=1e-12)
    # the commanded body acceleration J^-1 (q'' - J' nu) is what the design model's body
    # equations give for tau (full actuation, a perfect model)
    nu = jnp.linalg.solve(rd.kinematics5(q), qd)
    nu_dot = jnp.linalg.solve(rd.mass_matrix5(DM), aux.tau - rd.body_bias5(DM, q, nu))
    np.testing.assert_allclose(aux.nu_dot_cmd, nu_dot, rtol=1e-9, atol=1e-12)


def test_defaults_are_the_documented_ones():
    """The API reference shows these defaults (typed in here from it)."""
    g = vcm3d_gains()
    expected = {
        "P_G": [1.0, 1.0, 0.3, 0.3, 0.3],
        "P_Phi": [0.5, 0.5, 0.5, 2.0, 2.0, 0.5, 0.5, 0.5],
        "Delta": [8.0, 8.0],
        "sigma": 0.3,
        "k_int": [0.05, 0.05, 0.05],
        "sigma_i": [0.5, 0.5],
    }
    for name, value in expected.items():
        np.testing.assert_array_equal(getattr(g, name), value, err_msg=name)
    p = vcm3d_params(g, DM, LINE_C)
    assert float(p.u_d) == 1.5 and float(p.int_limit) == 50.0


def _axis(p_K, p_G, p_Phi):
    """``[y, y']`` of one cross axis: the rows ``v' = -p_K v`` and ``y'' + (p_G + p_Phi) y' +
    p_Phi p_G y = 0`` share one acceleration (``v = y'``); least squares takes their mean."""
    return np.array([[0.0, 1.0], [-0.5 * p_Phi * p_G, -0.5 * (p_K + p_G + p_Phi)]])


def _along(p_K, p_G, p_Phi, sigma):
    """``[u - u_d, s]``: ``s' = (u - u_d) - sigma s`` (the particle runs at ``u_d + sigma s``),
    ``s'' = u' - sigma s'``; the rows ``u' = -p_K (u - u_d)`` and ``s'' + (p_G + p_Phi) s' +
    p_Phi p_G s = 0`` share ``u'``; least squares takes their mean."""
    k = sigma - p_G - p_Phi  # u' from the s row: k s' - p_Phi p_G s
    return np.array([[0.5 * (k - p_K), -0.5 * (k * sigma + p_Phi * p_G)], [1.0, -sigma]])


@pytest.mark.parametrize("channel", ["along", "cross", "vertical"])
def test_linear_rows_least_squares_per_channel(channel):
    """Full actuation, aligned with the inclined line, one channel excited (speed error,
    sideways or depth offset). With the attitude held at the path's (look-ahead 1e8 m), the
    path frame is the body frame and the six linear rows split into three pairs, one per axis,
    each pair sharing that axis's acceleration: rows [u, s], [v, e], [w, h] are inconsistent
    and the least-squares solve (17) gives each axis the mean of its two rows' demands. That
    linear system (derived here by hand) predicts every channel; gains differ between every
    two channels, so a swapped gain, row or axis fails."""
    P_G = np.array([1.0, 1.4, 0.45, 0.25, 0.35])
    P_Phi = np.array([0.5, 0.45, 0.55, 2.0, 1.6, 0.7, 0.4, 0.6])
    sigma = 0.3
    gains = vcm3d_gains(P_G=P_G, P_Phi=P_Phi, Delta=(1e8, 1e8), sigma=sigma)
    f = paths.path_frame(LINE, LINE_C, 4.0)
    R_p = np.asarray(Rzyx(0.0, f.theta_p, f.psi_p))  # columns: along, cross, down of the path
    offset, du = {"along": ((0.0, 0.0, 0.0), 0.4), "cross": ((0.0, 0.8, 0.0), 0.0)}.get(
        channel, ((0.0, 0.0, 0.6), 0.0)
    )
    q0 = jnp.concatenate([f.p + R_p @ np.asarray(offset), jnp.stack([f.theta_p, f.psi_p])])
    nu0 = jnp.array([1.5 + du, 0.0, 0.0, 0.0, 0.0])
    traj = _simulate(cfg_of(), gains, (q0, nu0), T=6.0, dt=0.01, z0=vcm3d_state(varpi0=4.0))
    t = np.asarray(traj.t[:-1])
    eps = np.asarray(traj.aux.eps)
    nu = np.asarray(traj.x[1][:-1])
    assert float(traj.aux.ls_residual[0]) > 0.05  # the rows are inconsistent from the start

    def predict(A, x0):  # x(t_k) = expm(A dt)^k x0 (the samples are evenly spaced)
        step, x = expm(A * (t[1] - t[0])), [np.asarray(x0, dtype=float)]
        for _ in t[1:]:
            x.append(step @ x[-1])
        return np.stack(x)

    along = predict(_along(P_Phi[0], P_G[2], P_Phi[5], sigma), [du, offset[0]])
    cross = predict(_axis(P_Phi[1], P_G[3], P_Phi[6]), [offset[1], 0.0])
    vert = predict(_axis(P_Phi[2], P_G[4], P_Phi[7]), [offset[2], 0.0])
    tol = 1e-6  # measured: 2e-8 (the attitude's 1e-8 rad response to the offset)
    np.testing.assert_allclose(nu[:, 0] - 1.5, along[:, 0], atol=tol)
    np.testing.assert_allclose(eps[:, 0], along[:, 1], atol=tol)
    np.testing.assert_allclose(eps[:, 1], cross[:, 0], atol=tol)
    np.testing.assert_allclose(nu[:, 1], cross[:, 1], atol=tol)
    np.testing.assert_allclose(eps[:, 2], vert[:, 0], atol=tol)
    np.testing.assert_allclose(nu[:, 2], vert[:, 1], atol=tol)
    # the excited channel moved (by more than 10 % of its start) and is being driven back
    x = {"along": eps[:, 0], "cross": eps[:, 1], "vertical": eps[:, 2]}[channel]
    assert np.max(np.abs(x)) > 0.05
    assert abs(x[-1]) < 0.7 * np.max(np.abs(x))


@pytest.mark.parametrize("guidance,integral", [("los", False), ("ilos", True)])
def test_heading_and_pitch_rows_decay_exactly_from_any_state(guidance, integral):
    """Off the path, mis-aligned, inconsistent linear rows: the heading and pitch rows still
    decay as exp(-p_Phi t) (their accelerations appear in no other row), and psi~ obeys the
    two-pole law (37). Gains with no two entries equal (heading vs pitch, v vs w, e vs h), so a
    row or index swap between them fails this test."""
    gains = vcm3d_gains(
        P_G=(1.0, 1.4, 0.3, 0.25, 0.35), P_Phi=(0.5, 0.45, 0.55, 2.0, 1.6, 0.5, 0.4, 0.6)
    )
    q0 = jnp.array([3.0, -4.0, 1.0, 0.2, 1.2])
    nu0 = jnp.array([1.2, 0.1, -0.05, 0.02, -0.05])
    traj = _simulate(cfg_of("full", integral, guidance), gains, (q0, nu0), T=8.0, dt=0.01)
    t = np.asarray(traj.t[:-1])
    Phi = np.asarray(traj.aux.Phi)
    pPhi = np.asarray(gains.P_Phi)
    for i in (3, 4):
        assert abs(Phi[0, i]) > 0.05
        np.testing.assert_allclose(Phi[:, i], Phi[0, i] * np.exp(-pPhi[i] * t), atol=1e-8)
    assert float(traj.aux.ls_residual[0]) > 0.1  # the linear rows are inconsistent at first
    psit = np.asarray(traj.aux.psi_tilde)
    c = Phi[0, 3]
    a, b = float(gains.P_G[0]), pPhi[3]
    exact = psit[0] * np.exp(-a * t) + c * (np.exp(-b * t) - np.exp(-a * t)) / (a - b)
    np.testing.assert_allclose(psit, exact, atol=1e-7)
    # and the vehicle converges to the path
    assert float(traj.aux.dist[-1]) < 0.3 * float(traj.aux.dist[0])
    if guidance == "los":  # the paper angles: the ILOS states stay as they were (zero)
        assert not np.any(np.asarray(traj.z.e_int)) and not np.any(np.asarray(traj.z.h_int))
