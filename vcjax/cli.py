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


class _CLIError(Exception):
    """A bad input of the command line: printed as one line, exit code 2."""


def _out_dir(path) -> Path:
    """Create the output directory ``path`` (and parents) or raise :class:`_CLIError`."""
    out = Path(path)
    try:
        out.mkdir(parents=True, exist_ok=True)
    except FileExistsError:
        raise _CLIError(f"--out {path}: exists and is not a directory") from None
    except OSError as err:
        raise _CLIError(f"--out {path}: cannot create the directory: {err.strerror}") from None
    if not out.is_dir():
        raise _CLIError(f"--out {path}: exists and is not a directory")
    return out


def _check_out(path) -> None:
    """Raise :class:`_CLIError` if ``path`` cannot become a directory (checked, not created):
    it, or its first existing ancestor, is not a directory."""
    p = Path(path)
    if p.exists():
        if not p.is_dir():
            raise _CLIError(f"--out {path}: exists and is not a directory")
        return
    for parent in p.parents:
        if parent.exists():
            if not parent.is_dir():
                raise _CLIError(f"--out {path}: cannot create the directory: {parent} is a file")
            return


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
            "(the trajectory is kept in memory); use a larger --dt or a shorter --horizon"
        )
    return n


def _cmd_demo(args) -> int:
    from vcjax.demos import ARM_DT

    _time_grid(args.horizon, ARM_DT)
    out = _out_dir(args.out)
    _enable_x64(args.x64)
    from vcjax.demos import arm_demo

    files = arm_demo(out, horizon=args.horizon)
    for f in files:
        print(f"wrote {f}")
    _record(out, "demo", args)
    return 0


def _fail(msg: str) -> int:
    print(f"vcjax: {msg}", file=sys.stderr)
    return 2


#: Per-experiment defaults of ``vcjax simulate`` (horizon [s], RK4 step [s]).
_SIM_DEFAULTS = {"sim1": (150.0, 0.05), "sim2": (300.0, 0.05), "remus100": (880.0, 0.05)}


def _cmd_simulate(args) -> int:
    _enable_x64(args.x64)
    horizon, dt = _SIM_DEFAULTS[args.experiment]
    horizon = horizon if args.horizon is None else args.horizon
    dt = dt if args.dt is None else args.dt
    _time_grid(horizon, dt)
    out = _out_dir(args.out or f"out/{args.experiment}")
    if args.experiment == "sim2":
        return _simulate_sim2(args, out, horizon, dt)
    if args.experiment == "remus100":
        return _simulate_remus100(args, out, horizon, dt)
    return _simulate_sim1(args, out, horizon, dt)


def _simulate_sim1(args, out: Path, horizon: float, dt: float) -> int:
    import json

    from vcjax import sim1

    gains = None
    if args.gains:
        try:
            gains = sim1.gains_from_json(json.loads(Path(args.gains).read_text()))
        except (OSError, json.JSONDecodeError, ValueError) as err:
            return _fail(f"simulate: cannot use gains file {args.gains}: {err}")
    try:
        scenario = sim1.sim1_scenario(current=args.current or (0.0, 0.5))
    except ValueError as err:
        return _fail(f"simulate: {err}")
    result = sim1.run_sim1(
        out, gains, horizon=horizon, dt=dt, edd=args.edd, timing=args.timing, scenario=scenario
    )
    _print_metrics(result["metrics"])
    for f in result["files"]:
        print(f"wrote {f}")
    config = {**vars(args), "horizon": horizon, "dt": dt, "scenario": scenario, "gains": gains}
    config.pop("func")
    _record(out, "simulate sim1", args, config=config)
    return _report_unhealthy(result["unhealthy"], dt)


def _report_unhealthy(unhealthy: dict, dt: float) -> int:
    """Print one line per unhealthy run (stderr); exit code 1 if there is any, else 0."""
    for variant, (k, t) in unhealthy.items():
        print(
            f"vcjax: UNHEALTHY RUN: {variant} diverged at step {k} (t = {t:g} s, dt {dt:g} s): "
            "its state became non-finite or left the divergence bound and was frozen there; "
            "its metrics and figures after that time are not meaningful",
            file=sys.stderr,
        )
    return 1 if unhealthy else 0


def _simulate_sim2(args, out: Path, horizon: float, dt: float) -> int:
    import json

    from vcjax import sim2

    if args.current:
        return _fail("simulate sim2: --current is not supported for Simulation 2")
    gains = None
    if args.gains:
        try:
            gains = sim2.gains_from_json(json.loads(Path(args.gains).read_text()), args.actuation)
        except (OSError, json.JSONDecodeError, ValueError) as err:
            return _fail(f"simulate sim2: cannot use gains file {args.gains}: {err}")
    result = sim2.run_sim2(out, gains, horizon=horizon, dt=dt, actuation=args.actuation)
    by_mode = result["metrics"]["by_actuation"]
    _print_metrics(
        {mode: {k: v for k, v in m.items() if _is_number(v)} for mode, m in by_mode.items()}
    )
    for f in result["files"]:
        print(f"wrote {f}")
    _record(out, "simulate sim2", args, config={**vars(args), "horizon": horizon, "dt": dt})
    unhealthy = {f"sim2 {mode}": m for mode, m in by_mode.items() if not m.get("healthy", True)}
    for name in unhealthy:
        print(f"vcjax: UNHEALTHY RUN: {name} diverged (see metrics.json)", file=sys.stderr)
    return 1 if unhealthy else 0


def _simulate_remus100(args, out: Path, horizon: float, dt: float) -> int:
    from vcjax import sim_remus100

    if args.gains:
        return _fail("simulate remus100: --gains is not supported (tune through `vcjax tune`)")
    current = tuple(args.current) if args.current else (0.0, 0.3)
    if not all(math.isfinite(c) for c in current):
        return _fail(f"simulate remus100: --current must be finite, got {current}")
    result = sim_remus100.run_remus100(out, horizon=horizon, dt=dt, current=current)
    _print_metrics(result["metrics"])
    for f in result["files"]:
        print(f"wrote {f}")
    config = {**vars(args), "horizon": horizon, "dt": dt, "current": current}
    _record(out, "simulate remus100", args, config=config)
    unhealthy = [name for name, m in result["metrics"].items() if not m.get("healthy", True)]
    for name in unhealthy:
        print(
            f"vcjax: UNHEALTHY RUN: remus100 {name}: a non-finite or runaway state, or more "
            "than 25 m off the path (see metrics.json)",
            file=sys.stderr,
        )
    return 1 if unhealthy else 0


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
    _check_out(args.out)
    if (rc := _use_cores(args, "sweep")) is not None:
        return rc
    _enable_x64(args.x64)
    from vcjax.sweep import load_config, run_sweep_config

    try:
        spec, extras = load_config(args.config)
        result = run_sweep_config(args.config, args.out, progress=True, netcdf=args.netcdf)
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
    return 0


def _cmd_tune(args) -> int:
    _check_out(args.out)
    if (rc := _use_cores(args, "tune")) is not None:
        return rc
    _enable_x64(args.x64)  # before importing tuning: sim1 builds its path constants at import
    from tuning import run_tune_config
    from tuning.config import load_config

    try:
        cfg = load_config(args.config)
        result = run_tune_config(args.config, args.out)
    except (OSError, ValueError) as err:
        return _fail(f"tune: {err}")
    for f in result["files"]:
        print(f"wrote {f}")
    seeds = {"train": cfg["train"]["seed"], "heldout": cfg["heldout"]["seed"]}
    _record(args.out, "tune", args, config={"file": args.config, **cfg}, seeds=seeds)
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
    return 0


def _cmd_fit(args) -> int:
    _check_out(args.out)
    _enable_x64(args.x64)
    from vcjax.identify import run_fit_config

    print(f"fit: {args.config} (compiling the multiple-shooting Jacobian first)")
    try:
        result = run_fit_config(args.config, args.out, progress=not args.quiet)
    except (OSError, ValueError) as err:
        return _fail(f"fit: {err}")
    fit = result["fit"]
    print(f"{'parameter':<22}{'initial':>14}{'estimate':>14}{'std':>12}")
    sections = [fit] + ([fit["current"]] if "current" in fit else [])
    for sec in sections:
        for name, value in sec["estimates"].items():
            print(f"{name:<22}{sec['initial'][name]:>14.6g}{value:>14.6g}{sec['std'][name]:>12.3g}")
    print(f"{fit['iterations']} iterations, {fit['wall_time_s']:.1f} s ({fit['reason']})")
    for w in fit["warnings"]:
        print(f"vcjax: fit: warning: {w}", file=sys.stderr)
    for f in result["files"]:
        print(f"wrote {f}")
    from vcjax.identify.config import load_fit_config

    _record(args.out, "fit", args, config={"file": args.config, **load_fit_config(args.config)})
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

    # the local processes share the cores: by default each splits off its share of them
    cpu = max(1, usable_cores() // args.n) if args.cpu_devices is None else args.cpu_devices
    codes = distributed.spawn(
        args.n,
        [sys.executable, "-m", "vcjax.cli", *rest],
        port=args.port,
        cpu_devices=cpu,
        timeout_s=args.timeout,
    )
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


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="vcjax",
        description="Differentiable simulator and gain tuner for the virtually-constrained-motion "
        "(VCM) controller of underwater vehicles.",
    )
    sub = p.add_subparsers(dest="command", metavar="COMMAND")

    s = sub.add_parser("simulate", help="run one of the paper's experiments and write figures")
    s.add_argument(
        "experiment",
        choices=sorted(_SIM_DEFAULTS),
        help="sim1: Simulation 1 (INFANTE-class, line, Figs. 4-5); "
        "sim2: Simulation 2 (ODIN-class, helix, Figs. 6-7); "
        "remus100: 3-D survey mission of the PVS REMUS 100 under a cross current",
    )
    s.add_argument("--out", help="output directory (default: out/EXPERIMENT)")
    s.add_argument(
        "--gains", help="sim1/sim2: JSON file of gains (e.g. the gains.json `vcjax tune` writes)"
    )
    s.add_argument(
        "--horizon", type=float, help="simulated time [s] (sim1: 150, sim2: 300, remus100: 880)"
    )
    s.add_argument("--dt", type=float, help="RK4 step [s] (default 0.05)")
    s.add_argument(
        "--current",
        type=float,
        nargs=2,
        metavar=("V_N", "V_E"),
        help="sim1/remus100: ocean current, north and east [m/s] (sim1: 0 0.5, along the path; "
        "remus100: 0 0.3, across the legs)",
    )
    s.add_argument(
        "--edd",
        choices=["paper", "implied"],
        default="paper",
        help="sim1: which e_ddot enters psi_d_ddot (SPEC §3; paper = reference mode)",
    )
    s.add_argument(
        "--timing",
        choices=["continuous", "sampled"],
        default="continuous",
        help="sim1: controller evaluated at every RK4 stage, or once per step and held",
    )
    s.add_argument(
        "--actuation",
        choices=["underactuated", "full"],
        default="underactuated",
        help="sim2: headline mode (the paper: underactuated); the other is run for comparison",
    )
    s.add_argument("--no-x64", dest="x64", action="store_false", help="run in float32")
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
    w.set_defaults(func=_cmd_sweep)

    t = sub.add_parser(
        "tune", help="tune a loop's gains by gradient descent through the closed loop (TOML)"
    )
    t.add_argument("config", help="TOML config (see examples/tuning/)")
    t.add_argument("--out", default="out/tune", help="output directory (default: out/tune)")
    t.add_argument("--no-x64", dest="x64", action="store_false", help="run in float32")
    _add_cpu_devices(t)
    t.set_defaults(func=_cmd_tune)

    f = sub.add_parser(
        "fit",
        help="identify plant parameters from logged runs by multiple shooting (TOML)",
    )
    f.add_argument("config", help="TOML config (see examples/fit/)")
    f.add_argument("--out", default="out/fit", help="output directory (default: out/fit)")
    f.add_argument("--quiet", action="store_true", help="no per-iteration progress lines")
    f.add_argument("--no-x64", dest="x64", action="store_false", help="run in float32")
    f.set_defaults(func=_cmd_fit)

    d = sub.add_parser(
        "demo",
        help="generic engine demo: a two-link arm whose end effector is held on a circle",
    )
    d.add_argument("--out", default="out/demo", help="output directory (default: out/demo)")
    d.add_argument("--horizon", type=float, default=6.0, help="simulated time [s]")
    d.add_argument("--no-x64", dest="x64", action="store_false", help="run in float32")
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
    n.add_argument("--timeout", type=float, help="terminate all processes after this many s")
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


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
