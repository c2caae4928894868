"""The bodies of ``vcjax``'s commands (:mod:`vcjax.cli` parses the command line once and
dispatches here): ``simulate`` through the experiments registry, ``sweep``, ``tune``, ``fit``,
``demo``; and what they share -- preparing and locking ``--out``, recording ``run.json``, one
line and exit status 2 for a bad input (:class:`CLIError`), interruptible long loops."""

from __future__ import annotations

import math
import sys
import time
from pathlib import Path

__all__ = [
    "CLIError",
    "demo",
    "simulate",
    "sweep",
    "falsify",
    "tune",
    "fit",
    "fail",
    "release_outputs",
]


def _enable_x64(flag: bool) -> None:
    import jax

    jax.config.update("jax_enable_x64", bool(flag))


def _record(out, command: str, args, config=None, seeds=None, **wall) -> None:
    """Write ``out/run.json`` (:mod:`vcjax.runtime.runinfo`) and say so; ``config`` defaults to the
    parsed command-line options."""
    from vcjax.runtime.runinfo import write_run_json

    config = {k: v for k, v in vars(args).items() if k != "func"} if config is None else config
    config.pop("func", None)
    wall = {"total": time.perf_counter() - args.t_start, **wall}
    path = write_run_json(out, command, config=config, seeds=seeds, wall_s=wall)
    if path is not None:
        print(f"wrote {path}")
    _outputs_done()


def _prepare(args, path, command: str) -> Path:
    """Check, clear (``--overwrite``) and lock ``--out`` before any work
    (:mod:`vcjax.runtime.outputs`)."""
    from vcjax.runtime.outputs import OutputError, prepare_out

    try:
        inputs = [getattr(args, k, None) for k in ("config", "gains")]  # never removed
        _OUT[:] = [prepare_out(path, getattr(args, "overwrite", False), command, keep=inputs)]
    except OutputError as err:
        raise CLIError(str(err)) from None
    return _OUT[0].path


#: The output folder of the running command (:func:`_prepare`), released when it ends.
_OUT: list = []


def _outputs_done() -> None:
    """List the files this run wrote (for a later ``--overwrite``) and release the lock."""
    if _OUT:
        _OUT[0].record_written()
        _OUT.pop().release()


class CLIError(Exception):
    """A bad input of the command line: printed as one line, exit code 2."""


def _time_grid(horizon: float, dt: float, max_steps: int = 10_000_000) -> int:
    """Number of steps of ``horizon`` in steps of ``dt``; both finite, ``0 < dt <= horizon``."""
    if not (math.isfinite(horizon) and math.isfinite(dt)):
        raise CLIError(f"need finite --dt and --horizon, got dt={dt}, horizon={horizon}")
    if not (horizon > 0 and dt > 0 and horizon >= dt):
        raise CLIError(f"need 0 < dt <= horizon, got dt={dt}, horizon={horizon}")
    n = int(round(horizon / dt))
    if n > max_steps:
        raise CLIError(
            f"--horizon {horizon:g} / --dt {dt:g} = {n} steps: more than {max_steps} "
            "(the trajectory is kept in memory); use a larger --dt or a shorter --horizon, "
            "or raise the limit with --max-steps"
        )
    return n


def demo(args) -> int:
    from vcjax.experiments import ARM

    _time_grid(args.horizon, ARM.dt)
    out = _prepare(args, args.out, "demo")
    _enable_x64(args.x64)
    files = ARM.load().arm_demo(out, horizon=args.horizon)
    for f in files:
        print(f"wrote {f}")
    _record(out, "demo", args)
    return 0


def fail(msg: str) -> int:
    print(f"vcjax: {msg}", file=sys.stderr)
    return 2


#: options of ``vcjax simulate`` that only some experiments take (Experiment.options)
_OWN_OPTIONS = ("edd", "timing", "actuation", "diverge_e", "waves", "wave_seed")


def _check_waves(args, where: str, dt: float) -> None:
    """``--waves HS TP DIR_DEG`` and ``--wave-seed`` of ``vcjax simulate`` (one line, exit 2)."""
    from vcjax.runtime import sizing

    if args.wave_seed is not None:
        if args.waves is None:
            raise CLIError(f"{where}: --wave-seed needs --waves HS TP DIR_DEG")
        try:
            sizing.check_seed("--wave-seed", args.wave_seed, args.x64)
        except ValueError as err:
            raise CLIError(f"{where}: {err}") from None
    if args.waves is None:
        return
    hs, tp, direction = args.waves
    if not all(math.isfinite(v) for v in args.waves):
        raise CLIError(f"{where}: --waves: contains NaN or inf, got {list(args.waves)}")
    if hs < 0:
        raise CLIError(f"{where}: --waves: HS must be >= 0 [m], got {hs:g}")
    if tp < 40.0 * dt:
        raise CLIError(
            f"{where}: --waves: TP must be >= 40 dt = {40.0 * dt:g} s (the shortest component, "
            f"TP / 4, needs 10 steps), got {tp:g}"
        )


def simulate(args) -> int:
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
            return fail(f"{where}: {flag} does not apply to {exp.name} (its own options: {takes})")
    if args.current is not None and exp.current is None:
        return fail(f"{where}: --current is not supported for {exp.name} (no ocean current)")
    if args.gains is not None and not exp.gains:
        return fail(f"{where}: --gains is not supported for {exp.name}")
    current = None if exp.current is None else tuple(args.current or exp.current)
    if current is not None and not all(math.isfinite(c) for c in current):
        return fail(f"{where}: --current: contains NaN or inf, got {list(current)}")
    horizon = exp.horizon if args.horizon is None else args.horizon
    dt = exp.dt if args.dt is None else args.dt
    if args.max_steps is not None and args.max_steps < 1:
        raise CLIError(f"--max-steps: expected an integer >= 1, got {args.max_steps}")
    _time_grid(horizon, dt, args.max_steps or 10_000_000)
    if args.diverge_e is not None and not (math.isfinite(args.diverge_e) and args.diverge_e > 0):
        raise CLIError(f"--diverge-e: expected a finite bound > 0 [m], got {args.diverge_e:g}")
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
            return fail(f"{where}: cannot use gains file {args.gains}: {err}")
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
    from vcjax.runtime import distributed
    from vcjax.runtime.devices import use_cpu_cores

    try:
        use_cpu_cores(args.cpu_devices)
    except ValueError as err:
        return fail(f"{command}: {err}")
    distributed.warm_up()  # a multi-process run: collectives ready before anyone compiles
    return None


def sweep(args) -> int:
    _prepare(args, args.out, "sweep")
    if (rc := _use_cores(args, "sweep")) is not None:
        return rc
    _enable_x64(args.x64)
    from vcjax.plots.sweep import sweep_figures as draw
    from vcjax.sweep import load_config, run_sweep_config

    try:
        spec, extras = loaded = load_config(args.config)  # parsed once, recorded in run.json
        _size_check(args, "sweep", spec=spec)
        with interruptible():
            result = run_sweep_config(
                args.config, args.out, progress=True, netcdf=args.netcdf, loaded=loaded, draw=draw
            )
    except (OSError, ValueError, ImportError) as err:
        return fail(f"sweep: {err}")
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


def falsify(args) -> int:
    """``vcjax falsify CONFIG``: worst-case scenario search (:mod:`vcjax.search`); with
    ``--replay worst.json``: those scenarios run again."""
    _enable_x64(args.x64)
    from vcjax.search.config import load_config, replay_worst, run_falsify_config

    try:  # everything checked before --out is touched
        cfg = load_config(args.config, metric=args.metric, bound=args.bound)
        if args.replay is not None:
            from vcjax.search.config import read_worst

            read_worst(args.replay, cfg["envelope"], cfg["metric"])
    except (OSError, ValueError) as err:
        return fail(f"falsify: {err}")
    out = _prepare(args, args.out, "falsify")
    record = {"file": args.config, "spec": cfg["spec"], **cfg["opts"], "metric": cfg["metric"]}
    if args.replay is not None:
        res = replay_worst(cfg, args.replay, out)
        for s in res["replay"]["scenarios"]:
            print(f"{cfg['metric']} {s[cfg['metric']]} (recorded {s['recorded']})")
        for f in res["files"]:
            print(f"wrote {f}")
        _record(out, "falsify", args, config={**record, "replay": args.replay})
        return 0
    say = lambda line: print(f"falsify: {line}", file=sys.stderr, flush=True)
    with interruptible():
        result = run_falsify_config(cfg, out, progress=say)
    s = result["summary"]
    print(
        f"worst {s['metric']}: gradient search {s['worst']} ({s['rollouts']} rollouts, "
        f"{s['wall_s']:.1f} s), random sampling {s['random_worst']} "
        f"({s['random_rollouts']} rollouts, {s['random_wall_s']:.1f} s)"
    )
    if s["bound"] is not None:
        print(f"bound {s['bound']:g}: " + ("FALSIFIED" if s["falsified"] else "not exceeded"))
    for f in result["files"]:
        print(f"wrote {f}")
    _record(out, "falsify", args, config=record, seeds={"falsify": cfg["opts"]["seed"]})
    if s["interrupted"]:
        return _interrupted("falsify", f"kept what was found (summary.json: interrupted) in {out}")
    return 0


def interruptible():
    """SIGINT / SIGTERM ask the running loop to stop at its next safe point and write what is
    done (:func:`vcjax.runtime.interrupts.interrupt_guard`)."""
    from vcjax.runtime.interrupts import interrupt_guard

    return interrupt_guard()


def _interrupted(command: str, what: str) -> int:
    """The one line of an interrupted run; exit code 130."""
    from vcjax.runtime.interrupts import EXIT_INTERRUPTED, stop_signal

    print(f"vcjax: {command}: interrupted ({stop_signal() or 'signal'}): {what}", file=sys.stderr)
    return EXIT_INTERRUPTED


def _size_check(args, command: str, spec=None, cfg=None) -> None:
    """Refuse (ValueError, exit 2) work that cannot fit or seeds the PRNG cannot take
    (:mod:`vcjax.runtime.sizing`), before anything is compiled."""
    from vcjax.runtime import sizing

    sizing.check_limits_options(args.max_steps, args.max_memory_gb)
    if spec is not None:
        sizing.check_seed(f"{args.config}: [sweep] seed", spec.seed, args.x64)
        est = sizing.sweep_estimate(spec)
    else:
        for sec in ("train", "heldout"):
            sizing.check_seed(f"{args.config}: {sec}.seed", cfg[sec]["seed"], args.x64)
        est = sizing.tune_estimate(cfg)
    sizing.check_estimate(est, f"{args.config}", args.max_steps, args.max_memory_gb)


def tune(args) -> int:
    _prepare(args, args.out, "tune")
    if (rc := _use_cores(args, "tune")) is not None:
        return rc
    _enable_x64(args.x64)  # before importing tuning: sim1 builds its path constants at import
    from tuning import run_tune_config
    from tuning.config import load_config

    try:
        cfg = load_config(args.config)  # parsed once, recorded in run.json
        _size_check(args, "tune", cfg=cfg)
        with interruptible():
            result = run_tune_config(args.config, args.out, cfg=cfg)
    except (OSError, ValueError) as err:
        return fail(f"tune: {err}")
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
        return fail(f"tune: aborted: {summary.get('reason', 'non-finite steps')}")
    if summary.get("interrupted"):
        return _interrupted(
            "tune",
            f"after {summary['iterations']} of {summary['steps_planned']} steps; wrote the best "
            f"gains so far, the history and summary.json (interrupted) to {args.out}",
        )
    return 0


def fit(args) -> int:
    _prepare(args, args.out, "fit")
    from vcjax.runtime.sizing import check_limits_options

    try:
        check_limits_options(None, args.max_memory_gb)
    except ValueError as err:
        raise CLIError(str(err)) from None
    _enable_x64(args.x64)
    from vcjax.identify import load_fit_config, run_fit_config

    print(f"fit: {args.config} (compiling the multiple-shooting Jacobian first)")
    try:
        cfg = load_fit_config(args.config)  # parsed once, recorded in run.json
        with interruptible():
            result = run_fit_config(
                args.config,
                args.out,
                progress=not args.quiet,
                cfg=cfg,
                max_memory_gb=args.max_memory_gb,
            )
    except (OSError, ValueError) as err:
        return fail(f"fit: {err}")
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


def release_outputs() -> None:
    """Release the output folder of a command that ended early (an error, an interrupt)."""
    while _OUT:
        _OUT.pop().release()
