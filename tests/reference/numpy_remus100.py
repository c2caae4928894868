"""REMUS 100: PythonVehicleSimulator's discrete step in plain NumPy (an independent oracle).

PythonVehicleSimulator (PVS) steps one vehicle from Python: per step a handful of 6x6 NumPy
products and a 3-vector of actuator states. :func:`step` does that work, written here from the
equations in :mod:`vcjax.vehicles.remus100`'s docstrings (Fossen's ``m2c`` Coriolis from the
symmetrised mass blocks, ``gvect`` restoring, zyx ``J(Theta)``, yaw-only current, hull
lift/drag, 21-strip cross-flow, propeller and fin forces, then PVS's Euler update with the new
velocity and the old angles) and a precomputed ``M^-1`` as PVS keeps it. Only the parameter
*values* are taken from ``remus100_params()`` (converted to floats once).
``tests/test_numpy_reference.py`` checks it against the recorded PVS trajectory
(``tests/data/remus100_pvs_reference.csv``), which it must reproduce as closely as vcjax does;
``benchmarks/perf/numpy_remus100.py`` times it against vcjax's
:func:`~vcjax.vehicles.remus100.pvs_step`.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

CSV = Path(__file__).resolve().parents[1] / "data" / "remus100_pvs_reference.csv"
DT = 0.02
POSE = ["x", "y", "z", "phi", "theta", "psi"]
VEL = ["u", "v", "w", "p", "q", "r"]
ACT = ["delta_r", "delta_s", "n_rpm"]
CMD = ["delta_r_cmd", "delta_s_cmd", "n_cmd_rpm"]


def reference() -> dict:
    """The PVS CSV as float64 columns."""
    data = np.genfromtxt(CSV, delimiter=",", skip_header=1, names=True, dtype=np.float64)
    return {name: data[name] for name in data.dtype.names}


def columns(ref: dict, names) -> np.ndarray:
    return np.stack([ref[n] for n in names], axis=-1)


def numpy_params(p) -> dict:
    """Float64 NumPy copies of a :class:`~vcjax.vehicles.remus100.Remus100Params`."""
    out = {k: np.asarray(v, dtype=np.float64) for k, v in p._asdict().items() if k != "body"}
    out.update({k: np.asarray(v, dtype=np.float64) for k, v in p.body._asdict().items()})
    out["Minv"] = np.linalg.inv(out["M_RB"] + out["M_A"])
    mask = np.ones((6, 6))
    from vcjax.vehicles.remus100 import CA_ZEROED

    for i, j in CA_ZEROED:
        mask[i, j] = 0.0
    out["CA_mask"] = mask
    return out


def _skew(a):
    """(..., 3, 3) ``S(a)`` with ``S(a) b = a x b``."""
    z = np.zeros_like(a[..., 0])
    return np.stack(
        [
            np.stack([z, -a[..., 2], a[..., 1]], -1),
            np.stack([a[..., 2], z, -a[..., 0]], -1),
            np.stack([-a[..., 1], a[..., 0], z], -1),
        ],
        -2,
    )


def m2c(M, nu):
    """(..., 6, 6) Coriolis matrix of ``M`` (symmetrised) at ``nu`` (..., 6)."""
    M = 0.5 * (M + M.T)
    a = nu[..., :3] @ M[:3, :3].T + nu[..., 3:] @ M[:3, 3:].T
    b = nu[..., :3] @ M[3:, :3].T + nu[..., 3:] @ M[3:, 3:].T
    Sa, Sb = _skew(a), _skew(b)
    top = np.concatenate([np.zeros_like(Sa), -Sa], -1)
    bottom = np.concatenate([-Sa, -Sb], -1)
    return np.concatenate([top, bottom], -2)


def nu_dot(q: dict, eta, nu, act, v_c):
    """(..., 6) body acceleration with applied actuator values ``act`` (..., 3)."""
    psi, theta, phi = eta[..., 5], eta[..., 4], eta[..., 3]
    c, s = np.cos(psi), np.sin(psi)
    u_c = c * v_c[0] + s * v_c[1]
    v_cb = -s * v_c[0] + c * v_c[1]
    r = nu[..., 5]
    zeros = np.zeros_like(u_c)
    nu_c = np.stack([u_c, v_cb, zeros, zeros, zeros, zeros], -1)
    nu_c_dot = np.stack([r * v_cb, -r * u_c, zeros, zeros, zeros, zeros], -1)
    nu_r = nu - nu_c
    U_r = np.sqrt(np.sum(nu_r[..., :3] ** 2, -1))
    U = np.sqrt(np.sum(nu[..., :3] ** 2, -1))

    # Coriolis (rigid body + masked added mass) and faded linear damping
    C = m2c(q["M_RB"], nu_r) + m2c(q["M_A"], nu_r) * q["CA_mask"]
    fade = np.exp(-q["fade"] * U_r)
    Dnu = nu_r @ q["D"].T
    Dnu[..., 0] = Dnu[..., 0] - (1 - fade) * q["D"][0, 0] * nu_r[..., 0]
    Dnu[..., 1] = Dnu[..., 1] - (1 - fade) * q["D"][1, 1] * nu_r[..., 1]
    Cnu = np.einsum("...ij,...j->...i", C, nu_r)

    # hull lift and drag
    u_r, w_r = nu_r[..., 0], nu_r[..., 2]
    alpha = np.where(u_r**2 + w_r**2 > 0, np.arctan2(w_r, u_r), 0.0)
    AR = q["AR"]
    CL = math.pi * AR / (1.0 + math.sqrt(1.0 + (AR / 2.0) ** 2)) * alpha
    CD = q["CD_0"] + CL**2 / (math.pi * q["oswald"] * AR)
    qd = 0.5 * q["rho"] * U_r**2 * q["S"]
    ca, sa = np.cos(alpha), np.sin(alpha)
    X_ld = -ca * qd * CD + sa * qd * CL
    Z_ld = -sa * qd * CD - ca * qd * CL

    # cross-flow strips
    h = nu_r[..., 1:2] + q["cf_x"] * nu_r[..., 5:6]
    hh = np.abs(h) * h
    k = q["cf_coeff"] * q["cf_dx"]
    Y_cf = -k * np.sum(hh, -1)
    N_cf = -k * np.sum(q["cf_x"] * hh, -1)

    # propeller and fins
    d_r, d_s, n_rpm = act[..., 0], act[..., 1], act[..., 2]
    n = n_rpm / 60.0
    nn = np.abs(n) * n
    lin = np.where(n > 0, (q["wake"] * U / q["D_prop"]) * np.abs(n) / q["Ja_max"], 0.0)
    X_prop = q["rho"] * q["D_prop"] ** 4 * (q["KT_0"] * nn + (q["KT_max"] - q["KT_0"]) * lin)
    K_prop = q["rho"] * q["D_prop"] ** 5 * (q["KQ_0"] * nn + (q["KQ_max"] - q["KQ_0"]) * lin)
    k_r = 0.5 * q["rho"] * (u_r**2 + nu_r[..., 1] ** 2) * q["A_r"] * q["CL_delta_r"]
    k_s = 0.5 * q["rho"] * (u_r**2 + w_r**2) * q["A_s"] * q["CL_delta_s"]
    Y_r, Z_s = -k_r * d_r, -k_s * d_s
    X_fins = -k_r * d_r**2 - k_s * d_s**2

    # restoring
    W, B, rg, rb = q["W"], q["B"], q["r_bg"], q["r_bb"]
    sth, cth, sph, cph = np.sin(theta), np.cos(theta), np.sin(phi), np.cos(phi)
    mx, my, mz = (rg[i] * W - rb[i] * B for i in range(3))
    g = np.stack(
        [
            (W - B) * sth,
            -(W - B) * cth * sph,
            -(W - B) * cth * cph,
            -my * cth * cph + mz * cth * sph,
            mz * sth + mx * cth * cph,
            -mx * cth * sph - my * sth,
        ],
        -1,
    )
    tau = np.stack(
        [
            (1.0 - q["t_prop"]) * X_prop + X_fins + X_ld,
            Y_r + Y_cf,
            Z_s + Z_ld,
            q["K_prop_scale"] * K_prop,
            -q["x_s"] * Z_s,
            q["x_r"] * Y_r + N_cf,
        ],
        -1,
    )
    return nu_c_dot + (tau - Cnu - Dnu - g) @ q["Minv"].T


def pose_rate(eta, nu):
    """(..., 6) ``J(Theta) nu`` (zyx Euler angles)."""
    phi, th, psi = eta[..., 3], eta[..., 4], eta[..., 5]
    cf, sf, ct, st, cp, sp = (
        np.cos(phi),
        np.sin(phi),
        np.cos(th),
        np.sin(th),
        np.cos(psi),
        np.sin(psi),
    )
    u, v, w, p, q_, r = (nu[..., i] for i in range(6))
    return np.stack(
        [
            cp * ct * u + (-sp * cf + cp * st * sf) * v + (sp * sf + cp * cf * st) * w,
            sp * ct * u + (cp * cf + sf * st * sp) * v + (-cp * sf + st * sp * cf) * w,
            -st * u + ct * sf * v + ct * cf * w,
            p + sf * st / ct * q_ + cf * st / ct * r,
            cf * q_ - sf * r,
            sf / ct * q_ + cf / ct * r,
        ],
        -1,
    )


def step(q: dict, eta, nu, act, u_cmd, v_c, dt):
    """PVS's step: clip the actuator states, Euler on ``nu`` and ``act``, then the pose with the
    new velocity and the old angles. Works on (6,) states or (B, 6) batches."""
    a = np.clip(act, -q["act_max"], q["act_max"])
    nu_next = nu + dt * nu_dot(q, eta, nu, a, v_c)
    act_next = a + dt * (u_cmd - a) / q["T_act"]
    eta_next = eta + dt * pose_rate(eta, nu_next)
    return eta_next, nu_next, act_next


def replay(q, eta0, nu0, act0, cmds, v_c, dt=DT):
    """(N+1, ...) states of the replayed commands (N, 3) (Python loop of :func:`step`)."""
    eta, nu, act = eta0, nu0, act0
    out = [(eta, nu, act)]
    for k in range(cmds.shape[0]):
        eta, nu, act = step(q, eta, nu, act, cmds[k], v_c, dt)
        out.append((eta, nu, act))
    return tuple(np.stack(x) for x in zip(*out, strict=True))


def pvs_inputs(dtype=None):
    """``(params, args, x0, cmds)`` of the recorded PVS run (vcjax objects)."""
    import jax.numpy as jnp

    from vcjax.vehicles import remus100 as rm

    ref = reference()
    p = rm.remus100_params(dtype=dtype)
    args = rm.remus100_args(p, V_c=0.5, beta_c=math.radians(170.0))
    x0 = rm.remus100_state(
        columns(ref, POSE)[0], columns(ref, VEL)[0], columns(ref, ACT)[0], dtype=dtype
    )
    cmds = jnp.asarray(columns(ref, CMD)[:-1], dtype=p.rho.dtype)
    return p, args, x0, cmds
