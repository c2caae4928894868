"""Edge cases of :mod:`vcjax.control.baselines3d` that the mutation run (``tools/mutation.py
control``) found untested: the ALOS3D/LOS autopilot law and the decoupled law, each evaluated
once (eagerly) on a path curved in both planes, against the module docstring's formulas written
out in NumPy; the projection's edges; defaults and validation. Milliseconds each."""

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from _craft import CRAFT, K_RUDDER

from vcjax import paths
from vcjax.control.baselines3d import (
    AutopilotConfig,
    AutopilotState,
    DecoupledConfig,
    DecoupledState,
    autopilot_gains,
    autopilot_law,
    autopilot_state,
    baseline3d_params,
    decoupled_law,
    decoupled_state,
)
from vcjax.control.vcm import VCMConfig, pm_gains, vcm_law, vcm_params, vcm_state
from vcjax.control.vcm3d import VCM3DConfig, vcm3d_state


def _curve(w):
    """Curved in azimuth and elevation (every path rate of the laws nonzero), speed_bar != 1."""
    return jnp.stack([3.0 * w + 0.1 * w**2, 2.0 * w - 0.05 * w**2, 0.4 * w + 0.03 * w**2])


PATH, COEFFS = paths.custom(_curve, w_range=(-10.0, 10.0))
W0 = 1.2  # the particle
INERTIA = (30.0, 9.0, 7.5)  # [m11, m55, m66], distinct
GAINS = dict(w_psi=1.3, zeta_psi=0.8, w_theta=1.7, zeta_theta=0.6, k_u=0.45, k_ui=0.03)
GAINS |= dict(Delta=(8.0, 12.0), gamma=(0.004, 0.006), M_theta=0.35, sigma=0.3)
Q = jnp.array([4.4, 4.1, 0.4, 0.15, 0.9])  # [x, y, z, theta, psi]: s, e, h all distinct
QD = jnp.array([1.1, 0.6, -0.2, 0.07, -0.04])
NU5 = jnp.array([1.3, 0.12, -0.08, 0.07, -0.04])  # u != u_d


def _params(**kw):
    g = autopilot_gains(**GAINS)
    return baseline3d_params(g, INERTIA, 10.0, COEFFS, u_d=1.5, **kw)


def _frame(w=W0):
    f = paths.path_frame(PATH, COEFFS, w)
    cp, sp, ct, st = (float(x) for x in (jnp.cos(f.psi_p), jnp.sin(f.psi_p),
                                         jnp.cos(f.theta_p), jnp.sin(f.theta_p)))  # fmt: skip
    R_p = np.array([[cp, -sp, 0.0], [sp, cp, 0.0], [0.0, 0.0, 1.0]]) @ np.array(
        [[ct, 0.0, st], [0.0, 1.0, 0.0], [-st, 0.0, ct]]
    )  # Rz(psi_p) Ry(theta_p)
    return f, R_p


def _pid(inertia, w, zeta, err, rate_err, integ):
    return -inertia * (w**2 * err + 2 * zeta * w * rate_err + w**3 / 10 * integ)


def _state(beta, alpha):
    return AutopilotState(*(jnp.asarray(x) for x in (W0, beta, alpha, 0.2, -0.3, 0.4)))


def test_autopilot_law_is_the_documented_alos3d_with_pid_autopilots():
    f, R_p = _frame()
    tau, z_dot, aux = autopilot_law(
        AutopilotConfig(PATH), _params(), 0.0, Q, QD, NU5, _state(0.1, -0.05)
    )
    s, e, h = R_p.T @ (np.asarray(Q[:3]) - np.asarray(f.p))
    assert min(abs(s), abs(e), abs(h), abs(abs(e) - abs(h))) > 0.3
    assert min(abs(float(f.dpsi_dw)), abs(float(f.dtheta_dw)), abs(float(f.speed_bar) - 1)) > 0.01
    np.testing.assert_allclose(aux.eps, [s, e, h], rtol=1e-12)
    w_dot = (1.5 + 0.3 * s) * np.cos(float(f.theta_p)) / float(f.speed_bar)
    beta_dot = 0.004 * 8.0 / np.sqrt(64.0 + e * e) * e
    alpha_dot = 0.006 * 12.0 / np.sqrt(144.0 + h * h) * h
    psi_d = float(f.psi_p) - 0.1 - np.arctan(e / 8.0)
    theta_d = float(f.theta_p) - 0.05 + np.arctan(h / 12.0)
    _, e_dot, h_dot = R_p.T @ (np.asarray(QD[:3]) - np.asarray(f.dp_dw) * w_dot)
    psi_d_dot = float(f.dpsi_dw) * w_dot - beta_dot - 8.0 * e_dot / (64.0 + e * e)
    theta_d_dot = float(f.dtheta_dw) * w_dot + alpha_dot + 12.0 * h_dot / (144.0 + h * h)
    psi_t, theta_t = float(Q[4]) - psi_d, float(Q[3]) - theta_d
    N = _pid(7.5, 1.3, 0.8, psi_t, float(QD[4]) - psi_d_dot, 0.2)
    M = _pid(9.0, 1.7, 0.6, theta_t, float(QD[3]) - theta_d_dot, -0.3)
    X = 10.0 - 30.0 * (0.45 * (1.3 - 1.5) + 0.03 * 0.4)
    np.testing.assert_allclose(aux.psi_d, psi_d, rtol=1e-12)
    np.testing.assert_allclose(aux.theta_d, theta_d, rtol=1e-12)
    np.testing.assert_allclose(z_dot, [w_dot, beta_dot, alpha_dot, psi_t, theta_t, -0.2], 1e-11)
    np.testing.assert_allclose(tau, [X, 0.0, 0.0, M, N], rtol=1e-11)
    np.testing.assert_array_equal(aux.tau, tau)
    # plain LOS: the same autopilots, no estimates (the state's are ignored)
    tau_los, z_dot, aux = autopilot_law(
        AutopilotConfig(PATH, "los"), _params(), 0.0, Q, QD, NU5, _state(0.1, -0.05)
    )
    np.testing.assert_allclose(aux.psi_d, psi_d + 0.1, rtol=1e-12)
    np.testing.assert_allclose(aux.theta_d, theta_d + 0.05, rtol=1e-12)
    assert float(z_dot.beta_hat) == 0.0 == float(z_dot.alpha_hat)
    psi_d_dot += beta_dot
    np.testing.assert_allclose(
        tau_los[4], _pid(7.5, 1.3, 0.8, psi_t - 0.1, float(QD[4]) - psi_d_dot, 0.2), rtol=1e-11
    )


def test_alos_projection_at_and_beyond_the_bound():
    # Proj(est, err) = 0 while |est| > M_theta and est err > 0 (pushing outwards), else err
    f, R_p = _frame()
    _, e, h = R_p.T @ (np.asarray(Q[:3]) - np.asarray(f.p))
    assert e > 0.5 and -0.5 < h < 0.0
    beta_rate = 0.004 * 8.0 / np.sqrt(64.0 + e * e) * e
    alpha_rate = 0.006 * 12.0 / np.sqrt(144.0 + h * h) * h
    cfg = AutopilotConfig(PATH)
    for beta, alpha, rates in [
        (0.35, 0.5, (beta_rate, alpha_rate)),  # at the bound; beyond it but pushed inwards
        (-0.5, -0.5, (beta_rate, 0.0)),  # beyond, inwards; beyond, outwards (stopped)
    ]:
        _, z_dot, _ = autopilot_law(cfg, _params(), 0.0, Q, QD, NU5, _state(beta, alpha))
        np.testing.assert_allclose([z_dot.beta_hat, z_dot.alpha_hat], rates, rtol=1e-12)


def test_alos_adaptation_on_the_path_has_the_error_gradient_beyond_the_bound():
    # on the path (eps = 0 exactly) an estimate beyond the bound is not pushed outwards, so the
    # rate keeps its slope gamma R_p^T in p (and reverse mode through Proj is NaN-free)
    f, R_p = _frame()
    q = jnp.concatenate([f.p, jnp.array([0.1, 0.5])])
    cfg = AutopilotConfig(PATH)

    def rates(q):
        _, z_dot, _ = autopilot_law(cfg, _params(), 0.0, q, QD, NU5, _state(0.5, -0.5))
        return jnp.stack([z_dot.beta_hat, z_dot.alpha_hat])

    jac = jax.jacrev(rates)(q)
    np.testing.assert_allclose(jac[:, :3], [0.004 * R_p[:, 1], 0.006 * R_p[:, 2]], atol=1e-15)
    np.testing.assert_array_equal(jac[:, 3:], 0.0)


def test_autopilot_defaults_validation_and_static_config():
    g = autopilot_gains()
    expected = [1.2, 1.0, 1.5, 1.0, 0.5, 0.02, (8.0, 8.0), (0.004, 0.004), 0.35, 0.3]
    for value, want in zip(g, expected, strict=True):
        np.testing.assert_array_equal(value, want)
    autopilot_gains(k_ui=0.0, gamma=(0.0, 0.0))  # may be zero
    for name in ("w_psi", "zeta_psi", "w_theta", "k_u"):
        with pytest.raises(ValueError, match=name):
            autopilot_gains(**{name: 0.0})
    assert float(baseline3d_params(g, INERTIA, 10.0, COEFFS).u_d) == 1.5
    assert all(float(x) == 0.0 for x in autopilot_state())
    cfg = AutopilotConfig(PATH)
    horizontal = VCMConfig(path=PATH)
    for static in (cfg, DecoupledConfig(horizontal)):  # static arguments: frozen, hashable
        assert hash(static) == hash(dataclasses.replace(static))
        with pytest.raises(dataclasses.FrozenInstanceError):
            static.path = None


# --- the decoupled law: horizontal VCM on [x, y, psi] + depth through pitch ---

_HP = vcm_params(pm_gains(), CRAFT, COEFFS, u_d=1.5, k_rudder=K_RUDDER)
_ZH = vcm_state(varpi0=W0, v_d0=0.05)
_Z = DecoupledState(_ZH, jnp.asarray(0.6), jnp.asarray(-0.3))


def _bias(design, q, nu5):
    """A stand-in full-model bias: distinct in every row and depending on q and nu5."""
    return design * (jnp.arange(1.0, 6.0) + q + 2.0 * nu5)


@pytest.mark.parametrize("with_bias", [False, True])
def test_decoupled_law_is_vcm_plus_the_ilos_depth_loop(with_bias):
    # theta_d = theta_p + atan(H / Dv), H = h + sigma_v h_int, h_int' = Dv h / (H^2 + Dv^2),
    # theta_d' = theta_p' w' + Dv H' / (Dv^2 + H^2), M the pitch PID; tau5 = [X, Y, 0, M, N]
    design = 0.7 if with_bias else None
    params = _params(horizontal=_HP, design=design)
    hcfg = VCMConfig(path=PATH)
    cfg = DecoupledConfig(hcfg, _bias if with_bias else None)
    tau, z_dot, aux = decoupled_law(cfg, params, 0.0, Q, QD, NU5, _Z)
    n_b = None
    if with_bias:
        n_b = _bias(0.7, Q, NU5)[jnp.array([0, 1, 4])]
    eta3, nu3 = Q[jnp.array([0, 1, 4])], NU5[jnp.array([0, 1, 4])]
    tau3, zh_dot, haux = vcm_law(hcfg, _HP, 0.0, eta3, nu3, _ZH, n_b=n_b)
    f, R_p = _frame()
    s, e, h = R_p.T @ (np.asarray(Q[:3]) - np.asarray(f.p))
    w_dot = float(zh_dot.varpi)
    H = h + 0.006 * 0.6
    h_int_dot = 12.0 * h / (H * H + 144.0)
    theta_d = float(f.theta_p) + np.arctan(H / 12.0)
    h_dot = (R_p.T @ (np.asarray(QD[:3]) - np.asarray(f.dp_dw) * w_dot))[2]
    H_dot = h_dot + 0.006 * h_int_dot
    theta_d_dot = float(f.dtheta_dw) * w_dot + 12.0 * H_dot / (144.0 + H * H)
    theta_t = float(Q[3]) - theta_d
    M = _pid(9.0, 1.7, 0.6, theta_t, float(QD[3]) - theta_d_dot, -0.3)
    np.testing.assert_allclose(aux.eps, [s, e, h], rtol=1e-12)
    np.testing.assert_allclose(aux.theta_d, theta_d, rtol=1e-12)
    np.testing.assert_allclose(aux.psi_d, haux.psi_d, rtol=1e-14)
    np.testing.assert_allclose(tau, [tau3[0], tau3[1], 0.0, M, tau3[2]], rtol=1e-11)
    np.testing.assert_allclose([z_dot.h_int, z_dot.int_theta], [h_int_dot, theta_t], rtol=1e-12)
    for a, b in zip(z_dot.horizontal, zh_dot, strict=True):
        np.testing.assert_allclose(a, b, rtol=1e-14)
    assert abs(float(tau3[0] - tau3[1])) > 1.0 and abs(float(tau3[2] - tau3[1])) > 1.0
    if with_bias:
        no_bias, _, _ = decoupled_law(DecoupledConfig(hcfg), params, 0.0, Q, QD, NU5, _Z)
        assert abs(float(no_bias[0] - tau[0])) > 1.0  # the bias is used
        with pytest.raises(ValueError, match="design"):
            decoupled_law(cfg, _params(horizontal=_HP), 0.0, Q, QD, NU5, _Z)
    assert all(float(x) == 0.0 for x in decoupled_state(_ZH)[1:])


# --- vcm3d.py: the state's defaults and validation, the static config's defaults ---


def test_vcm3d_state_defaults_and_validation():
    z = vcm3d_state()
    assert all(np.all(np.asarray(x) == 0.0) for x in z) and np.shape(z.zeta) == (3,)
    for name in ("varpi0", "v_d0", "w_d0", "e_int0", "h_int0"):
        with pytest.raises(ValueError, match=name):
            vcm3d_state(**{name: (0.0, 0.0)})
    with pytest.raises(ValueError, match="zeta0"):
        vcm3d_state(zeta0=(0.0, 0.0))
    cfg = VCM3DConfig(path=PATH, system=None, kinematics=None, tied_rows=None)
    assert (cfg.actuation, cfg.integral, cfg.guidance) == ("underactuated", False, "los")
    assert cfg.kinematics_inverse is None
