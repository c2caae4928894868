"""REMUS 100 AUV: Fossen's PythonVehicleSimulator model (``remus100.py``), in JAX.

What this model is
------------------
This is T. I. Fossen's REMUS 100 model from PythonVehicleSimulator (PVS,
``cybergalactic/PythonVehicleSimulator``, ``src/python_vehicle_simulator/vehicles/remus100.py``
and ``lib/gnc.py``, MIT licence; the sources in ``docs/reference/vehicles.md``), re-implemented
formula by formula.
It is **not** Prestero's (2001) classical-derivative REMUS model: no Prestero coefficients are
used. Mass and added mass come from a prolate spheroid, damping from time constants plus hull
lift/drag and cross-flow drag, the propeller from a linearised Wageningen B-series fit.

Validation: replaying the commands of a 60 s PVS run (commit c717e073, depth/heading autopilot,
0.5 m/s current; ``tests/data/remus100_pvs_reference.csv``) through
[`pvs_step`][vcjax.vehicles.remus100.pvs_step] reproduces
PVS's trajectory to the CSV's 10 significant digits (``tests/test_remus100.py``).

Model (6-DOF, NED / body x forward, z down; ``vcjax.vehicles.sixdof`` conventions)::

    M nu_r_dot + C(nu_r) nu_r + D(U_r) nu_r + g(eta) = tau + tau_liftdrag + tau_crossflow
    nu_dot = nu_r_dot + nu_c_dot,      eta_dot = J(Theta) nu

* Geometry: L = 1.6 m, diameter 0.19 m, spheroid semi-axes ``a = L/2``, ``b = diam/2``;
  CG ``r_bg = [0, 0, 0.02]`` m, CB at the CO. ``m = 4/3 pi rho a b^2`` (31.03 kg; PVS's docstring
  says 31.9 kg, its code gives 31.03), ``W = B = m g``.
* ``M_RB = H(r_bg)^T diag(m, m, m, Ix, Iy, Iz) H(r_bg)``, ``Ix = 2/5 m b^2``,
  ``Iy = Iz = 1/5 m (a^2 + b^2)``; ``M_A = diag(m k1, m k2, m k2, 0.3 Ix, k' Iy, k' Iy)`` from
  Lamb's k-factors of the spheroid.
* ``C = m2c(M_RB, nu_r) + C_A`` with ``C_A = m2c(M_A, nu_r)`` and the entries (0-based)
  (4,0), (0,4), (4,2), (2,4) (pitch) and (5,0), (0,5), (5,1), (1,5) (yaw Munk moment) set to 0.
* ``D = diag(M11/T_surge, M22/T_sway, M33/T_heave, 2 zeta_roll w_roll M44,
  2 zeta_pitch w_pitch M55, M66/T_yaw)`` with ``D11, D22`` multiplied by ``exp(-3 U_r)``;
  ``w_roll = sqrt(W (z_g - z_b) / M44)``, ``w_pitch = sqrt(W (z_g - z_b) / M55)``.
* Hull lift/drag (``gnc.forceLiftDrag``, span ``b = diam``, area ``S = 0.7 L diam``,
  ``CD_0 = 0.42 pi (diam/2)^2 / S``, Oswald ``e = 0.7``): ``alpha = atan2(w_r, u_r)``,
  ``CL = CL_alpha alpha``, ``CD = CD_0 + CL^2 / (pi e AR)``, ``F = 0.5 rho U_r^2 S C``, rotated
  from flow to body axes.
* Cross-flow drag (``gnc.crossFlowDrag``): 21 strips ``x = -L/2 ... L/2`` of width ``L/20``,
  2-D coefficient from Hoerner's curve at ``B/(2T) = 0.5`` (linear interpolation of PVS's table),
  sway force and yaw moment only.
* Fins at ``x_r = x_s = -a``, areas ``2 S_fin`` (``S_fin = 0.00665`` m^2), ``CL = 0.5`` (rudder)
  and 0.7 (stern planes): ``Y_r = -0.5 rho U_rh^2 A_r CL_r delta_r``,
  ``Z_s = -0.5 rho U_rv^2 A_s CL_s delta_s``, drag ``X = -0.5 rho U^2 A CL delta^2``;
  moments ``M = -x_s Z_s``, ``N = x_r Y_r``.
* Propeller (D = 0.14 m, thrust deduction 0.1, advance speed ``Va = 0.944 U`` with the speed
  over ground ``U = |nu[:3]|``): for ``n > 0``,
  ``X = rho D^4 (KT_0 |n| n + (KT_max - KT_0)/Ja_max (Va/D) |n|)``, likewise ``K`` with ``D^5``
  and the KQ's; for ``n <= 0`` only the ``KT_0 / KQ_0`` term. The roll moment is applied as
  ``K_prop / 10`` (PVS: "scaled down by a factor of 10 to match exp. results").
* ``tau = [(1 - t) X_prop + X_r + X_s, Y_r, Z_s, K_prop/10, -x_s Z_s, x_r Y_r]``.
* Current: speed ``V_c`` and direction ``beta_c``, i.e. the NED vector
  ``v_c = [V_c cos beta_c, V_c sin beta_c]``, reaching the plant through its one water door
  ``Remus100Args.water`` ([`WaterMotion`][vcjax.environment.component.WaterMotion], (3,) NED
  velocity and acceleration). As in PVS it is rotated by the **yaw angle only**, and its vertical
  component is not felt:
  ``nu_c = [V_c cos(beta_c - psi), V_c sin(beta_c - psi), 0, 0, 0, 0]``,
  ``nu_c_dot = [r v_c, -r u_c, 0, ...]`` (+ the rotated ``v_c_dot`` of a time-varying current,
  zero in PVS). The generic [`vcjax.vehicles.sixdof`][vcjax.vehicles.sixdof] uses the full
  ``R(Theta)^T``.
* Actuators ``act = [delta_r rad, delta_s rad, n rpm]``: PVS saturates the actuator *states*
  (not the commands) at 15 deg, 15 deg, 1525 rpm at the start of every step, uses the
  saturated values for the forces, and lags them towards the (unsaturated) commands with
  ``T_delta = 0.1 s`` and ``T_n = 1 s``.

Two ways to step it:

* [`pvs_step`][vcjax.vehicles.remus100.pvs_step]: PVS's own discrete step, reproduced exactly
(forward Euler on ``nu`` and the
  actuators, then ``eta[k+1] = eta[k] + dt J(eta[k]) nu[k+1]``, as ``attitudeEuler`` does).
* [`remus100_plant`][vcjax.vehicles.remus100.remus100_plant]: the continuous-time vector field, for
[`vcjax.integrators`][vcjax.integrators] and
  [`vcjax.rollout`][vcjax.rollout]. Its actuator lag is the ``dt -> 0`` limit of PVS's: forces use
  the
  clipped state and the state stops at a limit while the command pushes outwards (no windup).
  [`remus100_plant_smooth`][vcjax.vehicles.remus100.remus100_plant_smooth] instead lags ``limit *
  tanh(cmd / limit)`` (gradients pass
  saturation; note that it maps a command equal to the limit, e.g. 1525 rpm, to 0.76 x it).

Differences from PVS (none at the default parameters): a single ``rho`` is used everywhere
(PVS hard-codes 1026 in ``gnc.forceLiftDrag`` / ``crossFlowDrag`` and uses ``self.rho = 1026``
elsewhere); ``M^-1`` is applied with a Cholesky solve (the factor computed once per run,
``Remus100Args.M_factor``) instead of a precomputed inverse; square
roots and ``atan2`` are NaN-gradient-safe at zero relative velocity.

Everything traced is a ``NamedTuple`` of arrays; the functions are pure ``jax.numpy``,
jit/vmap/grad-safe in float32 and float64.
"""

from __future__ import annotations

import math
from typing import Any, NamedTuple

import jax
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
from vcjax.environment.component import WaterMotion, water_motion
from vcjax.environment.current import current_ned
from vcjax.linalg import cho_solve_small, cholesky_small, safe_norm, saturate, smooth_saturate
from vcjax.vehicles.sixdof import (
    SixDofParams,
    gvect,
    kinematics,
    m2c,
    sixdof_params,
)
from vcjax.vehicles.sixdof import current_in_body as _current_in_body_3d
from vcjax.vehicles.sixdof import validate as _validate_body

__all__ = [
    "CA_ZEROED",
    "HOERNER_TABLE",
    "hoerner",
    "Remus100Params",
    "remus100_params",
    "validate",
    "Remus100State",
    "remus100_state",
    "Remus100Args",
    "remus100_args",
    "mass_matrix",
    "mass_factor",
    "coriolis",
    "damping",
    "current_in_body",
    "propeller",
    "lift_drag",
    "crossflow_drag",
    "control_forces",
    "restoring",
    "remus100_plant",
    "remus100_plant_smooth",
    "pvs_step",
    "pvs_rollout",
    "PVSReplay",
]

#: Hoerner's 2-D cross-flow drag coefficient vs. ``B / (2 T)`` as digitised in PVS ``gnc.py``.
HOERNER_TABLE = (
    (
        0.0109, 0.1766, 0.3530, 0.4519, 0.4728, 0.4929, 0.4933, 0.5585, 0.6464, 0.8336,
        0.9880, 1.3081, 1.6392, 1.8600, 2.3129, 2.6000, 3.0088, 3.4508, 3.7379, 4.0031,
    ),
    (
        1.9661, 1.9657, 1.8976, 1.7872, 1.5837, 1.2786, 1.2108, 1.0836, 0.9986, 0.8796,
        0.8284, 0.7599, 0.6914, 0.6571, 0.6307, 0.5962, 0.5868, 0.5859, 0.5599, 0.5593,
    ),
)  # fmt: skip

#: C_A entries (0-based row, col) that PVS sets to zero (pitch terms and the yaw Munk moment).
CA_ZEROED = ((4, 0), (0, 4), (4, 2), (2, 4), (5, 0), (0, 5), (5, 1), (1, 5))
_CA_MASK = np.ones((6, 6))
for _i, _j in CA_ZEROED:
    _CA_MASK[_i, _j] = 0.0


def hoerner(B, T) -> float:
    """Hoerner's 2-D cross-flow drag coefficient at ``B / (2 T)`` (PVS ``gnc.Hoerner``)."""
    return float(np.interp(B / (2 * T), HOERNER_TABLE[0], HOERNER_TABLE[1]))


class Remus100Params(NamedTuple):
    """REMUS 100 parameters (traced; scalars are () arrays unless noted).

    Attributes:
        body: [`SixDofParams`][vcjax.vehicles.sixdof.SixDofParams] with ``M_RB``, ``M_A``, the
            linear
            damping ``D`` (6, 6) *before* the speed fade, ``W``, ``B``, ``r_bg``, ``r_bb``.
        rho: water density [kg/m^3]; length: L [m]; diam: hull diameter [m].
        S: hull planform area [m^2]; CD_0: parasitic drag coefficient (on ``S``);
        AR: hull aspect ratio ``diam^2 / S``; oswald: Oswald efficiency number.
        fade: rate of the ``exp(-fade U_r)`` fade of ``D11, D22`` [s/m].
        cf_x: (21,) strip positions [m]; cf_dx: strip width [m];
        cf_coeff: ``0.5 rho T Cd_2D`` [kg/m^3] (cross-flow force per strip length per m^2/s^2).
        A_r, A_s: rudder / stern-plane areas [m^2]; CL_delta_r, CL_delta_s: lift coefficients;
        x_r, x_s: fin x-positions [m].
        D_prop: propeller diameter [m]; t_prop: thrust deduction; wake: ``Va / U`` (1 - w);
        Ja_max, KT_0, KQ_0, KT_max, KQ_max: linearised Wageningen fit;
        K_prop_scale: factor on the propeller roll moment (PVS: 0.1).
        act_max: (3,) actuator limits [rad, rad, rpm]; T_act: (3,) lag time constants [s].
    """

    body: SixDofParams
    rho: Any
    length: Any
    diam: Any
    S: Any
    CD_0: Any
    AR: Any
    oswald: Any
    fade: Any
    cf_x: Any
    cf_dx: Any
    cf_coeff: Any
    A_r: Any
    A_s: Any
    CL_delta_r: Any
    CL_delta_s: Any
    x_r: Any
    x_s: Any
    D_prop: Any
    t_prop: Any
    wake: Any
    Ja_max: Any
    KT_0: Any
    KQ_0: Any
    KT_max: Any
    KQ_max: Any
    K_prop_scale: Any
    act_max: Any
    T_act: Any


class Remus100State(NamedTuple):
    """REMUS 100 state (traced).

    Attributes:
        eta: (6,) ``[x, y, z, phi, theta, psi]`` (NED [m], zyx Euler angles [rad]).
        nu: (6,) ``[u, v, w, p, q, r]`` body velocity over ground [m/s, rad/s].
        act: (3,) actuator states ``[delta_r rad, delta_s rad, n rpm]``.
    """

    eta: Any
    nu: Any
    act: Any


class Remus100Args(NamedTuple):
    """Traced arguments of [`remus100_plant`][vcjax.vehicles.remus100.remus100_plant] /
    [`pvs_step`][vcjax.vehicles.remus100.pvs_step].

    Attributes:
        vehicle: [`Remus100Params`][vcjax.vehicles.remus100.Remus100Params].
        water: [`WaterMotion`][vcjax.environment.component.WaterMotion], the water at the hull
            (the one door of every plant): velocity (3,) NED [m/s] and material acceleration
            (3,) [m/s^2].
        M_factor: (6, 6) lower Cholesky factor of ``mass_matrix(vehicle)``
            ([`mass_factor`][vcjax.vehicles.remus100.mass_factor]), or ``None``. ``M`` is constant,
            so [`remus100_args`][vcjax.vehicles.remus100.remus100_args]
            and the loops factor it once, outside the rollout's loop; with ``None`` the plant
            factors it at every evaluation (the same numbers). Rebuild the arguments (or the
            factor) when ``vehicle`` changes.
        uniform: the share of ``water`` that is uniform in space (the current,
            a [`WaterMotion`][vcjax.environment.component.WaterMotion]), or ``None``: all of it.
            PVS's door: the uniform share's horizontal part is rotated by the yaw angle only
            ([`current_in_body`][vcjax.vehicles.remus100.current_in_body]) and its vertical part
            is not felt (PVS's current is horizontal); the rest, ``water - uniform`` (e.g. the
            orbital motion of waves), goes through the full rotation ``R(Theta)^T``, all three
            components.
        tau_w: (6,) extra body force of the waves
            ([`current_door_correction`][vcjax.environment.waves.current_door_correction],
            the pendulum moment of the CG below the CB) [N, N m], or None.
    """

    vehicle: Remus100Params
    water: WaterMotion
    M_factor: Any = None
    uniform: WaterMotion | None = None
    tau_w: Any = None


# --------------------------------------------------------------------------------------------
# Constructors (eager, validated)
# --------------------------------------------------------------------------------------------


def _spheroid(rho, a, b, r_bg, r44):
    """PVS's spheroid mass, rigid-body mass about the CO and Lamb added mass (float64)."""
    m = 4.0 / 3.0 * math.pi * rho * a * b**2
    Ix = 2.0 / 5.0 * m * b**2
    Iy = 1.0 / 5.0 * m * (a**2 + b**2)
    Iz = Iy
    # H(r_bg) = [[I, S(r_bg)^T], [0, I]] (sixdof.Hmtrx), in float64 numpy
    H = np.eye(6)
    H[0:3, 3:6] = np.array(
        [[0.0, r_bg[2], -r_bg[1]], [-r_bg[2], 0.0, r_bg[0]], [r_bg[1], -r_bg[0], 0.0]]
    )
    M_RB = H.T @ np.diag([m, m, m, Ix, Iy, Iz]) @ H

    e = math.sqrt(1.0 - (b / a) ** 2)
    log_e = math.log((1.0 + e) / (1.0 - e))
    alpha_0 = (2.0 * (1.0 - e**2) / e**3) * (0.5 * log_e - e)
    beta_0 = 1.0 / e**2 - (1.0 - e**2) / (2.0 * e**3) * log_e
    k1 = alpha_0 / (2.0 - alpha_0)
    k2 = beta_0 / (2.0 - beta_0)
    k_prime = (
        e**4
        * (beta_0 - alpha_0)
        / ((2.0 - e**2) * (2.0 * e**2 - (2.0 - e**2) * (beta_0 - alpha_0)))
    )
    M_A = np.diag([m * k1, m * k2, m * k2, r44 * Ix, k_prime * Iy, k_prime * Iy])
    return m, M_RB, M_A


def remus100_params(
    rho=1026.0,
    g=9.81,
    r_bg=(0.0, 0.0, 0.02),
    r_bb=(0.0, 0.0, 0.0),
    delta_max_deg=15.0,
    n_max=1525.0,
    T_delta=0.1,
    T_n=1.0,
    dtype=None,
) -> Remus100Params:
    """Build the PVS REMUS 100 parameters; every other number is PVS's (see module docstring).

    Args:
        rho: water density [kg/m^3] (PVS: 1026); g: gravity [m/s^2] (PVS: 9.81).
        r_bg, r_bb: (3,) CG and CB w.r.t. the CO [m]; the CG must lie below the CB
            (``z_g > z_b``), which PVS's roll/pitch damping formula needs.
        delta_max_deg: rudder and stern-plane saturation [deg] (PVS: 15).
        n_max: propeller saturation [rpm] (PVS: 1525).
        T_delta: fin time constant [s] (PVS: 0.1); T_n: propeller time constant [s] (PVS: 1).
        dtype: float dtype of every array (default: JAX's default float).

    Other PVS numbers can be changed afterwards with ``params._replace(...)``.

    Raises:
        ValueError: naming the offending argument.
    """
    for name, v in dict(rho=rho, g=g, n_max=n_max, T_delta=T_delta, T_n=T_n).items():
        check_positive(name, v, ())
    check_positive("delta_max_deg", delta_max_deg, ())
    if not float(delta_max_deg) < 90.0:
        raise ValueError(f"delta_max_deg: expected a value in (0, 90) deg, got {delta_max_deg}")
    rbg = check_array("r_bg", r_bg, (3,)).astype(np.float64)
    rbb = check_array("r_bb", r_bb, (3,)).astype(np.float64)
    if not rbg[2] > rbb[2]:
        raise ValueError(
            f"r_bg: the CG must lie below the CB (z_g > z_b) for the roll/pitch damping, "
            f"got z_g = {rbg[2]}, z_b = {rbb[2]}"
        )
    rho, g = float(rho), float(g)

    L, diam = 1.6, 0.19
    a, b = L / 2.0, diam / 2.0
    S = 0.7 * L * diam
    CD_0 = 0.42 * math.pi * b**2 / S
    m, M_RB, M_A = _spheroid(rho, a, b, rbg, r44=0.3)
    W = m * g
    B = W
    M = M_RB + M_A
    w_roll = math.sqrt(W * (rbg[2] - rbb[2]) / M[3, 3])
    w_pitch = math.sqrt(W * (rbg[2] - rbb[2]) / M[4, 4])
    T_surge, T_sway, T_yaw, zeta_roll, zeta_pitch = 20.0, 20.0, 1.0, 0.3, 0.8
    T_heave = T_sway
    D = np.diag(
        [
            M[0, 0] / T_surge,
            M[1, 1] / T_sway,
            M[2, 2] / T_heave,
            M[3, 3] * 2.0 * zeta_roll * w_roll,
            M[4, 4] * 2.0 * zeta_pitch * w_pitch,
            M[5, 5] / T_yaw,
        ]
    )

    # Cross-flow strips exactly as gnc.crossFlowDrag lays them out (x accumulated by += dx).
    n_strips = 20
    dx = L / n_strips
    xs, x = [], -L / 2.0
    for _ in range(n_strips + 1):
        xs.append(x)
        x += dx
    T_draft = diam
    cf_coeff = 0.5 * rho * T_draft * hoerner(diam, T_draft)

    S_fin = 0.00665
    dtype = float_dtype(dtype)
    body = sixdof_params(M_RB, M_A, D, W, B, rbg, rbb, dtype=dtype)

    def s(v):
        return jnp.asarray(v, dtype=dtype)

    return Remus100Params(
        body=body,
        rho=s(rho),
        length=s(L),
        diam=s(diam),
        S=s(S),
        CD_0=s(CD_0),
        AR=s(diam**2 / S),
        oswald=s(0.7),
        fade=s(3.0),
        cf_x=s(np.array(xs)),
        cf_dx=s(dx),
        cf_coeff=s(cf_coeff),
        A_r=s(2.0 * S_fin),
        A_s=s(2.0 * S_fin),
        CL_delta_r=s(0.5),
        CL_delta_s=s(0.7),
        x_r=s(-a),
        x_s=s(-a),
        D_prop=s(0.14),
        t_prop=s(0.1),
        wake=s(0.944),
        Ja_max=s(0.6632),
        KT_0=s(0.4566),
        KQ_0=s(0.0700),
        KT_max=s(0.1798),
        KQ_max=s(0.0312),
        K_prop_scale=s(0.1),
        act_max=s(np.array([math.radians(delta_max_deg)] * 2 + [float(n_max)])),
        T_act=s(np.array([float(T_delta), float(T_delta), float(T_n)])),
    )


def validate(params: Remus100Params, name: str = "vehicle") -> Remus100Params:
    """Eagerly check [`Remus100Params`][vcjax.vehicles.remus100.Remus100Params] however they were
    built (also after
    ``_replace``): every field finite; density, length, diameter, areas, propeller diameter,
    actuator limits and time constants > 0; the body
    ([`vcjax.vehicles.sixdof.validate`][vcjax.vehicles.sixdof.validate]).

    Returns ``params``. Raises ``ValueError`` naming ``name.field``. Skipped under ``jit``.
    """
    check_params(
        Remus100Params,
        params,
        positive=("rho", "length", "diam", "S", "A_r", "A_s", "D_prop", "act_max", "T_act"),
        name=name,
    )
    _validate_body(params.body, f"{name}.body")
    return params


def remus100_state(eta=None, nu=None, act=None, dtype=None) -> Remus100State:
    """Validated [`Remus100State`][vcjax.vehicles.remus100.Remus100State]; every field defaults to
    zeros.

    Args:
        eta: (6,) pose; nu: (6,) body velocity; act: (3,) ``[delta_r rad, delta_s rad, n rpm]``.
        dtype: float dtype (default: JAX's default float).

    Raises:
        ValueError: naming the field for a wrong shape or a NaN/inf entry.
    """
    dtype = float_dtype(dtype)
    eta = jnp.zeros(6, dtype=dtype) if eta is None else as_float_array("eta", eta, (6,), dtype)
    nu = jnp.zeros(6, dtype=dtype) if nu is None else as_float_array("nu", nu, (6,), dtype)
    act = jnp.zeros(3, dtype=dtype) if act is None else as_float_array("act", act, (3,), dtype)
    return Remus100State(eta=eta, nu=nu, act=act)


def remus100_args(
    vehicle: Remus100Params, V_c=0.0, beta_c=0.0, water: WaterMotion | None = None
) -> Remus100Args:
    """Validated [`Remus100Args`][vcjax.vehicles.remus100.Remus100Args].

    The current is given either as PVS does, speed ``V_c`` [m/s] and direction ``beta_c``
    [rad] (the direction it flows to, from north towards east; PVS's constructor takes degrees),
    or as the water at the hull, ``water``, which then takes precedence.

    Args:
        vehicle: [`Remus100Params`][vcjax.vehicles.remus100.Remus100Params].
        V_c, beta_c: () current speed [m/s] and direction [rad].
        water: [`WaterMotion`][vcjax.environment.component.WaterMotion] (velocity (3,) NED
            [m/s], acceleration (3,) [m/s^2], default 0 as in PVS; overrides ``V_c``,
            ``beta_c``), e.g. ``water_motion([0.3, -0.2, 0.0])``.
    """
    validate(vehicle)
    dtype = jnp.asarray(vehicle.rho).dtype
    if water is None:
        check_array("V_c", V_c, ())
        check_array("beta_c", beta_c, ())
        v = current_ned(jnp.asarray(V_c, dtype=dtype), jnp.asarray(beta_c, dtype=dtype))
        water = WaterMotion(v, None)
    water = water_motion(*water, dtype=dtype)
    return Remus100Args(vehicle=vehicle, water=water, M_factor=mass_factor(vehicle))


# --------------------------------------------------------------------------------------------
# Model terms
# --------------------------------------------------------------------------------------------


def mass_matrix(p: Remus100Params):
    """(6, 6) ``M = M_RB + M_A`` about the CO."""
    return p.body.M_RB + p.body.M_A


def mass_factor(p: Remus100Params):
    """(6, 6) lower Cholesky factor ``L`` of [`mass_matrix`][vcjax.vehicles.remus100.mass_matrix]
    (``M = L L^T``), for
    ``Remus100Args.M_factor``."""
    return cholesky_small(mass_matrix(p))


def coriolis(p: Remus100Params, nu_r):
    """(6, 6) ``C = m2c(M_RB, nu_r) + C_A``, PVS's ``C_A`` entries ``CA_ZEROED`` set to 0."""
    C_A = m2c(p.body.M_A, nu_r) * jnp.asarray(_CA_MASK, dtype=nu_r.dtype)
    return m2c(p.body.M_RB, nu_r) + C_A


def damping(p: Remus100Params, U_r):
    """(6, 6) linear damping with ``D11, D22`` faded by ``exp(-fade U_r)`` (``U_r`` [m/s])."""
    f = jnp.exp(-p.fade * U_r)
    return p.body.D.at[0, 0].multiply(f).at[1, 1].multiply(f)


def current_in_body(eta, nu, v_c, v_c_dot=None):
    """PVS's body-frame current: yaw rotation only.

    ``nu_c = [Rz(psi)^T v_c, 0, 0, 0, 0]`` (= ``[V_c cos(beta_c - psi), V_c sin(beta_c - psi),
    0, ...]``) and ``nu_c_dot = [r v_c, -r u_c, 0, ...]`` (+ ``Rz(psi)^T v_c_dot``).

    A (3,) ``v_c`` (the water's NED velocity, e.g. current + waves,
    [`water_kinematics`][vcjax.environment.waves.water_kinematics]) takes the full rotation instead,
    ``nu_c = [R(Theta)^T v_c; 0]`` ([`current_in_body`][vcjax.vehicles.sixdof.current_in_body]).

    Args:
        eta: (6,) pose; nu: (6,) body velocity; v_c, v_c_dot: (2,) NED current and its rate,
            or (3,) both.

    Returns:
        ``(nu_c (6,), nu_c_dot (6,))``.
    """
    if v_c.shape[-1] == 3:
        return _current_in_body_3d(eta, nu, v_c, v_c_dot)
    c, s = jnp.cos(eta[5]), jnp.sin(eta[5])
    u_c = c * v_c[0] + s * v_c[1]
    v_cb = -s * v_c[0] + c * v_c[1]
    r = nu[5]
    du, dv = r * v_cb, -r * u_c
    if v_c_dot is not None:
        du = du + c * v_c_dot[0] + s * v_c_dot[1]
        dv = dv - s * v_c_dot[0] + c * v_c_dot[1]
    z = jnp.zeros(4, dtype=u_c.dtype)
    return (
        jnp.concatenate([jnp.stack([u_c, v_cb]), z]),
        jnp.concatenate([jnp.stack([du, dv]), z]),
    )


def propeller(p: Remus100Params, n_rpm, U):
    """Propeller thrust ``X_prop`` [N] and roll moment ``K_prop`` [N m] (before ``(1 - t)``
    and ``K_prop_scale``).

    Args:
        p: parameters; n_rpm: () applied (saturated) propeller speed [rpm];
        U: () vehicle speed over ground ``|nu[:3]|`` [m/s] (PVS uses it for ``Va``).
    """
    n = n_rpm / 60.0
    nn = jnp.abs(n) * n
    D4 = p.D_prop**4
    D5 = p.D_prop**5
    Va = p.wake * U
    lin = (Va / p.D_prop) * jnp.abs(n) / p.Ja_max
    fwd = n > 0
    X = p.rho * D4 * (p.KT_0 * nn + jnp.where(fwd, (p.KT_max - p.KT_0) * lin, 0.0 * lin))
    K = p.rho * D5 * (p.KQ_0 * nn + jnp.where(fwd, (p.KQ_max - p.KQ_0) * lin, 0.0 * lin))
    return X, K


def _safe_atan2(y, x):
    ok = (x * x + y * y) > 0
    return jnp.where(
        ok, jnp.arctan2(jnp.where(ok, y, 0.0 * y), jnp.where(ok, x, jnp.ones_like(x))), 0.0 * x
    )


def lift_drag(p: Remus100Params, nu_r):
    """(6,) hull lift and drag (PVS ``gnc.forceLiftDrag`` with ``b = diam``), body axes.

    ``alpha = atan2(w_r, u_r)``, ``CL = CL_alpha alpha``, ``CD = CD_0 + CL^2/(pi e AR)``,
    ``CL_alpha = pi AR / (1 + sqrt(1 + (AR/2)^2))``;
    ``X = -cos(alpha) F_D + sin(alpha) F_L``, ``Z = -sin(alpha) F_D - cos(alpha) F_L``.
    """
    u, w = nu_r[0], nu_r[2]
    U2 = nu_r[0] ** 2 + nu_r[1] ** 2 + nu_r[2] ** 2
    alpha = _safe_atan2(w, u)
    CL_alpha = jnp.pi * p.AR / (1.0 + jnp.sqrt(1.0 + (p.AR / 2.0) ** 2))
    CL = CL_alpha * alpha
    CD = p.CD_0 + CL**2 / (jnp.pi * p.oswald * p.AR)
    q = 0.5 * p.rho * U2 * p.S
    F_drag, F_lift = q * CD, q * CL
    ca, sa = jnp.cos(alpha), jnp.sin(alpha)
    z = jnp.zeros_like(u)
    X = ca * (-F_drag) - sa * (-F_lift)
    Z = sa * (-F_drag) + ca * (-F_lift)
    return jnp.stack([X, z, Z, z, z, z])


def crossflow_drag(p: Remus100Params, nu_r):
    """(6,) cross-flow drag by strip theory (PVS ``gnc.crossFlowDrag``): sway and yaw only."""
    h = nu_r[1] + p.cf_x * nu_r[5]
    hh = jnp.abs(h) * h
    k = p.cf_coeff * p.cf_dx
    Y = -k * jnp.sum(hh)
    N = -k * jnp.sum(p.cf_x * hh)
    z = jnp.zeros_like(Y)
    return jnp.stack([z, Y, z, z, z, N])


def control_forces(p: Remus100Params, nu, nu_r, act):
    """(6,) ``tau`` of the propeller, rudder and stern planes.

    Args:
        p: parameters; nu: (6,) velocity over ground (for the propeller's advance speed);
        nu_r: (6,) relative velocity; act: (3,) *applied* (saturated) ``[delta_r, delta_s, n]``.

    Returns:
        ``[(1-t) X_prop + X_r + X_s, Y_r, Z_s, K_prop_scale K_prop, -x_s Z_s, x_r Y_r]``.
    """
    delta_r, delta_s, n = act[0], act[1], act[2]
    U = safe_norm(nu[:3])
    X_prop, K_prop = propeller(p, n, U)
    U_rh2 = nu_r[0] ** 2 + nu_r[1] ** 2
    U_rv2 = nu_r[0] ** 2 + nu_r[2] ** 2
    k_r = 0.5 * p.rho * U_rh2 * p.A_r * p.CL_delta_r
    k_s = 0.5 * p.rho * U_rv2 * p.A_s * p.CL_delta_s
    X_r = -k_r * delta_r**2
    X_s = -k_s * delta_s**2
    Y_r = -k_r * delta_r
    Z_s = -k_s * delta_s
    return jnp.stack(
        [
            (1.0 - p.t_prop) * X_prop + X_r + X_s,
            Y_r,
            Z_s,
            p.K_prop_scale * K_prop,
            -p.x_s * Z_s,
            p.x_r * Y_r,
        ]
    )


def restoring(p: Remus100Params, eta):
    """(6,) ``g(eta) = gvect(W, B, theta, phi, r_bg, r_bb)``."""
    b = p.body
    return gvect(b.W, b.B, eta[4], eta[3], b.r_bg, b.r_bb)


def _nu_dot(x: Remus100State, act_applied, args: Remus100Args):
    """``nu_dot`` (6,) with the applied (saturated) actuator values."""
    p = args.vehicle
    eta, nu = x.eta, x.nu
    w = args.water
    c = w if args.uniform is None else args.uniform
    # PVS's door: the uniform current's horizontal part, yaw rotation only
    a_c = None if c.acceleration is None else c.acceleration[:2]
    nu_c, nu_c_dot = current_in_body(eta, nu, c.velocity[:2], a_c)
    if args.uniform is not None:  # what varies in space (waves) on top: the full rotation
        a = w.acceleration
        if a is not None and c.acceleration is not None:
            a = a - c.acceleration
        nu_w, nu_w_dot = _current_in_body_3d(eta, nu, w.velocity - c.velocity, a)
        nu_c, nu_c_dot = nu_c + nu_w, nu_c_dot + nu_w_dot
    nu_r = nu - nu_c
    U_r = safe_norm(nu_r[:3])
    tau_sum = (
        control_forces(p, nu, nu_r, act_applied)
        + lift_drag(p, nu_r)
        + crossflow_drag(p, nu_r)
        - (coriolis(p, nu_r) + damping(p, U_r)) @ nu_r
        - restoring(p, eta)
    )
    if args.tau_w is not None:
        tau_sum = tau_sum + args.tau_w
    L = mass_factor(p) if args.M_factor is None else args.M_factor
    return nu_c_dot + cho_solve_small(L, tau_sum)


# --------------------------------------------------------------------------------------------
# Continuous-time plant and PVS's discrete step
# --------------------------------------------------------------------------------------------


def remus100_plant(t, x: Remus100State, u_cmd, args: Remus100Args) -> Remus100State:
    """Vector field ``x_dot = f(t, x, u_cmd, args)`` (the [`vcjax.rollout`][vcjax.rollout] plant
    signature).

    The forces use the clipped actuator state ``sat(act)``; ``act_dot = (u_cmd - sat(act)) / T``,
    set to zero where ``act`` sits at (or beyond) a limit and the command pushes further out:
    the ``dt -> 0`` limit of PVS's per-step state clipping, without integrator windup.

    Args:
        t: () time [s] (unused; the plant is autonomous).
        x: [`Remus100State`][vcjax.vehicles.remus100.Remus100State].
        u_cmd: (3,) commands ``[delta_r_cmd rad, delta_s_cmd rad, n_cmd rpm]``.
        args: [`Remus100Args`][vcjax.vehicles.remus100.Remus100Args].

    Returns:
        [`Remus100State`][vcjax.vehicles.remus100.Remus100State] of time derivatives.
    """
    p = args.vehicle
    act_s = saturate(x.act, p.act_max)
    act_dot = (u_cmd - act_s) / p.T_act
    outward = (jnp.abs(x.act) >= p.act_max) & (act_dot * x.act > 0)
    act_dot = jnp.where(outward, 0.0 * act_dot, act_dot)
    nu_dot = _nu_dot(x, act_s, args)
    return Remus100State(eta=kinematics(x.eta) @ x.nu, nu=nu_dot, act=act_dot)


def remus100_plant_smooth(t, x: Remus100State, u_cmd, args: Remus100Args) -> Remus100State:
    """As [`remus100_plant`][vcjax.vehicles.remus100.remus100_plant], lagging ``limit * tanh(u_cmd /
    limit)`` (for gradients).

    The actuator state stays inside the limits on its own, so the forces use it unclipped.
    A command equal to the limit settles at ``tanh(1) = 0.76`` x the limit.
    """
    p = args.vehicle
    act_dot = (smooth_saturate(u_cmd, p.act_max) - x.act) / p.T_act
    nu_dot = _nu_dot(x, x.act, args)
    return Remus100State(eta=kinematics(x.eta) @ x.nu, nu=nu_dot, act=act_dot)


def pvs_step(x: Remus100State, u_cmd, args: Remus100Args, dt) -> Remus100State:
    """One step of PythonVehicleSimulator's own scheme, reproduced exactly.

    ``remus100.dynamics`` then ``gnc.attitudeEuler``::

        a      = sat(act[k])                          (clip the actuator *states*)
        nu[k+1]  = nu[k] + dt * nu_dot(eta[k], nu[k], a)
        act[k+1] = a + dt * (u_cmd[k] - a) / T
        eta[k+1] = eta[k] + dt * J(eta[k]) nu[k+1]    (the *new* velocity, the old angles)

    Args:
        x: [`Remus100State`][vcjax.vehicles.remus100.Remus100State] at step k; u_cmd: (3,) commands
            held over the step;
        args: [`Remus100Args`][vcjax.vehicles.remus100.Remus100Args]; dt: () step [s] (PVS
            ``sampleTime``, e.g. 0.02).

    Returns:
        [`Remus100State`][vcjax.vehicles.remus100.Remus100State] at step k + 1.
    """
    p = args.vehicle
    act_s = saturate(x.act, p.act_max)
    nu_next = x.nu + dt * _nu_dot(x, act_s, args)
    act_next = act_s + dt * ((u_cmd - act_s) / p.T_act)
    eta_next = x.eta + dt * (kinematics(x.eta) @ nu_next)
    return Remus100State(eta=eta_next, nu=nu_next, act=act_next)


class PVSReplay(NamedTuple):
    """Result of [`pvs_rollout`][vcjax.vehicles.remus100.pvs_rollout].

    Attributes:
        x: [`Remus100State`][vcjax.vehicles.remus100.Remus100State] with leaves stacked to (N + 1,
            ...), starting with ``x0``.
        ok: (N,) bool, step k was valid: its command finite, ``dt`` finite and > 0, and the
            state it produced finite (False from the first bad step on, as a NaN never heals).
    """

    x: Remus100State
    ok: Any


def pvs_rollout(x0: Remus100State, u_cmds, args: Remus100Args, dt) -> PVSReplay:
    """Replay commands ``u_cmds`` (N, 3) through [`pvs_step`][vcjax.vehicles.remus100.pvs_step] as
    one ``lax.scan``.

    ``dt`` and ``u_cmds`` are checked eagerly when concrete (``ValueError`` naming them); inside
    ``jit`` a bad command or step is reported as data in ``PVSReplay.ok``.

    Returns:
        [`PVSReplay`][vcjax.vehicles.remus100.PVSReplay]. Not jitted: jit at your entry point
        (``jax.jit(pvs_rollout)``).
    """
    if is_concrete(dt):
        a = np.asarray(dt)
        if a.shape != () or not (np.isfinite(a) and a > 0):
            raise ValueError(f"dt: expected a finite step size > 0 [s], got {dt!r}")
    check_array("u_cmds", u_cmds, (None, 3))
    dt = jnp.asarray(dt, dtype=x0.nu.dtype)
    dt_ok = jnp.isfinite(dt) & (dt > 0)

    def step(carry, u):
        x, ok = carry
        x_next = pvs_step(x, u, args, dt)
        ok = ok & dt_ok & jnp.all(jnp.isfinite(u)) & _finite_state(x_next)
        return (x_next, ok), (x_next, ok)

    _, (xs, oks) = jax.lax.scan(step, (x0, jnp.array(True)), u_cmds)
    x = jax.tree_util.tree_map(lambda a, b: jnp.concatenate([a[None], b]), x0, xs)
    return PVSReplay(x=x, ok=oks)


def _finite_state(x) -> jax.Array:
    return jnp.all(jnp.stack([jnp.all(jnp.isfinite(a)) for a in jax.tree_util.tree_leaves(x)]))
