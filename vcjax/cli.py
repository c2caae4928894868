"""``vcjax`` command line: simulations of the paper's experiments and demos, writing figures."""

from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

__all__ = ["main"]


def _enable_x64(flag: bool) -> None:
    import jax

    jax.config.update("jax_enable_x64", bool(flag))


def _record(out, command: str, args, config=None, seeds=None, **wall) -> None:
    """Write ``out/run.json`` (:mod:`vcjax.runinfo`) and say so; ``config`` defaults to the
    parsed command-line options."""
    from vcjax.runinfo import write_run_json

    config = {k: v for k, v in vars(args).items() if k != "func"} if config is None else config
    config.pop("func", None)
    wall = {"total": time.perf_counter() - args.t_start, **wall}
    path = write_run_json(out, command, config=config, seeds=seeds, wall_s=wall)
    if path is not None:
        print(f"wrote {path}")
    _outputs_done()


def _prepare(args, path, command: str) -> Path:
    """Check, clear (``--overwrite``) and lock ``--out`` before any work (:mod:`vcjax.outputs`)."""
    from vcjax.outputs import OutputError, prepare_out

    try:
        inputs = [getattr(args, k, None) for k in ("config", "gains")]  # never removed
        _OUT[:] = [prepare_out(path, getattr(args, "overwrite", False), command, keep=inputs)]
    except OutputError as err:
        raise _CLIError(str(err)) from None
    return _OUT[0].path


#: The output folder of the running command (:func:`_prepare`), released when it ends.
_OUT: list = []


def _outputs_done() -> None:
    """List the files this run wrote (for a later ``--overwrite``) and release the lock."""
    if _OUT:
        _OUT[0].record_written()
        _OUT.pop().release()


class _CLIError(Exception):
    """A bad input of the command line: printed as one line, exit code 2."""


def _time_grid(horizon: float, dt: float, max_steps: int = 10_000_000) -> int:
    """Number of steps of ``horizon`` in steps of ``dt``; both finite, ``0 < dt <= horizon``."""
    if not (math.isfinite(horizon) and math.isfinite(dt)):
        raise _CLIError(f"need finite --dt and --horizon, got dt={dt}, horizon={horizon}")
    if not (horizon > 0 and dt > 0 and horizon >= dt):
        raise _CLIError(f"need 0 < dt <= horizon, got dt={dt}, horizon={horizon}")
    n = int(round(horizon / dt))
    if n > max_steps:
        raise _CLIError(
            f"--horizon {horizon:g} / --dt {dt:g} = {n} steps: more than {max_steps} "
            "(the trajectory is kept in memory); use a larger --dt or a shorter --horizon, "
            "or raise the limit with --max-steps"
        )
    return n


def _cmd_demo(args) -> int:
    from vcjax.experiments import ARM

    _time_grid(args.horizon, ARM.dt)
    out = _prepare(args, args.out, "demo")
    _enable_x64(args.x64)
    files = ARM.load().arm_demo(out, horizon=args.horizon)
    for f in files:
        print(f"wrote {f}")
    _record(out, "demo", args)
    return 0


def _fail(msg: str) -> int:
    print(f"vcjax: {msg}", file=sys.stderr)
    return 2


#: options of ``vcjax simulate`` that only some experiments take (Experiment.options)
_OWN_OPTIONS = ("edd", "timing", "actuation", "diverge_e", "waves", "wave_seed")


def _check_waves(args, where: str, dt: float) -> None:
    """``--waves HS TP DIR_DEG`` and ``--wave-seed`` of ``vcjax simulate`` (one line, exit 2)."""
    from vcjax import sizing

    if args.wave_seed is not None:
        if args.waves is None:
            raise _CLIError(f"{where}: --wave-seed needs --waves HS TP DIR_DEG")
        try:
            sizing.check_seed("--wave-seed", args.wave_seed, args.x64)
        except ValueError as err:
            raise _CLIError(f"{where}: {err}") from None
    if args.waves is None:
        return
    hs, tp, direction = args.waves
    if not all(math.isfinite(v) for v in args.waves):
        raise _CLIError(f"{where}: --waves: contains NaN or inf, got {list(args.waves)}")
    if hs < 0:
        raise _CLIError(f"{where}: --waves: HS must be >= 0 [m], got {hs:g}")
    if tp < 40.0 * dt:
        raise _CLIError(
            f"{where}: --waves: TP must be >= 40 dt = {40.0 * dt:g} s (the shortest component, "
            f"TP / 4, needs 10 steps), got {tp:g}"
        )


def _cmd_simulate(args) -> int:
    """``vcjax simulate NAME``: one experiment of the registry (:mod:`vcjax.experiments`)."""
    import json

    from vcjax.experiments import get

    exp = get(args.experiment)
    where = f"simulate {exp.name}"
    own = dict(exp.options)
    for opt in _OWN_OPTIONS:
        if getattr(args, opt) is not None and opt not in own:
            takes = ", ".join("--" + o.replace("_", "-") for o in own) or "none"
            flag = "--" + opt.replace("_", "-")
            return _fail(f"{where}: {flag} does not apply to {exp.name} (its own options: {takes})")
    if args.current is not None and exp.current is None:
        return _fail(f"{where}: --current is not supported for {exp.name} (no ocean current)")
    if args.gains is not None and not exp.gains:
        return _fail(f"{where}: --gains is not supported for {exp.name}")
    current = None if exp.current is None else tuple(args.current or exp.current)
    if current is not None and not all(math.isfinite(c) for c in current):
        return _fail(f"{where}: --current: contains NaN or inf, got {list(current)}")
    horizon = exp.horizon if args.horizon is None else args.horizon
    dt = exp.dt if args.dt is None else args.dt
    if args.max_steps is not None and args.max_steps < 1:
        raise _CLIError(f"--max-steps: expected an integer >= 1, got {args.max_steps}")
    _time_grid(horizon, dt, args.max_steps or 10_000_000)
    if args.diverge_e is not None and not (math.isfinite(args.diverge_e) and args.diverge_e > 0):
        raise _CLIError(f"--diverge-e: expected a finite bound > 0 [m], got {args.diverge_e:g}")
    _check_waves(args, where, dt)
    out = _prepare(args, args.out or f"out/{exp.name}", where)
    _enable_x64(args.x64)
    options = {
        k: default if getattr(args, k) is None else getattr(args, k) for k, default in own.items()
    }
    mod = exp.load()
    gains = None
    if args.gains:
        try:
            gains = mod.load_gains(json.loads(Path(args.gains).read_text()), **options)
        except (OSError, json.JSONDecodeError, ValueError) as err:
            return _fail(f"{where}: cannot use gains file {args.gains}: {err}")
    result = mod.run_experiment(out, gains, horizon=horizon, dt=dt, current=current, **options)
    _print_metrics(result["printed"])
    for f in result["files"]:
        print(f"wrote {f}")
    config = {
        "experiment": exp.name,
        "horizon": horizon,
        "dt": dt,
        "current": current,
        "gains": args.gains,
        "gains_values": gains,
        "out": str(out),
        "x64": args.x64,
        **options,
        **result.get("config", {}),
    }
    _record(out, where, args, config=config)
    for line in result["unhealthy"]:
        print(f"vcjax: UNHEALTHY RUN: {line}", file=sys.stderr)
    return 1 if result["unhealthy"] else 0


def _is_number(v) -> bool:
    return isinstance(v, int | float) and not isinstance(v, bool)


def _use_cores(args, command: str) -> int | None:
    """Split the host CPU into devices (before JAX initialises); a bad count is one line."""
    from vcjax import distributed
    from vcjax.devices import use_cpu_cores

    try:
        use_cpu_cores(args.cpu_devices)
    except ValueError as err:
        return _fail(f"{command}: {err}")
    distributed.warm_up()  # a multi-process run: collectives ready before anyone compiles
    return None


def _cmd_sweep(args) -> int:
    _prepare(args, args.out, "sweep")
    if (rc := _use_cores(args, "sweep")) is not None:
        return rc
    _enable_x64(args.x64)
    from vcjax.plots.sweep import sweep_figures as draw
    from vcjax.sweep import load_config, run_sweep_config

    try:
        spec, extras = loaded = load_config(args.config)  # parsed once, recorded in run.json
        _size_check(args, "sweep", spec=spec)
        with _interruptible():
            result = run_sweep_config(
                args.config, args.out, progress=True, netcdf=args.netcdf, loaded=loaded, draw=draw
            )
    except (OSError, ValueError, ImportError) as err:
        return _fail(f"sweep: {err}")
    summary = result["summary"]
    if summary is not None:  # None on the non-zero processes of a multi-host run
        for variant, s in summary.get("variants", {}).items():
            t = s.get("timing")
            if t and t.get("traj_steps_per_s"):
                print(
                    f"{variant}: compile {t['compile_s']:.2f} s, run {t['run_s']:.2f} s, "
                    f"{t['traj_steps_per_s'] / 1e6:.3g} M trajectory-steps/s "
                    f"({t['scenarios']} x {t['steps']} steps, {t['devices']} device(s))",
                    file=sys.stderr,
                )
            n, n_div = s.get("n", 0), s.get("n_diverged", 0)
            e = s.get("metrics", {}).get("ss_abs_e", {})
            if e and e.get("p50") is not None:
                print(
                    f"{variant:<14} ss_abs_e median {e['p50']:.3g} m, p95 {e['p95']:.3g} m; "
                    f"diverged {n_div} of {n}"
                )
            else:
                print(f"{variant:<14} no metrics: diverged {n_div} of {n}")
            if n_div:
                print(
                    f"vcjax: warning: sweep: {variant}: {n_div} of {n} runs diverged "
                    "(left out of the metrics and figures; flagged in results.npz)",
                    file=sys.stderr,
                )
    for f in result["files"]:
        print(f"wrote {f}")
    config = {"file": args.config, "spec": spec, **extras}
    _record(args.out, "sweep", args, config=config, seeds={"sweep": spec.seed})
    if summary is not None and summary.get("interrupted"):
        return _interrupted(
            "sweep",
            f"kept the {summary['num_scenarios']} of {summary['num_scenarios_planned']} "
            f"scenarios that ran (summary.json: interrupted) in {args.out}",
        )
    return 0


def _interruptible():
    """SIGINT / SIGTERM ask the running loop to stop at its next safe point and write what is
    done (:func:`vcjax.outputs.interrupt_guard`)."""
    from vcjax.outputs import interrupt_guard

    return interrupt_guard()


def _interrupted(command: str, what: str) -> int:
    """The one line of an interrupted run; exit code 130."""
    from vcjax.outputs import EXIT_INTERRUPTED, stop_signal

    print(f"vcjax: {command}: interrupted ({stop_signal() or 'signal'}): {what}", file=sys.stderr)
    return EXIT_INTERRUPTED


def _size_check(args, command: str, spec=None, cfg=None) -> None:
    """Refuse (ValueError, exit 2) work that cannot fit or seeds the PRNG cannot take
    (:mod:`vcjax.sizing`), before anything is compiled."""
    from vcjax import sizing

    sizing.check_limits_options(args.max_steps, args.max_memory_gb)
    if spec is not None:
        sizing.check_seed(f"{args.config}: [sweep] seed", spec.seed, args.x64)
        est = sizing.sweep_estimate(spec)
    else:
        for sec in ("train", "heldout"):
            sizing.check_seed(f"{args.config}: {sec}.seed", cfg[sec]["seed"], args.x64)
        est = sizing.tune_estimate(cfg)
    sizing.check_estimate(est, f"{args.config}", args.max_steps, args.max_memory_gb)


def _add_size_limits(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--max-steps",
        type=int,
        metavar="N",
        help="allow up to N steps per rollout (default 10,000,000)",
    )
    p.add_argument(
        "--max-memory-gb",
        type=float,
        metavar="G",
        help="allow an estimated peak memory up to G GB (default: 80%% of the physical memory)",
    )


def _cmd_tune(args) -> int:
    _prepare(args, args.out, "tune")
    if (rc := _use_cores(args, "tune")) is not None:
        return rc
    _enable_x64(args.x64)  # before importing tuning: sim1 builds its path constants at import
    from tuning import run_tune_config
    from tuning.config import load_config

    try:
        cfg = load_config(args.config)  # parsed once, recorded in run.json
        _size_check(args, "tune", cfg=cfg)
        with _interruptible():
            result = run_tune_config(args.config, args.out, cfg=cfg)
    except (OSError, ValueError) as err:
        return _fail(f"tune: {err}")
    for f in result["files"]:
        print(f"wrote {f}")
    seeds = {"train": cfg.train.seed, "heldout": cfg.heldout.seed}
    _record(args.out, "tune", args, config={"file": args.config, **cfg.to_dict()}, seeds=seeds)
    summary = result["summary"]
    if summary is None:  # processes other than 0 of a multi-process run
        return 0
    before, after = summary.get("heldout_loss_before"), summary.get("heldout_loss_after")
    if before is not None and after is not None:
        print(
            f"held-out loss: {before:.4g} -> {after:.4g} ({100 * (1 - after / before):.1f} % lower)"
        )
    if summary.get("aborted"):
        return _fail(f"tune: aborted: {summary.get('reason', 'non-finite steps')}")
    if summary.get("interrupted"):
        return _interrupted(
            "tune",
            f"after {summary['iterations']} of {summary['steps_planned']} steps; wrote the best "
            f"gains so far, the history and summary.json (interrupted) to {args.out}",
        )
    return 0


def _cmd_fit(args) -> int:
    _prepare(args, args.out, "fit")
    from vcjax.sizing import check_limits_options

    try:
        check_limits_options(None, args.max_memory_gb)
    except ValueError as err:
        raise _CLIError(str(err)) from None
    _enable_x64(args.x64)
    from vcjax.identify import load_fit_config, run_fit_config

    print(f"fit: {args.config} (compiling the multiple-shooting Jacobian first)")
    try:
        cfg = load_fit_config(args.config)  # parsed once, recorded in run.json
        with _interruptible():
            result = run_fit_config(
                args.config,
                args.out,
                progress=not args.quiet,
                cfg=cfg,
                max_memory_gb=args.max_memory_gb,
            )
    except (OSError, ValueError) as err:
        return _fail(f"fit: {err}")
    fit = result["fit"]
    print(f"{'parameter':<22}{'initial':>14}{'estimate':>14}{'std':>12}")
    sections = [fit] + ([fit["current"]] if "current" in fit else [])
    for sec in sections:
        for name, value in sec["estimates"].items():
            sd = sec["std"][name]
            sd = f"{sd:>12.3g}" if sd is not None else f"{'null':>12}"  # non-finite: null
            est = f"{value:>14.6g}" if value is not None else f"{'null':>14}"
            print(f"{name:<22}{sec['initial'][name]:>14.6g}{est}{sd}")
    print(f"{fit['iterations']} iterations, {fit['wall_time_s']:.1f} s ({fit['reason']})")
    for w in fit["warnings"]:
        print(f"vcjax: fit: warning: {w}", file=sys.stderr)
    if not fit["converged"] and fit["reason"] != "interrupted":
        print(
            "vcjax: fit: warning: converged: false -- the optimum is not trustworthy "
            "(see the warnings in fit.json)",
            file=sys.stderr,
        )
    for f in result["files"]:
        print(f"wrote {f}")
    _record(args.out, "fit", args, config={"file": args.config, **cfg.to_dict()})
    if fit["reason"] == "interrupted":
        return _interrupted(
            "fit",
            f"after {fit['iterations']} iterations; wrote the current estimates "
            f"(converged: false) to {args.out}",
        )
    return 0


def _cmd_launch(args) -> int:
    """``vcjax launch -n N -- COMMAND ...``: N local processes of one distributed run (or, inside
    a multi-task SLURM step, this process joins the step's run and runs COMMAND itself)."""
    from vcjax import distributed

    rest = list(args.rest)
    if rest[:1] == ["--"]:
        rest = rest[1:]
    commands = list(_DISTRIBUTED)
    if not rest or rest[0] not in commands:
        got = rest[0] if rest else "nothing"
        return _fail(
            f"launch: expected a command that runs across processes after --, one of {commands};"
            f" got {got}"
        )
    if distributed.in_slurm_step():
        try:
            distributed.initialize_from_env()
        except (RuntimeError, ValueError) as err:
            return _fail(f"launch: cannot join the SLURM step's run: {err}")
        return main(rest)
    if args.n is None or args.n < 1:
        return _fail("launch: -n N (number of processes, >= 1) is required outside SLURM")
    if args.cpu_devices is not None and args.cpu_devices < 1:
        return _fail(f"launch: --cpu-devices must be >= 1, got {args.cpu_devices}")
    from vcjax.devices import usable_cores
    from vcjax.sizing import SizeError, check_launch

    try:
        check_launch(args.n, args.timeout, args.max_processes, usable_cores())
    except SizeError as err:
        return _fail(f"launch: {err}")

    # the local processes share the cores: by default each splits off its share of them
    cpu = max(1, usable_cores() // args.n) if args.cpu_devices is None else args.cpu_devices
    with _interruptible():  # Ctrl-C: forwarded to the processes, which keep what is done
        codes = distributed.spawn(
            args.n,
            [sys.executable, "-m", "vcjax.cli", *rest],
            port=args.port,
            cpu_devices=cpu,
            timeout_s=args.timeout,
        )
    if any(codes) and set(codes) <= {0, 130}:  # interrupted: the processes kept what was done
        print(f"vcjax: launch: interrupted: exit codes {codes}", file=sys.stderr)
        return 130
    if any(codes):
        return _fail(f"launch: exit codes of the {args.n} processes: {codes}")
    return 0


def _print_metrics(metrics: dict) -> None:
    """A table: one row per variant, one column per numeric metric."""
    keys = [k for k, v in next(iter(metrics.values())).items() if _is_number(v)]
    widths = [max(len(k), 10) + 2 for k in keys]
    print("variant".ljust(14) + "".join(k.rjust(w) for k, w in zip(keys, widths, strict=True)))
    for name, m in metrics.items():
        cells = (
            f"{m[k]:{w}.4g}" if _is_number(m.get(k)) else "-".rjust(w)
            for k, w in zip(keys, widths, strict=True)
        )
        print(name.ljust(14) + "".join(cells))


def _add_cpu_devices(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--cpu-devices",
        metavar="N",
        default=None,
        help="split the host CPU into N JAX devices and shard the scenarios over them "
        "(default: $VCJAX_CPU_DEVICES, else one per core; 1: no sharding)",
    )


def _add_overwrite(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--overwrite",
        action="store_true",
        help="--out may hold an earlier vcjax run: its files are removed first (files vcjax "
        "did not write are kept)",
    )


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="vcjax",
        description="Differentiable simulator and gain tuner for the virtually-constrained-motion "
        "(VCM) controller of underwater vehicles.",
    )
    sub = p.add_subparsers(dest="command", metavar="COMMAND")

    from vcjax.experiments import EXPERIMENTS

    s = sub.add_parser("simulate", help="run one of the paper's experiments and write figures")
    s.add_argument(
        "experiment",
        choices=sorted(EXPERIMENTS),
        help="; ".join(f"{e.name}: {e.summary}" for e in EXPERIMENTS.values()),
    )
    s.add_argument("--out", help="output directory (default: out/EXPERIMENT)")
    s.add_argument(
        "--gains",
        help="JSON file of gains (e.g. the gains.json `vcjax tune` writes for the vehicle)",
    )
    s.add_argument(
        "--horizon",
        type=float,
        help="simulated time [s] ("
        + ", ".join(f"{e.name}: {e.horizon:g}" for e in EXPERIMENTS.values())
        + ")",
    )
    s.add_argument("--dt", type=float, help="RK4 step [s] (default 0.05)")
    s.add_argument(
        "--current",
        type=float,
        nargs=2,
        metavar=("V_N", "V_E"),
        help="ocean current, north and east [m/s] ("
        + ", ".join(
            f"{e.name}: {e.current[0]:g} {e.current[1]:g}"
            for e in EXPERIMENTS.values()
            if e.current
        )
        + "); not for experiments without a current",
    )
    s.add_argument(
        "--edd",
        choices=["paper", "implied"],
        help="sim1 only: which e_ddot enters psi_d_ddot (paper = reference mode; default paper)",
    )
    s.add_argument(
        "--timing",
        choices=["continuous", "sampled"],
        help="sim1 only: controller evaluated at every RK4 stage, or once per step and held "
        "(default continuous)",
    )
    s.add_argument(
        "--actuation",
        choices=["underactuated", "full"],
        help="sim2 only: headline mode (the paper: underactuated, the default); the other is "
        "run for comparison",
    )
    s.add_argument("--no-x64", dest="x64", action="store_false", help="run in float32")
    s.add_argument(
        "--diverge-e",
        type=float,
        metavar="M",
        help="sim1/sim2: a run more than M metres off the path is unhealthy (default: 25%% of "
        "u_d x horizon, at least 50 m)",
    )
    s.add_argument(
        "--waves",
        type=float,
        nargs=3,
        metavar=("HS", "TP", "DIR_DEG"),
        help="remus100/sim2: a random JONSWAP sea (64 components, long-crested): significant "
        "height HS [m], peak period TP [s], direction the waves travel towards DIR_DEG [deg, "
        "clockwise from north]",
    )
    s.add_argument(
        "--wave-seed",
        type=int,
        metavar="N",
        help="with --waves: seed of the sea's frequencies and phases (default 0)",
    )
    s.add_argument(
        "--max-steps", type=int, metavar="N", help="allow up to N steps (default 10,000,000)"
    )
    _add_overwrite(s)
    s.set_defaults(func=_cmd_simulate)

    w = sub.add_parser(
        "sweep", help="Monte-Carlo sweep of any registered closed loop (TOML; default Sim. 1)"
    )
    w.add_argument("config", help="TOML config (see examples/sweeps/)")
    w.add_argument("--out", default="out/sweep", help="output directory (default: out/sweep)")
    w.add_argument("--no-x64", dest="x64", action="store_false", help="run in float32")
    w.add_argument(
        "--netcdf",
        action="store_true",
        help='also write results.nc (labelled xarray dataset; pip install "vcjax[xarray]")',
    )
    _add_cpu_devices(w)
    _add_overwrite(w)
    _add_size_limits(w)
    w.set_defaults(func=_cmd_sweep)

    t = sub.add_parser(
        "tune", help="tune a loop's gains by gradient descent through the closed loop (TOML)"
    )
    t.add_argument("config", help="TOML config (see examples/tuning/)")
    t.add_argument("--out", default="out/tune", help="output directory (default: out/tune)")
    t.add_argument("--no-x64", dest="x64", action="store_false", help="run in float32")
    _add_cpu_devices(t)
    _add_overwrite(t)
    _add_size_limits(t)
    t.set_defaults(func=_cmd_tune)

    f = sub.add_parser(
        "fit",
        help="identify plant parameters from logged runs by multiple shooting (TOML)",
    )
    f.add_argument("config", help="TOML config (see examples/fit/)")
    f.add_argument("--out", default="out/fit", help="output directory (default: out/fit)")
    f.add_argument("--quiet", action="store_true", help="no per-iteration progress lines")
    f.add_argument("--no-x64", dest="x64", action="store_false", help="run in float32")
    f.add_argument(
        "--max-memory-gb",
        type=float,
        metavar="G",
        help="allow an estimated peak memory up to G GB (default: 80%% of the physical memory)",
    )
    _add_overwrite(f)
    f.set_defaults(func=_cmd_fit)

    d = sub.add_parser(
        "demo",
        help="generic engine demo: a two-link arm whose end effector is held on a circle",
    )
    d.add_argument("--out", default="out/demo", help="output directory (default: out/demo)")
    d.add_argument("--horizon", type=float, default=6.0, help="simulated time [s]")
    d.add_argument("--no-x64", dest="x64", action="store_false", help="run in float32")
    _add_overwrite(d)
    d.set_defaults(func=_cmd_demo)

    n = sub.add_parser(
        "launch",
        help="run `sweep` or `tune` as N local processes of one distributed JAX run",
        description="Start N local processes running `vcjax sweep|tune ...`, joined by "
        "jax.distributed (coordinator on localhost). Inside an `srun` step of SLURM it spawns "
        "nothing: each task joins the step's run through JAX's cluster auto-detection.",
    )
    n.add_argument("-n", type=int, help="number of processes (ignored under srun)")
    n.add_argument(
        "--cpu-devices",
        type=int,
        help="CPU devices per process (default: the cores divided among the processes)",
    )
    n.add_argument("--port", type=int, help="coordinator port (default: a free one)")
    n.add_argument("--timeout", type=float, help="terminate all processes after this many s (> 0)")
    n.add_argument(
        "--max-processes",
        type=int,
        metavar="N",
        help="allow up to N local processes (default: the number of usable CPU cores)",
    )
    n.add_argument("rest", nargs=argparse.REMAINDER, help="-- COMMAND [ARGS...]")
    n.set_defaults(func=_cmd_launch)
    return p


#: The subcommands that split their work across the processes of ``vcjax launch``.
_DISTRIBUTED = ("sweep", "tune")


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if not getattr(args, "func", None):
        parser.print_help()
        return 0
    args.t_start = time.perf_counter()
    from vcjax.cache import enable_compilation_cache

    enable_compilation_cache()
    if args.command != "launch":  # a process started by `vcjax launch` joins its run first
        from vcjax import distributed

        try:
            distributed.initialize_from_env()
        except (RuntimeError, ValueError) as err:
            return _fail(f"{args.command}: {err}")
    try:
        return int(args.func(args) or 0)
    except _CLIError as err:
        return _fail(f"{args.command}: {err}")
    except KeyboardInterrupt:  # a signal outside the long loops, or a second one
        print(
            f"vcjax: {args.command}: interrupted: stopped at once (the files written so far "
            "are complete; the rest are missing)",
            file=sys.stderr,
        )
        return 130
    finally:
        while _OUT:
            _OUT.pop().release()


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
