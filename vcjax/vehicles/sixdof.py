"""Generic 6-DOF marine-craft model (paper eq. (2)) in Fossen's conventions.

Frames and signs follow SNAME/Fossen: the inertial frame is NED (x north, y east, z down); the
body frame has x forward, y starboard, z down; the body origin CO is a fixed point of the body.

* ``eta = [x, y, z, phi, theta, psi]``: NED position of the CO [m] and zyx Euler angles [rad].
* ``nu = [u, v, w, p, q, r]``: body-frame linear [m/s] and angular [rad/s] velocity of the CO.
* Kinematics ``eta_dot = J(Theta) nu`` with ``J = blockdiag(R(Theta), T(Theta))``,
  ``R = Rz(psi) Ry(theta) Rx(phi)`` and ``T`` the Euler-angle attitude transform (singular at
  ``theta = +-90 deg``).
* Kinetics, in the relative velocity ``nu_r = nu - nu_c``, ``nu_c = [R(Theta)^T v_c; 0]`` of an
  irrotational ocean current ``v_c`` (3,) given in NED (the velocity of the plant's one water
  door, [`WaterMotion`][vcjax.environment.component.WaterMotion], ``v_c_dot`` its
  acceleration)::

      M nu_r_dot + C(nu_r) nu_r + D nu_r + g(eta) = tau,        M = M_RB + M_A,
      nu_dot = nu_r_dot + nu_c_dot,   nu_c_dot = [-S(omega) R^T v_c + R^T v_c_dot; 0],

  ``omega = [p, q, r]``. ``C(nu) = m2c(M, nu)`` (Fossen 2021, Ch. 3; the same formula serves the
  rigid body and the added mass, and is linear in ``M``). ``g(eta) = gvect(W, B, theta, phi,
  r_bg, r_bb)`` is the restoring vector of a submerged body. ``D`` is linear (constant).

Building blocks keep Fossen's names (``Smtrx``, ``Hmtrx``, ``Rzyx``, ``Tzyx``, ``m2c``,
``gvect``) so they can be read side by side with PythonVehicleSimulator / MSS. Everything is pure
``jax.numpy``: jit/vmap/grad-safe in float32 and float64 (arrays keep the dtype they are given;
no default-dtype constants are mixed in).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, NamedTuple

import jax.numpy as jnp
import numpy as np

from vcjax._checks import (
    as_float_array,
    check_array,
    check_params,
    check_positive,
    check_spd,
    float_dtype,
    is_concrete,
)
from vcjax.environment.component import WaterMotion, water_motion
from vcjax.linalg import Rzyx, spd_solve_small

__all__ = [
    "Smtrx",
    "Hmtrx",
    "Rzyx",
    "Tzyx",
    "kinematics",
    "m2c",
    "gvect",
    "rigid_body_mass_matrix",
    "current_in_body",
    "SixDofParams",
    "sixdof_params",
    "validate",
    "SixDofState",
    "sixdof_state",
    "SixDofArgs",
    "sixdof_args",
    "mass_matrix",
    "coriolis",
    "restoring",
    "kinetic_energy",
    "vector_field",
    "sixdof_plant",
    "make_sixdof_plant",
]


# --------------------------------------------------------------------------------------------
# Kinematics and matrix building blocks
# --------------------------------------------------------------------------------------------


def Smtrx(a):
    """(3, 3) skew-symmetric matrix ``S(a)`` with ``S(a) b = a x b`` (``S(a)^T = -S(a)``)."""
    z = jnp.zeros_like(a[0])
    return jnp.stack(
        [
            jnp.stack([z, -a[2], a[1]]),
            jnp.stack([a[2], z, -a[0]]),
            jnp.stack([-a[1], a[0], z]),
        ]
    )


def Hmtrx(r):
    """(6, 6) system transformation ``H(r) = [[I, S(r)^T], [0, I]]``; ``H(r)^-1 = H(-r)``.

    With ``r = r_bg`` (CG w.r.t. the CO, body frame [m]): ``M_CO = H(r)^T M_CG H(r)``.
    """
    eye = jnp.eye(3, dtype=r.dtype)
    zero = jnp.zeros((3, 3), dtype=r.dtype)
    return jnp.block([[eye, Smtrx(r).T], [zero, eye]])


def Tzyx(phi, theta):
    """(3, 3) attitude transform ``T`` with ``[phi, theta, psi]_dot = T [p, q, r]`` (zyx).

    Singular at ``theta = +-pi/2`` (the Euler-angle representation's gimbal lock).
    """
    cphi, sphi = jnp.cos(phi), jnp.sin(phi)
    cth, sth = jnp.cos(theta), jnp.sin(theta)
    one, z = jnp.ones_like(phi * theta), jnp.zeros_like(phi * theta)
    return jnp.stack(
        [
            jnp.stack([one, sphi * sth / cth, cphi * sth / cth]),
            jnp.stack([z, cphi, -sphi]),
            jnp.stack([z, sphi / cth, cphi / cth]),
        ]
    )


def kinematics(eta):
    """(6, 6) ``J(Theta) = blockdiag(R(Theta), T(Theta))``: ``eta_dot = J(Theta) nu``.

    Args:
        eta: (6,) ``[x, y, z, phi, theta, psi]`` (only the angles are used).
    """
    R = Rzyx(eta[3], eta[4], eta[5])
    T = Tzyx(eta[3], eta[4])
    zero = jnp.zeros((3, 3), dtype=R.dtype)
    return jnp.block([[R, zero], [zero, T]])


def m2c(M, nu):
    """Coriolis-centripetal matrix from a mass matrix (Fossen 2021, Ch. 3).

    6-DOF (``nu`` (6,)): with ``M`` symmetrised and split into 3x3 blocks,
    ``a = M11 nu1 + M12 nu2``, ``b = M21 nu1 + M22 nu2``::

        C = [[0, -S(a)], [-S(a), -S(b)]]

    Skew-symmetric for every ``nu`` (so ``nu^T C(nu) nu = 0``). Serves ``C_RB = m2c(M_RB, nu)``
    and ``C_A = m2c(M_A, nu_r)`` alike. 3-DOF (``nu = [u, v, r]`` (3,)): Fossen's surge-sway-yaw
    form ``C = [[0, 0, -M22 v - M23 r], [0, 0, M11 u], [M22 v + M23 r, -M11 u, 0]]``.

    Args:
        M: (6, 6) or (3, 3) mass matrix; nu: (6,) or (3,) velocity.

    Returns:
        C with the shape of ``M``.
    """
    M = 0.5 * (M + M.T)
    if nu.shape[0] == 6:
        nu1, nu2 = nu[:3], nu[3:]
        a = M[:3, :3] @ nu1 + M[:3, 3:] @ nu2
        b = M[3:, :3] @ nu1 + M[3:, 3:] @ nu2
        Sa = Smtrx(a)
        return jnp.block([[jnp.zeros_like(Sa), -Sa], [-Sa, -Smtrx(b)]])
    if nu.shape[0] == 3:
        c02 = -M[1, 1] * nu[1] - M[1, 2] * nu[2]
        c12 = M[0, 0] * nu[0]
        z = jnp.zeros_like(c02)
        return jnp.stack(
            [jnp.stack([z, z, c02]), jnp.stack([z, z, c12]), jnp.stack([-c02, -c12, z])]
        )
    raise ValueError(f"nu: expected shape (6,) or (3,), got {nu.shape}")


def gvect(W, B, theta, phi, r_bg, r_bb):
    """(6,) restoring forces/moments about the CO of a submerged body (Fossen 2021, (4.6)).

    Equals ``-[f_g + f_b; r_bg x f_g + r_bb x f_b]`` with ``f_g = R^T [0, 0, W]`` and
    ``f_b = -R^T [0, 0, B]`` (it does not depend on ``psi``).

    Args:
        W, B: () weight and buoyancy [N]; theta, phi: () pitch and roll [rad];
        r_bg, r_bb: (3,) CG and CB w.r.t. the CO, body frame [m].
    """
    sth, cth = jnp.sin(theta), jnp.cos(theta)
    sphi, cphi = jnp.sin(phi), jnp.cos(phi)
    WB = W - B
    mx = r_bg[0] * W - r_bb[0] * B
    my = r_bg[1] * W - r_bb[1] * B
    mz = r_bg[2] * W - r_bb[2] * B
    return jnp.stack(
        [
            WB * sth,
            -WB * cth * sphi,
            -WB * cth * cphi,
            -my * cth * cphi + mz * cth * sphi,
            mz * sth + mx * cth * cphi,
            -mx * cth * sphi - my * sth,
        ]
    )


def rigid_body_mass_matrix(m, inertia_cg, r_bg):
    """(6, 6) ``M_RB`` about the CO: ``H(r_bg)^T blockdiag(m I3, I_g) H(r_bg)``.

    Args:
        m: () mass [kg]; inertia_cg: (3, 3) inertia tensor about the CG [kg m^2];
        r_bg: (3,) CG w.r.t. the CO [m].
    """
    zero = jnp.zeros((3, 3), dtype=inertia_cg.dtype)
    M_cg = jnp.block([[m * jnp.eye(3, dtype=inertia_cg.dtype), zero], [zero, inertia_cg]])
    H = Hmtrx(r_bg)
    return H.T @ M_cg @ H


def current_in_body(eta, nu, v_c, v_c_dot=None):
    """Body-frame current ``nu_c = [R^T v_c; 0]`` (6,) and its time derivative (6,).

    ``d/dt (R^T v_c) = -S(omega) R^T v_c + R^T v_c_dot`` (``R_dot = R S(omega)``).

    Args:
        eta: (6,) pose; nu: (6,) body velocity (its ``omega = nu[3:]`` is used);
        v_c: (3,) current in NED [m/s]; v_c_dot: (3,) its time derivative [m/s^2] (default 0).
    """
    Rt = Rzyx(eta[3], eta[4], eta[5]).T
    vb = Rt @ v_c
    vb_dot = -jnp.cross(nu[3:], vb)
    if v_c_dot is not None:
        vb_dot = vb_dot + Rt @ v_c_dot
    z = jnp.zeros(3, dtype=vb.dtype)
    return jnp.concatenate([vb, z]), jnp.concatenate([vb_dot, z])


# --------------------------------------------------------------------------------------------
# Parameters and state (validated)
# --------------------------------------------------------------------------------------------


class SixDofParams(NamedTuple):
    """Parameters of the generic 6-DOF model (traced).

    Attributes:
        M_RB: (6, 6) rigid-body mass matrix about the CO [kg, kg m, kg m^2], SPD.
        M_A: (6, 6) added-mass matrix (symmetric); ``M_RB + M_A`` is SPD.
        D: (6, 6) linear damping matrix (``D + D^T`` positive semi-definite).
        W, B: () weight and buoyancy [N].
        r_bg, r_bb: (3,) CG and CB w.r.t. the CO, body frame [m].
    """

    M_RB: Any
    M_A: Any
    D: Any
    W: Any
    B: Any
    r_bg: Any
    r_bb: Any


class SixDofState(NamedTuple):
    """State of the generic 6-DOF model (traced).

    Attributes:
        eta: (6,) ``[x, y, z, phi, theta, psi]`` (NED [m], zyx Euler angles [rad]).
        nu: (6,) ``[u, v, w, p, q, r]`` body velocity over ground [m/s, rad/s].
    """

    eta: Any
    nu: Any


class SixDofArgs(NamedTuple):
    """Traced arguments of [`sixdof_plant`][vcjax.vehicles.sixdof.sixdof_plant].

    Attributes:
        vehicle: [`SixDofParams`][vcjax.vehicles.sixdof.SixDofParams].
        water: [`WaterMotion`][vcjax.environment.component.WaterMotion], the water at the body:
            velocity ``v_c`` (3,) NED [m/s] (all three components felt) and material
            acceleration ``v_c_dot`` (3,) [m/s^2].
    """

    vehicle: SixDofParams
    water: WaterMotion


def _check_symmetric(name, a, rtol=1e-8):
    if not is_concrete(a):
        return
    a = np.asarray(a, dtype=np.float64)
    scale = max(float(np.max(np.abs(a))), 1e-300)
    if not np.allclose(a, a.T, rtol=0.0, atol=rtol * scale):
        asym = float(np.max(np.abs(a - a.T)))
        raise ValueError(f"{name}: matrix is not symmetric (max |M - M^T| = {asym:.3g})")


def sixdof_params(M_RB, M_A=None, D=None, W=0.0, B=None, r_bg=None, r_bb=None, dtype=None):
    """Build validated [`SixDofParams`][vcjax.vehicles.sixdof.SixDofParams].

    Args:
        M_RB: (6, 6) rigid-body mass matrix about the CO (symmetric positive definite).
        M_A: (6, 6) added mass (symmetric; default zeros); ``M_RB + M_A`` must be SPD.
        D: (6, 6) linear damping (default zeros); must be dissipative (``D + D^T >= 0``).
        W: () weight [N] (>= 0); B: () buoyancy [N] (>= 0, default ``W``: neutrally buoyant).
        r_bg, r_bb: (3,) CG and CB w.r.t. the CO [m] (default zeros).
        dtype: float dtype of every array (default: JAX's default float).

    Raises:
        ValueError: naming the offending field (wrong shape, NaN/inf, not SPD, ...).
    """
    dtype = float_dtype(dtype)
    M_A = np.zeros((6, 6)) if M_A is None else M_A
    D = np.zeros((6, 6)) if D is None else D
    B = W if B is None else B
    r_bg = np.zeros(3) if r_bg is None else r_bg
    r_bb = np.zeros(3) if r_bb is None else r_bb

    check_spd("M_RB", M_RB, 6)
    check_array("M_A", M_A, (6, 6))
    _check_symmetric("M_A", M_A)
    if is_concrete(M_RB) and is_concrete(M_A):
        M = np.asarray(M_RB, np.float64) + np.asarray(M_A, np.float64)
        check_spd("M_RB + M_A", M, 6)
    a = check_array("D", D, (6, 6))
    if a is not None:
        sym = 0.5 * (a + a.T).astype(np.float64)
        eig = np.linalg.eigvalsh(sym)
        if eig[0] < -1e-10 * max(float(np.max(np.abs(sym))), 1e-300):
            raise ValueError(
                f"D: damping is not dissipative (D + D^T has eigenvalue {eig[0]:.3g} < 0)"
            )
    check_positive("W", W, (), strict=False)
    check_positive("B", B, (), strict=False)
    return SixDofParams(
        M_RB=as_float_array("M_RB", M_RB, (6, 6), dtype),
        M_A=as_float_array("M_A", M_A, (6, 6), dtype),
        D=as_float_array("D", D, (6, 6), dtype),
        W=jnp.asarray(W, dtype=dtype),
        B=jnp.asarray(B, dtype=dtype),
        r_bg=as_float_array("r_bg", r_bg, (3,), dtype),
        r_bb=as_float_array("r_bb", r_bb, (3,), dtype),
    )


def validate(params: SixDofParams, name: str = "vehicle") -> SixDofParams:
    """Eagerly check [`SixDofParams`][vcjax.vehicles.sixdof.SixDofParams] however they were built
    (also after ``_replace``):
    every field finite, ``W, B >= 0``, ``M_RB + M_A`` symmetric positive definite.

    Returns ``params``. Raises ``ValueError`` naming ``name.field``. Skipped under ``jit``.
    """
    check_params(
        SixDofParams,
        params,
        nonnegative=("W", "B"),
        spd={"M_RB + M_A": lambda p: p.M_RB + p.M_A},
        name=name,
    )
    return params


def sixdof_state(eta=None, nu=None, dtype=None) -> SixDofState:
    """Validated [`SixDofState`][vcjax.vehicles.sixdof.SixDofState]; ``eta``, ``nu`` (6,) default to
    zeros.

    Raises:
        ValueError: naming the field for a wrong shape or a NaN/inf entry.
    """
    dtype = float_dtype(dtype)
    eta = jnp.zeros(6, dtype=dtype) if eta is None else as_float_array("eta", eta, (6,), dtype)
    nu = jnp.zeros(6, dtype=dtype) if nu is None else as_float_array("nu", nu, (6,), dtype)
    return SixDofState(eta=eta, nu=nu)


def sixdof_args(vehicle: SixDofParams, water: WaterMotion | None = None) -> SixDofArgs:
    """Validated [`SixDofArgs`][vcjax.vehicles.sixdof.SixDofArgs]; ``water``
    ([`WaterMotion`][vcjax.environment.component.WaterMotion], (3,) NED velocity and
    acceleration) defaults to still water.

    The arrays take the dtype of ``vehicle.M_RB``.
    """
    if not isinstance(vehicle, SixDofParams):
        raise ValueError(f"vehicle: expected SixDofParams, got {type(vehicle).__name__}")
    dtype = jnp.asarray(vehicle.M_RB).dtype
    water = WaterMotion(None, None) if water is None else water
    return SixDofArgs(vehicle=vehicle, water=water_motion(*water, dtype=dtype))


# --------------------------------------------------------------------------------------------
# Model
# --------------------------------------------------------------------------------------------


def mass_matrix(p: SixDofParams):
    """(6, 6) ``M = M_RB + M_A``."""
    return p.M_RB + p.M_A


def coriolis(p: SixDofParams, nu_r):
    """(6, 6) ``C(nu_r) = m2c(M_RB, nu_r) + m2c(M_A, nu_r)`` (= ``m2c(M, nu_r)``)."""
    return m2c(mass_matrix(p), nu_r)


def restoring(p: SixDofParams, eta):
    """(6,) ``g(eta) = gvect(W, B, theta, phi, r_bg, r_bb)``."""
    return gvect(p.W, p.B, eta[4], eta[3], p.r_bg, p.r_bb)


def kinetic_energy(p: SixDofParams, nu_r):
    """() ``0.5 nu_r^T M nu_r`` [J] (rigid body + added mass)."""
    return 0.5 * nu_r @ mass_matrix(p) @ nu_r


def vector_field(p: SixDofParams, eta, nu, tau, water: WaterMotion | None = None):
    """``(eta_dot, nu_dot)`` of model (2) in optional (possibly time-varying) water.

    ``M nu_r_dot = tau - C(nu_r) nu_r - D nu_r - g(eta)``, ``nu_dot = nu_r_dot + nu_c_dot``,
    ``eta_dot = J(Theta) nu``.

    Args:
        p: parameters; eta: (6,) pose; nu: (6,) body velocity over ground;
        tau: (6,) generalised body force ``[X, Y, Z, K, M, N]`` [N, N m] about the CO;
        water: [`WaterMotion`][vcjax.environment.component.WaterMotion] at this time: the
            current ``v_c`` (3,) NED [m/s] and its material acceleration ``v_c_dot`` (3,)
            [m/s^2] (``None``: 0); default none (still water).

    Returns:
        ``(eta_dot (6,), nu_dot (6,))``.
    """
    if water is None:
        nu_r, nu_c_dot = nu, jnp.zeros_like(nu)
    else:
        nu_c, nu_c_dot = current_in_body(eta, nu, water.velocity, water.acceleration)
        nu_r = nu - nu_c
    rhs = tau - coriolis(p, nu_r) @ nu_r - p.D @ nu_r - restoring(p, eta)
    nu_r_dot = spd_solve_small(mass_matrix(p), rhs)
    return kinematics(eta) @ nu, nu_r_dot + nu_c_dot


def sixdof_plant(t, x: SixDofState, tau, args: SixDofArgs) -> SixDofState:
    """Plant vector field ``x_dot = f(t, x, tau, args)`` (the [`vcjax.rollout`][vcjax.rollout]
    signature).

    Args:
        t: () time [s] (unused); x: [`SixDofState`][vcjax.vehicles.sixdof.SixDofState]; tau: (6,)
            body force [N, N m];
        args: [`SixDofArgs`][vcjax.vehicles.sixdof.SixDofArgs] (vehicle, the water at it).
    """
    eta_dot, nu_dot = vector_field(args.vehicle, x.eta, x.nu, tau, args.water)
    return SixDofState(eta=eta_dot, nu=nu_dot)


def make_sixdof_plant(water: Callable) -> Callable:
    """A plant ``f(t, x, tau, vehicle)`` for a uniform, time-varying current.

    Args:
        water: ``water(t) ->`` [`WaterMotion`][vcjax.environment.component.WaterMotion]
            (or the pair ``(v_c (3,), v_c_dot (3,))``) in NED [m/s, m/s^2], a pure jnp function
            of time (uniform in space, hence irrotational).

    Returns:
        ``plant(t, x: SixDofState, tau, vehicle: SixDofParams) -> SixDofState``. Build it once
        and pass the same object to jitted code (it is a static argument).
    """

    def plant(t, x: SixDofState, tau, vehicle: SixDofParams) -> SixDofState:
        w = WaterMotion(*water(t))
        eta_dot, nu_dot = vector_field(vehicle, x.eta, x.nu, tau, w)
        return SixDofState(eta=eta_dot, nu=nu_dot)

    return plant
