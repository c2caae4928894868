"""Closed-loop throughput of Simulation 1's VCM controller (``vcm_integral``, underactuated) on
the INFANTE-class plant, RK4, continuous-time controller (``--timing sampled``: once per step).

``--cpu-devices N`` splits the host CPU into N JAX devices (:mod:`vcjax.runtime.devices`) and shards
each batch over them (``NamedSharding`` along the scenario axis, as ``vcjax sweep`` does); the
``cores_used`` column says over how many devices a row ran. Default 1: one device, one core.

Measures, in one dtype per process:

* compile time (trace+lower and XLA compile, timed separately) for two horizons, single and
  batched, to show that it does not depend on the horizon (one ``lax.scan``);
* a single trajectory (``jax.jit(simulate)``, no vmap): trajectory-steps per second;
* ``jax.vmap`` over a batch of scenarios (random initial offsets and currents) for each batch
  size: trajectory-steps per second.

Each timed function returns only the (B,) mean cross-track error |e| over the run, computed
inside jit (returning the full Trajectory for 16384 x N steps would be memory-bound, not
compute-bound); the rest of the Trajectory is dead code that XLA removes.

    python -m benchmarks.perf.throughput --dtype float32 --json results/throughput_f32.json
"""

from __future__ import annotations

import argparse

from benchmarks import _common as C

COLUMNS = [
    "kind",
    "timing",
    "cores_used",
    "batch",
    "steps",
    "dtype",
    "device",
    "lower_s",
    "compile_s",
    "run_s",
    "steps_per_s",
    "cpu_s",
    "load",
    "temp_MB",
    "mean_abs_e",
]


def parse_args(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    C.add_common_args(p)
    p.add_argument(
        "--batches",
        type=int,
        nargs="+",
        default=None,
        help="batch sizes (default 1 4 16 ... 16384)",
    )
    p.add_argument("--steps", type=int, default=None, help="RK4 steps per run (default 500)")
    p.add_argument("--timing", choices=("continuous", "sampled"), default="continuous")
    p.add_argument("--cpu-devices", type=int, default=1, help="host CPU devices to shard over")
    p.add_argument("--compile-horizons", type=int, nargs=2, default=(1000, 4000))
    p.add_argument(
        "--compile-batch",
        type=int,
        default=4096,
        help="batched program used for the compile-time rows",
    )
    args = p.parse_args(argv)
    if args.quick:
        args.batches = args.batches or [1, 64, 1024]
        args.steps = args.steps or 200
        args.repeats = min(args.repeats, 2)
        args.compile_batch = min(args.compile_batch, 1024)
    args.batches = args.batches or [4**k for k in range(8)]
    args.steps = args.steps or 500
    return args


def single_rollout(steps: int, repeats: int, dtype: str, timing: str = "continuous"):
    """Row for one trajectory (jit of the unbatched ``simulate``)."""
    import jax

    gains, sc = C.base_inputs()
    f = jax.jit(C.metric_fn(steps, batched=False, timing=timing))
    lower_s, compile_s, comp = C.compile_timed(f, gains, sc, C.DT)
    run_s = C.best_of(lambda: comp(gains, sc, C.DT), repeats)
    return {
        "kind": "single",
        "timing": timing,
        "cores_used": 1,
        "batch": 1,
        "steps": steps,
        "dtype": dtype,
        "device": C.device_str(),
        "lower_s": lower_s,
        "compile_s": compile_s,
        "run_s": run_s,
        "steps_per_s": steps / run_s,
        "cpu_s": C.LAST_CPU_S,
        "load": C.load_average(),
        "temp_MB": C.memory(comp)["temp_bytes"] / 1e6,
        "mean_abs_e": float(comp(gains, sc, C.DT)),
    }


def batched_rollout(
    batch: int, steps: int, repeats: int, dtype: str, timing: str = "continuous", devices: int = 1
):
    """Row for ``batch`` trajectories (vmap over scenarios), sharded over ``devices``."""
    import jax
    import numpy as np

    gains, sc = C.base_inputs()
    scb = C.shard_batch(C.batched_scenario(sc, batch), devices)
    f = jax.jit(C.metric_fn(steps, timing=timing))
    lower_s, compile_s, comp = C.compile_timed(f, gains, scb, C.DT)
    run_s = C.best_of(lambda: comp(gains, scb, C.DT), repeats)
    out = np.asarray(comp(gains, scb, C.DT))
    return {
        "kind": "vmap",
        "timing": timing,
        "cores_used": C.devices_used(scb.eta0),
        "batch": batch,
        "steps": steps,
        "dtype": dtype,
        "device": C.device_str(),
        "lower_s": lower_s,
        "compile_s": compile_s,
        "run_s": run_s,
        "steps_per_s": batch * steps / run_s,
        "cpu_s": C.LAST_CPU_S,
        "load": C.load_average(),
        "temp_MB": C.memory(comp)["temp_bytes"] / 1e6,
        "mean_abs_e": float(np.nanmean(out)),
    }


def compile_rows(horizons, batch: int, dtype: str):
    """Compile time for each horizon, single and batched (nothing is run)."""
    import jax

    gains, sc = C.base_inputs()
    scb = C.batched_scenario(sc, batch)
    rows = []
    for n in horizons:
        for b, s, batched in ((1, sc, False), (batch, scb, True)):
            f = jax.jit(C.metric_fn(n, batched=batched))
            lower_s, compile_s, comp = C.compile_timed(f, gains, s, C.DT)
            rows.append(
                {
                    "kind": "compile" + ("-vmap" if batched else "-single"),
                    "batch": b,
                    "steps": n,
                    "dtype": dtype,
                    "device": C.device_str(),
                    "lower_s": lower_s,
                    "compile_s": compile_s,
                    "temp_MB": C.memory(comp)["temp_bytes"] / 1e6,
                }
            )
    return rows


def main(argv=None):
    args = parse_args(argv)
    C.setup(args.dtype, args.cpu_devices)
    rows = compile_rows(args.compile_horizons, args.compile_batch, args.dtype)
    cols = ["kind", "batch", "steps", "dtype", "device", "lower_s", "compile_s", "temp_MB"]
    C.print_table(rows, cols, "compile time vs horizon (jit lower / compile)")
    run_rows = [single_rollout(args.steps, args.repeats, args.dtype, args.timing)]
    for b in args.batches:
        b_dev = args.cpu_devices if b % args.cpu_devices == 0 else 1
        run_rows.append(
            batched_rollout(b, args.steps, args.repeats, args.dtype, args.timing, b_dev)
        )
        print(f"  batch {b}: {run_rows[-1]['steps_per_s']:.3e} steps/s", flush=True)
    C.print_table(run_rows, COLUMNS, "closed-loop throughput (trajectory-steps per second)")
    C.write_json(args.json, args, rows + run_rows)
    return rows + run_rows


if __name__ == "__main__":
    main()
