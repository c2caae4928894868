"""INFANTE-class, NPS-AUV-derived horizontal-plane AUV plant (paper Sec. 4.3, Simulation 1).

What this model is — and is not
-------------------------------
The paper simulates the INFANTE AUV (IST/ISR Lisbon) with its nonlinear model; those coefficients
are not publicly readable. This module therefore simulates an **INFANTE-class, NPS-AUV-derived**
vehicle (sources in ``docs/reference/vehicles.md``): the NPS AUV II model of Healey & Lienard
(1993), as
coded in MSS ``CRAFT/AUV/models/npsauv.m``, scaled from L = 5.3 m to L = 4.5 m by geometric
similarity and restricted to the horizontal plane. Only the paper's own facts about INFANTE are
honoured exactly: 920 N of thrust gives 5 m/s in calm water, rudder saturation 30 deg,
first-order actuators, no sway actuation. It is *not* INFANTE's published model.

Scaling: the prime (non-dimensional) coefficients of ``npsauv.m`` are kept; the dimensional
factors ``r_k = rho/2 L^k`` are recomputed with the new L; mass and yaw inertia scale as
``(L / 5.3)^3`` and ``(L / 5.3)^5`` (i.e. ``m' = m / r3`` and ``Iz' = Iz / r5`` are kept); the
cross-flow strip geometry (height, strip width) scales with L.

Horizontal-plane model (w = p = q = 0, z = 0, phi = theta = 0), state
``x = (eta, nu, act)``:

* ``eta = [x, y, psi]`` (NED north/east [m], heading [rad]); ``eta_dot = J(psi) nu``.
* ``nu = [u, v, r]`` body velocity; ``nu_r = nu - [R(psi)^T V_c, 0]`` the velocity relative to an
  irrotational ocean current ``V_c`` (2,), the horizontal part of the water's NED velocity
  ``PlantArgs.water`` (the one door of every plant,
  [`WaterMotion`][vcjax.environment.component.WaterMotion]). A horizontal-plane model cannot
  feel the water's vertical component: it is ignored.
* Kinetics (as in ``npsauv.m``, relative-velocity form)::

      M nu_r_dot = -C_RB(nu_r) nu_r + tau_hyd(nu_r, delta) + tau_cf(nu_r) + [thrust, 0, 0]
      nu_dot     = nu_r_dot + d/dt(R(psi)^T V_c)

  ``M = M_RB + M_A`` with ``M_RB = [[m, 0, 0], [0, m, m x_g], [0, m x_g, Iz]]`` and
  ``M_A = -[[X_udot, 0, 0], [0, Y_vdot, Y_rdot], [0, N_vdot, N_rdot]]``. Only the rigid-body
  Coriolis ``C_RB`` appears: the NPS linear derivatives are *total* derivatives that already
  contain the added-mass (Munk) terms (a note in the vehicle sources). For a constant
  current and
  any ``x_g``, ``M_RB nu_dot + C_RB(nu) nu = M_RB nu_r_dot + C_RB(nu_r) nu_r`` holds exactly in
  3-DOF, so the relative form is the rigid-body law written in ``nu_r``.

  Hydrodynamic and rudder forces (``u, v, r`` below are relative: ``u_r, v_r, r``)::

      X = X_u|u| u|u| + X_vv v^2 + X_vr v r + X_rr r^2
          + X_urdr u r delta + X_uvdr u v delta + X_uudrdr u^2 delta^2 + thrust
      Y = Y_uv u v + Y_ur u r + Y_uudr u^2 delta + Y_cf
      N = N_uv u v + N_ur u r + N_uudr u^2 delta + N_cf

  with ``X_vv = r2 Xvv``, ``X_vr = r3 Xvr``, ``X_rr = r4 Xrr``, ``Y_uv = r2 Yv``,
  ``Y_ur = r3 Yr``, ``N_uv = r3 Nv``, ``N_ur = r4 Nr``, ``X_urdr = r3 Xrdr``, ``X_uvdr = r2 Xvdr``,
  ``X_uudrdr = r2 Xdrdr``, ``Y_uudr = r2 Ydr``, ``N_uudr = r3 Ndr`` (npsauv.m's prime names).
  Cross-flow drag by strips along the hull, as ``npsauv.m`` does it (11 stations
  ``x_i = -L/2, ..., L/2``, each weighted ``dx = L/10``)::

      Y_cf = -rho/2 Cdy H dx sum_i h_i |h_i|,   N_cf = -rho/2 Cdy H dx sum_i x_i h_i |h_i|,
      h_i = v + x_i r.

  ``h_i`` is linear along the hull, so it changes sign at most once: the sums are evaluated in
  closed form ([`crossflow_forces`][vcjax.vehicles.infante.crossflow_forces]), equal to the strip
  sum within round-off.

* Surge: NPS's propeller/drag model is replaced by a thrust *force* actuator and an axial
  quadratic drag ``X_u|u|`` calibrated so that ``thrust_max`` gives exactly
  ``speed_at_max_thrust`` in straight-line calm-water steady state (paper: 920 N -> 5 m/s).
  The calibration evaluates the model's other pure-surge forces (none are nonzero in this
  model at v = r = delta = 0), so it stays exact if such terms are added.
* Actuators, ``act = [thrust N, delta rad]``, first-order lags of the saturated commands::

      act_dot = (sat(u_cmd) - act) / [T_thrust, T_rudder]

  ``sat`` is a hard clip ([`infante_plant`][vcjax.vehicles.infante.infante_plant]) or ``limit *
  tanh(cmd / limit)``
  ([`infante_plant_smooth`][vcjax.vehicles.infante.infante_plant_smooth], for gradients; note it
  maps a command equal to the limit to
  0.76 × the limit). Starting inside the limits, the actuator states stay inside them (exactly
  in continuous time; with RK4 and a command held over the step while ``dt < 2.7 T``).
  ``T_rudder = 0.1 s`` is npsauv.m's value; ``T_thrust = 0.5 s`` is **[INF]** (chosen here; the
  paper gives no time constants).
* The rudder gives a sway force ``Y_delta(u_r) delta`` and a yaw moment ``N_delta(u_r) delta``
  (paper Remark 4); there is no sway actuator.

Sign conventions are SNAME/Fossen (x forward, y starboard, z down, positive yaw to starboard).
With npsauv.m's ``Ydr > 0`` and ``Ndr < 0`` a positive rudder angle pushes the stern to
starboard (``Y > 0``) and turns the bow to port (``N < 0``).

Differences from ``npsauv.m`` besides the surge model: the cross-flow speed uses the exact
``h |h|`` instead of ``h^3 / (|h| + 1e-6)``; heave, roll, pitch, stern/bow planes and the
``epsilon`` propeller-slip corrections are dropped with the vertical plane.

Everything traced is a ``NamedTuple`` of arrays; the functions are pure ``jax.numpy`` and are
jit/vmap/grad-safe (no NaN gradients at zero velocity) in float32 and float64.
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
    check_spd,
    float_dtype,
    is_concrete,
)
from vcjax.environment.component import WaterMotion, water_motion
from vcjax.linalg import (
    saturate,
    signed_square_sums,
    smooth_saturate,
    solve_surge_decoupled,
)
from vcjax.vehicles.design3dof import Design3DOF, current_in_body, design3dof, pose_rate

__all__ = [
    "NPS_LENGTH",
    "NPS_PRIME",
    "InfanteParams",
    "HYDRODYNAMIC_FIELDS",
    "INERTIA_FIELDS",
    "infante_params",
    "validate",
    "ideal_fluid",
    "InfanteState",
    "infante_state",
    "PlantArgs",
    "plant_args",
    "mass_matrix",
    "kinetic_energy",
    "body_forces",
    "crossflow_forces",
    "infante_plant",
    "infante_plant_smooth",
    "design_model",
    "rudder_gains",
    "actuator_commands",
    "rudder_sway_force",
    "describe",
]

#: Length of the NPS AUV II [m] (npsauv.m).
NPS_LENGTH = 5.3
#: NPS AUV II weight W = B [N], g [m/s^2], yaw inertia Iz [kg m^2] (npsauv.m).
_NPS_WEIGHT, _NPS_G, _NPS_IZ = 53400.0, 9.81, 13587.0
#: npsauv.m's cross-flow data: Cdy, average height Hx [m], number of strip intervals.
_NPS_CDY, _NPS_HX, _NPS_STRIPS = 0.5, 0.53, 10

#: The prime (non-dimensional) coefficients of npsauv.m that act in the horizontal plane.
NPS_PRIME: dict[str, float] = {
    "Xudot": -7.6e-3,
    "Yvdot": -5.5e-2,
    "Yrdot": 1.2e-3,
    "Nvdot": 1.2e-3,
    "Nrdot": -3.4e-3,
    "Xvv": 5.3e-2,
    "Xvr": 2.0e-2,
    "Xrr": 4.0e-3,
    "Yv": -1.0e-1,
    "Yr": 3.0e-2,
    "Nv": -7.4e-3,
    "Nr": -1.6e-2,
    "Xrdr": -1.0e-3,
    "Xvdr": 1.7e-3,
    "Xdrdr": -1.0e-2,
    "Ydr": 2.7e-2,
    "Ndr": -1.3e-2,
}


#: Fields of [`InfanteParams`][vcjax.vehicles.infante.InfanteParams] holding damping, lift,
#: cross-flow and rudder coefficients.
HYDRODYNAMIC_FIELDS = (
    "X_uu",
    "X_vv",
    "X_vr",
    "X_rr",
    "Y_uv",
    "Y_ur",
    "N_uv",
    "N_ur",
    "X_urdr",
    "X_uvdr",
    "X_uudrdr",
    "Y_uudr",
    "N_uudr",
    "cf_coeff",
)
#: Fields holding mass, inertia and added mass.
INERTIA_FIELDS = ("mass", "Iz", "X_udot", "Y_vdot", "Y_rdot", "N_vdot", "N_rdot")


class InfanteParams(NamedTuple):
    """Dimensional plant parameters (traced; every field a scalar array unless noted).

    Attributes:
        length: () hull length L [m]; rho: () water density [kg/m^3].
        mass: () m [kg]; Iz: () yaw inertia about the body origin [kg m^2]; x_g: () CG [m].
        X_udot, Y_vdot, Y_rdot, N_vdot, N_rdot: added-mass derivatives, SNAME signs
            [kg, kg, kg m, kg m, kg m^2].
        X_uu: () axial quadratic drag X_u|u| [kg/m] (calibrated, < 0).
        X_vv, X_vr, X_rr: surge terms in v^2, v r, r^2 [kg/m, kg, kg m].
        Y_uv, Y_ur, N_uv, N_ur: sway/yaw terms in u v, u r [kg/m, kg, kg, kg m].
        X_urdr, X_uvdr, X_uudrdr: rudder-induced surge terms in u r d, u v d, u^2 d^2.
        Y_uudr, N_uudr: rudder sway force / yaw moment per u^2 delta [kg/m, kg].
        cf_coeff: () rho/2 Cdy H, cross-flow drag per unit strip length [kg/m^3].
        cf_x: (n+1,) strip stations along the hull, uniformly spaced by ``cf_dx`` from the stern
            ``cf_x[0]`` [m] (its length fixes n); cf_dx: () strip weight and spacing [m].
        thrust_max: () [N]; rudder_max: () [rad]; T_thrust, T_rudder: () time constants [s].
        rudder_speed_min: () speed floor used by
            [`actuator_commands`][vcjax.vehicles.infante.actuator_commands] [m/s].
    """

    length: Any
    rho: Any
    mass: Any
    Iz: Any
    x_g: Any
    X_udot: Any
    Y_vdot: Any
    Y_rdot: Any
    N_vdot: Any
    N_rdot: Any
    X_uu: Any
    X_vv: Any
    X_vr: Any
    X_rr: Any
    Y_uv: Any
    Y_ur: Any
    N_uv: Any
    N_ur: Any
    X_urdr: Any
    X_uvdr: Any
    X_uudrdr: Any
    Y_uudr: Any
    N_uudr: Any
    cf_coeff: Any
    cf_x: Any
    cf_dx: Any
    thrust_max: Any
    rudder_max: Any
    T_thrust: Any
    T_rudder: Any
    rudder_speed_min: Any


class InfanteState(NamedTuple):
    """Plant state (traced).

    Attributes:
        eta: (3,) pose [x, y, psi] (NED [m], heading [rad]).
        nu: (3,) body velocity [u, v, r] over ground [m/s, m/s, rad/s].
        act: (2,) actuator states [thrust N, rudder angle rad].
    """

    eta: Any
    nu: Any
    act: Any


class PlantArgs(NamedTuple):
    """Traced arguments of [`infante_plant`][vcjax.vehicles.infante.infante_plant].

    Attributes:
        vehicle: [`InfanteParams`][vcjax.vehicles.infante.InfanteParams].
        water: [`WaterMotion`][vcjax.environment.component.WaterMotion], the water at the
            vehicle: velocity (3,) NED [m/s] and material acceleration (3,) [m/s^2] (zero for a
            constant current). The plant uses their horizontal parts ``[:2]`` (the current
            ``V_c`` and its rate); the vertical part is ignored (a horizontal-plane model).
    """

    vehicle: InfanteParams
    water: WaterMotion


# --------------------------------------------------------------------------------------------
# Constructors (eager, validated)
# --------------------------------------------------------------------------------------------


def infante_params(
    length=4.5,
    thrust_max=920.0,
    rudder_max_deg=30.0,
    T_thrust=0.5,
    T_rudder=0.1,
    speed_at_max_thrust=5.0,
    rho=1025.0,
    x_g=0.0,
    rudder_speed_min=0.5,
    dtype=None,
) -> InfanteParams:
    """Build the INFANTE-class plant parameters (NPS AUV II scaled to ``length``).

    Args:
        length: hull length L [m] (NPS AUV II: 5.3; INFANTE-class: 4.5).
        thrust_max: thrust saturation [N] (paper: 920).
        rudder_max_deg: rudder saturation [deg] (paper: 30).
        T_thrust: thrust lag [s] (0.5 s, [INF]); T_rudder: rudder lag [s] (0.1 s, npsauv.m).
        speed_at_max_thrust: straight-line calm-water speed at ``thrust_max`` [m/s] (paper: 5);
            ``X_u|u|`` is calibrated from it.
        rho: water density [kg/m^3] (npsauv.m: 1025).
        x_g: longitudinal CG position [m] (npsauv.m: 0).
        rudder_speed_min: speed floor of
            [`actuator_commands`][vcjax.vehicles.infante.actuator_commands] [m/s].
        dtype: float dtype of every array (default: JAX's default float).

    Raises:
        ValueError: naming the offending field.
    """
    scalars = dict(
        length=length,
        thrust_max=thrust_max,
        rudder_max_deg=rudder_max_deg,
        T_thrust=T_thrust,
        T_rudder=T_rudder,
        speed_at_max_thrust=speed_at_max_thrust,
        rho=rho,
        rudder_speed_min=rudder_speed_min,
    )
    for name, v in scalars.items():
        check_positive(name, v, ())
    check_array("x_g", x_g, ())
    if not float(rudder_max_deg) < 90.0:
        raise ValueError(f"rudder_max_deg: expected a value in (0, 90) deg, got {rudder_max_deg}")

    L = float(length)
    scale = L / NPS_LENGTH
    half_rho = 0.5 * float(rho)
    r2, r3, r4, r5 = (half_rho * L**k for k in (2, 3, 4, 5))
    P = NPS_PRIME
    # Geometric similarity: m' = m / r3 and Iz' = Iz / r5 kept; with rho fixed this is L^3, L^5.
    rho_ratio = float(rho) / 1025.0
    mass = _NPS_WEIGHT / _NPS_G * scale**3 * rho_ratio
    Iz = _NPS_IZ * scale**5 * rho_ratio
    n = _NPS_STRIPS
    cf_x = np.linspace(-L / 2, L / 2, n + 1)

    dtype = float_dtype(dtype)
    vals = dict(
        length=L,
        rho=float(rho),
        mass=mass,
        Iz=Iz,
        x_g=float(x_g),
        X_udot=r3 * P["Xudot"],
        Y_vdot=r3 * P["Yvdot"],
        Y_rdot=r4 * P["Yrdot"],
        N_vdot=r4 * P["Nvdot"],
        N_rdot=r5 * P["Nrdot"],
        X_uu=0.0,
        X_vv=r2 * P["Xvv"],
        X_vr=r3 * P["Xvr"],
        X_rr=r4 * P["Xrr"],
        Y_uv=r2 * P["Yv"],
        Y_ur=r3 * P["Yr"],
        N_uv=r3 * P["Nv"],
        N_ur=r4 * P["Nr"],
        X_urdr=r3 * P["Xrdr"],
        X_uvdr=r2 * P["Xvdr"],
        X_uudrdr=r2 * P["Xdrdr"],
        Y_uudr=r2 * P["Ydr"],
        N_uudr=r3 * P["Ndr"],
        cf_coeff=half_rho * _NPS_CDY * _NPS_HX * scale,
        cf_x=cf_x,
        cf_dx=L / n,
        thrust_max=float(thrust_max),
        rudder_max=math.radians(float(rudder_max_deg)),
        T_thrust=float(T_thrust),
        T_rudder=float(T_rudder),
        rudder_speed_min=float(rudder_speed_min),
    )
    p = InfanteParams(**{k: jnp.asarray(v, dtype=dtype) for k, v in vals.items()})
    check_spd("M (mass, Iz, x_g and added mass)", mass_matrix(p), 3)

    # Calibrate X_u|u|: thrust_max + X_other(U) + X_u|u| U^2 = 0 at nu_r = [U, 0, 0], delta = 0.
    U = float(speed_at_max_thrust)
    nu_r = jnp.asarray([U, 0.0, 0.0], dtype=dtype)
    act0 = jnp.zeros(2, dtype=dtype)
    X_other = float(body_forces(p, nu_r, act0)[0])
    X_uu = -(float(thrust_max) + X_other) / U**2
    if not X_uu < 0:
        raise ValueError(
            f"speed_at_max_thrust: calibration needs X_u|u| < 0, got {X_uu:.4g} "
            f"(other pure-surge forces at {U} m/s: {X_other:.4g} N)"
        )
    return p._replace(X_uu=jnp.asarray(X_uu, dtype=dtype))


def validate(params: InfanteParams, name: str = "vehicle") -> InfanteParams:
    """Eagerly check [`InfanteParams`][vcjax.vehicles.infante.InfanteParams] however they were built
    (also after ``_replace``):
    every field finite; lengths, density, mass, inertia, limits, time constants > 0; the mass
    matrix ``M`` (mass, ``Iz``, ``x_g``, added mass) with a positive-definite symmetric part
    (``infante_params`` builds it symmetric; a model-error study may perturb ``Y_rdot`` and
    ``N_vdot`` apart).

    Returns ``params``. Raises ``ValueError`` naming ``name.field``. Skipped under ``jit``.
    """
    check_params(
        InfanteParams,
        params,
        positive=(
            "length",
            "rho",
            "mass",
            "Iz",
            "cf_dx",
            "thrust_max",
            "rudder_max",
            "T_thrust",
            "T_rudder",
            "rudder_speed_min",
        ),
        spd={"M (mass, Iz, x_g and added mass)": mass_matrix},
        name=name,
        symmetric=False,  # model-error studies perturb Y_rdot and N_vdot independently
    )
    return params


def ideal_fluid(params: InfanteParams) -> InfanteParams:
    """Same vehicle with every damping, lift, cross-flow and rudder term set to zero.

    Mass, added mass and the rigid-body Coriolis terms remain, so ``0.5 nu^T M nu`` is conserved
    in calm water with zero thrust (a check of the skew-symmetry of ``C_RB``).
    """
    return params._replace(**{k: jnp.zeros_like(getattr(params, k)) for k in HYDRODYNAMIC_FIELDS})


def infante_state(eta, nu, act=None, dtype=None) -> InfanteState:
    """Validated [`InfanteState`][vcjax.vehicles.infante.InfanteState].

    Args:
        eta: (3,) pose; nu: (3,) body velocity; act: (2,) actuator states
            [thrust N, rudder rad] (default zeros).
        dtype: float dtype of the arrays (default: that of ``eta``, or JAX's default float).

    Raises:
        ValueError: naming the field for a wrong shape or a NaN/inf entry.
    """
    eta = as_float_array("eta", eta, (3,), dtype)
    dtype = eta.dtype
    nu = as_float_array("nu", nu, (3,), dtype)
    act = jnp.zeros(2, dtype=dtype) if act is None else as_float_array("act", act, (2,), dtype)
    return InfanteState(eta=eta, nu=nu, act=act)


def plant_args(vehicle: InfanteParams, water: WaterMotion | None = None) -> PlantArgs:
    """Validated [`PlantArgs`][vcjax.vehicles.infante.PlantArgs]; ``water``
    ([`WaterMotion`][vcjax.environment.component.WaterMotion], (3,) NED velocity and
    acceleration, e.g. ``water_motion([0.0, 0.5, 0.0])``) defaults to still water.

    The arrays take the dtype of ``vehicle.mass``.
    """
    validate(vehicle)
    dtype = jnp.asarray(vehicle.mass).dtype
    water = WaterMotion(None, None) if water is None else water
    return PlantArgs(vehicle=vehicle, water=water_motion(*water, dtype=dtype))


# --------------------------------------------------------------------------------------------
# Model
# --------------------------------------------------------------------------------------------


def mass_matrix(p: InfanteParams):
    """(3, 3) ``M = M_RB + M_A`` in the horizontal plane (surge, sway, yaw)."""
    z = jnp.zeros_like(p.mass)
    mxg = p.mass * p.x_g
    return jnp.stack(
        [
            jnp.stack([p.mass - p.X_udot, z, z]),
            jnp.stack([z, p.mass - p.Y_vdot, mxg - p.Y_rdot]),
            jnp.stack([z, mxg - p.N_vdot, p.Iz - p.N_rdot]),
        ]
    )


def kinetic_energy(p: InfanteParams, nu_r):
    """() ``0.5 nu_r^T M nu_r`` [J] (rigid body + added mass)."""
    return 0.5 * nu_r @ mass_matrix(p) @ nu_r


def crossflow_forces(p: InfanteParams, v, r):
    """``(Y_cf, N_cf)``: cross-flow drag of the strips [N, N m] at sway ``v`` and yaw rate ``r``.

    The strip sums of the model (``Y_cf = -k sum_i h_i |h_i|``, ``N_cf = -k sum_i x_i h_i |h_i|``,
    ``k = cf_coeff cf_dx``, ``h_i = v + x_i r``) over the uniformly spaced stations
    ``x_i = cf_x[0] + i cf_dx``, ``i = 0..n``, evaluated in closed form
    ([`signed_square_sums`][vcjax.linalg.signed_square_sums]: ``h_i`` is linear in ``i`` and changes
    sign at most
    once along the hull). Equal to the 11-station sum within round-off, with the same finite
    gradient ``2 |h_i|`` per strip (zero at ``h_i = 0``).

    Args:
        p: parameters (``cf_x`` (n+1,) fixes ``n`` statically; its first entry is the stern
            station); v: () relative sway velocity [m/s]; r: () yaw rate [rad/s].
    """
    n = p.cf_x.shape[-1] - 1
    x0 = p.cf_x[0]
    s0, s1 = signed_square_sums(v + x0 * r, p.cf_dx * r, n)
    k = p.cf_coeff * p.cf_dx
    return -k * s0, -k * (x0 * s0 + p.cf_dx * s1)


def body_forces(p: InfanteParams, nu_r, act):
    """(3,) everything but inertia: ``-C_RB(nu_r) nu_r + tau_hyd + tau_cf + tau_act``.

    Args:
        p: parameters; nu_r: (3,) relative velocity [u_r, v_r, r];
        act: (2,) applied [thrust N, rudder rad] (actuator *states*, not commands).

    Returns:
        (3,) ``[X, Y, N]`` [N, N, N m]; the plant solves ``M nu_r_dot = body_forces``.
    """
    u, v, r = nu_r[0], nu_r[1], nu_r[2]
    thrust, d = act[0], act[1]
    m, mxg = p.mass, p.mass * p.x_g
    Y_cf, N_cf = crossflow_forces(p, v, r)
    X = (
        (m * v * r + mxg * r * r)  # -C_RB(nu_r) nu_r, surge row
        + p.X_uu * u * jnp.abs(u)
        + p.X_vv * v * v
        + p.X_vr * v * r
        + p.X_rr * r * r
        + (p.X_urdr * u * r + p.X_uvdr * u * v) * d
        + p.X_uudrdr * u * u * d * d
        + thrust
    )
    Y = -m * u * r + p.Y_uv * u * v + p.Y_ur * u * r + p.Y_uudr * u * u * d + Y_cf
    N = -mxg * u * r + p.N_uv * u * v + p.N_ur * u * r + p.N_uudr * u * u * d + N_cf
    return jnp.stack([X, Y, N])


def _plant(t, x: InfanteState, u_cmd, args: PlantArgs, smooth: bool) -> InfanteState:
    p = args.vehicle
    eta, nu, act = x
    limits = jnp.stack([p.thrust_max, p.rudder_max])
    sat = smooth_saturate if smooth else saturate
    act_dot = (sat(u_cmd, limits) - act) / jnp.stack([p.T_thrust, p.T_rudder])

    w = args.water  # its horizontal part: the plane's current V_c and its rate
    a_c = None if w.acceleration is None else w.acceleration[:2]
    nu_c, nu_c_dot = current_in_body(eta[2], nu[2], w.velocity[:2], a_c)
    nu_r = nu - nu_c
    nu_r_dot = solve_surge_decoupled(mass_matrix(p), body_forces(p, nu_r, act))
    eta_dot = pose_rate(eta[2], nu)
    return InfanteState(eta=eta_dot, nu=nu_r_dot + nu_c_dot, act=act_dot)


def infante_plant(t, x: InfanteState, u, args: PlantArgs) -> InfanteState:
    """Vector field ``x_dot = f(t, x, u, args)`` with hard-clipped actuator commands.

    Args:
        t: () time [s] (unused; the plant is autonomous).
        x: [`InfanteState`][vcjax.vehicles.infante.InfanteState].
        u: (2,) commands [thrust_cmd N, rudder_cmd rad].
        args: [`PlantArgs`][vcjax.vehicles.infante.PlantArgs] (vehicle, the water at it).

    Returns:
        [`InfanteState`][vcjax.vehicles.infante.InfanteState] of time derivatives.
    """
    return _plant(t, x, u, args, smooth=False)


def infante_plant_smooth(t, x: InfanteState, u, args: PlantArgs) -> InfanteState:
    """As [`infante_plant`][vcjax.vehicles.infante.infante_plant], with ``limit * tanh(cmd /
    limit)`` saturation (for gradients)."""
    return _plant(t, x, u, args, smooth=True)


# --------------------------------------------------------------------------------------------
# Controller-side helpers
# --------------------------------------------------------------------------------------------


def design_model(p: InfanteParams, u_design=2.0, match_coriolis: bool = True) -> Design3DOF:
    """The paper's simplified model (20) derived from this plant at straight-line motion.

    Inertia: ``m11 = m - X_udot``, ``m22 = m - Y_vdot``, ``m23 = m x_g - Y_rdot`` (Fossen/SNAME:
    ``M_RB[v, r] = m x_g``, ``M_A[v, r] = -Y_rdot``; (20) is symmetric, ``N_vdot = Y_rdot`` here),
    ``m33 = Iz - N_rdot``.

    Damping: the linearisation of the plant's forces about ``nu_r = [u_design, 0, 0]``,
    ``delta = 0`` (cross-flow drag and the v^2, v r, r^2 terms have zero slope there):

    * ``d11 = -X_u|u| u_design``, the *secant* of the quadratic drag: ``d11 u_design`` equals
      the true drag at the design speed, so the controller's feed-forward ``n_b`` asks for the
      right steady thrust (the tangent ``-2 X_u|u| u_design`` gives the right local time
      constant but twice the steady force, i.e. a surge speed error without integral action).
    * ``d22 = -Y_uv u_d``, ``d23 = -Y_ur u_d``, ``d32 = -N_uv u_d``, ``d33 = -N_ur u_d`` are the
      hydrodynamic slopes. The plant has only rigid-body Coriolis (total derivatives), but (20)'s
      ``C_b`` also contains added-mass terms. With ``match_coriolis=True`` (default) the
      difference of the linearised Coriolis terms is moved into ``D_b`` so that
      ``C_b(nu) nu + D_b nu`` has the plant's slopes at the design point (no Munk moment
      counted twice)::

          d23 += (m - m11) u_d = X_udot u_d,      d32 -= (m22 - m11) u_d,
          d33 += (m x_g - m23) u_d = Y_rdot u_d.

      ``match_coriolis=False`` returns the bare hydrodynamic slopes (MSS ``npsauv.m``).

    Args:
        p: plant parameters; u_design: () design surge speed [m/s], > 0.
        match_coriolis: static flag, see above.
    """
    check_positive("u_design", u_design, ())
    ud = u_design
    m11 = p.mass - p.X_udot
    m22 = p.mass - p.Y_vdot
    m23 = p.mass * p.x_g - p.Y_rdot
    m33 = p.Iz - p.N_rdot
    d11 = -p.X_uu * ud
    d22 = -p.Y_uv * ud
    d23 = -p.Y_ur * ud
    d32 = -p.N_uv * ud
    d33 = -p.N_ur * ud
    if match_coriolis:
        d23 = d23 + (p.mass - m11) * ud
        d32 = d32 - (m22 - m11) * ud
        d33 = d33 + (p.mass * p.x_g - m23) * ud
    return design3dof(m11, m22, m23, m33, d11, d22, d23, d32, d33)


def rudder_gains(p: InfanteParams, nu_r):
    """``(Y_delta, N_delta)``: rudder sway force [N/rad] and yaw moment [N m/rad] at ``nu_r``.

    ``Y_delta = Y_uudr u_r^2``, ``N_delta = N_uudr u_r^2`` (npsauv.m uses ``u_r^2``, so the sign
    does not flip when going astern).
    """
    uu = nu_r[0] * nu_r[0]
    return p.Y_uudr * uu, p.N_uudr * uu


def _rudder_angle(p: InfanteParams, nu_r, tau_r):
    # Safe division: the speed is floored at rudder_speed_min (exact above it; N_uudr != 0).
    uu = jnp.maximum(nu_r[0] * nu_r[0], p.rudder_speed_min * p.rudder_speed_min)
    return tau_r / (p.N_uudr * uu)


def actuator_commands(p: InfanteParams, nu_r, tau_u, tau_r):
    """Map a desired surge force and yaw moment to ``[thrust_cmd N, rudder_cmd rad]`` (2,).

    ``thrust_cmd = tau_u`` (the thrust is a direct surge force); ``rudder_cmd = tau_r / N_delta``
    with ``N_delta = N_uudr max(u_r^2, u_min^2)``, ``u_min = rudder_speed_min``: exact for
    ``|u_r| >= u_min``, finite (and with finite gradients) at ``u_r = 0``. The commands are not
    saturated here; the plant saturates them. The rudder drag in surge is not compensated.

    Args:
        p: parameters; nu_r: (3,) relative velocity (the controller's estimate);
        tau_u: () desired surge force [N]; tau_r: () desired yaw moment [N m].
    """
    delta = _rudder_angle(p, nu_r, tau_r)
    return jnp.stack([tau_u * jnp.ones_like(delta), delta])


def rudder_sway_force(p: InfanteParams, nu_r, tau_r):
    """() Sway force [N] of the rudder when it delivers yaw moment ``tau_r`` (Remark 4: tau_0v).

    ``Y_delta(u_r) * rudder_cmd`` with the rudder angle of
    [`actuator_commands`][vcjax.vehicles.infante.actuator_commands]; for
    ``|u_r| >= rudder_speed_min`` this is ``tau_r * Y_uudr / N_uudr`` = ``tau_r Ydr / (Ndr L)``.
    """
    Y_delta, _ = rudder_gains(p, nu_r)
    return Y_delta * _rudder_angle(p, nu_r, tau_r)


def describe(p: InfanteParams, u_design=2.0) -> str:
    """A text table of the plant's main numbers and the derived design model (20)."""
    if not is_concrete(p.mass):
        raise ValueError("params: describe() needs concrete (non-traced) parameters")
    dm = design_model(p, u_design)
    raw = design_model(p, u_design, match_coriolis=False)
    ud = float(u_design)
    nu_d = jnp.stack(
        [jnp.asarray(ud, p.mass.dtype), jnp.zeros_like(p.mass), jnp.zeros_like(p.mass)]
    )
    Yd, Nd = rudder_gains(p, nu_d)
    f = float
    rows = [
        ("L", f(p.length), "m", "NPS AUV II (5.3 m) scaled"),
        ("m", f(p.mass), "kg", "(L/5.3)^3 x 5443.4"),
        ("Iz", f(p.Iz), "kg m^2", "(L/5.3)^5 x 13587"),
        ("m11 = m - X_udot", f(dm.m11), "kg", ""),
        ("m22 = m - Y_vdot", f(dm.m22), "kg", ""),
        ("m23 = m x_g - Y_rdot", f(dm.m23), "kg m", ""),
        ("m33 = Iz - N_rdot", f(dm.m33), "kg m^2", ""),
        ("X_u|u|", f(p.X_uu), "kg/m", "calibrated: thrust_max -> speed"),
        ("d11 = -X_u|u| u_d", f(dm.d11), "N s/m", "secant"),
        ("d22 = -Y_uv u_d", f(dm.d22), "N s/m", ""),
        ("d23", f(dm.d23), "N s", f"hydro only: {f(raw.d23):.1f}"),
        ("d32", f(dm.d32), "N s", f"hydro only: {f(raw.d32):.1f}"),
        ("d33", f(dm.d33), "N m s", f"hydro only: {f(raw.d33):.1f}"),
        ("Y_delta(u_d)", f(Yd), "N/rad", "r2 Ydr u^2"),
        ("N_delta(u_d)", f(Nd), "N m/rad", "r3 Ndr u^2"),
        ("thrust_max", f(p.thrust_max), "N", "paper"),
        ("rudder_max", math.degrees(f(p.rudder_max)), "deg", "paper"),
        ("T_thrust", f(p.T_thrust), "s", "[INF]"),
        ("T_rudder", f(p.T_rudder), "s", "npsauv.m"),
    ]
    head = f"INFANTE-class, NPS-AUV-derived plant; design model (20) at u_d = {ud:g} m/s"
    lines = [
        head,
        f"| {'quantity':<22} | {'value':>11} | {'unit':<7} | note |",
        "|---|---|---|---|",
    ]
    lines += [f"| {n:<22} | {v:>11.2f} | {u:<7} | {note} |" for n, v, u, note in rows]
    return "\n".join(lines)
