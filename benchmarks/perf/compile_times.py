"""Compile time and graph size of every closed loop (issue 20): what a user waits for.

For every registered vehicle x controller (:mod:`vcjax.loops`), two programs of one scenario
(the loop's default, RK4, dt = 0.05 s, ``--steps`` steps, default 250):

* ``forward``: the rollout reduced to a scalar (mean squared cross-track error);
* ``gradient``: the reverse-mode gradient of that scalar w.r.t. the gains
  (``jax.value_and_grad``).

Each is built as ``jax.jit(f).trace(...)``, ``.lower()``, ``.compile()``, timed separately
(``trace_s``, ``lower_s``, ``compile_s``), and its size is the line count of the lowered
StableHLO text (``hlo_lines``, ``lowered.as_text()``): deterministic, unlike the times, so it is
the number to compare under load. ``--tune CONFIG`` also builds the ``vcjax tune`` training
step of that tuning config (L-BFGS or Adam step: loss, gradient and optimiser update in one
program; default ``examples/tuning/remus100.toml``; ``--tune none`` skips it).

    python -m benchmarks.perf.compile_times --dtype float64
    python -m benchmarks.perf.compile_times --loops remus100/vcm3d,infante/vcm_integral --tune none

By default the programs compile with the XLA CPU code generator the ``vcjax`` command line
uses (:mod:`vcjax.runtime.compiler`); ``--xla-default`` measures XLA's default one (what a Python
user's own ``jax.jit`` gets); ``--vcjax-jit`` builds every program with ``vcjax.jit`` under XLA's
default flags (the per-program option vcjax's own programs compile with).

``--before REV`` measures in one run an older revision against this checkout: each program
(loop x kind, and the tune step) is built in fresh processes that alternate, before then after,
``--rounds`` times (the revision's ``vcjax``, ``tuning`` and ``benchmarks`` packages extracted
with ``git archive`` into a temporary folder); each side keeps its fastest round (the sizes do
not change between rounds); the older revision compiles with XLA's defaults, as its command
line did, this checkout as its command line does (``--xla-default``: XLA's defaults on both
sides, the code's own share). On a shared machine only such same-run ratios compare.

    python -m benchmarks.perf.compile_times --before ff295bc --loops remus100/vcm3d --tune none \
        --json benchmarks/results/compile_times_before_after.json

Writes ``benchmarks/results/compile_times.json`` (``--json``): one key per loop,
``"vehicle/controller": {"forward": {...}, "gradient": {...}}`` with ``trace_s``, ``lower_s``,
``compile_s``, ``hlo_lines``; ``"tune:<config>"`` for the training step (``"step"``: every
program it compiles together; with L-BFGS also each of them: ``value_and_grad``, ``start``,
``advance``, ``finish``, :class:`tuning.optim.LBFGSStep`); and a ``machine`` block
(CPU model, cores, jax version, dtype, load average). The persistent compilation cache is off
in this process (``jax_enable_compilation_cache``), so every compile is a real one.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import tempfile
from pathlib import Path

from benchmarks import _common as C
from tests.reference.programs import build_times, loop_programs

ROOT = Path(__file__).resolve().parents[2]
DEFAULT_JSON = ROOT / "benchmarks" / "results" / "compile_times.json"
DEFAULT_TUNE = ROOT / "examples" / "tuning" / "remus100.toml"


def parse_args(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--dtype", choices=("float32", "float64"), default="float64")
    p.add_argument("--steps", type=int, default=250, help="rollout steps (default 250)")
    p.add_argument(
        "--loops",
        default=None,
        help="comma-separated vehicle/controller names or vehicle names (default: all; "
        "'none': only the tune step)",
    )
    p.add_argument("--timing", choices=("continuous", "sampled"), default="continuous")
    p.add_argument(
        "--kinds",
        default="forward,gradient",
        help="comma-separated programs per loop: forward, gradient",
    )
    p.add_argument(
        "--tune",
        default=str(DEFAULT_TUNE),
        help="tuning config whose training step is built too ('none' to skip)",
    )
    p.add_argument("--json", type=Path, default=DEFAULT_JSON, help="output JSON file")
    p.add_argument(
        "--no-compile",
        action="store_true",
        help="trace and lower only (graph sizes; compile_s is null): a quick size check",
    )
    p.add_argument(
        "--before",
        default=None,
        help="git revision to measure against this checkout, program by program, in "
        "alternating fresh processes (writes {program: {kind: {before, after}}})",
    )
    p.add_argument("--rounds", type=int, default=2, help="alternating rounds with --before")
    p.add_argument(
        "--xla-default",
        action="store_true",
        help="XLA's default CPU code generator; by default the one the vcjax command line "
        "uses (vcjax.runtime.compiler: --xla_cpu_use_fusion_emitters=false)",
    )
    p.add_argument(
        "--vcjax-jit",
        action="store_true",
        help="XLA_FLAGS as a Python user has them (XLA's defaults) and every program built with "
        "vcjax.jit (the per-program option vcjax's own programs compile with)",
    )
    p.add_argument(
        "--run",
        action="store_true",
        help="also time a warm call of each loop program (best of 5, block_until_ready): "
        "run_s in the JSON (costs one more compile of each)",
    )
    args = p.parse_args(argv)
    if args.run and (args.before or args.no_compile):
        p.error("--run: measure it without --before and --no-compile")
    if args.vcjax_jit and args.before:
        p.error("--vcjax-jit: measure it without --before (the older revisions have no vcjax.jit)")
    if args.vcjax_jit and args.xla_default:
        p.error("--vcjax-jit and --xla-default: choose one")
    if args.steps < 1:
        p.error("--steps: expected a positive int")
    kinds = [k for k in args.kinds.split(",") if k]
    bad = sorted(set(kinds) - {"forward", "gradient"})
    if bad or not kinds:
        p.error(f"--kinds: expected forward and/or gradient, got {args.kinds!r}")
    args.kinds = kinds
    return args


def machine(args) -> dict:
    import jax

    return {
        "cpu": C.cpu_model(),
        "cores": os.cpu_count(),
        "device": C.device_str(),
        "jax": jax.__version__,
        "jaxlib": getattr(jax.lib, "__version__", None) or _jaxlib_version(),
        "python": platform.python_version(),
        "dtype": args.dtype,
        "steps": args.steps,
        "timing": args.timing,
        "load_average_1min_at_start": C.load_average(),
        "xla_flags": os.environ.get("XLA_FLAGS", ""),
        "vcjax_jit": bool(getattr(args, "vcjax_jit", False)),
    }


def _jaxlib_version():
    try:
        import jaxlib

        return jaxlib.__version__
    except (ImportError, AttributeError):
        return None


def select(names: str | None) -> list[tuple[str, str]]:
    from vcjax import loops

    every = [(v, c) for v in loops.vehicles() for c in loops.controllers(v)]
    if not names:
        return every
    if names.strip().lower() == "none":  # only the tune step
        return []
    out = []
    for name in [n.strip() for n in names.split(",") if n.strip()]:
        if "/" in name:
            v, c = name.split("/", 1)
            if (v, c) not in every:
                raise SystemExit(
                    f"--loops: unknown loop {name!r}; registered: "
                    f"{', '.join(f'{a}/{b}' for a, b in every)}"
                )
            out.append((v, c))
        else:
            hits = [(v, c) for v, c in every if v == name]
            if not hits:
                raise SystemExit(
                    f"--loops: unknown vehicle {name!r}; registered: {loops.vehicles()}"
                )
            out.extend(hits)
    return list(dict.fromkeys(out))


def tune_program(config: Path):
    """``{name: (jitted, args)}``: the programs of one ``vcjax tune`` training step of
    ``config`` (Adam: one; L-BFGS: the batch value-and-gradient and the small line-search
    programs of :class:`tuning.optim.LBFGSStep`)."""
    import jax.numpy as jnp

    from tuning.config import load_config
    from tuning.loss import objective
    from tuning.optim import init_state, make_optimizer, make_step, replicate_like, tuner_options
    from tuning.run import build, distribute

    cfg = load_config(config)
    problem, _, data, train, _ = build(cfg)
    start = data.theta_ref + problem.space.symmetry_break(data.base)
    train_d, data_d, start = distribute(train, data, start)
    loss_fn = lambda th, d, s: objective(th, d, s, problem)[0]
    o = tuner_options(cfg["optimizer"])
    opt = make_optimizer(
        o["optimizer"], o["learning_rate"], o["memory_size"], o["max_linesearch_steps"]
    )
    step = make_step(loss_fn, opt, o["optimizer"], o["grad_mode"])
    theta = jnp.asarray(start)
    state = init_state(opt, theta)
    args = (data_d, train_d)
    theta, state = replicate_like(args, theta, state)
    if hasattr(step, "programs"):
        return step.programs(theta, state, args)
    return {"step": (step, (theta, state, jnp.asarray(1.0, theta.dtype), args))}


def _run_time(fn, *args) -> float:
    """Best of 5 warm calls of ``fn`` (jitted; one call first to compile)."""
    import jax

    jitted = fn if hasattr(fn, "lower") else jax.jit(fn)
    return C.best_of(lambda: jitted(*args), repeats=5)


def _say(name: str, kind: str, r: dict) -> None:
    comp = "-" if r["compile_s"] is None else f"{r['compile_s']:.2f}"
    run = f"  run {r['run_s'] * 1e3:8.1f} ms" if "run_s" in r else ""
    print(
        f"  {name:28s} {kind:8s} trace {r['trace_s']:7.2f} s  lower {r['lower_s']:6.2f} s"
        f"  compile {comp:>7s} s  {r['hlo_lines']:8d} lines{run}",
        flush=True,
    )


def main(argv=None) -> dict:
    args = parse_args(argv)
    if args.before:
        return before_after(args)
    if not (args.xla_default or args.vcjax_jit):
        from vcjax.runtime.compiler import prefer_fast_compile

        prefer_fast_compile()  # what the CLI compiles with (before JAX starts)
    C.setup(args.dtype)
    import jax

    # measure real compiles: never read a persistent cache entry (the caller's setting back
    # at the end: the benchmark also runs inside the test session)
    cache_was = jax.config.jax_enable_compilation_cache
    jax.config.update("jax_enable_compilation_cache", False)
    try:
        return _main(args)
    finally:
        jax.config.update("jax_enable_compilation_cache", cache_was)


def _main(args) -> dict:
    mach = machine(args)
    print(
        f"compile times: {mach['cpu']}, {mach['cores']} cores, jax {mach['jax']}, {args.dtype}, "
        f"{args.steps} steps, timing {args.timing}, load {mach['load_average_1min_at_start']:.2f}"
    )
    results: dict = {}
    rows = []
    for vehicle, controller in select(args.loops):
        name = f"{vehicle}/{controller}"
        fwd, grad, gains, sc = loop_programs(vehicle, controller, args.steps, args.timing, C.DT)
        if args.vcjax_jit:
            from vcjax.runtime.compiler import jit

            fwd, grad = jit(fwd), jit(grad)
        entry = {}
        for kind in args.kinds:
            r = build_times(
                fwd if kind == "forward" else grad, gains, sc, compile=not args.no_compile
            )
            if args.run:
                r["run_s"] = _run_time(fwd if kind == "forward" else grad, gains, sc)
            entry[kind] = r
            rows.append({"program": name, "kind": kind, **r, "load": C.load_average()})
            _say(name, kind, r)
        results[name] = entry
    if args.tune and args.tune.lower() != "none":
        key = f"tune:{Path(args.tune).name}"
        results[key] = {}
        for kind, (fn, fn_args) in tune_program(Path(args.tune)).items():
            r = build_times(fn, *fn_args, compile=not args.no_compile)
            results[key][kind] = r
            rows.append({"program": key, "kind": kind, **r, "load": C.load_average()})
            _say(key, kind, r)
        if len(results[key]) > 1:  # the whole step: every program it compiles
            total = {
                k: (None if any(r[k] is None for r in results[key].values())
                    else sum(r[k] for r in results[key].values()))
                for k in ("trace_s", "lower_s", "compile_s", "hlo_lines")
            }  # fmt: skip
            results[key]["step"] = total
            rows.append({"program": key, "kind": "step", **total, "load": C.load_average()})
            _say(key, "step", total)
    mach["load_average_1min_at_end"] = C.load_average()
    doc = {"machine": mach, **results}
    cols = ["program", "kind", "trace_s", "lower_s", "compile_s", "hlo_lines", "load"]
    cols += ["run_s"] if args.run else []
    C.print_table(rows, cols, title="compile times (s) and StableHLO size")
    if args.json is not None:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(doc, indent=2) + "\n")
        print(f"\nwrote {args.json}")
    return doc


# ----------------------------------------------------------------------------- before/after


def _extract(rev: str, dest: Path) -> str:
    """Write revision ``rev``'s packages into ``dest``; return the full commit hash."""
    full = subprocess.run(
        ["git", "rev-parse", rev], cwd=ROOT, check=True, capture_output=True, text=True
    ).stdout.strip()
    paths = ["vcjax", "tuning", "benchmarks", "examples"]
    has_reference = subprocess.run(  # the shared helpers (build_times, ...) of later revisions
        ["git", "cat-file", "-e", f"{full}:tests/reference"], cwd=ROOT, capture_output=True
    )
    paths += ["tests/reference"] if has_reference.returncode == 0 else []
    arch = subprocess.run(
        ["git", "archive", full, *paths],
        cwd=ROOT,
        check=True,
        capture_output=True,
    ).stdout
    subprocess.run(["tar", "-x", "-C", str(dest)], input=arch, check=True)
    return full


def _one(root: Path, args, loops: str, kind: str, tune: str) -> dict:
    """One program built by ``root``'s own compile_times in a fresh process."""
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "ct.json"
        # the module's place in ``root``'s tree (before the benchmarks were grouped: top level)
        grouped = (root / "benchmarks" / "perf" / "compile_times.py").exists()
        module = "benchmarks.perf.compile_times" if grouped else "benchmarks.compile_times"
        cmd = [sys.executable, "-m", module, "--dtype", args.dtype]
        cmd += ["--steps", str(args.steps), "--timing", args.timing, "--loops", loops]
        cmd += ["--kinds", kind, "--tune", tune, "--json", str(out)]
        cmd += ["--no-compile"] if args.no_compile else []
        cmd += ["--xla-default"] if args.xla_default and root == ROOT else []
        env = {k: v for k, v in os.environ.items() if k not in ("XLA_FLAGS", "PYTHONPATH")}
        env["PYTHONPATH"] = str(root)
        res = subprocess.run(cmd, cwd=root, env=env, capture_output=True, text=True)
        if res.returncode != 0:
            raise RuntimeError(f"{root}: {' '.join(cmd)} failed:\n{res.stderr[-3000:]}")
        return json.loads(out.read_text())


def before_after(args) -> dict:
    """``--before``: every selected program of both revisions, alternating fresh processes."""
    C.setup(args.dtype)
    jobs = [(f"{v}/{c}", k, "none") for v, c in select(args.loops) for k in args.kinds]
    if args.tune and args.tune.lower() != "none":
        jobs.append((f"tune:{Path(args.tune).name}", "step", str(Path(args.tune).resolve())))
    results: dict = {}
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        full = _extract(args.before, Path(tmp))
        mach = machine(args)
        mach["before"] = full
        mach["after"] = "this checkout"
        load = mach["load_average_1min_at_start"]
        print(
            f"compile times, {args.before} ({full[:10]}) against this checkout, "
            f"{args.rounds} alternating rounds, load {load:.2f}"
        )
        for name, kind, tune in jobs:
            loops = "none" if name.startswith("tune:") else name
            kinds = "forward" if kind == "step" else kind
            best: dict = {}
            for _ in range(args.rounds):
                for side, root in (("before", Path(tmp)), ("after", ROOT)):
                    doc = _one(root, args, loops, kinds, tune)
                    r = doc[name][kind]
                    r = {**r, "load": C.load_average()}
                    total = r["trace_s"] + r["lower_s"] + (r["compile_s"] or 0.0)
                    if side not in best or total < best[side]["total_s"]:
                        best[side] = {**r, "total_s": total}
            results.setdefault(name, {})[kind] = best
            b, a = best["before"], best["after"]
            rows.append(
                {
                    "program": name,
                    "kind": kind,
                    "before_s": b["total_s"],
                    "after_s": a["total_s"],
                    "before_lines": b["hlo_lines"],
                    "after_lines": a["hlo_lines"],
                    "load": a["load"],
                }
            )
            print(
                f"  {name:28s} {kind:8s} before {b['total_s']:7.2f} s {b['hlo_lines']:7d} lines"
                f"   after {a['total_s']:7.2f} s {a['hlo_lines']:7d} lines",
                flush=True,
            )
    mach["load_average_1min_at_end"] = C.load_average()
    doc = {"machine": mach, **results}
    cols = ["program", "kind", "before_s", "after_s", "before_lines", "after_lines", "load"]
    C.print_table(rows, cols, title="trace + lower + compile (s) and StableHLO lines")
    if args.json is not None:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(doc, indent=2) + "\n")
        print(f"\nwrote {args.json}")
    return doc


if __name__ == "__main__":
    main()
