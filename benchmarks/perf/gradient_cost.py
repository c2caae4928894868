"""Cost of reverse-mode gradients through the Simulation 1 closed loop.

Loss: ``L(g) = mean_b sum_k (s_k^2 + e_k^2) dt`` over a batch of scenarios (random initial offsets
and currents), differentiated w.r.t. every field of the VCM gains (:class:`PMGains`).

1. Timing, in ``--dtype``, for a few batch sizes: the forward loss alone vs
   ``jax.value_and_grad`` (plain and with ``RolloutConfig(checkpoint=True)``), and the ratios;
   also the ratio of XLA's flop counts (``cost_analysis()``, which counts each ``while`` body
   once, so the ratio is per step: the gradient program's forward and backward bodies against
   the forward's body).
2. Memory for ``--mem-batch`` x ``--mem-steps`` (default 8192 x 4000) in float64, with and
   without ``jax.checkpoint``: XLA's static ``compiled.memory_analysis()`` (argument + output +
   temp bytes) for the forward and both gradients (nothing allocated: the inputs are
   ``ShapeDtypeStruct``\\ s), then a measured peak RSS, in a fresh process each, only for the
   configurations whose static peak is below ``--mem-limit-gb``.

    python -m benchmarks.perf.gradient_cost --dtype float32 --json results/gradient_f32.json
"""

from __future__ import annotations

import argparse
import json
import resource
import subprocess
import sys
import time

from benchmarks import _common as C

COLUMNS = [
    "batch",
    "steps",
    "timing",
    "segment",
    "dtype",
    "device",
    "fwd_s",
    "grad_s",
    "grad_ckpt_s",
    "grad_over_fwd",
    "ckpt_over_fwd",
    "ckpt_seg_over_fwd",
    "jacfwd_over_fwd",
    "flops_grad_over_fwd",
    "flops_ckpt_seg_over_fwd",
    "compile_fwd_s",
    "compile_grad_s",
    "load",
]
MEM_COLUMNS = ["config", "batch", "steps", "dtype", "xla_peak_GB", "xla_temp_GB", "measured"]
MEM_COLUMNS += ["run_batch", "run_steps", "xla_peak_at_run_size_GB", "rss_increase_GB", "run_s"]


def parse_args(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    C.add_common_args(p)
    p.add_argument("--batches", type=int, nargs="+", default=None, help="default 1 64 1024")
    p.add_argument("--steps", type=int, default=None, help="default 500")
    p.add_argument(
        "--timing",
        choices=("continuous", "sampled"),
        default="continuous",
        help="controller timing (RolloutConfig.timing); the tuner's default is continuous",
    )
    p.add_argument(
        "--segment",
        type=int,
        default=10,
        help="checkpoint_every of the segment-checkpointed gradient (default 10)",
    )
    p.add_argument("--mem-batch", type=int, default=8192)
    p.add_argument("--mem-steps", type=int, default=4000)
    p.add_argument(
        "--mem-limit-gb", type=float, default=8.0, help="run only configs below this static peak"
    )
    p.add_argument(
        "--mem-run-batch",
        type=int,
        default=None,
        help="batch of the measured runs (default 1024; --quick: 512)",
    )
    p.add_argument("--mem-run-steps", type=int, default=None, help="default 1000")
    p.add_argument("--no-memory", action="store_true", help="skip the memory section")
    p.add_argument("--no-timing", action="store_true", help="skip the timing section")
    p.add_argument("--_worker", default=None, help=argparse.SUPPRESS)
    args = p.parse_args(argv)
    if args.quick:
        args.batches = args.batches or [1, 64]
        args.steps = args.steps or 200
        args.repeats = min(args.repeats, 2)
        args.mem_run_batch = args.mem_run_batch or 512
        args.mem_run_steps = args.mem_run_steps or 1000
    args.batches = args.batches or [1, 64, 1024]
    args.steps = args.steps or 500
    args.mem_run_batch = args.mem_run_batch or 1024
    args.mem_run_steps = args.mem_run_steps or 1000
    return args


def loss_fn(num_steps: int, checkpoint: bool, every: int = 1, timing: str = "continuous"):
    """``L(pm_gains, scenario_batch, dt)``: mean over the batch of sum (s^2 + e^2) dt."""
    import jax
    import jax.numpy as jnp

    from vcjax import experiments, loops
    from vcjax.rollout import RolloutConfig

    cfg = RolloutConfig(
        num_steps=num_steps,
        integrator="rk4",
        checkpoint=checkpoint,
        checkpoint_every=every,
        timing=timing,
    )
    sim1 = experiments.get("sim1")
    base, loop = sim1.default_gains(C.VARIANT), sim1.loop(C.VARIANT)

    def one(pm, sc, dt):
        tr = loops.simulate(loop, base._replace(vcm=pm), sc, cfg, dt)
        return jnp.sum(tr.aux.eps**2) * dt

    def loss(pm, sc, dt):
        per = jax.vmap(one, in_axes=(None, C.scenario_axes(sc), None))(pm, sc, dt)
        return jnp.mean(per)

    return loss


#: default segment length of the ``grad_checkpoint_seg`` program (``--segment``)
SEGMENT = 10


def _programs(num_steps, timing="continuous", segment=SEGMENT):
    import jax

    def lf(checkpoint, every=1):
        return loss_fn(num_steps, checkpoint, every, timing)

    return {
        "forward": jax.jit(lf(False)),
        "grad": jax.jit(jax.value_and_grad(lf(False))),
        "grad_checkpoint": jax.jit(jax.value_and_grad(lf(True))),
        "grad_checkpoint_seg": jax.jit(jax.value_and_grad(lf(True, segment))),
        # forward mode: 12 gain scalars -> 12 tangents carried along the scan, no residuals
        "jacfwd": jax.jit(jax.jacfwd(lf(False))),
    }


def timing_row(batch, steps, repeats, dtype, timing="continuous", segment=SEGMENT):
    gains, sc = C.base_inputs()
    pm, scb = gains.vcm, C.batched_scenario(sc, batch)
    out = {"batch": batch, "steps": steps, "dtype": dtype, "device": C.device_str()}
    out.update(timing=timing, segment=segment)
    for name, f in _programs(steps, timing, segment).items():
        lower_s, compile_s, comp = C.compile_timed(f, pm, scb, C.DT)
        out[f"compile_{name}_s"] = lower_s + compile_s
        # XLA's cost analysis counts each while body once: per-step flops of the program
        ca = C.cost(comp)
        out[f"{name}_flops"] = float(ca.get("flops", 0.0))
        out[f"{name}_transcendentals"] = float(ca.get("transcendentals", 0.0))
        out[f"{name}_s"] = C.best_of(lambda comp=comp: comp(pm, scb, C.DT), repeats)
        out[f"{name}_cpu_s"] = C.LAST_CPU_S
    out["fwd_s"], out["grad_s"], out["grad_ckpt_s"] = (
        out["forward_s"],
        out["grad_s"],
        out["grad_checkpoint_s"],
    )
    out["compile_fwd_s"] = out["compile_forward_s"]
    out["grad_over_fwd"] = out["grad_s"] / out["fwd_s"]
    out["ckpt_over_fwd"] = out["grad_ckpt_s"] / out["fwd_s"]
    out["jacfwd_over_fwd"] = out["jacfwd_s"] / out["fwd_s"]
    out["ckpt_seg_over_fwd"] = out["grad_checkpoint_seg_s"] / out["fwd_s"]
    out["flops_grad_over_fwd"] = out["grad_flops"] / out["forward_flops"]
    out["flops_ckpt_seg_over_fwd"] = out["grad_checkpoint_seg_flops"] / out["forward_flops"]
    out["load"] = C.load_average()
    return out


# ---------------------------------------------------------------------------- memory section


def _abstract_inputs(batch):
    import jax

    gains, sc = C.base_inputs()
    dtype = sc.eta0.dtype
    batched = C.batched_scenario(sc, 2)
    scb = sc._replace(
        **{
            f: jax.ShapeDtypeStruct((batch, *getattr(batched, f).shape[1:]), dtype)
            for f in C.scenario_axes(sc)._asdict()
            if getattr(C.scenario_axes(sc), f) == 0
        }
    )
    return gains.vcm, scb


def _worker_static(args):
    """In a float64 process: memory_analysis of the three programs (nothing is run)."""
    pm, scb = _abstract_inputs(args.mem_batch)
    res = {}
    for name, f in _programs(args.mem_steps).items():
        t = time.perf_counter()
        comp = f.lower(pm, scb, C.DT).compile()
        res[name] = {**C.memory(comp), "compile_s": time.perf_counter() - t}
    return res


def _rss_now_gb():
    with open("/proc/self/statm") as fh:
        return int(fh.read().split()[1]) * resource.getpagesize() / 1e9


def _worker_measure(args, name):
    """In a fresh float64 process: compile, then run ``name`` once while a thread samples the
    resident set size every 2 ms; report its peak and its increase over the RSS at the start of
    the run (the compile's own high-water mark is excluded). Also XLA's static analysis of the
    same program at this size, for comparison."""
    import threading

    gains, sc = C.base_inputs()
    pm, scb = gains.vcm, C.batched_scenario(sc, args.mem_run_batch)
    f = _programs(args.mem_run_steps)[name]
    comp = f.lower(pm, scb, C.DT).compile()
    before = _rss_now_gb()
    peak = [before]
    done = threading.Event()

    def sample():
        while not done.is_set():
            peak[0] = max(peak[0], _rss_now_gb())
            time.sleep(0.002)

    th = threading.Thread(target=sample, daemon=True)
    th.start()
    t = time.perf_counter()
    C.block(comp(pm, scb, C.DT))
    run_s = time.perf_counter() - t
    done.set()
    th.join()
    peak[0] = max(peak[0], _rss_now_gb())
    return {
        "rss_before_run_GB": before,
        "rss_peak_GB": peak[0],
        "run_s": run_s,
        "xla_at_run_size": C.memory(comp),
    }


def _spawn(args, worker):
    cmd = [sys.executable, "-m", "benchmarks.perf.gradient_cost", "--dtype", "float64"]
    cmd += ["--mem-batch", str(args.mem_batch), "--mem-steps", str(args.mem_steps)]
    cmd += ["--mem-run-batch", str(args.mem_run_batch), "--mem-run-steps", str(args.mem_run_steps)]
    cmd += ["--_worker", worker]
    out = subprocess.run(cmd, capture_output=True, text=True, check=False)
    if out.returncode != 0:
        return {"error": (out.stderr or out.stdout)[-2000:], "returncode": out.returncode}
    return json.loads(out.stdout.strip().splitlines()[-1])


def memory_rows(args):
    static = _spawn(args, "static")
    if "error" in static:
        print(static["error"], file=sys.stderr)
        return []
    rows = []
    scale = (args.mem_run_batch * args.mem_run_steps) / (args.mem_batch * args.mem_steps)
    for name, m in static.items():
        row = {
            "config": name,
            "batch": args.mem_batch,
            "steps": args.mem_steps,
            "dtype": "float64",
            "xla_peak_GB": m["peak_bytes"] / 1e9,
            "xla_temp_GB": m["temp_bytes"] / 1e9,
            "xla": m,
            "measured": False,
        }
        # the measured run is at mem_run_batch x mem_run_steps; its static peak scales ~ B N
        if m["peak_bytes"] * scale / 1e9 < args.mem_limit_gb:
            meas = _spawn(args, "measure:" + name)
            if "error" not in meas:
                row.update(
                    measured=True,
                    run_batch=args.mem_run_batch,
                    run_steps=args.mem_run_steps,
                    rss_peak_GB=meas["rss_peak_GB"],
                    rss_increase_GB=meas["rss_peak_GB"] - meas["rss_before_run_GB"],
                    run_s=meas["run_s"],
                    xla_peak_at_run_size_GB=meas["xla_at_run_size"]["peak_bytes"] / 1e9,
                )
            else:
                row["error"] = meas["error"][-300:]
        else:
            row["skipped"] = f"static peak above --mem-limit-gb {args.mem_limit_gb}"
        rows.append(row)
        print(f"  memory {name}: done", flush=True)
    return rows


def main(argv=None):
    args = parse_args(argv)
    C.setup(args.dtype)
    if args._worker:
        if args._worker == "static":
            res = _worker_static(args)
        else:
            res = _worker_measure(args, args._worker.split(":", 1)[1])
        print(json.dumps(res))
        return res
    rows = []
    if not args.no_timing:
        for b in args.batches:
            rows.append(
                timing_row(b, args.steps, args.repeats, args.dtype, args.timing, args.segment)
            )
            print(f"  batch {b}: grad/fwd = {rows[-1]['grad_over_fwd']:.2f}", flush=True)
        C.print_table(rows, COLUMNS, "forward vs value_and_grad (w.r.t. the VCM gains)")
    mem = [] if args.no_memory else memory_rows(args)
    if mem:
        C.print_table(
            mem,
            MEM_COLUMNS,
            f"peak memory, float64 (XLA static analysis at {args.mem_batch} x {args.mem_steps}; "
            f"measured runs at {args.mem_run_batch} x {args.mem_run_steps})",
        )
    C.write_json(args.json, args, rows, memory=mem)
    return rows, mem


if __name__ == "__main__":
    main()
