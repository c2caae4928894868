"""VCM 2-D path-maneuvering controller (paper Section 4: (26)–(38), (41); docs/method.md).

Constraints on the horizontal 3-DOF design model (20):

    K = [u - u_d, v - v_d]                      (26)  velocity rows, P law
    G = [psi - psi_d, s, e]                     (27)  holonomic rows, PD law

``W_b`` is 5x3 of rank 3, so the reaction force comes from the pseudo-inverse (31):
``tau = n_b(nu) - M_b W_b^+ h``. Re-derived in closed form (docs/method.md), with
``W_b = [[I2, 0], [0, 0, 1], [R(gamma), 0]]`` and ``W_b^T W_b = diag(2, 2, 1)``:

    [u_dot, v_dot] = 1/2 (alpha_K + R(gamma)^T alpha_eps)
    r_dot = psi_d_ddot - p_G1 psi~_dot - p_Phi3 (psi~_dot + p_G1 psi~)

with ``alpha_K = [u_d_dot - p_Phi1 (u - u_d), v_d_dot - p_Phi2 (v - v_d)]``,
``alpha_eps = eps_ddot_des - drift`` and ``eps_ddot_des = -P_eps2 eps_dot - P_eps1 eps``
(``- P_eps0 int(eps)`` with integral action (41)). (The paper prints ``0.5 R(gamma)`` in (32); the
algebra with ``gamma = psi - psi_p`` gives the transpose, which is what is implemented and tested.)

Because ``r_dot`` enters only the heading row, the least-squares solution decouples: the linear
accelerations come from the velocity and position rows, and the heading row then holds exactly.
The one choice left is which ``e_ddot`` enters ``psi_d_ddot`` (36)
([`VCMConfig`][vcjax.control.vcm.VCMConfig] ``edd``):

* ``"paper"`` (reference mode, Appendix A): the *designed* ``e_ddot`` of (35)/(41). While the
  position rows are not yet satisfied the actual ``e_ddot`` differs, so (37) holds only
  approximately;
* ``"implied"``: the ``e_ddot`` implied by the commanded accelerations. Then (37)
  ``psi~_ddot + p_psi2 psi~_dot + p_psi1 psi~ = 0`` holds exactly under a perfect model, and the
  law equals the generic engine ([`vcjax.mechanics`][vcjax.mechanics]) fed the exact constraint set.

Underactuation in sway (Section 4.1): ``v_d`` is a controller state whose rate is chosen so that
the sway row of (31) equals the sway force the rudder produces along with the yaw moment
(Remark 4): ``tau_v = k_rudder tau_r``. ``tau`` is affine in ``v_d_dot``; the condition is solved
exactly (value and slope from one ``jax.jvp``) instead of via Appendix A's explicit terms.
"""

from __future__ import annotations

import dataclasses
from typing import Any, Literal, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from vcjax._checks import check_array, check_positive
from vcjax.control.params import LawParams, law_params
from vcjax.guidance import los_angle, path_kinematics
from vcjax.linalg import safe_sqrt, wrap_angle
from vcjax.paths import path_frame
from vcjax.vehicles import design3dof as d3

__all__ = [
    "PMGains",
    "pm_gains",
    "VCMParams",
    "vcm_params",
    "VCMConfig",
    "VCMState",
    "vcm_state",
    "VCMAux",
    "vcm_law",
]


class PMGains(NamedTuple):
    """Path-maneuvering gains (traced).

    Attributes:
        P_G: (3,) ``[p_G1 (heading), p_G2 (s), p_G3 (e)]`` [1/s] of (11).
        P_Phi: (5,) ``[p_Phi1 (u), p_Phi2 (v), p_Phi3 (heading), p_Phi4 (s), p_Phi5 (e)]`` [1/s].
        Delta: () look-ahead distance of the approach angle (24) [m].
        sigma: () particle-speed gain of ``ubar_p = u_d + sigma s`` [1/s].
        P_int: (2,) integral gains ``P_eps0`` on ``[s, e]`` of (41) [1/s^3] (used when
            ``VCMConfig.integral``).
        sigma_i: () integral gain of the approach angle when ``VCMConfig.guidance`` is
            ``"ilos"`` [-] (unused otherwise).
    """

    P_G: Any
    P_Phi: Any
    Delta: Any
    sigma: Any
    P_int: Any
    sigma_i: Any


def pm_gains(
    P_G=(1.0, 0.5, 0.5),
    P_Phi=(1.0, 1.0, 2.0, 0.5, 0.5),
    Delta=5.0,
    sigma=0.5,
    P_int=(0.05, 0.05),
    sigma_i=0.4,
) -> PMGains:
    """Validated [`PMGains`][vcjax.control.vcm.PMGains] (defaults: docs/method.md's order-one
    gains).

    Raises ``ValueError`` for non-positive gains, wrong shapes, NaN, or integral gains that make
    the ``eps`` error dynamics (41) unstable (Routh–Hurwitz: ``P_eps2 P_eps1 > P_eps0``).
    """
    check_positive("P_G", P_G, (3,))
    check_positive("P_Phi", P_Phi, (5,))
    check_positive("Delta", Delta, ())
    check_positive("sigma", sigma, ())
    check_positive("P_int", P_int, (2,), strict=False)
    check_positive("sigma_i", sigma_i, (), strict=False)
    pg, pphi, pint = (np.asarray(x, float) for x in (P_G, P_Phi, P_int))
    p2 = pg[1:] + pphi[3:]
    p1 = pg[1:] * pphi[3:]
    if np.any(pint >= p2 * p1):
        raise ValueError(
            f"P_int: integral gains {pint} make (41) unstable; need P_int < (P_Geps + P_Phieps) "
            f"* P_Geps * P_Phieps = {p2 * p1}"
        )
    vals = (P_G, P_Phi, Delta, sigma, P_int, sigma_i)
    return PMGains(*(jnp.asarray(x, dtype=float) for x in vals))


#: The VCM law's traced parameters ([`LawParams`][vcjax.control.params.LawParams] with
#: [`PMGains`][vcjax.control.vcm.PMGains]); [`vcm_params`][vcjax.control.params.law_params]
#: validates them.
VCMParams = LawParams
vcm_params = law_params


EDD_MODES = ("paper", "implied")


def check_edd(edd) -> None:
    """Raise ``ValueError`` naming ``edd`` unless it is one of ``EDD_MODES``."""
    if edd not in EDD_MODES:
        raise ValueError(f"edd: expected 'paper' or 'implied', got {edd!r}")


@dataclasses.dataclass(frozen=True)
class VCMConfig:
    """Static choices of the VCM law.

    Attributes:
        path: the static path (kind) from [`vcjax.paths`][vcjax.paths]; its coefficients are traced
            in
            ``VCMParams.path``.
        actuation: ``"full"`` (sway force available, ``v_d = 0``) or ``"underactuated"``
            (``tau_v`` is whatever the rudder gives; ``v_d`` follows (38)).
        edd: ``"paper"`` or ``"implied"`` (module docstring).
        integral: integral action on ``eps`` (41) with anti-windup.
        guidance: the approach angle of the heading constraint: ``"los"`` (24),
            ``psi_r = atan(-e / Delta)``, as the paper; or ``"ilos"``, the integral LOS angle
            ``psi_r = atan(-(e + sigma_i e_int) / Delta)`` with the Børhaug–Pettersen law
            ``e_int_dot = Delta e / ((e + sigma_i e_int)^2 + Delta^2)`` (40) *inside* the VCM
            heading row. An extension, not in the paper: an underactuated craft must crab into a
            cross current, which with (24) needs ``e = Delta tan(crab)`` because the heading row
            (37) is enforced exactly; with ``"ilos"`` the integral supplies the crab angle and
            ``e -> 0``.
    """

    path: Any
    actuation: Literal["full", "underactuated"] = "underactuated"
    edd: Literal["paper", "implied"] = "paper"
    integral: bool = False
    guidance: Literal["los", "ilos"] = "los"

    def __post_init__(self):
        if self.guidance not in ("los", "ilos"):
            raise ValueError(f"guidance: 'los' or 'ilos', got {self.guidance!r}")
        if self.actuation not in ("full", "underactuated"):
            raise ValueError(f"actuation: 'full' or 'underactuated', got {self.actuation!r}")
        check_edd(self.edd)


@dataclasses.dataclass(frozen=True)
class VCMLoopOptions:
    """The static option of a loop whose laws include the VCM law: a mixin of the loop's
    dataclass (``class MyLoop(VCMLoopOptions, Loop)``), so the option is declared once for every
    such vehicle and parsed from ``[scenario]`` like the loop's other options.

    Attributes:
        edd: which ``e_ddot`` enters the VCM heading row, ``"paper"`` or ``"implied"`` (module
            docstring).
    """

    edd: Literal["paper", "implied"] = "paper"

    def __post_init__(self):
        post = getattr(super(), "__post_init__", None)
        if post is not None:
            post()
        check_edd(self.edd)

    def vcm_config(self, **choices) -> VCMConfig:
        """The [`VCMConfig`][vcjax.control.vcm.VCMConfig] of this loop's VCM law: the loop's
        path and option, and ``choices`` (actuation, integral, guidance)."""
        return VCMConfig(path=self.path, edd=self.edd, **choices)


class VCMState(NamedTuple):
    """Controller state.

    Attributes:
        varpi: () path-particle parameter.
        v_d: () desired sway velocity [m/s] (a state only when underactuated).
        int_eps: (2,) integral of ``eps`` [m s] (41).
        e_int: () integral state of the ``"ilos"`` approach angle [m s].
    """

    varpi: Any
    v_d: Any
    int_eps: Any
    e_int: Any


def vcm_state(varpi0=0.0, v_d0=0.0, int_eps0=(0.0, 0.0), e_int0=0.0) -> VCMState:
    """Initial controller state (validated)."""
    check_array("varpi0", varpi0, ())
    check_array("v_d0", v_d0, ())
    check_array("int_eps0", int_eps0, (2,))
    check_array("e_int0", e_int0, ())
    f = lambda x: jnp.asarray(x, dtype=float)
    return VCMState(f(varpi0), f(v_d0), f(int_eps0), f(e_int0))


class VCMAux(NamedTuple):
    """Signals the law exposes for plots, losses and tests (scalars unless noted)."""

    eps: Any  # (2,) [s, e]
    eps_dot: Any  # (2,)
    u_tilde: Any
    v_tilde: Any
    psi_tilde: Any
    psi_tilde_dot: Any
    psi_d: Any
    tau: Any  # (3,) commanded body force [tau_u, tau_v, tau_r]
    nu_dot_cmd: Any  # (3,) commanded body acceleration
    edd_paper: Any  # designed e_ddot
    edd_implied: Any  # e_ddot implied by the commanded accelerations
    ls_residual: Any  # || W_b nu_dot + h ||: 0 once the rows are consistent


def vcm_law(cfg: VCMConfig, params: VCMParams, t, eta, nu, z: VCMState, n_b=None):
    """The VCM control law (31)/(38)/(41).

    Args:
        cfg: static [`VCMConfig`][vcjax.control.vcm.VCMConfig].
        params: traced [`VCMParams`][vcjax.control.params.LawParams].
        t: () time [s].
        eta: (3,) ``[x, y, psi]`` measured pose.
        nu: (3,) ``[u, v, r]`` measured body velocity over ground.
        z: [`VCMState`][vcjax.control.vcm.VCMState].
        n_b: optional (3,) body bias ``[X, Y, N]`` [N, N, N m] at ``nu`` replacing the design
            model's ``C_b(nu) nu + D_b nu`` of (20) (``M_b`` stays the design model's): for a
            caller whose vehicle model of these three rows is richer than (20)'s structure
            (the decoupled 3-D baseline,
            [`decoupled_law`][vcjax.control.baselines3d.decoupled_law]).

    Returns:
        ``(tau, z_dot, aux)``: (3,) body force ``[tau_u, tau_v, tau_r]`` [N, N, N m] (when
        underactuated, ``tau_v = k_rudder tau_r`` is what the rudder delivers, not a command),
        the [`VCMState`][vcjax.control.vcm.VCMState] rate, and [`VCMAux`][vcjax.control.vcm.VCMAux].
    """
    g = params.gains
    m = params.model
    frame = path_frame(cfg.path, params.path, z.varpi)
    u_d = params.u_d
    u_d_dot = jnp.zeros_like(u_d)
    kin = path_kinematics(frame, eta, nu, u_d, g.sigma, u_d_dot)
    eps, eps_dot = kin.eps, kin.eps_dot
    e, e_dot = eps[1], eps_dot[1]
    u, v, r = nu[0], nu[1], nu[2]
    v_d = z.v_d if cfg.actuation == "underactuated" else jnp.zeros_like(z.v_d)

    # (35)/(41): designed eps dynamics
    P_Ge, P_Phie = g.P_G[1:], g.P_Phi[3:]
    eps_ddot_des = -(P_Ge + P_Phie) * eps_dot - (P_Ge * P_Phie) * eps
    if cfg.integral:
        eps_ddot_des = eps_ddot_des - g.P_int * z.int_eps
    alpha_eps = eps_ddot_des - kin.eps_ddot_drift
    R_g = kin.R_gamma

    # heading errors (24)-(25). The approach angle is atan(-E / Delta) with E = e (LOS) or
    # E = e + sigma_i e_int (ILOS, (40)); (36) holds with e replaced by E, and E_ddot is affine in
    # e_ddot: E_ddot = e_ddot + sigma_i e_int_ddot.
    if cfg.guidance == "ilos":
        E = e + g.sigma_i * z.e_int
        den = E * E + g.Delta * g.Delta
        e_int_dot = g.Delta * e / den
        E_dot = e_dot + g.sigma_i * e_int_dot
        e_int_ddot_free = g.Delta * e_dot / den - 2 * g.Delta * e * E * E_dot / (den * den)

        def E_ddot(edd):
            return edd + g.sigma_i * e_int_ddot_free
    else:
        E, E_dot, e_int_dot = e, e_dot, jnp.zeros_like(e)

        def E_ddot(edd):
            return edd

    los0 = los_angle(E, E_dot, jnp.zeros_like(e), g.Delta)
    psi_d = kin.psi_p + los0.psi_r
    psi_tilde = wrap_angle(eta[2] - psi_d)
    psi_tilde_dot = r - (kin.psi_p_dot + los0.psi_r_dot)
    pG1, pPhi3 = g.P_G[0], g.P_Phi[2]
    n_b = d3.body_bias(m, nu) if n_b is None else n_b
    M_b = d3.mass_matrix(m)

    def command(v_d_dot):
        # Everything here is affine in v_d_dot (the only unknown of the underactuated case).
        alpha_K = jnp.stack([u_d_dot - g.P_Phi[0] * (u - u_d), v_d_dot - g.P_Phi[1] * (v - v_d)])
        w_dot = 0.5 * (alpha_K + R_g.T @ alpha_eps)
        edd_implied = (R_g @ w_dot + kin.eps_ddot_drift)[1]
        edd = eps_ddot_des[1] if cfg.edd == "paper" else edd_implied
        psi_d_ddot = kin.psi_p_ddot + los_angle(E, E_dot, E_ddot(edd), g.Delta).psi_r_ddot
        r_dot = psi_d_ddot - pG1 * psi_tilde_dot - pPhi3 * (psi_tilde_dot + pG1 * psi_tilde)
        nu_dot = jnp.concatenate([w_dot, r_dot[None]])
        tau = M_b @ nu_dot + n_b
        return tau, nu_dot, edd_implied, alpha_K

    zero = jnp.zeros_like(u)
    if cfg.actuation == "underactuated":
        # The sway row of (31) must equal the rudder's own sway force: tau_v - k tau_r = 0
        # (Remark 4). One jvp gives the value at v_d_dot = 0 and the (constant) slope of every
        # output; the exact root follows, and the outputs by linearity (no re-evaluation).
        out0, slope = jax.jvp(command, (zero,), (jnp.ones_like(zero),))
        gap0 = out0[0][1] - params.k_rudder * out0[0][2]
        dgap = slope[0][1] - params.k_rudder * slope[0][2]
        v_d_dot = -gap0 / dgap  # dgap = m22/2 - k m23/2 (+ coupling via e_ddot): away from 0
        tau, nu_dot, edd_implied, alpha_K = jax.tree_util.tree_map(
            lambda a, b: a + v_d_dot * b, out0, slope
        )
    else:
        v_d_dot = zero
        tau, nu_dot, edd_implied, alpha_K = command(zero)
    w_dot = nu_dot[:2]
    # NaN-safe at 0 (consistent rows): its cotangent is a materialised zero inside scans
    res = safe_sqrt(jnp.sum((w_dot - alpha_K) ** 2) + jnp.sum((R_g @ w_dot - alpha_eps) ** 2))

    if cfg.integral:
        clipped = jnp.clip(z.int_eps, -params.int_limit, params.int_limit)
        int_dot = eps - (z.int_eps - clipped)  # back-calculation anti-windup, unit gain
    else:
        int_dot = jnp.zeros_like(z.int_eps)
    z_dot = VCMState(varpi=kin.varpi_dot, v_d=v_d_dot, int_eps=int_dot, e_int=e_int_dot)
    aux = VCMAux(
        eps=eps,
        eps_dot=eps_dot,
        u_tilde=u - u_d,
        v_tilde=v - v_d,
        psi_tilde=psi_tilde,
        psi_tilde_dot=psi_tilde_dot,
        psi_d=psi_d,
        tau=tau,
        nu_dot_cmd=nu_dot,
        edd_paper=eps_ddot_des[1],
        edd_implied=edd_implied,
        ls_residual=res,
    )
    return tau, z_dot, aux
