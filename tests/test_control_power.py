"""Edge cases of :mod:`vcjax.control` that the mutation run (``tools/mutation.py control``)
found untested. Eager checks on single numbers (milliseconds each)."""

import dataclasses
import types

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from _craft import CRAFT, K_RUDDER

from vcjax import paths
from vcjax.control.attitude import roll_pitch_pd
from vcjax.control.baselines import (
    MAX_CRAB,
    BaselineConfig,
    baseline_gains,
    baseline_law,
    baseline_params,
    baseline_state,
)
from vcjax.control.depth import depth_pid, depth_reference
from vcjax.control.vcm import (
    VCMConfig,
    VCMLoopOptions,
    pm_gains,
    vcm_law,
    vcm_params,
    vcm_state,
)


def test_roll_pitch_pd_is_the_documented_law():
    # tau_K = -k_p phi - k_d p, tau_M = -k_p theta - k_d q, with every input distinct
    gains = jnp.array([3.0, 0.5])
    eta = jnp.array([10.0, 20.0, 30.0, 0.2, -0.3, 40.0])
    nu = jnp.array([1.0, 2.0, 3.0, 0.7, 1.1, 5.0])
    tau = roll_pitch_pd(gains, eta, nu)
    np.testing.assert_allclose(tau, [-3.0 * 0.2 - 0.5 * 0.7, 3.0 * 0.3 - 0.5 * 1.1], rtol=1e-15)


def test_ilos_integral_rate_is_equation_40():
    # e_int' = Delta e / ((e + sigma_i e_int)^2 + Delta^2), off the path with a wound-up integral
    path, coeffs = paths.paper_line()
    gains = baseline_gains(Delta=4.0, sigma_i=0.7)
    params = baseline_params(gains, CRAFT, coeffs, u_d=2.0, k_rudder=K_RUDDER)
    eta, nu = jnp.array([3.0, 1.0, 1.4]), jnp.array([1.8, 0.1, 0.05])
    z = baseline_state(varpi0=0.1, e_int0=2.5)
    _, z_dot, aux = baseline_law(BaselineConfig(path=path, kind="ilos"), params, 0.0, eta, nu, z)
    e = float(aux.eps[1])
    assert abs(e) > 0.5
    big_e = e + 0.7 * 2.5
    np.testing.assert_allclose(z_dot.e_int, 4.0 * e / (big_e**2 + 16.0), rtol=1e-13)


_PATH, _COEFFS = paths.paper_line()
_ETA, _NU = jnp.array([3.0, 1.0, 1.4]), jnp.array([1.8, 0.1, 0.05])


def _los_pid(e_int0, **gains):
    params = baseline_params(baseline_gains(**gains), CRAFT, _COEFFS, u_d=2.0, k_rudder=K_RUDDER)
    z = baseline_state(varpi0=0.1, e_int0=e_int0)
    cfg = BaselineConfig(path=_PATH, kind="los_pid")
    return baseline_law(cfg, params, 0.0, _ETA, _NU, z)


def test_defaults_are_the_documented_ones_and_the_config_is_hashable():
    g = baseline_gains()
    assert [float(x) for x in g] == [5.0, 0.5, 1.0, 2.0, 3.0, 0.02, 0.1, 0.005, 0.4, 0.016]
    assert float(g.gamma) == float(g.sigma_i / g.Delta**2)  # ALOS shares ILOS's linearisation
    assert all(float(x) == 0.0 for x in baseline_state())
    cfg = BaselineConfig(path=_PATH, kind="ilos")
    assert hash(cfg) == hash(BaselineConfig(path=_PATH, kind="ilos"))  # a static argument


def test_los_pid_anti_windup_clamps_the_integral_to_a_crab_angle_of_max_crab():
    # k_ei e_int / k_psi_p <= MAX_CRAB (pi/4): beyond, back-calculation pulls e_int back
    _, z_dot, aux = _los_pid(1e4, k_ei=0.01, k_psi_p=2.0)
    lim = 2.0 * MAX_CRAB / 0.01
    assert MAX_CRAB == np.pi / 4
    np.testing.assert_allclose(z_dot.e_int, aux.eps[1] - (1e4 - lim), rtol=1e-13)
    _, z_dot, aux = _los_pid(-60.0, k_ei=0.0)  # no integral gain: int_limit (50) clamps
    np.testing.assert_allclose(z_dot.e_int, aux.eps[1] - (-60.0 + 50.0), rtol=1e-13)


def test_los_pid_cross_track_terms_enter_the_yaw_moment_as_equation_39():
    # tau_r = ... - m33 (k_ed e_dot + k_ep e + k_ei e_int): each gain's share, by differences
    base = dict(k_ep=0.0, k_ed=0.0, k_ei=0.0)
    tau0, _, aux = _los_pid(3.0, **base)
    e, e_dot = float(aux.eps[1]), float(aux.eps_dot[1])
    for name, signal in (("k_ep", e), ("k_ed", e_dot)):
        tau, _, _ = _los_pid(3.0, **(base | {name: 0.3}))
        np.testing.assert_allclose(tau[2] - tau0[2], -CRAFT.m33 * 0.3 * signal, rtol=1e-10)


def test_los_pid_without_an_integral_gain_has_finite_gradients():
    # k_ei = 0: int_limit clamps, and the crab-angle branch (a division by k_ei) stays NaN-free
    params = baseline_params(baseline_gains(k_ei=0.0), CRAFT, _COEFFS, u_d=2.0, k_rudder=K_RUDDER)
    cfg = BaselineConfig(path=_PATH, kind="los_pid")

    def out(k_ei):
        p = params._replace(gains=params.gains._replace(k_ei=k_ei))
        tau, z_dot, _ = baseline_law(cfg, p, 0.0, _ETA, _NU, baseline_state(0.1, -60.0))
        return tau[2] + z_dot.e_int

    assert np.isfinite(jax.grad(out)(0.0))


def test_ilos_heading_rate_feedback_is_the_derivative_of_equation_40():
    # on the straight line (psi_p constant) the yaw moment's k_psi_d share is
    # -m33 k_psi_d (r - psi_r_dot), psi_r_dot = -Delta E_dot / (Delta^2 + E^2),
    # E = e + sigma_i e_int, E_dot = e_dot + sigma_i e_int_dot
    def law(k_psi_d):
        gains = baseline_gains(Delta=4.0, sigma_i=0.7, k_psi_d=k_psi_d)
        params = baseline_params(gains, CRAFT, _COEFFS, u_d=2.0, k_rudder=K_RUDDER)
        cfg = BaselineConfig(path=_PATH, kind="ilos")
        return baseline_law(cfg, params, 0.0, _ETA, _NU, baseline_state(0.1, 2.5))

    tau1, z_dot, aux = law(1.0)
    tau2, _, _ = law(3.0)
    e, e_dot = float(aux.eps[1]), float(aux.eps_dot[1])
    big_e, big_e_dot = e + 0.7 * 2.5, e_dot + 0.7 * float(z_dot.e_int)
    psi_r_dot = -4.0 * big_e_dot / (16.0 + big_e**2)
    expected = -CRAFT.m33 * 2.0 * (float(_NU[2]) - psi_r_dot)
    np.testing.assert_allclose(tau2[2] - tau1[2], expected, rtol=1e-10)


def test_law_params_defaults_are_the_documented_ones():
    p = baseline_params(baseline_gains(), CRAFT, _COEFFS)  # u_d 2 m/s, no rudder, clamp 50 m s
    assert (float(p.u_d), float(p.k_rudder), float(p.int_limit)) == (2.0, 0.0, 50.0)


# --- vcm.py (the 2-D VCM law): defaults, validation boundaries, and single law evaluations ---


def test_vcm_defaults_are_the_documented_ones():
    g = pm_gains()
    expected = [(1.0, 0.5, 0.5), (1.0, 1.0, 2.0, 0.5, 0.5), 5.0, 0.5, (0.05, 0.05), 0.4]
    for value, want in zip(g, expected, strict=True):
        np.testing.assert_array_equal(value, want)
    assert all(np.all(np.asarray(x) == 0.0) for x in vcm_state())
    assert np.asarray(vcm_state().int_eps).shape == (2,)
    pm_gains(sigma_i=0.0, P_int=(0.0, 0.0))  # the integral gains may be zero


def test_pm_gains_rejects_integral_gains_on_the_routh_hurwitz_boundary():
    # defaults: P_Geps = P_Phieps = (0.5, 0.5): (P_G + P_Phi) P_G P_Phi = 1 * 0.25 per row
    pm_gains(P_int=(0.2499, 0.0))
    with pytest.raises(ValueError, match=r"P_int: .* = \[0\.25 0\.25\]"):
        pm_gains(P_int=(0.25, 0.0))


def test_vcm_loop_options_is_a_frozen_mixin_that_runs_the_loop_post_init():
    options = VCMLoopOptions()  # no __post_init__ above it: nothing else to call
    assert options.edd == "paper"
    with pytest.raises(dataclasses.FrozenInstanceError):
        options.edd = "implied"
    seen = []

    @dataclasses.dataclass(frozen=True)
    class Base:
        def __post_init__(self):
            seen.append(self)

    @dataclasses.dataclass(frozen=True)
    class Loop(VCMLoopOptions, Base):
        pass

    assert Loop(edd="implied").edd == "implied" and len(seen) == 1
    with pytest.raises(ValueError, match="edd"):
        Loop(edd="exact")


_V_ETA, _V_NU = jnp.array([11.5, 3.0, 1.3]), jnp.array([1.8, 0.1, 0.05])  # s, e, rates distinct


def _vcm(z=None, gains=None, **choices):
    params = vcm_params(gains or pm_gains(), CRAFT, _COEFFS, u_d=2.0, k_rudder=K_RUDDER)
    z = vcm_state(varpi0=2.0) if z is None else z
    return vcm_law(VCMConfig(path=_PATH, **choices), params, 0.0, _V_ETA, _V_NU, z)


def test_vcm_designed_e_ddot_enters_the_heading_row_in_paper_mode():
    # (35): edd_paper = -(p_G3 + p_Phi5) e_dot - p_G3 p_Phi5 e; the two modes differ only in the
    # e_ddot of psi_r_ddot = -Delta e_ddot / (Delta^2 + e^2) + (terms free of e_ddot)
    gains = pm_gains(P_G=(1.0, 0.5, 0.7), P_Phi=(1.0, 1.0, 2.0, 0.5, 0.3))
    _, _, paper = _vcm(gains=gains, actuation="full", edd="paper")
    _, _, implied = _vcm(gains=gains, actuation="full", edd="implied")
    e, e_dot = float(paper.eps[1]), float(paper.eps_dot[1])
    assert abs(float(paper.eps[0])) > 0.3 and abs(e) > 0.3 and abs(e_dot) > 0.1
    np.testing.assert_allclose(paper.edd_paper, -1.0 * e_dot - 0.21 * e, rtol=1e-13)
    d_edd = float(paper.edd_paper - paper.edd_implied)
    assert abs(d_edd) > 0.05
    np.testing.assert_allclose(
        paper.nu_dot_cmd[2] - implied.nu_dot_cmd[2], -5.0 * d_edd / (25.0 + e * e), rtol=1e-9
    )
    np.testing.assert_allclose(paper.nu_dot_cmd[:2], implied.nu_dot_cmd[:2], rtol=1e-13)


def test_vcm_desired_sway_is_a_state_only_when_underactuated():
    z = vcm_state(varpi0=2.0, v_d0=0.3)
    tau, _, aux = _vcm(z, actuation="full")
    tau0, _, _ = _vcm(vcm_state(varpi0=2.0), actuation="full")
    np.testing.assert_allclose(aux.v_tilde, float(_V_NU[1]), rtol=1e-15)  # v_d = 0
    np.testing.assert_array_equal(tau, tau0)
    _, _, aux = _vcm(z, actuation="underactuated")
    np.testing.assert_allclose(aux.v_tilde, float(_V_NU[1]) - 0.3, rtol=1e-14)


def test_vcm_ilos_integral_rate_and_anti_windup():
    # (40): e_int' = Delta e / ((e + sigma_i e_int)^2 + Delta^2); (41)'s integral with
    # back-calculation: int' = eps - (int - clip(int, -limit, limit)), limit 50 m s
    z = vcm_state(varpi0=2.0, int_eps0=(80.0, -3.0), e_int0=2.5)
    gains = pm_gains(Delta=4.0, sigma_i=0.7)
    _, z_dot, aux = _vcm(z, gains=gains, guidance="ilos", integral=True)
    e = float(aux.eps[1])
    np.testing.assert_allclose(z_dot.e_int, 4.0 * e / ((e + 0.7 * 2.5) ** 2 + 16.0), rtol=1e-13)
    np.testing.assert_allclose(z_dot.int_eps, aux.eps - jnp.array([30.0, 0.0]), rtol=1e-13)


# --- depth.py: the depth reference and PID of the ODIN loop, one evaluation each ---


def test_depth_reference_moves_with_the_particle():
    frame = types.SimpleNamespace(z_p=3.0, dz_dw=0.4, d2z_dw2=-0.2)
    ref = depth_reference(frame, 1.5, 0.3)
    np.testing.assert_allclose(ref, [3.0, 0.4 * 1.5, -0.2 * 1.5**2 + 0.4 * 0.3], rtol=1e-15)


@pytest.mark.parametrize(
    ("int_z", "tilt", "clamped", "divisor"),
    [(0.7, 0.9, 0.7, 0.9), (12.0, 0.3, 10.0, 0.5), (-12.0, 0.6, -10.0, 0.6)],
)
def test_depth_pid_is_the_documented_law(int_z, tilt, clamped, divisor):
    # a_z = z_p'' - k_d (z' - z_p') - k_p (z - z_p) - k_i int; Z = m_w a_z + d_w z';
    # tau_Z = Z / max(tilt, 1/2); int' = e_z - (int - clip(int, -10, 10))
    gains = jnp.array([0.8, 1.7, 0.05])
    ref = depth_reference(types.SimpleNamespace(z_p=3.0, dz_dw=0.4, d2z_dw2=-0.2), 1.5, 0.3)
    tau, int_dot, ez = depth_pid(gains, 10.0, ref, 4.5, 0.9, int_z, 70.0, 25.0, tilt)
    a_z = float(ref.z_ddot) - 1.7 * (0.9 - float(ref.z_dot)) - 0.8 * 1.5 - 0.05 * int_z
    np.testing.assert_allclose(tau, (70.0 * a_z + 25.0 * 0.9) / divisor, rtol=1e-13)
    np.testing.assert_allclose(ez, 1.5, rtol=1e-15)
    np.testing.assert_allclose(int_dot, 1.5 - (int_z - clamped), rtol=1e-15)
