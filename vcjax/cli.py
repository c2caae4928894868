"""``vcjax`` command line: simulations of the paper's experiments and demos, writing figures."""

from __future__ import annotations

import argparse
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


def _cmd_simulate(args) -> int:
    _enable_x64(args.x64)
    import json

    from vcjax import sim1

    if args.experiment != "sim1":
        print(f"vcjax simulate: unknown experiment {args.experiment!r}", file=sys.stderr)
        return 2
    gains = None
    if args.gains:
        try:
            gains = sim1.gains_from_json(json.loads(Path(args.gains).read_text()))
        except (OSError, json.JSONDecodeError, ValueError) as err:
            print(f"vcjax simulate: cannot use gains file {args.gains}: {err}", file=sys.stderr)
            return 2
    try:
        scenario = sim1.sim1_scenario(V_c=args.current)
    except ValueError as err:
        print(f"vcjax simulate: {err}", file=sys.stderr)
        return 2
    result = sim1.run_sim1(
        Path(args.out),
        gains,
        horizon=args.horizon,
        dt=args.dt,
        edd=args.edd,
        timing=args.timing,
        scenario=scenario,
    )
    _print_metrics(result["metrics"])
    for f in result["files"]:
        print(f"wrote {f}")
    return 0


def _print_metrics(metrics: dict) -> None:
    keys = [k for k in next(iter(metrics.values())) if k != "healthy"]
    print("variant".ljust(14) + "".join(k.rjust(20) for k in keys))
    for name, m in metrics.items():
        print(name.ljust(14) + "".join(f"{m[k]:20.4g}" for k in keys))


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="vcjax",
        description="Differentiable simulator and gain tuner for the virtually-constrained-motion "
        "(VCM) controller of underwater vehicles.",
    )
    sub = p.add_subparsers(dest="command", metavar="COMMAND")

    s = sub.add_parser("simulate", help="run one of the paper's experiments and write figures")
    s.add_argument("experiment", choices=["sim1"], help="sim1: the paper's Simulation 1")
    s.add_argument("--out", default="out/sim1", help="output directory (default: out/sim1)")
    s.add_argument("--gains", help="JSON file of gains (e.g. written by `vcjax tune`)")
    s.add_argument("--horizon", type=float, default=150.0, help="simulated time [s]")
    s.add_argument("--dt", type=float, default=0.05, help="RK4 step [s]")
    s.add_argument(
        "--current",
        type=float,
        nargs=2,
        metavar=("V_N", "V_E"),
        default=(0.0, 0.5),
        help="ocean current, north and east [m/s] (paper: 0 0.5, along the path)",
    )
    s.add_argument(
        "--edd",
        choices=["paper", "implied"],
        default="paper",
        help="which e_ddot enters psi_d_ddot (SPEC §3; paper = reference mode)",
    )
    s.add_argument(
        "--timing",
        choices=["continuous", "sampled"],
        default="continuous",
        help="controller evaluated at every RK4 stage, or once per step and held",
    )
    s.add_argument("--no-x64", dest="x64", action="store_false", help="run in float32")
    s.set_defaults(func=_cmd_simulate)

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
