"""3-D VCM path maneuvering for a torpedo-shaped AUV (fins + propeller), on the generic engine.

The paper reaches 3-D only by pairing its horizontal law with a decoupled depth loop (Simulation 2).
Here the constraint set itself is 3-D, on the paper's path frame with azimuth and elevation (21).

Design model: 5 DOF, ``q = [x, y, z, theta, psi]`` (roll held at 0), body velocity
``nu5 = [u, v, w, q, r]``, ``q̇ = J5(q) nu5`` (e.g.
[`vcjax.vehicles.remus100_design`][vcjax.vehicles.remus100_design]).

Errors and particle. With ``R_p = Rz(psi_p) Ry(theta_p)`` at the particle ``varpi``,

    eps = [s, e, h] = R_p^T (p - p_p(varpi))                      (23) in 3-D
    varpi_dot = u_p cos(theta_p) / ||p_bar'||,  u_p = u_d + sigma s   (22)

(``ubar_p = u_p cos theta_p`` is the projected speed, so ``varpi_dot = u_p / ||p'||``.)

Constraints (8 rows on 5 DOF; ``W`` has full column rank, so the force is (17)):

    K = R(theta, psi)^T p_dot - [u_d, v_d, w_d]                   velocity rows (u, v, w)
    G = [psi - psi_d, theta - theta_d, eps + k_I zeta]             holonomic rows
    psi_d = psi_p + atan(-E / Delta_h),   theta_d = theta_p + atan(H / Delta_v)

with ``E = e``, ``H = h`` (paper angles, (24)) or the integral-LOS angles ``E = e + sigma_ih
e_int``, ``H = h + sigma_iv h_int`` with ``e_int_dot = Delta_h e / (E^2 + Delta_h^2)`` and
``h_int_dot = Delta_v h / (H^2 + Delta_v^2)`` (Børhaug–Pettersen (40), one per plane). ``h > 0``
means the vehicle is below the path: ``theta_d`` pitches the nose up.

The engine ([`vcjax.mechanics`][vcjax.mechanics]) computes ``W`` and ``Ẇq̇ + ȧ`` by autodiff,
including the
time derivative through the controller states (particle, ILOS and integral states). Because
``ψ̈`` and ``θ̈`` appear only in their own rows, the least-squares solve (17) satisfies the heading
and pitch rows exactly (the 3-D form of (37)); the six linear rows (velocity and position) share
the three linear accelerations and hold in the least-squares sense until they are consistent.

Decisions where the paper is silent:

* **Underactuation in sway and heave** (``actuation="underactuated"``). A fin's force comes with
  its moment: the rudder gives ``Y = N / x_r``, the stern planes ``Z = -M / x_s``. These two tied
  rows (body frame, mapped to generalised forces by ``J5^T``) are declared to the engine
  ([`Underactuation`][vcjax.mechanics.Underactuation]) with ``v_d``, ``w_d`` free: their rates are
  solved
  so that the law's sway and heave forces are exactly what the fins produce along with the yaw
  and pitch moments the law asks for — Remark 4 in both planes; the paper's (38) is the sway-only
  case. ``actuation="full"`` keeps ``v_d = w_d = 0`` (all five forces commanded).
* **Integral action** (41) enters as an augmented holonomic row ``G_eps = eps + k_I zeta``,
  ``zeta_dot = eps`` (with back-calculation anti-windup at ``int_limit``). With
  ``Φ̇ + P_Φ Φ = 0`` this gives exactly (41),
  ``eps''' ... : (s + k_I)(s + p_G)(s + p_Phi) eps = 0``, i.e. ``P_eps2 = k_I + p_G + p_Phi``,
  ``P_eps1 = k_I (p_G + p_Phi) + p_G p_Phi``, ``P_eps0 = k_I p_G p_Phi``: stable for every
  positive gain, so no Routh–Hurwitz condition to check, and the engine stays generic.
* The measured velocity is over ground; the law does not know the current. Under a cross
  current an underactuated vehicle must crab: with the paper angles the heading row (enforced
  exactly) then needs ``e = Delta tan(crab)``; the ILOS integral supplies the crab (and, in the
  vertical plane, the trim angle of attack) and ``e, h -> 0``.
* Roll is not in the design model; the plant's roll motion (metacentric, lightly excited) is
  measured but not controlled.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from typing import Any, Literal, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from vcjax._checks import check_array, check_positive
from vcjax.linalg import Rzyx, safe_norm, solve_small, wrap_angle
from vcjax.mechanics import (
    MechanicalSystem,
    Underactuation,
    VCMGains,
    VirtualConstraints,
    reaction_force,
    underactuated_reaction_force,
)
from vcjax.paths import path_frame, path_pose

__all__ = [
    "VCM3DGains",
    "vcm3d_gains",
    "VCM3DParams",
    "vcm3d_params",
    "VCM3DConfig",
    "VCM3DState",
    "vcm3d_state",
    "VCM3DAux",
    "vcm3d_law",
    "path_errors_3d",
    "pose_errors",
]


class VCM3DGains(NamedTuple):
    """Gains of the 3-D law (traced).

    Attributes:
        P_G: (5,) ``[p_psi, p_theta, p_s, p_e, p_h]`` [1/s] of the holonomic rows (11).
        P_Phi: (8,) ``[u, v, w, psi, theta, s, e, h]`` [1/s] of (14).
        Delta: (2,) look-ahead distances ``[horizontal, vertical]`` [m].
        sigma: () particle-speed gain of ``u_p = u_d + sigma s`` [1/s].
        k_int: (3,) integral poles ``k_I`` on ``[s, e, h]`` [1/s] (with ``integral``).
        sigma_i: (2,) ILOS gains ``[horizontal, vertical]`` [-] (with ``guidance="ilos"``).
    """

    P_G: Any
    P_Phi: Any
    Delta: Any
    sigma: Any
    k_int: Any
    sigma_i: Any


def vcm3d_gains(
    P_G=(1.0, 1.0, 0.3, 0.3, 0.3),
    P_Phi=(0.5, 0.5, 0.5, 2.0, 2.0, 0.5, 0.5, 0.5),
    Delta=(8.0, 8.0),
    sigma=0.3,
    k_int=(0.05, 0.05, 0.05),
    sigma_i=(0.5, 0.5),
) -> VCM3DGains:
    """Validated [`VCM3DGains`][vcjax.control.vcm3d.VCM3DGains] (every gain > 0; ``k_int``,
    ``sigma_i`` >= 0)."""
    check_positive("P_G", P_G, (5,))
    check_positive("P_Phi", P_Phi, (8,))
    check_positive("Delta", Delta, (2,))
    check_positive("sigma", sigma, ())
    check_positive("k_int", k_int, (3,), strict=False)
    check_positive("sigma_i", sigma_i, (2,), strict=False)
    vals = (P_G, P_Phi, Delta, sigma, k_int, sigma_i)
    return VCM3DGains(*(jnp.asarray(x, dtype=float) for x in vals))


class VCM3DParams(NamedTuple):
    """Traced parameters of [`vcm3d_law`][vcjax.control.vcm3d.vcm3d_law].

    Attributes:
        gains: [`VCM3DGains`][vcjax.control.vcm3d.VCM3DGains].
        model: the design model's parameters (``args`` of the config's ``system``).
        u_d: () desired speed along the path [m/s].
        int_limit: () anti-windup clamp of each integral state ``zeta`` [m s].
        path: the path's coefficients.
    """

    gains: Any
    model: Any
    u_d: Any
    int_limit: Any
    path: Any


def vcm3d_params(gains, model, path, u_d=1.5, int_limit=50.0) -> VCM3DParams:
    """Validated [`VCM3DParams`][vcjax.control.vcm3d.VCM3DParams] (``u_d``, ``int_limit`` > 0)."""
    if not isinstance(gains, VCM3DGains):
        raise ValueError(f"gains: expected VCM3DGains, got {type(gains).__name__}")
    check_positive("u_d", u_d, ())
    check_positive("int_limit", int_limit, ())
    f = lambda x: jnp.asarray(x, dtype=float)
    return VCM3DParams(gains, model, f(u_d), f(int_limit), path)


@dataclasses.dataclass(frozen=True)
class VCM3DConfig:
    """Static choices of the 3-D law.

    Attributes:
        path: static [`Path`][vcjax.paths.Path].
        system: the 5-DOF design model in ``q = [x, y, z, theta, psi]``
            ([`MechanicalSystem`][vcjax.mechanics.MechanicalSystem], ``args`` =
            ``VCM3DParams.model``).
        kinematics: ``J5(q, model) -> (5, 5)`` with ``q̇ = J5 nu5``.
        kinematics_inverse: optional closed-form ``J5(q, model)^-1`` (default: an
            elimination); a smaller program, the same numbers to round-off.
        tied_rows: ``model -> (2, 5)`` body-frame rows ``A_b`` with ``A_b tau5 = 0`` for every
            fin force (used when underactuated).
        actuation: ``"underactuated"`` (sway and heave tied to the fins; ``v_d``, ``w_d`` free)
            or ``"full"``.
        integral: integral action on ``eps``.
        guidance: ``"los"`` (paper angles (24) in both planes) or ``"ilos"``.
    """

    path: Any
    system: MechanicalSystem
    kinematics: Callable
    tied_rows: Callable
    actuation: Literal["full", "underactuated"] = "underactuated"
    integral: bool = False
    guidance: Literal["los", "ilos"] = "los"
    kinematics_inverse: Callable | None = None

    def __post_init__(self):
        if self.actuation not in ("full", "underactuated"):
            raise ValueError(f"actuation: 'full' or 'underactuated', got {self.actuation!r}")
        if self.guidance not in ("los", "ilos"):
            raise ValueError(f"guidance: 'los' or 'ilos', got {self.guidance!r}")
        if not isinstance(self.integral, bool):
            raise ValueError(f"integral: expected a bool, got {self.integral!r}")


class VCM3DState(NamedTuple):
    """Controller state (scalars unless noted).

    Attributes:
        varpi: path-particle parameter.
        v_d, w_d: desired sway and heave velocities [m/s] (states when underactuated).
        zeta: (3,) integral of ``eps`` [m s].
        e_int, h_int: ILOS integral states [m s].
    """

    varpi: Any
    v_d: Any
    w_d: Any
    zeta: Any
    e_int: Any
    h_int: Any


def vcm3d_state(varpi0=0.0, v_d0=0.0, w_d0=0.0, zeta0=(0.0, 0.0, 0.0), e_int0=0.0, h_int0=0.0):
    """Validated initial [`VCM3DState`][vcjax.control.vcm3d.VCM3DState]."""
    for name, v in dict(varpi0=varpi0, v_d0=v_d0, w_d0=w_d0, e_int0=e_int0, h_int0=h_int0).items():
        check_array(name, v, ())
    check_array("zeta0", zeta0, (3,))
    f = lambda x: jnp.asarray(x, dtype=float)
    return VCM3DState(f(varpi0), f(v_d0), f(w_d0), f(zeta0), f(e_int0), f(h_int0))


def _flat(z: VCM3DState):
    return jnp.concatenate(
        [jnp.stack([z.varpi, z.v_d, z.w_d]), z.zeta, jnp.stack([z.e_int, z.h_int])]
    )


def _unflat(v) -> VCM3DState:
    return VCM3DState(v[0], v[1], v[2], v[3:6], v[6], v[7])


class VCM3DAux(NamedTuple):
    """Signals for plots, losses and tests.

    Attributes:
        eps: (3,) ``[s, e, h]`` [m]; dist: () ``||eps||`` [m] (distance to the particle).
        psi_tilde, theta_tilde: () heading and pitch errors [rad]; psi_d, theta_d: () [rad].
        Phi: (8,) the unified constraint function ``[K; Ġ + P_G G]``.
        tau: (5,) body force ``[X, Y, Z, M, N]`` [N, N m] (sway/heave: what the fins give when
            underactuated); nu_dot_cmd: (5,) commanded body acceleration.
        ls_residual: () ``||W q̈ + h||`` (0 once the rows are consistent).
        tied_gap: () ``||A_b tau||`` (0 to round-off when underactuated).
    """

    eps: Any
    dist: Any
    psi_tilde: Any
    theta_tilde: Any
    psi_d: Any
    theta_d: Any
    Phi: Any
    tau: Any
    nu_dot_cmd: Any
    ls_residual: Any
    tied_gap: Any


def path_errors_3d(path, coeffs, varpi, p):
    """``(frame, eps)``: the path frame at ``varpi`` and ``eps = R_p^T (p - p_p)`` (3,) [m]."""
    f = path_frame(path, coeffs, varpi)
    R_p = Rzyx(jnp.zeros_like(f.psi_p), f.theta_p, f.psi_p)
    return f, R_p.T @ (p - f.p)


def _zy_transpose(theta, psi, v):
    """``(Rz(psi) Ry(theta))^T v`` for a (3,) ``v``: ``R(0, theta, psi)^T v`` as two planar
    rotations (no 3 x 3 matrix; a fraction of the operations under nested autodiff)."""
    c, s = jnp.cos(psi), jnp.sin(psi)
    x = c * v[0] + s * v[1]
    y = c * v[1] - s * v[0]
    ct, st = jnp.cos(theta), jnp.sin(theta)
    return jnp.stack([ct * x - st * v[2], y, st * x + ct * v[2]])


def pose_errors(path, coeffs, varpi, p):
    """``(pose, eps)``: [`path_errors_3d`][vcjax.control.vcm3d.path_errors_3d] from
    [`path_pose`][vcjax.paths.path_pose] (the same
    ``eps`` to round-off) for code that differentiates it (the engine's constraints, losses):
    no rates of the path are computed, and derivatives in ``varpi`` come from the pose's
    Taylor rule instead of differentiating the frame's own autodiff."""
    f = path_pose(path, coeffs, varpi)
    return f, _zy_transpose(f.theta_p, f.psi_p, p - f.p)


def _angles(cfg: VCM3DConfig, g: VCM3DGains, f, eps, zf):
    """``(psi_d, theta_d, e_int_dot, h_int_dot)`` from the path angles and the errors."""
    e, h = eps[1], eps[2]
    if cfg.guidance == "ilos":
        E = e + g.sigma_i[0] * zf[6]
        H = h + g.sigma_i[1] * zf[7]
        e_int_dot = g.Delta[0] * e / (E * E + g.Delta[0] ** 2)
        h_int_dot = g.Delta[1] * h / (H * H + g.Delta[1] ** 2)
    else:
        E, H = e, h
        e_int_dot = h_int_dot = jnp.zeros_like(e)
    psi_d = f.psi_p + jnp.arctan(-E / g.Delta[0])
    theta_d = f.theta_p + jnp.arctan(H / g.Delta[1])
    return psi_d, theta_d, e_int_dot, h_int_dot


def _constraints(cfg: VCM3DConfig, params: VCM3DParams) -> VirtualConstraints:
    g = params.gains

    def G(q, t, args, zf):
        f, eps = pose_errors(cfg.path, params.path, zf[0], q[:3])
        psi_d, theta_d, _, _ = _angles(cfg, g, f, eps, zf)
        pos = eps + g.k_int * zf[3:6] if cfg.integral else eps
        att = jnp.stack([wrap_angle(q[4] - psi_d), q[3] - theta_d])
        return jnp.concatenate([att, pos])

    def K(q, qd, t, args, zf):
        return _zy_transpose(q[3], q[4], qd[:3]) - jnp.stack([params.u_d, zf[1], zf[2]])

    def rate(q, t, zf, args):
        f, eps = pose_errors(cfg.path, params.path, zf[0], q[:3])
        varpi_dot = (params.u_d + g.sigma * eps[0]) * jnp.cos(f.theta_p) / f.speed_bar
        _, _, e_int_dot, h_int_dot = _angles(cfg, g, f, eps, zf)
        if cfg.integral:
            zeta = zf[3:6]
            zeta_dot = eps - (zeta - jnp.clip(zeta, -params.int_limit, params.int_limit))
        else:
            zeta_dot = jnp.zeros_like(eps)
        zero = jnp.zeros_like(varpi_dot)
        return jnp.concatenate(
            [jnp.stack([varpi_dot, zero, zero]), zeta_dot, jnp.stack([e_int_dot, h_int_dot])]
        )

    return VirtualConstraints(holonomic=G, velocity=K, state_rate=rate)


def vcm3d_law(cfg: VCM3DConfig, params: VCM3DParams, t, q, qd, z: VCM3DState):
    """The 3-D VCM law (module docstring).

    Args:
        cfg: static [`VCM3DConfig`][vcjax.control.vcm3d.VCM3DConfig]; params: traced
            [`VCM3DParams`][vcjax.control.vcm3d.VCM3DParams].
        t: () time [s]; q: (5,) ``[x, y, z, theta, psi]``; qd: (5,) its rate (over ground).
        z: [`VCM3DState`][vcjax.control.vcm3d.VCM3DState].

    Returns:
        ``(tau, z_dot, aux)``: (5,) body force ``[X, Y, Z, M, N]``, the
        [`VCM3DState`][vcjax.control.vcm3d.VCM3DState] rate
        and [`VCM3DAux`][vcjax.control.vcm3d.VCM3DAux].
    """
    g = params.gains
    cons = _constraints(cfg, params)
    gains = VCMGains(P_G=g.P_G, P_Phi=g.P_Phi)
    zf = _flat(z)
    m = params.model
    J = cfg.kinematics(q, m)
    A_b = cfg.tied_rows(m)
    zf_dot = cons.state_rate(q, t, zf, m)
    if cfg.actuation == "underactuated":
        under = Underactuation(
            unactuated=lambda q_, qd_, t_, a_: (A_b @ J.T, jnp.zeros((2,), q.dtype)), free=(1, 2)
        )
        tau_c, qdd, mu, diag = underactuated_reaction_force(
            cfg.system, cons, under, gains, q, qd, t, None, m, "column", zf
        )
        zf_dot = zf_dot.at[np.asarray(under.free)].add(mu)
    else:
        tau_c, qdd, diag = reaction_force(cfg.system, cons, gains, q, qd, t, None, m, "column", zf)
    tau_b = J.T @ tau_c
    f, eps = pose_errors(cfg.path, params.path, z.varpi, q[:3])
    psi_d, theta_d, _, _ = _angles(cfg, g, f, eps, zf)
    # nu_dot = J^-1 (q̈ - J̇ nu)
    if cfg.kinematics_inverse is not None:
        Jinv = cfg.kinematics_inverse(q, m)
    else:
        Jinv = solve_small(J, jnp.eye(J.shape[0], dtype=J.dtype))  # one elimination, two uses
    nu = Jinv @ qd
    J_dot = jax.jvp(lambda q_: cfg.kinematics(q_, m), (q,), (qd,))[1]
    nu_dot = Jinv @ (qdd - J_dot @ nu)
    aux = VCM3DAux(
        eps=eps,
        dist=safe_norm(eps),
        psi_tilde=wrap_angle(q[4] - psi_d),
        theta_tilde=q[3] - theta_d,
        psi_d=psi_d,
        theta_d=theta_d,
        Phi=diag.Phi,
        tau=tau_b,
        nu_dot_cmd=nu_dot,
        ls_residual=diag.residual,
        tied_gap=safe_norm(A_b @ tau_b),
    )
    return tau_b, _unflat(zf_dot), aux
