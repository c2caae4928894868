"""ODIN-class omnidirectional AUV: a neutrally buoyant sphere with 4 + 4 thrusters (Simulation 2).

What this model is — and is not
-------------------------------
The paper's Simulation 2 uses the ODIN AUV (Univ. of Hawaii) with parameters "taken from [39]",
which is not publicly readable. This module simulates an **ODIN-class** vehicle (sources in
``docs/reference/vehicles.md``): a sphere model with the thruster configuration matrix of a public
ODIN code base. Only these items are sourced: 8 thrusters (4 horizontal, 4 vertical), 27 N each,
spherical, neutrally buoyant, first-order thruster dynamics [PAPER]; the 6x8 configuration matrix
with arms ``R_hor = 0.356 m``, ``R_ver = 0.252 m`` [SRC ODIN-N, public code, not checked against
the primary paper]. Everything else is inferred and tagged; it is *not* ODIN's published model.

Parameters (defaults; tags as in ``docs/reference/vehicles.md``):

============================  =====================================  ==========  ========
quantity                      formula                                value       tag
============================  =====================================  ==========  ========
radius R                      —                                      0.3 m       [INF]
water density rho             —                                      1025 kg/m3  [INF]
displaced volume V            4/3 pi R^3                             0.1131 m3   [DER]
mass m (neutral: W = B)       rho V                                  115.9 kg    [INF]
inertia about the CG          2/5 m R^2 (solid sphere), each axis    4.17 kg m2  [INF]
translational added mass      1/2 rho V (exact: sphere, ideal fluid) 57.96 kg    [INF]
rotational added inertia      0 (sphere)                             0           [INF]
quadratic drag (isotropic)    F = -k |v_r| v_r, k = 1/2 rho Cd pi R^2  68.1 kg/m [INF]
                              (Cd = 0.47, subcritical sphere)
linear damping, translation   (m + 1/2 rho V) / T_trans, T_trans=20 s  8.69 N s/m  [INF]
linear damping, rotation      I / T_rot, T_rot = 2 s                 2.09 N m s  [INF]
CG below CB (metacentric BG)  z_g                                    0.02 m      [INF]
thruster limit                —                                      27 N        [PAPER]
thruster time constant        T_thrust                               0.2 s       [INF]
============================  =====================================  ==========  ========

Why these [INF] choices: a sphere's linear (skin-friction) damping is small next to the pressure
drag at cruise (at 0.5 m/s: 4.3 N vs 17 N), but it is what damps motion near rest; a 20 s time
constant keeps it a minor term. A sphere has no rotational added inertia or pressure drag in
rotation; the real ODIN's thrusters and housings do resist rotation, which a 2 s time constant
stands for. ``z_g = 2 cm`` gives roll/pitch restoring ``z_g W = 22.7 N m/rad`` (natural period
~2.7 s, open-loop damping ratio ~0.1), so that the vehicle is "structurally stable in roll and
pitch" as Corollaries 2-3 assume; the attitude PD of
[`vcjax.experiments.sim2`][vcjax.experiments.sim2] adds the damping.
The CG offset makes ``M_RB`` couple surge-pitch and sway-roll (``m z_g = 2.3 kg m``), as Fossen's
``H(r_bg)`` transformation prescribes. Quadratic drag is isotropic (``|v_r| v_r``, the physics of
a sphere) rather than Fossen's axis-by-axis ``|u| u``: the drag of a sphere does not depend on
the direction of the flow.

Model (6-DOF, built on [`vcjax.vehicles.sixdof`][vcjax.vehicles.sixdof]: ``m2c`` Coriolis of rigid
body + added mass,
``gvect`` restoring, ``J(Theta)`` kinematics, relative velocity to an irrotational current)::

    M nu_r_dot + C(nu_r) nu_r + D_lin nu_r + g(eta) = T f + tau_dist + tau_drag(nu_r)
    tau_drag = [-k |v_r| v_r; 0],   f_dot = (sat(f_cmd) - f) / T_thrust

with ``f`` (8,) the thruster forces (state), ``f_cmd`` (8,) the commands (input; clipped to
``±thrust_max``, or ``thrust_max tanh(f_cmd / thrust_max)`` in
[`odin_plant_smooth`][vcjax.vehicles.odin.odin_plant_smooth]),
``tau_dist`` (6,) a constant body-frame disturbance (traced) and ``water`` the water at the
vehicle ([`WaterMotion`][vcjax.environment.component.WaterMotion], the one door of every plant):
its velocity ``v_c`` (3,) in NED, all three components felt, with its material acceleration
``v_c_dot`` (3,) when it varies (a tidal current, a sea):
``nu_dot = nu_r_dot + nu_c_dot`` as in [`vector_field`][vcjax.vehicles.sixdof.vector_field], so the
water's acceleration acts on the rigid body and, through ``M_A``, on the added mass. Thruster
matrix (``s = 1/sqrt(2)``; rows ``[X Y Z K M N]``, columns
``[H1..H4 V1..V4]``; a positive vertical thrust pushes up, i.e. ``-Z``)::

      X [  s    -s    -s     s     0        0        0        0      ]
      Y [  s     s    -s    -s     0        0        0        0      ]
      Z [  0     0     0     0    -1       -1       -1       -1      ]
      K [  0     0     0     0     Rver s   Rver s  -Rver s  -Rver s ]
      M [  0     0     0     0     Rver s  -Rver s  -Rver s   Rver s ]
      N [  Rhor -Rhor  Rhor -Rhor  0        0        0        0      ]

Maximum single-axis forces with 27 N per thruster [DER]: ``|X| = |Y| = 76.4 N``, ``|Z| = 108 N``,
``|K| = |M| = 19.2 N m``, ``|N| = 38.4 N m``; cruise speed at full surge force ~1 m/s.

Everything traced is a ``NamedTuple`` of arrays; functions are pure ``jax.numpy``, jit/vmap/grad-
safe (the drag uses a NaN-safe norm at rest), in float32 and float64.
"""

from __future__ import annotations

import math
from typing import Any, NamedTuple

import jax.numpy as jnp
import numpy as np

from vcjax._checks import (
    as_float_array,
    check_array,
    check_params,
    check_positive,
    float_dtype,
    is_concrete,
)
from vcjax.environment.component import WaterMotion
from vcjax.linalg import safe_norm, saturate, smooth_saturate
from vcjax.vehicles import sixdof as sd
from vcjax.vehicles.design3dof import Design3DOF, design3dof

__all__ = [
    "OdinParams",
    "odin_params",
    "validate",
    "thruster_matrix",
    "OdinState",
    "odin_state",
    "OdinArgs",
    "odin_args",
    "mass_matrix",
    "drag_force",
    "potential_energy",
    "total_energy",
    "odin_plant",
    "odin_plant_smooth",
    "design_model",
    "describe",
]


class OdinParams(NamedTuple):
    """ODIN-class parameters (traced).

    Attributes:
        body: [`SixDofParams`][vcjax.vehicles.sixdof.SixDofParams] — ``M_RB`` (CG offset ``z_g``
            included), ``M_A``, linear damping ``D`` (6, 6), ``W = B``, ``r_bg``, ``r_bb``.
        radius: () hull radius R [m]; rho: () water density [kg/m^3].
        drag_coeff: () isotropic quadratic drag ``k = 1/2 rho Cd pi R^2`` [kg/m].
        thrusters: (6, 8) thruster configuration matrix (force/moment per newton of thrust).
        thrust_max: (8,) thrust limits [N].
        T_thrust: () thruster time constant [s].
    """

    body: sd.SixDofParams
    radius: Any
    rho: Any
    drag_coeff: Any
    thrusters: Any
    thrust_max: Any
    T_thrust: Any


class OdinState(NamedTuple):
    """Plant state (traced).

    Attributes:
        eta: (6,) ``[x, y, z, phi, theta, psi]`` (NED [m], zyx Euler angles [rad]).
        nu: (6,) ``[u, v, w, p, q, r]`` body velocity over ground [m/s, rad/s].
        thrust: (8,) thruster forces [N] (actuator states, ``[H1..H4, V1..V4]``).
    """

    eta: Any
    nu: Any
    thrust: Any


class OdinArgs(NamedTuple):
    """Traced arguments of [`odin_plant`][vcjax.vehicles.odin.odin_plant].

    Attributes:
        vehicle: [`OdinParams`][vcjax.vehicles.odin.OdinParams].
        tau_dist: (6,) constant body-frame disturbance ``[X, Y, Z, K, M, N]`` [N, N m].
        water: [`WaterMotion`][vcjax.environment.component.WaterMotion], the water at the
            vehicle (irrotational; uniform over the hull): velocity (3,) NED [m/s] and material
            acceleration (3,) [m/s^2], or ``None`` for a constant current (the same results as
            zeros).
    """

    vehicle: OdinParams
    tau_dist: Any
    water: WaterMotion


def thruster_matrix(R_hor=0.356, R_ver=0.252, dtype=None):
    """(6, 8) ODIN thruster configuration matrix (sources: ``docs/reference/vehicles.md``; module
    docstring).

    Args:
        R_hor: yaw arm of the horizontal thrusters [m]; R_ver: arm of the vertical ones [m]
            (enters roll/pitch as ``R_ver / sqrt(2)``).
    """
    check_positive("R_hor", R_hor, ())
    check_positive("R_ver", R_ver, ())
    s = 1.0 / math.sqrt(2.0)
    rh, rv = float(R_hor), float(R_ver) * s
    T = np.array(
        [
            [s, -s, -s, s, 0, 0, 0, 0],
            [s, s, -s, -s, 0, 0, 0, 0],
            [0, 0, 0, 0, -1, -1, -1, -1],
            [0, 0, 0, 0, rv, rv, -rv, -rv],
            [0, 0, 0, 0, rv, -rv, -rv, rv],
            [rh, -rh, rh, -rh, 0, 0, 0, 0],
        ]
    )
    return jnp.asarray(T, dtype=float_dtype(dtype))


def odin_params(
    radius=0.3,
    rho=1025.0,
    g=9.81,
    Cd=0.47,
    z_g=0.02,
    T_trans=20.0,
    T_rot=2.0,
    R_hor=0.356,
    R_ver=0.252,
    thrust_max=27.0,
    T_thrust=0.2,
    dtype=None,
) -> OdinParams:
    """Build the ODIN-class parameters (module docstring for formulas and tags).

    Args:
        radius: hull radius R [m] ([INF] 0.3). rho: water density [kg/m^3]. g: [m/s^2].
        Cd: sphere drag coefficient (0.47, subcritical). z_g: CG below the CB [m] (>= 0; [INF]
            0.02). T_trans, T_rot: time constants [s] that set the linear damping
            ``D_ii = M_ii / T`` of translation and rotation ([INF] 20 s, 2 s).
        R_hor, R_ver: thruster arms [m]. thrust_max: per-thruster limit [N] (paper: 27).
        T_thrust: thruster time constant [s] ([INF] 0.2).
        dtype: float dtype of every array (default: JAX's default float).

    Raises:
        ValueError: naming the offending field.
    """
    scalars = dict(
        radius=radius,
        rho=rho,
        g=g,
        Cd=Cd,
        T_trans=T_trans,
        T_rot=T_rot,
        thrust_max=thrust_max,
        T_thrust=T_thrust,
    )
    for name, v in scalars.items():
        check_positive(name, v, ())
    check_positive("z_g", z_g, (), strict=False)
    R = float(radius)
    if not float(z_g) < R:
        raise ValueError(f"z_g: the CG must lie inside the hull (z_g < radius = {R}), got {z_g}")
    dtype = float_dtype(dtype)
    V = 4.0 / 3.0 * math.pi * R**3
    m = float(rho) * V
    Ig = 0.4 * m * R**2
    ma = 0.5 * float(rho) * V
    r_bg = np.array([0.0, 0.0, float(z_g)])
    M_RB = np.asarray(
        sd.rigid_body_mass_matrix(
            jnp.asarray(m, dtype), jnp.asarray(Ig * np.eye(3), dtype), jnp.asarray(r_bg, dtype)
        )
    )
    M_A = np.diag([ma, ma, ma, 0.0, 0.0, 0.0])
    Mdiag = np.diag(M_RB + M_A)
    T_d = np.array([T_trans] * 3 + [T_rot] * 3, dtype=float)
    D = np.diag(Mdiag / T_d)
    W = m * float(g)
    body = sd.sixdof_params(M_RB, M_A, D, W, W, r_bg, np.zeros(3), dtype=dtype)
    f = lambda x: jnp.asarray(x, dtype=dtype)
    return OdinParams(
        body=body,
        radius=f(R),
        rho=f(rho),
        drag_coeff=f(0.5 * float(rho) * float(Cd) * math.pi * R**2),
        thrusters=thruster_matrix(R_hor, R_ver, dtype=dtype),
        thrust_max=f(np.full(8, float(thrust_max))),
        T_thrust=f(T_thrust),
    )


def validate(params: OdinParams, name: str = "vehicle") -> OdinParams:
    """Eagerly check [`OdinParams`][vcjax.vehicles.odin.OdinParams] however they were built (also
    after ``_replace``):
    every field finite; radius, density, thrust limits and time constant > 0, drag >= 0; the body
    ([`vcjax.vehicles.sixdof.validate`][vcjax.vehicles.sixdof.validate]); thruster matrix (6, 8).

    Returns ``params``. Raises ``ValueError`` naming ``name.field``. Skipped under ``jit``.
    """
    check_params(
        OdinParams,
        params,
        positive=("radius", "rho", "thrust_max", "T_thrust"),
        nonnegative=("drag_coeff",),
        name=name,
    )
    sd.validate(params.body, f"{name}.body")
    check_array(f"{name}.thrusters", params.thrusters, (6, 8))
    return params


def odin_state(eta, nu=None, thrust=None, dtype=None) -> OdinState:
    """Validated [`OdinState`][vcjax.vehicles.odin.OdinState]; ``nu`` (6,) and ``thrust`` (8,)
    default to zeros.

    Args:
        eta: (6,) pose; nu: (6,) body velocity; thrust: (8,) thruster forces [N].
        dtype: float dtype (default: JAX's default float).

    Raises:
        ValueError: naming the field for a wrong shape or a NaN/inf entry.
    """
    dtype = float_dtype(dtype)
    eta = as_float_array("eta", eta, (6,), dtype)
    nu = jnp.zeros(6, dtype) if nu is None else as_float_array("nu", nu, (6,), dtype)
    thrust = (
        jnp.zeros(8, dtype) if thrust is None else as_float_array("thrust", thrust, (8,), dtype)
    )
    return OdinState(eta=eta, nu=nu, thrust=thrust)


def odin_args(vehicle: OdinParams, tau_dist=None, water: WaterMotion | None = None) -> OdinArgs:
    """Validated [`OdinArgs`][vcjax.vehicles.odin.OdinArgs] (arrays take the dtype of ``vehicle``).

    Args:
        vehicle: [`OdinParams`][vcjax.vehicles.odin.OdinParams].
        tau_dist: (6,) body disturbance ``[X, Y, Z, K, M, N]``, or (3,) forces only (the paper's
            ``[0, 5, 0]`` N; moments zero). Default zeros.
        water: [`WaterMotion`][vcjax.environment.component.WaterMotion] (velocity (3,) NED,
            acceleration (3,) or ``None``: a constant current). Default still water.
    """
    validate(vehicle)
    dtype = jnp.asarray(vehicle.radius).dtype
    if tau_dist is None:
        tau_dist = jnp.zeros(6, dtype)
    else:
        a = check_array("tau_dist", tau_dist, None)
        if a is not None and a.shape not in ((3,), (6,)):
            raise ValueError(f"tau_dist: expected shape (3,) or (6,), got {a.shape}")
        tau_dist = jnp.asarray(tau_dist, dtype=dtype)
        if tau_dist.shape == (3,):
            tau_dist = jnp.concatenate([tau_dist, jnp.zeros(3, dtype)])
    v, a = (None, None) if water is None else water
    v = jnp.zeros(3, dtype) if v is None else as_float_array("water.velocity", v, (3,), dtype)
    if a is not None:
        a = as_float_array("water.acceleration", a, (3,), dtype)
    return OdinArgs(vehicle=vehicle, tau_dist=tau_dist, water=WaterMotion(v, a))


# --------------------------------------------------------------------------------------------
# Model
# --------------------------------------------------------------------------------------------


def mass_matrix(p: OdinParams):
    """(6, 6) ``M = M_RB + M_A``."""
    return sd.mass_matrix(p.body)


def drag_force(p: OdinParams, nu_r):
    """(6,) isotropic quadratic drag ``[-k |v_r| v_r; 0]`` of the sphere [N]."""
    v = nu_r[:3]
    F = -p.drag_coeff * safe_norm(v) * v
    return jnp.concatenate([F, jnp.zeros_like(F)])


def potential_energy(p: OdinParams, eta):
    """() gravity + buoyancy potential [J], zero when level: ``-W z_CG + B z_CB`` (NED)."""
    R = sd.Rzyx(eta[3], eta[4], eta[5])
    b = p.body
    z_g, z_b = R[2] @ b.r_bg, R[2] @ b.r_bb
    level_g, level_b = b.r_bg[2], b.r_bb[2]
    return -b.W * (eta[2] + z_g - level_g) + b.B * (eta[2] + z_b - level_b)


def total_energy(p: OdinParams, x: OdinState, water: WaterMotion | None = None):
    """() kinetic (relative to a constant current ``water``, rigid body + added mass) +
    potential [J]."""
    nu_r = x.nu
    if water is not None:
        nu_c, _ = sd.current_in_body(x.eta, x.nu, water.velocity)
        nu_r = x.nu - nu_c
    return sd.kinetic_energy(p.body, nu_r) + potential_energy(p, x.eta)


def _plant(t, x: OdinState, u_cmd, args: OdinArgs, smooth: bool) -> OdinState:
    p = args.vehicle
    sat = smooth_saturate if smooth else saturate
    thrust_dot = (sat(u_cmd, p.thrust_max) - x.thrust) / p.T_thrust
    v_c, v_c_dot = args.water  # all three components: a 6-DOF body feels vertical water
    nu_c, _ = sd.current_in_body(x.eta, x.nu, v_c)
    nu_r = x.nu - nu_c
    tau = p.thrusters @ x.thrust + args.tau_dist + drag_force(p, nu_r)
    eta_dot, nu_dot = sd.vector_field(p.body, x.eta, x.nu, tau, args.water)
    return OdinState(eta=eta_dot, nu=nu_dot, thrust=thrust_dot)


def odin_plant(t, x: OdinState, u_cmd, args: OdinArgs) -> OdinState:
    """Vector field ``x_dot = f(t, x, u_cmd, args)`` (the [`vcjax.rollout`][vcjax.rollout]
    signature).

    Args:
        t: () time [s] (unused; autonomous).
        x: [`OdinState`][vcjax.vehicles.odin.OdinState].
        u_cmd: (8,) thruster commands [N] (hard-clipped to ``±thrust_max``).
        args: [`OdinArgs`][vcjax.vehicles.odin.OdinArgs] (vehicle, ``tau_dist`` (6,), the water).

    Returns:
        [`OdinState`][vcjax.vehicles.odin.OdinState] of time derivatives.
    """
    return _plant(t, x, u_cmd, args, smooth=False)


def odin_plant_smooth(t, x: OdinState, u_cmd, args: OdinArgs) -> OdinState:
    """As [`odin_plant`][vcjax.vehicles.odin.odin_plant] with ``thrust_max tanh(cmd / thrust_max)``
    (for gradients)."""
    return _plant(t, x, u_cmd, args, smooth=True)


# --------------------------------------------------------------------------------------------
# Controller-side helpers
# --------------------------------------------------------------------------------------------


def design_model(p: OdinParams, u_design=0.5) -> Design3DOF:
    """The horizontal 3-DOF design model (20) of the sphere at straight-line motion ``u_design``.

    Inertia: ``m11 = M[u,u]``, ``m22 = M[v,v]`` (mass + 1/2 rho V), ``m23 = M[v,r]`` (0: no
    longitudinal CG offset), ``m33 = M[r,r]``. Damping: linear terms plus the quadratic drag
    linearised at ``nu_r = [u_design, 0, 0]``: ``d11 = D_u + k u_design`` (secant: ``d11 u_d``
    is the true drag at the design speed), ``d22 = D_v + k u_design`` (tangent of the isotropic
    drag ``k |v_r| v`` at ``v = 0``; it coincides with the secant), ``d33 = D_r``, ``d23 = d32 =
    0``. The design model's Coriolis (20b) equals the plant's horizontal ``m2c`` terms here
    (``m11 = m22``: no Munk moment).
    """
    check_positive("u_design", u_design, ())
    M = mass_matrix(p)
    D = p.body.D
    kud = p.drag_coeff * u_design
    return design3dof(
        M[0, 0], M[1, 1], M[1, 5], M[5, 5], D[0, 0] + kud, D[1, 1] + kud, D[1, 5], D[5, 1], D[5, 5]
    )


def describe(p: OdinParams) -> str:
    """A short text table of the vehicle's main numbers (for reports)."""
    if not is_concrete(p.radius):
        raise ValueError("params: describe() needs concrete (non-traced) parameters")
    M = np.asarray(mass_matrix(p))
    D = np.asarray(p.body.D)
    T = np.asarray(p.thrusters)
    fm = np.asarray(p.thrust_max)
    rows = [
        ("radius", float(p.radius), "m"),
        ("mass", float(p.body.M_RB[0, 0]), "kg"),
        ("M[u,u] = m + 1/2 rho V", M[0, 0], "kg"),
        ("M[p,p] (I + m z_g^2)", M[3, 3], "kg m^2"),
        ("M[r,r]", M[5, 5], "kg m^2"),
        ("drag k", float(p.drag_coeff), "kg/m"),
        ("D lin (u)", D[0, 0], "N s/m"),
        ("D lin (r)", D[5, 5], "N m s"),
        ("z_g W (roll stiffness)", float(p.body.r_bg[2] * p.body.W), "N m/rad"),
        ("max |X|", float(np.abs(T[0]) @ fm), "N"),
        ("max |Z|", float(np.abs(T[2]) @ fm), "N"),
        ("max |N|", float(np.abs(T[5]) @ fm), "N m"),
        ("T_thrust", float(p.T_thrust), "s"),
    ]
    lines = ["ODIN-class sphere model", "| quantity | value | unit |", "|---|---|---|"]
    lines += [f"| {n} | {v:.4g} | {u} |" for n, v, u in rows]
    return "\n".join(lines)
