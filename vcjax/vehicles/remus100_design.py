"""REMUS 100 for the controller: a 5-DOF design model and the actuator map.

Design model
------------
The VCM law needs ``M(q) q̈ + n(q, q̇) = τ`` (1). For REMUS 100 it is the PVS plant of
[`vcjax.vehicles.remus100`][vcjax.vehicles.remus100] with roll removed and the unknowns dropped:

* DOF: ``q = [x, y, z, theta, psi]`` (NED [m], pitch and yaw [rad]), body velocity
  ``nu5 = [u, v, w, q, r]``; roll is held at ``phi = p = 0`` (REMUS is metacentrically stable in
  roll and has no roll actuator; the propeller's roll torque is PVS-scaled by 0.1). Kinematics
  ``q̇ = J5(q) nu5`` with ``J5 = blockdiag(Rz(psi) Ry(theta), [[1, 0], [0, 1/cos(theta)]])``
  (Fossen's ``J(Theta)`` at ``phi = 0``).
* Kept exactly (rows/columns ``[0, 1, 2, 4, 5]`` of the plant's 6-DOF terms): ``M = M_RB + M_A``;
  Coriolis ``C(nu) nu`` with PVS's zeroed ``C_A`` entries; the linear damping ``D`` with its
  ``exp(-3 U)`` fade of ``D11, D22`` evaluated at the **design speed** ``U_design``; hull lift
  and drag; restoring forces.
* Dropped: the ocean current (the controller measures velocity over ground only: the integral
  action and the integral-LOS angles of [`vcjax.control.vcm3d`][vcjax.control.vcm3d] take it up),
  the roll DOF,
  the fins' induced drag (the actuator map compensates it), and the actuator lags.

So on the plant, at ``phi = p = 0`` and zero current, ``M[IDX5, :] nu_dot + n5 = tau[IDX5]``
holds exactly when ``U_design`` equals the speed (tested).

Actuator map
------------
The law's body force ``tau5 = [X, Y, Z, M, N]`` is inverted through the plant's own actuator
models at the measured velocity over ground ``nu`` (the fins see the relative flow; the
controller does not know the current):

* rudder from the yaw moment ``N = x_r Y_r = -x_r k_r delta_r``, stern planes from the pitch
  moment ``M = -x_s Z_s = x_s k_s delta_s``, with ``k = 1/2 rho U^2 A CL`` and
  ``U^2 = max(u^2 + v^2, U_min^2)`` (resp. ``u^2 + w^2``): the floor keeps the division finite
  at rest. Each fin's force comes with its moment, ``Y = N / x_r`` and ``Z = -M / x_s``: these
  are the two *tied* force directions the underactuated law must respect
  ([`unactuated_rows`][vcjax.vehicles.remus100_design.unactuated_rows]).
* propeller from the surge force after the fins' induced drag: ``X_prop = (X + k_r delta_r^2
  + k_s delta_s^2) / (1 - t)``, inverting ``X_prop = a n|n| + b |n|`` on its forward branch
  (``n = (-b + sqrt(b^2 + 4 a X_prop)) / (2 a)``, where ``b < 0`` at speed: the linearised
  Wageningen fit brakes at low rpm). Commands below that branch's minimum thrust give its
  minimum; the map never reverses the propeller (a survey AUV brakes with its drag).
* every command is clipped to ``act_max`` (15 deg, 15 deg, 1525 rpm).
"""

from __future__ import annotations

from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from vcjax._checks import check_positive
from vcjax.linalg import safe_norm, safe_sqrt, saturate
from vcjax.mechanics import MechanicalSystem, from_body_frame
from vcjax.vehicles import design3dof as d3
from vcjax.vehicles import remus100 as r100

__all__ = [
    "IDX5",
    "Remus100Design",
    "design_model",
    "to_six",
    "kinematics5",
    "mass_matrix5",
    "body_bias5",
    "design_system",
    "unactuated_rows",
    "fin_gains",
    "actuator_map",
    "ActuatorCommand",
]

#: rows/columns of the 6-DOF plant the design model keeps: surge, sway, heave, pitch, yaw
IDX5 = (0, 1, 2, 4, 5)


class Remus100Design(NamedTuple):
    """Traced parameters of the design model and the actuator map.

    Attributes:
        vehicle: [`Remus100Params`][vcjax.vehicles.remus100.Remus100Params] (PVS numbers).
        U_design: () speed at which the damping fade ``exp(-3 U)`` is evaluated [m/s].
        U_min: () floor of the fin speed in the actuator map [m/s].
    """

    vehicle: Any
    U_design: Any
    U_min: Any


def design_model(p: r100.Remus100Params, U_design=1.5, U_min=0.5) -> Remus100Design:
    """Validated [`Remus100Design`][vcjax.vehicles.remus100_design.Remus100Design] (``U_design``,
    ``U_min`` > 0, in m/s)."""
    if not isinstance(p, r100.Remus100Params):
        raise ValueError(f"vehicle: expected Remus100Params, got {type(p).__name__}")
    check_positive("U_design", U_design, ())
    check_positive("U_min", U_min, ())
    dtype = jnp.asarray(p.rho).dtype
    return Remus100Design(p, jnp.asarray(U_design, dtype), jnp.asarray(U_min, dtype))


def to_six(q5, nu5):
    """``(eta (6,), nu (6,))`` with ``phi = p = 0`` from the design model's ``q5``, ``nu5``."""
    z = jnp.zeros((1,), q5.dtype)
    eta = jnp.concatenate([q5[:3], z, q5[3:]])
    nu = jnp.concatenate([nu5[:3], z, nu5[3:]])
    return eta, nu


def kinematics5(q5, args=None):
    """(5, 5) ``J5(q)``: ``q̇ = J5 nu5`` (``phi = 0``); ``args`` unused (engine signature).

    ``blkdiag(R(0, theta, psi), diag(1, 1/cos theta))``: the rows and columns ``IDX5`` of
    [`kinematics`][vcjax.vehicles.sixdof.kinematics] at zero roll, entry for entry the same numbers,
    written out (the law differentiates it: no sines and cosines of a zero roll to carry)."""
    theta, psi = q5[3], q5[4]
    cth, sth = jnp.cos(theta), jnp.sin(theta)
    cpsi, spsi = jnp.cos(psi), jnp.sin(psi)
    one, z = jnp.ones_like(theta), jnp.zeros_like(theta)
    return jnp.stack(
        [
            jnp.stack([cpsi * cth, -spsi, cpsi * sth, z, z]),
            jnp.stack([spsi * cth, cpsi, sth * spsi, z, z]),
            jnp.stack([-sth, z, cth, z, z]),
            jnp.stack([z, z, z, one, z]),
            jnp.stack([z, z, z, z, one / cth]),
        ]
    )


def kinematics5_inverse(q5, args=None):
    """(5, 5) ``J5(q)^-1`` in closed form: ``J5 = blkdiag(R(0, theta, psi), diag(1,
    1/cos theta))``, so its inverse is ``blkdiag(R^T, diag(1, cos theta))`` (no elimination
    in the traced program)."""
    J = kinematics5(q5, args)
    R = J[:3, :3]
    z32 = jnp.zeros((3, 2), J.dtype)
    low = jnp.stack([jnp.ones_like(q5[3]), jnp.zeros_like(q5[3]), jnp.cos(q5[3])])
    T_inv = jnp.stack([low[:2], jnp.stack([low[1], low[2]])])
    return jnp.block([[R.T, z32], [z32.T, T_inv]])


def mass_matrix5(dm: Remus100Design):
    """(5, 5) ``M = M_RB + M_A`` without the roll row and column."""
    idx = np.asarray(IDX5)
    return r100.mass_matrix(dm.vehicle)[idx][:, idx]


def body_bias5(dm: Remus100Design, q5, nu5):
    """(5,) ``n5 = C(nu) nu + D(U_design) nu + g(eta) - lift/drag(nu)``.

    Args:
        dm: design parameters; q5: (5,) pose; nu5: (5,) body velocity over ground.
    """
    p = dm.vehicle
    eta, nu = to_six(q5, nu5)
    n6 = (
        (r100.coriolis(p, nu) + r100.damping(p, dm.U_design)) @ nu
        + r100.restoring(p, eta)
        - r100.lift_drag(p, nu)
    )
    return n6[np.asarray(IDX5)]


def design_system() -> MechanicalSystem:
    """The design model as a [`MechanicalSystem`][vcjax.mechanics.MechanicalSystem] in ``q =
    [x, y, z,
    theta, psi]`` (generalised forces ``tau = J5^-T tau_b``); ``args`` is
    [`Remus100Design`][vcjax.vehicles.remus100_design.Remus100Design].
    """
    return from_body_frame(
        lambda q, dm: mass_matrix5(dm),
        lambda q, nu, dm: body_bias5(dm, q, nu),
        kinematics5,
        kinematics_inverse=kinematics5_inverse,
    )


def unactuated_rows(dm: Remus100Design):
    """(2, 5) body-frame rows ``A_b`` with ``A_b tau5 = 0`` for any fin force: ``Y - N/x_r = 0``
    (rudder) and ``Z + M/x_s = 0`` (stern planes)."""
    p = dm.vehicle
    z = jnp.zeros_like(p.x_r)
    one = jnp.ones_like(p.x_r)
    return jnp.stack(
        [jnp.stack([z, one, z, z, -one / p.x_r]), jnp.stack([z, z, one, one / p.x_s, z])]
    )


def fin_gains(dm: Remus100Design, nu):
    """``(k_r, k_s)`` [N/rad]: fin force per unit deflection at the (floored) measured speed."""
    p = dm.vehicle
    Umin2 = dm.U_min * dm.U_min
    U_h2 = jnp.maximum(nu[0] ** 2 + nu[1] ** 2, Umin2)
    U_v2 = jnp.maximum(nu[0] ** 2 + nu[2] ** 2, Umin2)
    return 0.5 * p.rho * U_h2 * p.A_r * p.CL_delta_r, 0.5 * p.rho * U_v2 * p.A_s * p.CL_delta_s


class ActuatorCommand(NamedTuple):
    """Output of [`actuator_map`][vcjax.vehicles.remus100_design.actuator_map].

    Attributes:
        cmd: (3,) ``[delta_r rad, delta_s rad, n rpm]`` clipped to the limits.
        raw: (3,) the same before clipping (saturation statistics).
    """

    cmd: Any
    raw: Any


def actuator_map(dm: Remus100Design, tau5, nu) -> ActuatorCommand:
    """Invert fin lift and propeller thrust (module docstring).

    Args:
        dm: design parameters; tau5: (5,) body force ``[X, Y, Z, M, N]`` [N, N m];
        nu: (6,) measured body velocity over ground.
    """
    p = dm.vehicle
    k_r, k_s = fin_gains(dm, nu)
    d_r = -tau5[4] / (p.x_r * k_r)
    d_s = tau5[3] / (p.x_s * k_s)
    d_r_c = saturate(d_r, p.act_max[0])
    d_s_c = saturate(d_s, p.act_max[1])
    X_prop = (tau5[0] + k_r * d_r_c**2 + k_s * d_s_c**2) / (1.0 - p.t_prop)
    # X_prop = a n|n| + b |n| (n in rpm) on the forward branch
    a = p.rho * p.D_prop**4 * p.KT_0 / 3600.0
    Va = p.wake * safe_norm(nu[:3])
    b = p.rho * p.D_prop**4 * (p.KT_max - p.KT_0) / p.Ja_max * (Va / p.D_prop) / 60.0
    n = (-b + safe_sqrt(b * b + 4.0 * a * X_prop)) / (2.0 * a)
    n = jnp.maximum(n, -b / (2.0 * a))  # (b < 0): never below the branch's minimum
    raw = jnp.stack([d_r, d_s, n])
    return ActuatorCommand(cmd=saturate(raw, p.act_max), raw=raw)


def horizontal_design(dm: Remus100Design):
    """The paper's 3-DOF model (20) for the horizontal law, linearised from this design model
    at straight motion ``nu = [U_design, 0, 0]``: ``m11, m22, m23, m33`` from ``M``; ``d11`` the
    secant ``X(U) / U`` (the steady drag is fed forward exactly); ``d22, d23, d32, d33`` such that
    ``C_b(nu) nu + D_b nu`` of (20) has the 5-DOF model's slopes in ``(v, r)`` there (as
    [`design_model`][vcjax.vehicles.infante.design_model] with ``match_coriolis``). Jit-safe.

    Only the slopes match: (20)'s ``C_b`` carries the Munk yaw moment ``(m22 - m11) u v`` that
    this model lacks (PVS zeroes it), and ``d32`` cancels it at ``u = U_design`` only. The
    ``remus100`` loop's ``decoupled`` law therefore takes ``M_b`` from here and the bias from
    [`body_bias5`][vcjax.vehicles.remus100_design.body_bias5] (see
    [`vcjax.control.baselines3d`][vcjax.control.baselines3d]).
    """
    M = mass_matrix5(dm)
    U = dm.U_design
    q0 = jnp.zeros(5, dtype=jnp.asarray(U).dtype)
    z = 0.0 * U

    def n3(nu3):
        nu5 = jnp.stack([nu3[0], nu3[1], 0.0 * nu3[0], 0.0 * nu3[0], nu3[2]])
        return body_bias5(dm, q0, nu5)[np.asarray([0, 1, 4])]

    nu0 = jnp.stack([U, z, z])
    m11, m22, m23, m33 = M[0, 0], M[1, 1], M[1, 4], M[4, 4]
    bare = d3.Design3DOF(m11, m22, m23, m33, z, z, z, z, z)
    D = jax.jacfwd(n3)(nu0) - jax.jacfwd(lambda v: d3.body_bias(bare, v))(nu0)
    d11 = n3(nu0)[0] / U
    return d3.design3dof(m11, m22, m23, m33, d11, D[1, 1], D[1, 2], D[2, 1], D[2, 2])
