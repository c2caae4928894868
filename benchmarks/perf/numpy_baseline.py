"""NumPy baseline: the same closed loop (``tests/reference/numpy_reference.py``: INFANTE-class
plant, underactuated VCM law with integral action, RK4) stepped from Python, against vcjax.

* NumPy scalar: one trajectory, Python floats + ``math`` per step (what a user without JAX would
  write for one run);
* NumPy batch: B trajectories, one vectorised NumPy RK4 step per Python iteration;
* vcjax single (jit, no vmap) and vcjax vmap at a large batch, in ``--dtype``.

NumPy always runs in float64. Reported: trajectory-steps per second and the speed ratios.

    python -m benchmarks.perf.numpy_baseline --dtype float32 --json results/numpy_f32.json
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from benchmarks import _common as C
from tests.reference import numpy_reference as nr

COLUMNS = ["impl", "batch", "steps", "dtype", "device", "run_s", "steps_per_s", "cpu_s", "load"]


def parse_args(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    C.add_common_args(p)
    p.add_argument("--np-steps", type=int, default=2000, help="steps of the scalar NumPy run")
    p.add_argument("--np-batch", type=int, default=1024)
    p.add_argument("--np-batch-steps", type=int, default=100)
    p.add_argument("--jax-steps", type=int, default=500)
    p.add_argument("--jax-batch", type=int, default=4096)
    args = p.parse_args(argv)
    if args.quick:
        args.np_steps, args.np_batch, args.np_batch_steps = 400, 256, 40
        args.jax_steps, args.jax_batch = 200, 1024
        args.repeats = min(args.repeats, 2)
    return args


def _best_wall(fn, repeats):
    best, cpu = float("inf"), float("nan")
    for _ in range(max(1, repeats)):
        c = time.process_time()
        t = time.perf_counter()
        fn()
        w = time.perf_counter() - t
        if w < best:
            best, cpu = w, time.process_time() - c
    return best, cpu


def numpy_rows(args):
    rows = []
    run_s, cpu = _best_wall(lambda: nr.simulate(args.np_steps, C.DT), args.repeats)
    rows.append(
        {
            "impl": "numpy scalar",
            "batch": 1,
            "steps": args.np_steps,
            "dtype": "float64",
            "device": "cpu (1 thread)",
            "run_s": run_s,
            "steps_per_s": args.np_steps / run_s,
            "cpu_s": cpu,
            "load": C.load_average(),
        }
    )
    rng = np.random.default_rng(0)
    B = args.np_batch
    eta0 = np.array([0.0, 0.0, np.pi / 2]) + rng.normal(size=(B, 3)) * [5.0, 5.0, 0.5]
    ang, mag = rng.uniform(-np.pi, np.pi, B), rng.uniform(0, 0.5, B)
    V_c = np.stack([mag * np.cos(ang), mag * np.sin(ang)], axis=1)
    run_s, cpu = _best_wall(
        lambda: nr.simulate_batch(args.np_batch_steps, C.DT, eta0, V_c), args.repeats
    )
    rows.append(
        {
            "impl": "numpy batch",
            "batch": B,
            "steps": args.np_batch_steps,
            "dtype": "float64",
            "device": "cpu",
            "run_s": run_s,
            "steps_per_s": B * args.np_batch_steps / run_s,
            "cpu_s": cpu,
            "load": C.load_average(),
        }
    )
    return rows


def main(argv=None):
    args = parse_args(argv)
    C.setup(args.dtype)
    from benchmarks.perf import throughput as T

    rows = numpy_rows(args)
    for r in (
        T.single_rollout(args.jax_steps, args.repeats, args.dtype),
        T.batched_rollout(args.jax_batch, args.jax_steps, args.repeats, args.dtype),
    ):
        rows.append({"impl": f"vcjax {r['kind']}", **{k: r[k] for k in COLUMNS if k in r}})
    np_scalar = rows[0]["steps_per_s"]
    np_batch = rows[1]["steps_per_s"]
    for r in rows:
        r["x_numpy_scalar"] = r["steps_per_s"] / np_scalar
        r["x_numpy_batch"] = r["steps_per_s"] / np_batch
    C.print_table(
        rows,
        COLUMNS + ["x_numpy_scalar", "x_numpy_batch"],
        "NumPy baseline vs vcjax (trajectory-steps per second; x = speed-up over NumPy)",
    )
    C.write_json(args.json, args, rows)
    return rows


if __name__ == "__main__":
    main()
