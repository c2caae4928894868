"""Plain NumPy model of Simulation 1's ``vcm_integral`` closed loop (no JAX).

What a user without JAX would write: the INFANTE-class plant, the underactuated VCM law with
integral action and classical RK4, written from the equations in the docstrings of
``vcjax/vehicles/infante.py``, ``vcjax/vehicles/design3dof.py``, ``vcjax/guidance.py`` and
``vcjax/control/vcm.py`` (paper eqs. (20)-(41)), not by translating the JAX code. It is the
baseline of ``benchmarks/perf/numpy_baseline.py`` and an independent cross-check of vcjax
(``tests/test_numpy_reference.py``).

Derived independently where the JAX code takes another route:

* the plant parameters are rebuilt from npsauv.m's prime coefficients and the scaling rules
  (``r_k = rho/2 L^k``, ``m ~ L^3``, ``Iz ~ L^5``, ``X_u|u|`` calibrated from 920 N -> 5 m/s);
* the path is a straight line, so its frame is closed-form (``psi_p`` constant, no autodiff);
* the underactuation condition ``tau_v = k_rudder tau_r`` (Remark 4) is solved for ``v_dot`` in
  closed form (vcjax uses a ``jax.jvp`` of the affine map);
* ``M^{-1}`` of the plant is computed once (vcjax solves ``M nu_r_dot = f`` at every stage).

The vector field is written once over an array namespace ``xp``: :data:`SCALAR` (Python floats
and :mod:`math`, fastest for one trajectory) or :mod:`numpy` (arrays of shape (B,), one
Python-level RK4 step for a whole batch).

State ``y`` (11 entries, each a float or a (B,) array)::

    x, y, psi, u, v, r, thrust, delta, varpi, v_d, int_s, int_e

(``int_s, int_e``: the integral of ``eps = [s, e]``), i.e. vcjax's ``InfanteState(eta, nu, act)``
followed by ``VCMState(varpi, v_d, int_eps)``: 12 numbers.
"""

from __future__ import annotations

import math
import types
from typing import NamedTuple

import numpy as np

__all__ = [
    "NPS_PRIME",
    "Plant",
    "plant_params",
    "Design",
    "design_params",
    "Gains",
    "default_gains",
    "Scenario",
    "SCALAR",
    "closed_loop_rhs",
    "initial_state",
    "rk4_step",
    "simulate",
    "simulate_batch",
    "STATE_NAMES",
]

STATE_NAMES = (
    "x",
    "y",
    "psi",
    "u",
    "v",
    "r",
    "thrust",
    "delta",
    "varpi",
    "v_d",
    "int_s",
    "int_e",
)

#: npsauv.m (Healey & Lienard 1993) prime coefficients acting in the horizontal plane.
NPS_PRIME = {
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


class Plant(NamedTuple):
    """Dimensional INFANTE-class parameters (floats; ``cf_x`` a tuple of strip stations)."""

    mass: float
    Iz: float
    x_g: float
    X_udot: float
    Y_vdot: float
    Y_rdot: float
    N_vdot: float
    N_rdot: float
    X_uu: float
    X_vv: float
    X_vr: float
    X_rr: float
    Y_uv: float
    Y_ur: float
    N_uv: float
    N_ur: float
    X_urdr: float
    X_uvdr: float
    X_uudrdr: float
    Y_uudr: float
    N_uudr: float
    cf_k: float  # rho/2 Cdy H dx: cross-flow drag per strip
    cf_x: tuple
    thrust_max: float
    rudder_max: float
    T_thrust: float
    T_rudder: float
    rudder_speed_min: float
    Minv: tuple  # (3, 3) inverse of M = M_RB + M_A, row-major nested tuples


def plant_params(
    length=4.5,
    thrust_max=920.0,
    rudder_max_deg=30.0,
    T_thrust=0.5,
    T_rudder=0.1,
    speed_at_max_thrust=5.0,
    rho=1025.0,
    x_g=0.0,
    rudder_speed_min=0.5,
) -> Plant:
    """NPS AUV II (L = 5.3 m, W = 53400 N, Iz = 13587 kg m^2) scaled to ``length``."""
    L = float(length)
    scale = L / 5.3
    r2, r3, r4, r5 = (0.5 * rho * L**k for k in (2, 3, 4, 5))
    P = NPS_PRIME
    mass = 53400.0 / 9.81 * scale**3 * (rho / 1025.0)
    Iz = 13587.0 * scale**5 * (rho / 1025.0)
    # straight, calm water, v = r = delta = 0: thrust_max + X_u|u| U^2 = 0
    X_uu = -thrust_max / speed_at_max_thrust**2
    X_udot, Y_vdot, Y_rdot = r3 * P["Xudot"], r3 * P["Yvdot"], r4 * P["Yrdot"]
    N_vdot, N_rdot = r4 * P["Nvdot"], r5 * P["Nrdot"]
    M = np.array(
        [
            [mass - X_udot, 0.0, 0.0],
            [0.0, mass - Y_vdot, mass * x_g - Y_rdot],
            [0.0, mass * x_g - N_vdot, Iz - N_rdot],
        ]
    )
    Minv = tuple(tuple(float(a) for a in row) for row in np.linalg.inv(M))
    n_strips = 10
    return Plant(
        mass=mass,
        Iz=Iz,
        x_g=x_g,
        X_udot=X_udot,
        Y_vdot=Y_vdot,
        Y_rdot=Y_rdot,
        N_vdot=N_vdot,
        N_rdot=N_rdot,
        X_uu=X_uu,
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
        cf_k=0.5 * rho * 0.5 * 0.53 * scale * (L / n_strips),
        cf_x=tuple(float(a) for a in np.linspace(-L / 2, L / 2, n_strips + 1)),
        thrust_max=thrust_max,
        rudder_max=math.radians(rudder_max_deg),
        T_thrust=T_thrust,
        T_rudder=T_rudder,
        rudder_speed_min=rudder_speed_min,
        Minv=Minv,
    )


class Design(NamedTuple):
    """The controller's design model (20) and rudder ratio (floats)."""

    m11: float
    m22: float
    m23: float
    m33: float
    d11: float
    d22: float
    d23: float
    d32: float
    d33: float
    k_rudder: float  # Y_delta / N_delta (Remark 4)
    N_uudr: float  # for the rudder map
    rudder_speed_min: float


def design_params(p: Plant, u_design=2.0) -> Design:
    """Design model (20) linearised at ``nu_r = [u_design, 0, 0]``, Coriolis slopes matched."""
    m11 = p.mass - p.X_udot
    m22 = p.mass - p.Y_vdot
    m23 = p.mass * p.x_g - p.Y_rdot
    m33 = p.Iz - p.N_rdot
    ud = u_design
    return Design(
        m11=m11,
        m22=m22,
        m23=m23,
        m33=m33,
        d11=-p.X_uu * ud,
        d22=-p.Y_uv * ud,
        d23=-p.Y_ur * ud + (p.mass - m11) * ud,
        d32=-p.N_uv * ud - (m22 - m11) * ud,
        d33=-p.N_ur * ud + (p.mass * p.x_g - m23) * ud,
        k_rudder=p.Y_uudr / p.N_uudr,
        N_uudr=p.N_uudr,
        rudder_speed_min=p.rudder_speed_min,
    )


class Gains(NamedTuple):
    """VCM gains (docs/method.md), ``P_G = (pG1, pG2, pG3)``, ``P_Phi = (pPhi1..pPhi5)``."""

    P_G: tuple = (1.0, 0.5, 0.5)
    P_Phi: tuple = (1.0, 1.0, 2.0, 0.5, 0.5)
    Delta: float = 5.0
    sigma: float = 0.5
    P_int: tuple = (0.05, 0.0)
    int_limit: float = 50.0


def default_gains() -> Gains:
    """Simulation 1's ``vcm_integral`` gains (integral action on ``s`` only)."""
    return Gains()


class Scenario(NamedTuple):
    """Straight path ``p(w) = origin + w direction`` (unit 2-D direction), current, speed."""

    eta0: tuple = (0.0, 0.0, math.pi / 2)
    nu0: tuple = (2.0, 0.0, 0.0)
    V_c: tuple = (0.0, 0.5)
    u_d: float = 2.0
    origin: tuple = (10.0, 0.0)
    direction: tuple = (0.0, 1.0)


def _clip(x, lo, hi):
    return min(max(x, lo), hi)


#: Scalar "array namespace": Python floats and :mod:`math`.
SCALAR = types.SimpleNamespace(
    sin=math.sin,
    cos=math.cos,
    arctan=math.atan,
    abs=abs,
    clip=_clip,
    maximum=max,
    mod=lambda a, b: a % b,  # floor-mod, like numpy.mod (math.fmod truncates)
)


def _wrap(xp, a):
    """Angle into [-pi, pi)."""
    return xp.mod(a + math.pi, 2 * math.pi) - math.pi


def closed_loop_rhs(y, p: Plant, d: Design, g: Gains, sc: Scenario, xp=SCALAR):
    """Time derivative of the 12-entry closed-loop state (continuous-time controller).

    Returns a list of 12 derivatives and, as a second value, ``(s, e)``.
    """
    X, Y, psi, u, v, r, thrust, delta, varpi, v_d, int_s, int_e = y
    c, sn = xp.cos(psi), xp.sin(psi)

    # ---- path frame of the straight line (21): constant azimuth, unit speed
    dx, dy = sc.direction
    psi_p = math.atan2(dy, dx)
    cp, sp = math.cos(psi_p), math.sin(psi_p)
    px, py = sc.origin[0] + varpi * dx, sc.origin[1] + varpi * dy
    # (23) eps = R(psi_p)^T (p - p_bar)
    s = cp * (X - px) + sp * (Y - py)
    e = -sp * (X - px) + cp * (Y - py)

    # ---- guidance (22), (28): psi_p_dot = psi_p_ddot = 0 on a line
    ubar = sc.u_d + g.sigma * s
    varpi_dot = ubar  # |p_bar'| = 1
    gam = psi - psi_p
    cg, sg = xp.cos(gam), xp.sin(gam)
    s_dot = cg * u - sg * v - ubar
    e_dot = sg * u + cg * v
    ubar_dot = g.sigma * s_dot
    # eps_ddot = R(gamma) w_dot + drift, drift = gamma_dot R(gamma) [-v, u] - [ubar_dot, 0]
    drift_s = r * (cg * -v - sg * u) - ubar_dot
    drift_e = r * (sg * -v + cg * u)

    # ---- designed eps dynamics (35)/(41)
    pG1, pG2, pG3 = g.P_G
    pP1, pP2, pP3, pP4, pP5 = g.P_Phi
    a_s = -(pG2 + pP4) * s_dot - pG2 * pP4 * s - g.P_int[0] * int_s
    a_e = -(pG3 + pP5) * e_dot - pG3 * pP5 * e - g.P_int[1] * int_e
    al_s, al_e = a_s - drift_s, a_e - drift_e
    # R(gamma)^T alpha_eps
    rt_s = cg * al_s + sg * al_e
    rt_e = -sg * al_s + cg * al_e

    # ---- heading: LOS approach angle (24), (36)
    kap = g.Delta / (g.Delta**2 + e * e)
    psi_d = psi_p + xp.arctan(-e / g.Delta)
    psi_t = _wrap(xp, psi - psi_d)
    psi_t_dot = r + kap * e_dot
    psi_r_ddot = -kap * a_e + 2 * kap * kap * e_dot * e_dot * e / g.Delta
    r_dot = psi_r_ddot - pG1 * psi_t_dot - pP3 * (psi_t_dot + pG1 * psi_t)

    # ---- bias n_b = C_b(nu) nu + D_b nu of (20)
    a = d.m22 * v + d.m23 * r
    b = d.m11 * u
    n1 = -a * r + d.d11 * u
    n2 = b * r + d.d22 * v + d.d23 * r
    n3 = a * u - b * v + d.d32 * v + d.d33 * r

    # ---- surge row (31); underactuated sway (38): choose v_dot so that the sway force the
    # law asks for is the rudder's own, tau_v = k tau_r (Remark 4)
    u_dot = 0.5 * (-pP1 * (u - sc.u_d) + rt_s)
    k = d.k_rudder
    v_dot = (k * (d.m33 * r_dot + n3) - d.m23 * r_dot - n2) / (d.m22 - k * d.m23)
    v_d_dot = 2 * v_dot + pP2 * (v - v_d) - rt_e
    tau_u = d.m11 * u_dot + n1
    tau_r = d.m23 * v_dot + d.m33 * r_dot + n3

    # ---- actuator map (design vehicle, measured speed over ground)
    uu = xp.maximum(u * u, d.rudder_speed_min**2)
    thrust_cmd = tau_u
    delta_cmd = tau_r / (d.N_uudr * uu)

    # ---- integral action with back-calculation anti-windup (41)
    lim = g.int_limit
    int_s_dot = s - (int_s - xp.clip(int_s, -lim, lim))
    int_e_dot = e - (int_e - xp.clip(int_e, -lim, lim))

    # ---- plant: lags of the clipped commands
    thrust_dot = (xp.clip(thrust_cmd, -p.thrust_max, p.thrust_max) - thrust) / p.T_thrust
    delta_dot = (xp.clip(delta_cmd, -p.rudder_max, p.rudder_max) - delta) / p.T_rudder

    # current in the body frame and relative velocity
    Vx, Vy = sc.V_c
    uc = c * Vx + sn * Vy
    vc = -sn * Vx + c * Vy
    ur, vr = u - uc, v - vc
    # d/dt R^T V_c = -S(r) R^T V_c for a constant current
    uc_dot, vc_dot = r * vc, -r * uc

    # forces: -C_RB(nu_r) nu_r + hydrodynamics + cross-flow + thrust
    m, mxg = p.mass, p.mass * p.x_g
    Ycf = 0.0
    Ncf = 0.0
    for xi in p.cf_x:
        h = vr + xi * r
        hh = h * xp.abs(h)
        Ycf = Ycf + hh
        Ncf = Ncf + xi * hh
    Ycf, Ncf = -p.cf_k * Ycf, -p.cf_k * Ncf
    Fx = (
        m * vr * r
        + mxg * r * r
        + p.X_uu * ur * xp.abs(ur)
        + p.X_vv * vr * vr
        + p.X_vr * vr * r
        + p.X_rr * r * r
        + (p.X_urdr * ur * r + p.X_uvdr * ur * vr) * delta
        + p.X_uudrdr * ur * ur * delta * delta
        + thrust
    )
    Fy = -m * ur * r + p.Y_uv * ur * vr + p.Y_ur * ur * r + p.Y_uudr * ur * ur * delta + Ycf
    Fn = -mxg * ur * r + p.N_uv * ur * vr + p.N_ur * ur * r + p.N_uudr * ur * ur * delta + Ncf
    Mi = p.Minv
    ur_dot = Mi[0][0] * Fx + Mi[0][1] * Fy + Mi[0][2] * Fn
    vr_dot = Mi[1][0] * Fx + Mi[1][1] * Fy + Mi[1][2] * Fn
    rr_dot = Mi[2][0] * Fx + Mi[2][1] * Fy + Mi[2][2] * Fn

    dydt = [
        c * u - sn * v,
        sn * u + c * v,
        r,
        ur_dot + uc_dot,
        vr_dot + vc_dot,
        rr_dot,
        thrust_dot,
        delta_dot,
        varpi_dot,
        v_d_dot,
        int_s_dot,
        int_e_dot,
    ]
    return dydt, (s, e)


def initial_state(sc: Scenario, xp=SCALAR):
    """12-entry initial state: particle at the closest point of the line, zero actuators."""
    ox, oy = sc.origin
    dx, dy = sc.direction
    x0, y0, psi0 = sc.eta0
    varpi0 = (x0 - ox) * dx + (y0 - oy) * dy
    zero = 0.0 * x0
    return [x0, y0, psi0, *sc.nu0, zero, zero, varpi0, zero, zero, zero]


def _all_finite(y, xp):
    if xp is SCALAR:
        return all(math.isfinite(a) for a in y)
    return np.logical_and.reduce([np.isfinite(a) for a in y])


def rk4_step(y, dt, p, d, g, sc, xp=SCALAR):
    """One classical RK4 step; a step that yields a non-finite state leaves the state unchanged.

    Returns ``(y_next, (s, e))`` with ``(s, e)`` at the start of the step.
    """
    k1, se = closed_loop_rhs(y, p, d, g, sc, xp)
    h = 0.5 * dt
    k2, _ = closed_loop_rhs([a + h * b for a, b in zip(y, k1, strict=True)], p, d, g, sc, xp)
    k3, _ = closed_loop_rhs([a + h * b for a, b in zip(y, k2, strict=True)], p, d, g, sc, xp)
    k4, _ = closed_loop_rhs([a + dt * b for a, b in zip(y, k3, strict=True)], p, d, g, sc, xp)
    y1 = [
        a + dt / 6 * (b1 + 2 * b2 + 2 * b3 + b4)
        for a, b1, b2, b3, b4 in zip(y, k1, k2, k3, k4, strict=True)
    ]
    ok = _all_finite(y1, xp)
    if xp is SCALAR:
        return (y1 if ok else list(y)), se
    return [np.where(ok, a, b) for a, b in zip(y1, y, strict=True)], se


def simulate(num_steps: int, dt: float, sc: Scenario | None = None, g: Gains | None = None):
    """One trajectory, scalar per step.

    Returns ``(Y, SE)``: ``Y`` (N+1, 12) states, ``SE`` (N, 2) ``[s, e]`` at each step's start.
    """
    sc = Scenario() if sc is None else sc
    g = default_gains() if g is None else g
    p = plant_params()
    d = design_params(p)
    y = [float(a) for a in initial_state(sc)]
    Y = [y]
    SE = []
    for _ in range(num_steps):
        y, se = rk4_step(y, dt, p, d, g, sc)
        Y.append(y)
        SE.append(se)
    return np.array(Y), np.array(SE)


def simulate_batch(num_steps: int, dt: float, eta0, V_c, sc: Scenario | None = None, g=None):
    """B trajectories at once, vectorised over the batch with NumPy, one Python loop per step.

    Args:
        eta0: (B, 3) initial poses; V_c: (B, 2) currents; other scenario fields shared.

    Returns:
        (B,) mean |e| over the run.
    """
    sc = Scenario() if sc is None else sc
    g = default_gains() if g is None else g
    p = plant_params()
    d = design_params(p)
    eta0 = np.asarray(eta0, dtype=float)
    V_c = np.asarray(V_c, dtype=float)
    B = eta0.shape[0]
    sc_b = sc._replace(
        eta0=tuple(eta0.T),
        nu0=tuple(np.full(B, a) for a in sc.nu0),
        V_c=tuple(V_c.T),
    )
    y = initial_state(sc_b, np)
    acc = np.zeros(B)
    for _ in range(num_steps):
        y, (_, e) = rk4_step(y, dt, p, d, g, sc_b, np)
        acc += np.abs(e)
    return acc / num_steps
