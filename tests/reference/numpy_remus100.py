"""REMUS 100: PythonVehicleSimulator's discrete step in plain NumPy, and its throughput against
vcjax's :func:`~vcjax.vehicles.remus100.pvs_step` in the same run.

PythonVehicleSimulator (PVS) steps one vehicle from Python: per step a handful of 6x6 NumPy
products and a 3-vector of actuator states. :func:`step` does that work, written here from the
equations in :mod:`vcjax.vehicles.remus100`'s docstrings (Fossen's ``m2c`` Coriolis from the
symmetrised mass blocks, ``gvect`` restoring, zyx ``J(Theta)``, yaw-only current, hull
lift/drag, 21-strip cross-flow, propeller and fin forces, then PVS's Euler update with the new
velocity and the old angles) and a precomputed ``M^-1`` as PVS keeps it. Only the parameter
*values* are taken from ``remus100_params()`` (converted to floats once).
``tests/test_numpy_reference.py`` checks it against the recorded PVS trajectory
(``tests/data/remus100_pvs_reference.csv``), which it must reproduce as closely as vcjax does.

Timed (the CSV's 3000 commands, dt = 0.02 s, float64 NumPy):

* NumPy scalar: one vehicle, one Python step at a time (what PVS does);
* NumPy batch: B vehicles, one vectorised NumPy step per Python iteration;
* vcjax single: ``jit(pvs_rollout)`` (one ``lax.scan``), ``--dtype``;
* vcjax vmap: B replays with perturbed initial speeds, ``jax.vmap``; sharded over
  ``--cpu-devices`` host CPU devices when > 1.

    python -m benchmarks.numpy_remus100 --dtype float32 --json benchmarks/results/remus100.json
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

import numpy as np

from benchmarks import _common as C

CSV = Path(__file__).resolve().parents[1] / "tests" / "data" / "remus100_pvs_reference.csv"
DT = 0.02
POSE = ["x", "y", "z", "phi", "theta", "psi"]
VEL = ["u", "v", "w", "p", "q", "r"]
ACT = ["delta_r", "delta_s", "n_rpm"]
CMD = ["delta_r_cmd", "delta_s_cmd", "n_cmd_rpm"]
COLUMNS = ["impl", "batch", "steps", "dtype", "cores_used", "run_s", "steps_per_s", "cpu_s"]


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


# ------------------------------------------------------------------------------- timing


def parse_args(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    C.add_common_args(ap)
    ap.add_argument("--np-steps", type=int, default=3000)
    ap.add_argument("--np-batch", type=int, default=1024)
    ap.add_argument("--np-batch-steps", type=int, default=200)
    ap.add_argument("--jax-batch", type=int, default=4096)
    ap.add_argument("--cpu-devices", type=int, default=1)
    args = ap.parse_args(argv)
    if args.quick:
        args.np_steps, args.np_batch, args.np_batch_steps, args.jax_batch = 300, 256, 50, 512
        args.repeats = min(args.repeats, 2)
    return args


def _row(impl, batch, steps, dtype, cores, run_s):
    return {
        "impl": impl,
        "batch": batch,
        "steps": steps,
        "dtype": dtype,
        "cores_used": cores,
        "run_s": run_s,
        "steps_per_s": batch * steps / run_s,
        "cpu_s": C.LAST_CPU_S,
    }


def main(argv=None):
    args = parse_args(argv)
    C.setup(args.dtype, args.cpu_devices)
    import jax
    import jax.numpy as jnp

    from vcjax.vehicles import remus100 as rm

    ref = reference()
    p, rm_args, x0, cmds = pvs_inputs()
    q = numpy_params(rm.remus100_params(dtype=jnp.float64) if args.dtype == "float64" else p)
    v_c = np.asarray(rm_args.v_c, dtype=np.float64)
    e0, n0, a0 = (columns(ref, k)[0] for k in (POSE, VEL, ACT))
    c_np = columns(ref, CMD)[:-1]
    rows = []

    n = min(args.np_steps, c_np.shape[0])
    t = C.best_of(lambda: replay(q, e0, n0, a0, c_np[:n], v_c), args.repeats, warmup=0)
    rows.append(_row("numpy scalar (PVS-style loop)", 1, n, "float64", 1, t))

    B, nb = args.np_batch, args.np_batch_steps
    rng = np.random.default_rng(0)
    nuB = n0[None, :] * (1.0 + 0.05 * rng.standard_normal((B, 1)))
    eB, aB = np.broadcast_to(e0, (B, 6)).copy(), np.broadcast_to(a0, (B, 3)).copy()
    t = C.best_of(lambda: replay(q, eB, nuB, aB, c_np[:nb], v_c), args.repeats, warmup=0)
    rows.append(_row("numpy batch (vectorised)", B, nb, "float64", 1, t))

    single = jax.jit(rm.pvs_rollout).lower(x0, cmds, rm_args, DT).compile()
    t = C.best_of(lambda: single(x0, cmds, rm_args, DT).x.eta, args.repeats)
    rows.append(_row("vcjax single (jit scan)", 1, cmds.shape[0], args.dtype, 1, t))

    Bj = args.jax_batch
    scale = jnp.asarray(1.0 + 0.05 * rng.standard_normal((Bj, 1)), dtype=x0.nu.dtype)
    xB = x0._replace(nu=x0.nu[None, :] * scale)
    xB = xB._replace(eta=jnp.broadcast_to(x0.eta, (Bj, 6)), act=jnp.broadcast_to(x0.act, (Bj, 3)))
    if args.cpu_devices > 1:
        from jax.sharding import Mesh, NamedSharding, PartitionSpec

        mesh = Mesh(np.asarray(jax.devices()[: args.cpu_devices]), ("b",))
        xB = jax.device_put(xB, NamedSharding(mesh, PartitionSpec("b")))
    nbj = 500

    def final_pose(x, c, a, dt):  # the same steps as pvs_rollout, keeping only the last state
        def one(x1):
            step = lambda xk, u: (rm.pvs_step(xk, u, a, jnp.asarray(dt, x1.nu.dtype)), None)
            return jax.lax.scan(step, x1, c)[0].eta

        return jax.vmap(one)(x)

    batched = jax.jit(final_pose).lower(xB, cmds[:nbj], rm_args, DT).compile()
    t = C.best_of(lambda: batched(xB, cmds[:nbj], rm_args, DT), args.repeats)
    rows.append(_row("vcjax vmap", Bj, nbj, args.dtype, C.devices_used(xB.nu), t))

    scalar = rows[0]["steps_per_s"]
    for r in rows:
        r["x_numpy_scalar"] = r["steps_per_s"] / scalar
    C.print_table(rows, COLUMNS + ["x_numpy_scalar"], "REMUS 100, PVS step replay")
    C.write_json(args.json, args, rows)
    return rows


if __name__ == "__main__":
    main()
