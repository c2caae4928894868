"""3-DOF horizontal-plane model of a marine craft in the paper's design form (20).

State: pose ``eta = [x, y, psi]`` (NED north/east [m], heading [rad]) and body velocity
``nu = [u, v, r]`` (surge, sway [m/s], yaw rate [rad/s]); ``eta_dot = J(psi) nu`` with
``J = diag(R(psi), 1)``.

Kinetics (2) restricted to the plane, with the paper's structure (20):

    M_b = [[m11, 0, 0], [0, m22, m23], [0, m23, m33]]
    D_b = [[d11, 0, 0], [0, d22, d23], [0, d32, d33]]
    C_b(nu) = [[0, 0, -(m22 v + m23 r)], [0, 0, m11 u], [m22 v + m23 r, -m11 u, 0]]

    M_b nu_r_dot + C_b(nu_r) nu_r + D_b nu_r = tau

with the relative velocity ``nu_r = nu - [R(psi)^T V_c, 0]`` for an irrotational ocean current
``V_c`` (2,) given in the inertial frame (docs/method.md). The controller uses this model; plants
may be
richer.
"""

from __future__ import annotations

from typing import Any, NamedTuple

import jax.numpy as jnp

from vcjax._checks import check_array, check_spd
from vcjax.environment.component import WaterMotion
from vcjax.linalg import matvec, solve_surge_decoupled
from vcjax.mechanics import MechanicalSystem, from_body_frame

__all__ = [
    "Design3DOF",
    "design3dof",
    "mass_matrix",
    "coriolis",
    "damping",
    "body_bias",
    "kinematics",
    "pose_rate",
    "current_in_body",
    "vector_field",
    "DESIGN3DOF_SYSTEM",
    "kinetic_energy",
]


class Design3DOF(NamedTuple):
    """Parameters of (20) as scalars (traced).

    Attributes:
        m11, m22, m23, m33: mass/inertia incl. added mass [kg, kg, kg m, kg m^2].
        d11, d22, d23, d32, d33: linear damping [N s/m, N s/m, N s, N s, N m s].
    """

    m11: Any
    m22: Any
    m23: Any
    m33: Any
    d11: Any
    d22: Any
    d23: Any
    d32: Any
    d33: Any


def design3dof(m11, m22, m23, m33, d11=0.0, d22=0.0, d23=0.0, d32=0.0, d33=0.0) -> Design3DOF:
    """Build validated [`Design3DOF`][vcjax.vehicles.design3dof.Design3DOF] (``M_b`` must be SPD;
    values finite scalars)."""
    vals = dict(m11=m11, m22=m22, m23=m23, m33=m33, d11=d11, d22=d22, d23=d23, d32=d32, d33=d33)
    for name, v in vals.items():
        check_array(name, v, ())
    p = Design3DOF(**{k: jnp.asarray(v) for k, v in vals.items()})
    check_spd("M_b (m11, m22, m23, m33)", mass_matrix(p), 3)
    return p


def mass_matrix(p: Design3DOF):
    """(3, 3) body inertia matrix ``M_b`` of (20a)."""
    z = jnp.zeros_like(p.m11)
    return jnp.stack(
        [
            jnp.stack([p.m11, z, z]),
            jnp.stack([z, p.m22, p.m23]),
            jnp.stack([z, p.m23, p.m33]),
        ]
    )


def damping(p: Design3DOF):
    """(3, 3) linear damping matrix ``D_b`` of (20a)."""
    z = jnp.zeros_like(p.d11)
    return jnp.stack(
        [
            jnp.stack([p.d11, z, z]),
            jnp.stack([z, p.d22, p.d23]),
            jnp.stack([z, p.d32, p.d33]),
        ]
    )


def coriolis(p: Design3DOF, nu):
    """(3, 3) Coriolis–centripetal matrix ``C_b(nu)`` of (20b); skew-symmetric."""
    u, v, r = nu[0], nu[1], nu[2]
    a = p.m22 * v + p.m23 * r
    b = p.m11 * u
    z = jnp.zeros_like(a)
    return jnp.stack([jnp.stack([z, z, -a]), jnp.stack([z, z, b]), jnp.stack([a, -b, z])])


def body_bias(p: Design3DOF, nu):
    """(3,) ``n_b(nu) = C_b(nu) nu + D_b nu``."""
    return matvec(coriolis(p, nu), nu) + matvec(damping(p), nu)


def kinematics(psi):
    """(3, 3) ``J(psi) = diag(R(psi), 1)``."""
    c, s = jnp.cos(psi), jnp.sin(psi)
    z, o = jnp.zeros_like(psi), jnp.ones_like(psi)
    return jnp.stack([jnp.stack([c, -s, z]), jnp.stack([s, c, z]), jnp.stack([z, z, o])])


def pose_rate(psi, nu):
    """(3,) ``eta_dot = J(psi) nu = [u cos psi - v sin psi, u sin psi + v cos psi, r]``.

    The product written out: no 3x3 matrix is built (inside a batched rollout the matrix would
    be materialised per trajectory and stage).
    """
    c, s = jnp.cos(psi), jnp.sin(psi)
    return jnp.stack([c * nu[0] - s * nu[1], s * nu[0] + c * nu[1], nu[2]])


def current_in_body(psi, r, V_c, V_c_dot=None):
    """Body-frame current velocity ``[R^T V_c, 0]`` and its time derivative.

    Args:
        psi: () heading [rad]; r: () yaw rate [rad/s].
        V_c: (2,) current in the inertial frame [m/s]; V_c_dot: (2,) its rate [m/s^2].

    Returns:
        ``(nu_c, nu_c_dot)``, each (3,). ``d/dt R^T V_c = -S(r) R^T V_c + R^T V_c_dot``.
    """
    c, s = jnp.cos(psi), jnp.sin(psi)

    def body(w):  # R(psi)^T w
        return jnp.stack([c * w[0] + s * w[1], c * w[1] - s * w[0]])

    vc = body(V_c)
    vc_dot = jnp.stack([r * vc[1], -r * vc[0]])
    if V_c_dot is not None:
        vc_dot = vc_dot + body(V_c_dot)
    z = jnp.zeros_like(psi)
    return jnp.concatenate([vc, z[None]]), jnp.concatenate([vc_dot, z[None]])


def vector_field(p: Design3DOF, eta, nu, tau, water: WaterMotion | None = None):
    """``(eta_dot, nu_dot)`` of the design model in optional water.

    Args:
        p: parameters; eta: (3,) pose; nu: (3,) body velocity; tau: (3,) body force
            ``[tau_u, tau_v, tau_r]`` [N, N, N m];
        water: [`WaterMotion`][vcjax.environment.component.WaterMotion] (the one door of every
            plant; velocity and acceleration (3,) NED): its horizontal parts are the current
            ``V_c`` and its rate (a horizontal-plane model cannot feel the vertical one).
            Default none (still water).
    """
    eta_dot = pose_rate(eta[2], nu)
    if water is None:
        nu_r, nu_c_dot = nu, jnp.zeros_like(nu)
    else:
        a = None if water.acceleration is None else water.acceleration[:2]
        nu_c, nu_c_dot = current_in_body(eta[2], nu[2], water.velocity[:2], a)
        nu_r = nu - nu_c
    nu_r_dot = solve_surge_decoupled(mass_matrix(p), tau - body_bias(p, nu_r))
    return eta_dot, nu_r_dot + nu_c_dot


def kinetic_energy(p: Design3DOF, nu):
    """() ``0.5 nu^T M_b nu`` [J]."""
    return 0.5 * nu @ mass_matrix(p) @ nu


def _mb(q, p):
    return mass_matrix(p)


def _nb(q, nu, p):
    return body_bias(p, nu)


def _J(q, p):
    return kinematics(q[2])


#: The design model in generalised coordinates ``q = eta`` for the generic engine
#: ([`vcjax.mechanics`][vcjax.mechanics]); its ``args`` must be a
#: [`Design3DOF`][vcjax.vehicles.design3dof.Design3DOF]. Forces on it are
#: generalised (inertial-frame) forces ``tau = J^{-T} tau_b``. A module constant, so that jitted
#: functions taking it as a static argument compile once.
DESIGN3DOF_SYSTEM: MechanicalSystem = from_body_frame(_mb, _nb, _J)
