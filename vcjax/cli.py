"""``vcjax`` command line: the parser and the entry point (``main``); the commands' bodies
are in [`vcjax.commands`][vcjax.commands] (``launch``, which starts processes running ``main``
again, is here).
"""

from __future__ import annotations

import argparse
import sys
import time

from vcjax import commands
from vcjax.commands import CLIError, fail, interruptible

__all__ = ["main", "build_parser"]


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


def _cmd_launch(args) -> int:
    """``vcjax launch -n N -- COMMAND ...``: N local processes of one distributed run (or, inside
    a multi-task SLURM step, this process joins the step's run and runs COMMAND itself)."""
    from vcjax.runtime import distributed

    rest = list(args.rest)
    if rest[:1] == ["--"]:
        rest = rest[1:]
    commands = list(_DISTRIBUTED)
    if not rest or rest[0] not in commands:
        got = rest[0] if rest else "nothing"
        return fail(
            f"launch: expected a command that runs across processes after --, one of {commands};"
            f" got {got}"
        )
    if distributed.in_slurm_step():
        try:
            distributed.initialize_from_env()
        except (RuntimeError, ValueError) as err:
            return fail(f"launch: cannot join the SLURM step's run: {err}")
        return main(rest)
    if args.n is None or args.n < 1:
        return fail("launch: -n N (number of processes, >= 1) is required outside SLURM")
    if args.cpu_devices is not None and args.cpu_devices < 1:
        return fail(f"launch: --cpu-devices must be >= 1, got {args.cpu_devices}")
    from vcjax.runtime.devices import usable_cores
    from vcjax.runtime.sizing import SizeError, check_launch

    try:
        check_launch(args.n, args.timeout, args.max_processes, usable_cores())
    except SizeError as err:
        return fail(f"launch: {err}")

    # the local processes share the cores: by default each splits off its share of them
    cpu = max(1, usable_cores() // args.n) if args.cpu_devices is None else args.cpu_devices
    with interruptible():  # Ctrl-C: forwarded to the processes, which keep what is done
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
        return fail(f"launch: exit codes of the {args.n} processes: {codes}")
    return 0


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


def _add_experiment_flags(p: argparse.ArgumentParser, exp, out: str) -> None:
    """The flags of one experiment ([`vcjax.experiments`][vcjax.experiments]): the common ones,
    ``--gains`` and
    ``--current`` where it takes them, and one per field of its typed options
    ([`vcjax.experiments.flags`][vcjax.experiments.base.flags])."""
    from vcjax.experiments import flags

    p.add_argument("--out", default=out, help=f"output directory (default: {out})")
    if exp.gains:
        p.add_argument(
            "--gains",
            help="JSON file of gains (e.g. the gains.json `vcjax tune` writes for the vehicle)",
        )
    p.add_argument("--horizon", type=float, help=f"simulated time [s] (default {exp.horizon:g})")
    p.add_argument("--dt", type=float, help=f"RK4 step [s] (default {exp.dt:g})")
    if exp.current is not None:
        p.add_argument(
            "--current",
            type=float,
            nargs=2,
            metavar=("V_N", "V_E"),
            help="ocean current, north and east [m/s] (default "
            f"{exp.current[0]:g} {exp.current[1]:g})",
        )
    for flag, kw in flags(exp.options):
        p.add_argument(flag, **kw)
    p.add_argument("--no-x64", dest="x64", action="store_false", help="run in float32")
    p.add_argument(
        "--max-steps", type=int, metavar="N", help="allow up to N steps (default 10,000,000)"
    )
    _add_overwrite(p)
    p.set_defaults(experiment=exp.name, func=commands.simulate)


def _add_simulate(sub) -> None:
    """``vcjax simulate NAME``: one subcommand per experiment of the registry, its flags
    generated from the experiment."""
    from vcjax.experiments import EXPERIMENTS

    s = sub.add_parser("simulate", help="run one of the paper's experiments and write figures")
    names = s.add_subparsers(dest="experiment", metavar="EXPERIMENT", required=True)
    for e in EXPERIMENTS.values():
        p = names.add_parser(e.name, help=e.summary, description=e.summary)
        _add_experiment_flags(p, e, f"out/{e.name}")


def _add_demo(sub) -> None:
    """``vcjax demo``: ``vcjax simulate arm`` writing to ``out/demo`` by default."""
    from vcjax.experiments import EXPERIMENTS

    d = sub.add_parser(
        "demo",
        help="generic engine demo: a two-link arm whose end effector is held on a circle "
        "(vcjax simulate arm)",
    )
    _add_experiment_flags(d, EXPERIMENTS["arm"], "out/demo")


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="vcjax",
        description="Differentiable simulator and gain tuner for the virtually-constrained-motion "
        "(VCM) controller of underwater vehicles.",
    )
    sub = p.add_subparsers(dest="command", metavar="COMMAND")

    _add_simulate(sub)

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
    w.add_argument(
        "--scenario",
        metavar="WORST_JSON",
        help="run exactly the scenarios of a worst.json (vcjax falsify, or a robust tune's) "
        "instead of sampling: writes scenarios.json with every metric of each",
    )
    _add_cpu_devices(w)
    _add_overwrite(w)
    _add_size_limits(w)
    w.set_defaults(func=commands.sweep)

    t = sub.add_parser(
        "tune", help="tune a loop's gains by gradient descent through the closed loop (TOML)"
    )
    t.add_argument("config", help="TOML config (see examples/tuning/)")
    t.add_argument("--out", default="out/tune", help="output directory (default: out/tune)")
    t.add_argument("--no-x64", dest="x64", action="store_false", help="run in float32")
    _add_cpu_devices(t)
    _add_overwrite(t)
    _add_size_limits(t)
    t.set_defaults(func=commands.tune)

    x = sub.add_parser(
        "falsify",
        help="search the envelope for the current, sea and start that break a controller (TOML)",
    )
    x.add_argument("config", help="sweep-style TOML config with a [falsify] section")
    x.add_argument("--out", default="out/falsify", help="output directory (default: out/falsify)")
    x.add_argument(
        "--metric",
        metavar="NAME",
        help="sweep metric to maximise (default max_abs_e), or loss: the tuning loss of one "
        "scenario with the file's [weights]",
    )
    x.add_argument(
        "--bound", type=float, metavar="X", help="stop as soon as a scenario's metric exceeds X"
    )
    x.add_argument(
        "--replay",
        metavar="WORST_JSON",
        help="run the scenarios of a worst.json again (writes replay.json) instead of searching",
    )
    x.add_argument("--no-x64", dest="x64", action="store_false", help="run in float32")
    _add_overwrite(x)
    x.set_defaults(func=commands.falsify)

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
    f.set_defaults(func=commands.fit)

    _add_demo(sub)

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
    args, extra = parser.parse_known_args(argv)
    if extra and getattr(args, "experiment", None) is not None:  # simulate NAME, demo
        return fail(commands.flags_refused(args, extra))
    if extra:
        parser.error(f"unrecognized arguments: {' '.join(extra)}")
    if not getattr(args, "func", None):
        parser.print_help()
        return 0
    args.t_start = time.perf_counter()
    from vcjax.runtime.cache import enable_compilation_cache
    from vcjax.runtime.compiler import prefer_fast_compile

    prefer_fast_compile()  # before JAX starts: XLA reads its flags once
    enable_compilation_cache()
    if args.command != "launch":  # a process started by `vcjax launch` joins its run first
        from vcjax.runtime import distributed

        try:
            distributed.initialize_from_env()
        except (RuntimeError, ValueError) as err:
            return fail(f"{args.command}: {err}")
    try:
        return int(args.func(args) or 0)
    except CLIError as err:
        return fail(f"{args.command}: {err}")
    except (AssertionError, RuntimeError):  # JAX_PLATFORMS=cuda without a GPU: one line
        from vcjax.runtime.devices import backend_error

        if (why := backend_error()) is None:
            raise
        return fail(f"{args.command}: {why}")
    except KeyboardInterrupt:  # a signal outside the long loops, or a second one
        print(
            f"vcjax: {args.command}: interrupted: stopped at once (the files written so far "
            "are complete; the rest are missing)",
            file=sys.stderr,
        )
        return 130
    finally:
        commands.release_outputs()


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
