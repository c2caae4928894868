"""``vcjax`` command line: simulations of the paper's experiments and demos, writing figures."""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

__all__ = ["main"]


def _enable_x64(flag: bool) -> None:
    import jax

    jax.config.update("jax_enable_x64", bool(flag))


def _cmd_demo(args) -> int:
    _enable_x64(args.x64)
    from vcjax.demos import arm_demo

    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    files = arm_demo(out, horizon=args.horizon)
    for f in files:
        print(f"wrote {f}")
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
    if not (horizon > 0 and dt > 0 and horizon >= dt):
        return _fail(f"simulate: need 0 < dt <= horizon, got dt={dt}, horizon={horizon}")
    out = Path(args.out or f"out/{args.experiment}")
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
    return 0


def _simulate_sim2(args, out: Path, horizon: float, dt: float) -> int:
    from vcjax import sim2

    for flag, value in (("--gains", args.gains), ("--current", args.current)):
        if value:
            return _fail(f"simulate sim2: {flag} is not supported for Simulation 2")
    result = sim2.run_sim2(out, horizon=horizon, dt=dt, actuation=args.actuation)
    by_mode = result["metrics"]["by_actuation"]
    _print_metrics(
        {mode: {k: v for k, v in m.items() if _is_number(v)} for mode, m in by_mode.items()}
    )
    for f in result["files"]:
        print(f"wrote {f}")
    return 0


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
    return 0


def _is_number(v) -> bool:
    return isinstance(v, int | float) and not isinstance(v, bool)


def _use_cores(args, command: str) -> int | None:
    """Split the host CPU into devices (before JAX initialises); a bad count is one line."""
    from vcjax.devices import use_cpu_cores

    try:
        use_cpu_cores(args.cpu_devices)
    except ValueError as err:
        return _fail(f"{command}: {err}")
    return None


def _cmd_sweep(args) -> int:
    if (rc := _use_cores(args, "sweep")) is not None:
        return rc
    _enable_x64(args.x64)
    from vcjax.sweep import run_sweep_config

    try:
        result = run_sweep_config(args.config, args.out, progress=True)
    except (OSError, ValueError) as err:
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
            e = s.get("metrics", {}).get("ss_abs_e", {})
            if e:
                print(
                    f"{variant:<14} ss_abs_e median {e['p50']:.3g} m, p95 {e['p95']:.3g} m; "
                    f"diverged {s.get('n_diverged', 0)} of {s.get('n', '?')}"
                )
    for f in result["files"]:
        print(f"wrote {f}")
    return 0


def _cmd_tune(args) -> int:
    if (rc := _use_cores(args, "tune")) is not None:
        return rc
    _enable_x64(args.x64)  # before importing tuning: sim1 builds its path constants at import
    from tuning.cli import run_tune_config

    try:
        result = run_tune_config(args.config, args.out)
    except (OSError, ValueError) as err:
        return _fail(f"tune: {err}")
    for f in result["files"]:
        print(f"wrote {f}")
    summary = result["summary"]
    before, after = summary.get("heldout_loss_before"), summary.get("heldout_loss_after")
    if before is not None and after is not None:
        print(
            f"held-out loss: {before:.4g} -> {after:.4g} ({100 * (1 - after / before):.1f} % lower)"
        )
    if summary.get("aborted"):
        return _fail(f"tune: aborted: {summary.get('reason', 'non-finite steps')}")
    return 0


def _cmd_fit(args) -> int:
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
    return 0


def _print_metrics(metrics: dict) -> None:
    """A table: one row per variant, one column per numeric metric."""
    keys = [k for k, v in next(iter(metrics.values())).items() if _is_number(v)]
    widths = [max(len(k), 10) + 2 for k in keys]
    print("variant".ljust(14) + "".join(k.rjust(w) for k, w in zip(keys, widths, strict=True)))
    for name, m in metrics.items():
        cells = (f"{m[k]:{w}.4g}" for k, w in zip(keys, widths, strict=True))
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
    s.add_argument("--gains", help="sim1: JSON file of gains (e.g. written by `vcjax tune`)")
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

    w = sub.add_parser("sweep", help="Monte-Carlo sweep of Simulation 1 scenarios (TOML)")
    w.add_argument("config", help="TOML config (see examples/sweeps/)")
    w.add_argument("--out", default="out/sweep", help="output directory (default: out/sweep)")
    w.add_argument("--no-x64", dest="x64", action="store_false", help="run in float32")
    _add_cpu_devices(w)
    w.set_defaults(func=_cmd_sweep)

    t = sub.add_parser(
        "tune", help="tune the VCM gains by gradient descent through the closed loop (TOML)"
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
    return p


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if not getattr(args, "func", None):
        parser.print_help()
        return 0
    return int(args.func(args) or 0)


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
