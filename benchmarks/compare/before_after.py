"""Before/after in one run: the closed loop of an older vcjax revision against this checkout,
on one CPU device and sharded over every core.

The machine may be shared, so absolute rates drift between runs; ratios measured in one run do
not. This script extracts the ``vcjax`` package of ``--before`` (a git revision; default: the
state before throughput round 2, issue 12) into a temporary directory and measures, in fresh
worker processes that alternate (before, after, before, after, ... ``--rounds`` times, best of
each by wall time), Simulation 1's ``vcm_integral`` closed loop (INFANTE-class plant, RK4,
dt = 0.05 s, float32 by default) for every case:

* ``single``: one trajectory, ``jit(simulate)``, no vmap;
* ``vmap B``: ``jax.vmap`` over B scenarios on one CPU device (one core does the work);
* ``sharded B``: the same batch split into ``--cores`` host CPU devices
  (``jax_num_cpu_devices``) with a ``NamedSharding`` over the scenario axis (every core works),

each with the continuous-time controller (evaluated at every RK4 stage) and the sampled one
(once per step, held); and (``--kinds sweep``)

* ``sweep B``: ``vcjax.sweep.run_sweep`` of ``--sweep-config`` (default: the issue's
  8192 x 3000 sweep, sampled ``vcm_integral``) resized to ``--batch`` x ``--steps``, sharded
  over ``--cores`` devices, its own ``timing`` (compile apart from run) — for revisions whose
  sweep reports it (from the round-2 sweep timing on, e.g. ``--before b39f07b``).

The worker returns the best wall time of ``--repeats`` calls after a
warm-up, the process CPU time of that call (``steps_per_cpu_s``: on a machine shared with other
jobs, per-core efficiency is steadier than wall time; with N devices the CPU time is that of
all N cores), and the compile time; the timed function returns only the (B,) mean |e|
(computed in jit), as in :mod:`benchmarks.perf.throughput`.

    python -m benchmarks.compare.before_after --json benchmarks/results/before_after_float32.json
"""

from __future__ import annotations

import argparse
import functools
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from benchmarks import _common as C

#: The last commit before throughput round 2 (issue 12): 11-station cross-flow strip sum,
#: batched ``dot`` kernels for the small rotations and inertia products.
BEFORE = "381cf435d3e3a97f795be04438b148187557f901"
ROOT = Path(__file__).resolve().parents[2]
SWEEP_CONFIG = ROOT / "benchmarks" / "configs" / "sweep_8192x3000.toml"


def parse_args(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    C.add_common_args(p)
    p.add_argument("--before", default=BEFORE, help="git revision measured as 'before'")
    p.add_argument("--batch", type=int, default=4096)
    p.add_argument("--steps", type=int, default=500)
    p.add_argument("--single-steps", type=int, default=2000)
    p.add_argument("--rounds", type=int, default=2, help="alternating before/after rounds")
    p.add_argument("--cores", type=int, default=os.cpu_count() or 1)
    p.add_argument("--timings", nargs="+", default=["sampled", "continuous"])
    p.add_argument("--kinds", nargs="+", default=["single", "vmap", "sharded"])
    p.add_argument("--sweep-config", default=str(SWEEP_CONFIG))
    p.add_argument(
        "--cli-compiler",
        action="store_true",
        help="the 'after' workers compile with the XLA CPU code generator the vcjax command "
        "line uses (vcjax.runtime.compiler); default: XLA's defaults on both sides",
    )
    p.add_argument("--worker", default=None, help=argparse.SUPPRESS)
    args = p.parse_args(argv)
    if args.quick:
        args.batch, args.steps, args.single_steps, args.rounds = 512, 100, 200, 1
        args.repeats = min(args.repeats, 2)
    return args


# ----------------------------------------------------------------------------- worker side


def _simulation_1():
    """``(gains, scenario, simulate)`` of Simulation 1 in whichever vcjax is importable:
    ``simulate(variant, gains, scenario, config, dt)`` (not jitted)."""
    try:
        from vcjax import experiments, loops

        sim1 = experiments.get("sim1")
    except (ImportError, AttributeError):  # an older revision: the parallel module API
        try:
            from vcjax.experiments import sim1
        except ImportError:  # older still: the experiment under its former name
            from vcjax import sim1  # type: ignore[no-redef]
        return sim1.default_gains(), sim1.sim1_scenario(), sim1.simulate

    import jax

    @functools.cache
    def loop(variant):  # built eagerly (its path is checked on values), even inside a jit
        with jax.ensure_compile_time_eval():
            return sim1.loop(variant)

    def simulate(variant, gains, scenario, config, dt):
        return loops.simulate(loop(variant), gains, scenario, config, dt)

    return sim1.default_gains("vcm"), sim1.scenario(), simulate


def measure(case: dict) -> dict:
    """Run one case in this process (JAX must not be initialised before the device count)."""
    if case.get("lib"):  # before ``python -m`` put the checkout's root first on sys.path
        sys.path.insert(0, case["lib"])
    import jax

    n_dev = int(case["devices"])
    if n_dev > 1:
        jax.config.update("jax_num_cpu_devices", n_dev)
    C.setup(case["dtype"])
    import jax.numpy as jnp
    import numpy as np

    from vcjax.rollout import RolloutConfig

    if case["kind"] == "sweep":
        return _measure_sweep(case)
    gains, sc, simulate = _simulation_1()
    cfg = RolloutConfig(num_steps=case["steps"], integrator="rk4", timing=case["timing"])

    def one(g, s, dt):
        tr = simulate(C.VARIANT, g, s, cfg, dt)
        return jnp.mean(jnp.abs(tr.aux.eps[:, 1]))

    if case["kind"] == "single":
        f, inputs = jax.jit(one), (gains, sc, C.DT)
        batch = 1
    else:
        batch = case["batch"]
        scb = C.batched_scenario(sc, batch)
        axes = C.scenario_axes(scb)
        scb = C.shard_batch(scb, n_dev)
        f = jax.jit(lambda g, s, dt: jax.vmap(one, in_axes=(None, axes, None))(g, s, dt))
        inputs = (gains, scb, C.DT)
    lower_s, compile_s, comp = C.compile_timed(f, *inputs)
    run_s = C.best_of(lambda: comp(*inputs), case["repeats"])
    out = np.asarray(comp(*inputs))
    return {
        "compile_s": lower_s + compile_s,
        "run_s": run_s,
        "steps_per_s": batch * case["steps"] / run_s,
        "cpu_s": C.LAST_CPU_S,
        "devices_seen": len(jax.devices()),
        "mean_abs_e": float(np.nanmean(out)),
        "vcjax": str(Path(sys.modules["vcjax"].__file__).parent),
    }


def _measure_sweep(case: dict) -> dict:
    """``run_sweep`` of the sweep config at the case's size; best run of ``repeats``."""
    import dataclasses

    import jax
    import numpy as np

    from vcjax.sweep import load_config, run_sweep

    spec, _ = load_config(case["config"])
    spec = dataclasses.replace(
        spec,
        num_scenarios=case["batch"],
        chunk_size=case["batch"],
        horizon=case["steps"] * spec.dt,
    )
    best, first_compile_s = None, None
    for _ in range(case["repeats"]):  # later calls find the program in JAX's cache
        res = run_sweep(spec, progress=False)
        t = res.timing[spec.variants[0]]
        first_compile_s = t["compile_s"] if first_compile_s is None else first_compile_s
        if best is None or t["run_s"] < best[0]["run_s"]:
            best = (t, res)
    t, res = best
    return {
        "compile_s": first_compile_s,
        "run_s": t["run_s"],
        "steps_per_s": t["traj_steps_per_s"],
        "cpu_s": float("nan"),
        "devices_seen": len(jax.devices()),
        "mean_abs_e": float(np.nanmean(res.metrics[spec.variants[0]]["ss_abs_e"])),
        "vcjax": str(Path(sys.modules["vcjax"].__file__).parent),
    }


# ----------------------------------------------------------------------------- driver side


def extract(rev: str, dest: Path) -> str:
    """Write revision ``rev``'s ``vcjax/`` into ``dest``; return the full commit hash."""
    full = subprocess.run(
        ["git", "rev-parse", rev], cwd=ROOT, check=True, capture_output=True, text=True
    ).stdout.strip()
    arch = subprocess.run(
        ["git", "archive", full, "vcjax"], cwd=ROOT, check=True, capture_output=True
    ).stdout
    subprocess.run(["tar", "-x", "-C", str(dest)], input=arch, check=True)
    return full


def run_worker(case: dict, lib_path: Path | None, cli_compiler: bool = False) -> dict:
    """``measure(case)`` in a fresh process importing vcjax from ``lib_path`` (None: this one);
    ``cli_compiler``: with the command line's XLA CPU code generator
    (:mod:`vcjax.runtime.compiler`)."""
    env = dict(os.environ)
    env["PYTHONPATH"] = str(ROOT)
    env.pop("XLA_FLAGS", None)
    env.pop("VCJAX_CPU_DEVICES", None)
    if cli_compiler:
        from vcjax.runtime.compiler import prefer_fast_compile

        prefer_fast_compile(env)
    case = {**case, "lib": str(lib_path) if lib_path else None}
    cmd = [sys.executable, "-m", "benchmarks.compare.before_after", "--worker", json.dumps(case)]
    res = subprocess.run(cmd, env=env, capture_output=True, text=True, cwd=ROOT)
    if res.returncode != 0:
        raise RuntimeError(f"worker failed for {case}:\n{res.stderr[-3000:]}")
    return json.loads(res.stdout.strip().splitlines()[-1])


def case_steps(case: dict) -> int:
    """Trajectory-steps of one timed call."""
    return case.get("batch", 1) * case["steps"] if case["kind"] != "single" else case["steps"]


def cases(args) -> list[dict]:
    out = []
    for timing in args.timings:
        base = {"dtype": args.dtype, "timing": timing, "repeats": args.repeats}
        if "single" in args.kinds:
            out.append({**base, "kind": "single", "steps": args.single_steps, "devices": 1})
        for kind, dev in (("vmap", 1), ("sharded", args.cores)):
            if kind not in args.kinds or (kind == "sharded" and dev < 2):
                continue
            out.append({**base, "kind": kind, "batch": args.batch, "steps": args.steps})
            out[-1]["devices"] = dev
    if "sweep" in args.kinds:
        out.append(
            {
                "dtype": args.dtype,
                "repeats": args.repeats,
                "kind": "sweep",
                "timing": "config",
                "batch": args.batch,
                "steps": args.steps,
                "devices": args.cores,
                "config": args.sweep_config,
            }
        )
    return out


def main(argv=None):
    args = parse_args(argv)
    if args.worker:
        print(json.dumps(measure(json.loads(args.worker))))
        return None
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        before_rev = extract(args.before, Path(tmp))
        for case in cases(args):
            best = {}
            for _ in range(args.rounds):
                for side, lib in (("before", Path(tmp)), ("after", None)):
                    r = run_worker(case, lib, args.cli_compiler and lib is None)
                    if side not in best or r["run_s"] < best[side]["run_s"]:
                        best[side] = r
            b, a = best["before"], best["after"]
            if Path(b["vcjax"]) == Path(a["vcjax"]):
                raise RuntimeError(f"before and after both imported {a['vcjax']}")
            row = {
                "case": case["kind"]
                if case["kind"] == "single"
                else f"{case['kind']} B={case['batch']}",
                "timing": case["timing"],
                "cores_used": case["devices"],
                "steps": case["steps"],
                "before_steps_per_s": b["steps_per_s"],
                "after_steps_per_s": a["steps_per_s"],
                "speedup": a["steps_per_s"] / b["steps_per_s"],
                "before_compile_s": b["compile_s"],
                "after_compile_s": a["compile_s"],
                "before_steps_per_cpu_s": case_steps(case) / b["cpu_s"],
                "after_steps_per_cpu_s": case_steps(case) / a["cpu_s"],
                "after_cpu_s_per_wall": a["cpu_s"] / a["run_s"],
                "rel_diff_mean_abs_e": abs(a["mean_abs_e"] - b["mean_abs_e"])
                / max(abs(b["mean_abs_e"]), 1e-30),
                "load": C.load_average(),
                "time": time.strftime("%H:%M:%S"),
            }
            rows.append(row)
            print(
                f"  {row['case']:<16} {row['timing']:<10} cores {row['cores_used']}: "
                f"{b['steps_per_s']:.3e} -> {a['steps_per_s']:.3e} steps/s "
                f"(x{row['speedup']:.2f})",
                flush=True,
            )
    C.print_table(
        rows,
        [
            "case",
            "timing",
            "cores_used",
            "before_steps_per_s",
            "after_steps_per_s",
            "speedup",
            "before_steps_per_cpu_s",
            "after_steps_per_cpu_s",
            "before_compile_s",
            "after_compile_s",
            "after_cpu_s_per_wall",
            "rel_diff_mean_abs_e",
            "load",
        ],
        f"before ({before_rev[:9]}) / after (this checkout), {args.dtype}",
    )
    C.write_json(args.json, args, rows, before=before_rev)
    return rows


if __name__ == "__main__":
    main()
