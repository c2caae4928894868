"""REMUS 100: PythonVehicleSimulator's discrete step in plain NumPy
(:mod:`tests.reference.numpy_remus100`, the oracle the tests check against the recorded PVS run)
timed against vcjax's :func:`~vcjax.vehicles.remus100.pvs_step` in the same run.

Timed (the CSV's 3000 commands, dt = 0.02 s, float64 NumPy):

* NumPy scalar: one vehicle, one Python step at a time (what PVS does);
* NumPy batch: B vehicles, one vectorised NumPy step per Python iteration;
* vcjax single: ``jit(pvs_rollout)`` (one ``lax.scan``), ``--dtype``;
* vcjax vmap: B replays with perturbed initial speeds, ``jax.vmap``; sharded over
  ``--cpu-devices`` host CPU devices when > 1.

    python -m benchmarks.perf.numpy_remus100 --dtype float32 --json benchmarks/results/remus100.json
"""

from __future__ import annotations

import argparse

import numpy as np

from benchmarks import _common as C
from tests.reference.numpy_remus100 import (
    ACT,
    CMD,
    DT,
    POSE,
    VEL,
    columns,
    numpy_params,
    pvs_inputs,
    reference,
    replay,
)

COLUMNS = ["impl", "batch", "steps", "dtype", "cores_used", "run_s", "steps_per_s", "cpu_s"]


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
    v_c = np.asarray(rm_args.water.velocity[:2], dtype=np.float64)
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
