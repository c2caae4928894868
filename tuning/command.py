"""``vcjax tune``: the tuner's command, plugged into ``vcjax``'s command line through the
``vcjax.commands`` entry point (``pyproject.toml``: ``tune = "tuning.command:COMMAND"``; the
seam is ``vcjax.plugins``), so that ``vcjax`` never imports ``tuning``.

Importing this module is cheap (it runs for every ``vcjax`` invocation): the tuner itself is
imported by [`tune`][tuning.command.tune], once the precision is chosen.
"""

from __future__ import annotations

import argparse

from vcjax.plugins import (
    Command,
    add_cpu_devices,
    add_overwrite,
    add_size_limits,
    check_gains_file,
    early_end,
    enable_x64,
    fail,
    interrupted,
    interruptible,
    prepare,
    record,
    size_check,
    use_cores,
)

__all__ = ["COMMAND", "add_arguments", "tune"]


def add_arguments(t: argparse.ArgumentParser) -> None:
    """The arguments of ``vcjax tune``."""
    t.add_argument("config", help="TOML config (see examples/tuning/)")
    t.add_argument("--out", default="out/tune", help="output directory (default: out/tune)")
    t.add_argument("--no-x64", dest="x64", action="store_false", help="run in float32")
    add_cpu_devices(t)
    add_overwrite(t)
    add_size_limits(t)


def tune(args: argparse.Namespace) -> int:
    """Run ``vcjax tune CONFIG`` ([`run_tune_config`][tuning.run.run_tune_config]): every input
    checked before ``--out`` is touched, the files written, ``run.json``, the held-out change;
    returns the exit status (2: a bad input, 1: aborted, 130: interrupted)."""
    if (rc := use_cores(args, "tune")) is not None:
        return rc
    enable_x64(args.x64)  # before importing the tuner: the loops build their constants at import
    from tuning import run_tune_config
    from tuning.config import load_config
    from tuning.report import change_text

    try:
        cfg = load_config(args.config)  # parsed once, recorded in run.json
        size_check(args, "tune", cfg=cfg)
        if cfg.problem.initial_gains:
            loop = cfg.scenario.loop(cfg.problem.variant)
            where = f"problem.initial_gains: cannot use {cfg.problem.initial_gains}"
            check_gains_file(loop, cfg.problem.initial_gains, where)
    except (OSError, ValueError) as err:
        return fail(f"tune: {err}")
    prepare(args, args.out, "tune")  # every input checked: only now is --out touched
    try:
        with early_end(), interruptible():
            result = run_tune_config(args.config, args.out, cfg=cfg)
    except (OSError, ValueError) as err:
        return fail(f"tune: {err}")
    for f in result["files"]:
        print(f"wrote {f}")
    seeds = {"train": cfg.train.seed, "heldout": cfg.heldout.seed}
    record(args.out, "tune", args, config={"file": args.config, **cfg.to_dict()}, seeds=seeds)
    summary = result["summary"]
    if summary is None:  # processes other than 0 of a multi-process run
        return 0
    before, after = summary.get("heldout_loss_before"), summary.get("heldout_loss_after")
    if before is not None and after is not None:
        print(f"held-out loss: {before:.4g} -> {after:.4g} ({change_text(before, after)})")
    if summary.get("aborted"):
        return fail(f"tune: aborted: {summary.get('reason', 'non-finite steps')}")
    if summary.get("interrupted"):
        return interrupted(
            "tune",
            f"after {summary['iterations']} of {summary['steps_planned']} steps; wrote the best "
            f"gains so far, the history and summary.json (interrupted) to {args.out}",
        )
    return 0


#: what the ``vcjax.commands`` entry point ``tune`` names
COMMAND = Command(
    name="tune",
    help="tune a loop's gains by gradient descent through the closed loop (TOML)",
    add_arguments=add_arguments,
    run=tune,
    distributed=True,
)
