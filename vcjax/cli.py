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


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="vcjax",
        description="Differentiable simulator and gain tuner for the virtually-constrained-motion "
        "(VCM) controller of underwater vehicles.",
    )
    sub = p.add_subparsers(dest="command", metavar="COMMAND")

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
