"""The bodies of ``vcjax``'s commands ([`vcjax.cli`][vcjax.cli] parses the command line once and
dispatches here): ``simulate`` (and ``demo``, its ``arm`` experiment) through the experiments
registry, ``sweep``, ``falsify``, ``fit`` (``tune`` is the tuner's, ``tuning.command``, found
through the command seam ``vcjax.plugins``); and what they share -- preparing and locking ``--out``,
recording ``run.json``, one line and exit status 2 for a bad input
([`CLIError`][vcjax.commands.CLIError]),
interruptible long loops."""

from __future__ import annotations

import contextlib
import functools
import math
import signal
import sys
import threading
import time
from pathlib import Path

__all__ = [
    "CLIError",
    "flags_refused",
    "simulate",
    "sweep",
    "falsify",
    "fit",
    "fail",
    "release_outputs",
]


def _enable_x64(flag: bool) -> None:
    import jax

    jax.config.update("jax_enable_x64", bool(flag))


def _record(out, command: str, args, config=None, seeds=None, **wall) -> None:
    """Write ``out/run.json`` ([`vcjax.runtime.runinfo`][vcjax.runtime.runinfo]) and say so;
    ``config`` defaults to the
    parsed command-line options."""
    from vcjax.runtime.runinfo import write_run_json

    config = _args_config(args) if config is None else config
    config.pop("func", None)
    wall = {"total": time.perf_counter() - args.t_start, **wall}
    with _signals_held():  # a second Ctrl-C now cannot lose run.json or the manifest
        path = write_run_json(out, command, config=config, seeds=seeds, wall_s=wall)
        if path is not None:
            print(f"wrote {path}")
        _outputs_done()


def _args_config(args) -> dict:
    return {k: v for k, v in vars(args).items() if k != "func"}


@contextlib.contextmanager
def _signals_held():
    """SIGINT / SIGTERM held back (delivered when the block ends): for the few writes that
    must happen together (``run.json`` and the manifest). Main thread only (elsewhere: no-op)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    held = {signal.SIGINT, signal.SIGTERM}
    old = signal.pthread_sigmask(signal.SIG_BLOCK, held)
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, old)


def _config_inputs(config) -> list[str]:
    """Every existing file a TOML config names (relative to its folder, or as given): the
    command's inputs, which ``--overwrite`` must never remove (a gains file, a ``fit.json``,
    a loop module, logs ... that may sit in the folder being overwritten)."""
    import tomllib

    try:
        raw = tomllib.loads(Path(config).read_text())
    except (OSError, ValueError, TypeError):
        return []
    found: list[str] = []

    def walk(v):
        if isinstance(v, dict):
            for x in v.values():
                walk(x)
        elif isinstance(v, list):
            for x in v:
                walk(x)
        elif isinstance(v, str) and v.strip():
            for p in (Path(config).parent / v, Path(v)):
                with contextlib.suppress(OSError, ValueError):
                    if p.is_file():
                        found.append(str(p))

    walk(raw)
    return found


def _prepare(args, path, command: str, inputs=()) -> Path:
    """Check, clear (``--overwrite``) and lock ``--out``; called once every input has been
    read and checked, before any work ([`vcjax.runtime.outputs`][vcjax.runtime.outputs]).
    ``inputs``: files the
    command reads besides ``--config``/``--gains`` (never removed)."""
    from vcjax.runtime.outputs import OutputError, prepare_out

    keep = [getattr(args, k, None) for k in ("config", "gains")] + list(inputs)
    if getattr(args, "config", None):
        keep += _config_inputs(args.config)
    try:
        _OUT[:] = [prepare_out(path, getattr(args, "overwrite", False), command, keep=keep)]
    except OutputError as err:
        raise CLIError(str(err)) from None
    _OUT[0].run = (command, args)
    return _OUT[0].path


#: The output folder of the running command (``_prepare``), released when it ends.
_OUT: list = []


def _outputs_done() -> None:
    """List the files this run wrote (for a later ``--overwrite``) and release the lock."""
    if _OUT:
        _OUT[0].record_written()
        _OUT.pop().release()


def _ended_early(why: str) -> None:
    """A command that stopped before recording its run (a second Ctrl-C while figures were
    written, an error): its ``run.json`` (marked ``ended_early``) and manifest are written
    anyway, with signals held, so a later ``--overwrite`` removes exactly what it wrote."""
    if not _OUT:
        return
    d = _OUT[0]
    with _signals_held():
        try:
            if d.writer and d.written():
                from vcjax.runtime.runinfo import write_run_json

                command, args = getattr(d, "run", ("vcjax", None))
                config = _args_config(args) if args is not None else None
                wall = time.perf_counter() - args.t_start if args is not None else None
                extra = {"ended_early": why, "interrupted": True}
                write_run_json(d.path, command, config=config, wall_s=wall, extra=extra)
        except Exception:  # noqa: BLE001 - best effort: the manifest below matters more
            pass
        finally:
            d.record_written()


class CLIError(Exception):
    """A bad input of the command line: printed as one line, exit code 2."""


def _time_grid(
    horizon: float, dt: float, max_steps: int = 10_000_000, limit_option: str | None = None
) -> int:
    """Number of steps of ``horizon`` in steps of ``dt``; both finite, ``0 < dt <= horizon``.
    ``limit_option``: the command's option that raises ``max_steps`` (named in the advice; a
    command without one is not told to use it)."""
    if not (math.isfinite(horizon) and math.isfinite(dt)):
        raise CLIError(f"need finite --dt and --horizon, got dt={dt}, horizon={horizon}")
    if not (horizon > 0 and dt > 0 and horizon >= dt):
        raise CLIError(f"need 0 < dt <= horizon, got dt={dt}, horizon={horizon}")
    n = int(round(horizon / dt))
    if n > max_steps:
        raise CLIError(
            f"--horizon {horizon:g} / --dt {dt:g} = {n} steps: more than {max_steps} "
            "(the trajectory is kept in memory); use a larger --dt or a shorter --horizon"
            + (f", or raise the limit with {limit_option}" if limit_option else "")
        )
    return n


def fail(msg: str) -> int:
    print(f"vcjax: {msg}", file=sys.stderr)
    return 2


def _where(args) -> str:
    """How the errors of ``vcjax simulate NAME`` (or ``vcjax demo``) name the command."""
    return "demo" if args.command == "demo" else f"simulate {args.experiment}"


def flags_refused(args, extra: list[str]) -> str:
    """The one line refusing the flags ``extra`` that experiment ``args.experiment`` does not
    take (its flags are generated from its options, [`vcjax.experiments`][vcjax.experiments])."""
    from vcjax.experiments import EXPERIMENTS, flags

    exp = EXPERIMENTS[args.experiment]
    where = _where(args)
    flag = next((a for a in extra if a.startswith("--")), None)
    if flag is None:
        return f"{where}: unrecognized arguments: {' '.join(extra)}"
    flag = flag.split("=", 1)[0]
    if flag == "--current":
        return f"{where}: --current is not supported for {exp.name} (no ocean current)"
    if flag == "--gains":
        return f"{where}: --gains is not supported for {exp.name}"
    elsewhere = {f for e in EXPERIMENTS.values() for f, _ in flags(e.options)}
    if flag in elsewhere:
        own = ", ".join(f for f, _ in flags(exp.options)) or "none"
        return f"{where}: {flag} does not apply to {exp.name} (its own options: {own})"
    return f"{where}: unrecognized arguments: {' '.join(extra)}"


def _setup(exp, args, where: str):
    """The run's [`Setup`][vcjax.experiments.base.Setup] from the command line, every value checked
    ([`CLIError`][vcjax.commands.CLIError], one line) before anything is written."""
    current = None if exp.current is None else tuple(args.current or exp.current)
    if current is not None and not all(math.isfinite(c) for c in current):
        raise CLIError(f"{where}: --current: contains NaN or inf, got {list(current)}")
    horizon = exp.horizon if args.horizon is None else args.horizon
    dt = exp.dt if args.dt is None else args.dt
    if args.max_steps is not None and args.max_steps < 1:
        raise CLIError(f"--max-steps: expected an integer >= 1, got {args.max_steps}")
    _time_grid(horizon, dt, args.max_steps or 10_000_000, limit_option="--max-steps")
    import dataclasses

    given = {
        f.name: getattr(args, f.name)
        for f in dataclasses.fields(exp.options)
        if getattr(args, f.name) is not None
    }
    given = {k: tuple(v) if isinstance(v, list) else v for k, v in given.items()}
    setup = exp.setup(horizon, dt, current, **given)
    try:
        setup.options.check(dt, args.x64)
    except ValueError as err:
        raise CLIError(f"{where}: {err}") from None
    waves_given = getattr(setup.options, "waves", None)
    if waves_given is not None:  # beyond linear wave theory: said, not refused
        from vcjax.environment import waves

        for line in waves.envelope_warnings(waves_given[0], waves_given[1]):
            print(f"vcjax: warning: {where}: --waves: {line}", file=sys.stderr)
    return setup


def simulate(args) -> int:
    """``vcjax simulate NAME`` and ``vcjax demo`` (``simulate arm``): one experiment of the
    registry ([`vcjax.experiments`][vcjax.experiments])."""
    import json

    from vcjax.experiments import get

    exp = get(args.experiment)
    where = _where(args)
    setup = _setup(exp, args, where)
    _enable_x64(args.x64)
    gains_file = getattr(args, "gains", None)
    gains = None
    if gains_file:  # read and checked before --out is touched
        try:
            gains = exp.load_gains(json.loads(Path(gains_file).read_text()), setup.options)
        except (OSError, json.JSONDecodeError, ValueError) as err:
            return fail(f"{where}: cannot use gains file {gains_file}: {err}")
    out = _prepare(args, args.out, where)
    with _early_end():
        result = exp.run(out, gains, setup)
        if result["printed"]:
            _print_metrics(result["printed"])
        for f in result["files"]:
            print(f"wrote {f}")
    config = {
        "experiment": exp.name,
        "horizon": setup.horizon,
        "dt": setup.dt,
        "current": setup.current,
        "gains": gains_file,
        "gains_values": gains,
        "out": str(out),
        "x64": args.x64,
        **setup.options.record(),
        **result["config"],
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


def _figure_helper(figures: bool, draw):
    """A [`FigureHelper`][vcjax.plots.helper.FigureHelper] for a command that will draw
    figures with ``draw`` (a function taking ``helper=``), in a single-process run where it may
    start (None otherwise, or when it cannot)."""
    import inspect

    import jax

    from vcjax.plots import helper

    try:
        takes = "helper" in inspect.signature(draw).parameters
    except (TypeError, ValueError):
        takes = False
    if not (figures and takes) or jax.process_count() > 1 or not helper.wanted():
        return None
    try:
        return helper.FigureHelper()
    except (OSError, RuntimeError, ValueError):  # no process could start: figures drawn here
        return None


def sweep(args) -> int:
    if (rc := _use_cores(args, "sweep")) is not None:
        return rc
    _enable_x64(args.x64)
    if getattr(args, "scenario", None) is not None:
        return _sweep_scenarios(args)
    from vcjax.plots.sweep import sweep_figures as draw
    from vcjax.sweep import load_config, run_sweep_config

    try:
        spec, extras = loaded = load_config(args.config)  # parsed once, recorded in run.json
        _size_check(args, "sweep", spec=spec)
        if args.netcdf:
            from vcjax.sweep.labelled import _xr

            _xr()  # xarray missing: said before --out is touched
        if extras["gains"] is not None:
            where = f"{args.config}: [simulation] gains: {extras['gains']}"
            _check_gains_file(spec.loop(spec.variants[0]), extras["gains"], where)
    except (OSError, ValueError, ImportError) as err:
        return fail(f"sweep: {err}")
    _prepare(args, args.out, "sweep")  # every input checked: only now is --out touched
    helper = _figure_helper(extras["figures"], draw)
    if helper is not None:  # loads Matplotlib in a process of its own while the sweep compiles
        draw = functools.partial(draw, helper=helper)
    try:
        with _early_end(), interruptible():
            result = run_sweep_config(
                args.config, args.out, progress=True, netcdf=args.netcdf, loaded=loaded, draw=draw
            )
    except (OSError, ValueError, ImportError) as err:
        return fail(f"sweep: {err}")
    finally:
        if helper is not None:
            helper.close()
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
            k_up = s.get("n_above_surface", 0)
            if k_up:
                up = s["metrics"]["above_surface_fraction"]["max"]
                least = s["metrics"]["min_surface_clearance"]["min"]
                print(
                    f"vcjax: warning: sweep: {variant}: in {k_up} of {n - n_div} runs the vehicle "
                    f"was above the local sea surface (up to {100 * up:.0f} % of a run, up to "
                    f"{-least:.2f} m): outside the submerged model, whose numbers describe no "
                    "real vehicle there (above_surface_fraction, min_surface_clearance in "
                    "summary.json); start the runs deeper",
                    file=sys.stderr,
                )
    for f in result["files"]:
        print(f"wrote {f}")
    from vcjax.sweep.spec import spec_to_dict

    config = {"file": args.config, "spec": spec_to_dict(spec), **extras}  # as summary.json
    _record(args.out, "sweep", args, config=config, seeds={"sweep": spec.seed})
    if summary is not None and summary.get("interrupted"):
        return _interrupted(
            "sweep",
            f"kept the {summary['num_scenarios']} of {summary['num_scenarios_planned']} "
            f"scenarios that ran (summary.json: interrupted) in {args.out}",
        )
    return 0


def falsify(args) -> int:
    """``vcjax falsify CONFIG``: worst-case scenario search ([`vcjax.search`][vcjax.search]); with
    ``--replay worst.json``: those scenarios run again."""
    _enable_x64(args.x64)
    from vcjax.search.config import load_config, replay_worst, run_falsify_config

    try:  # everything checked before --out is touched
        cfg = load_config(
            args.config, metric=args.metric, bound=args.bound, loss_metric=_loss_metric
        )
        if args.replay is not None:
            from vcjax.search.config import read_worst

            read_worst(args.replay, cfg["envelope"], cfg["metric"])
    except (OSError, ValueError) as err:
        return fail(f"falsify: {err}")
    from vcjax.search.config import metric_label

    name = metric_label(cfg["metric"])
    out = _prepare(args, args.out, "falsify")
    record = {"file": args.config, "spec": cfg["spec"], **cfg["opts"], "metric": name}
    if args.replay is not None:
        res = replay_worst(cfg, args.replay, out)
        for s in res["replay"]["scenarios"]:
            print(f"{name} {s[name]} (recorded {s['recorded']})")
        for f in res["files"]:
            print(f"wrote {f}")
        _record(out, "falsify", args, config={**record, "replay": args.replay})
        return 0
    say = lambda line: print(f"falsify: {line}", file=sys.stderr, flush=True)
    with interruptible():
        result = run_falsify_config(cfg, out, progress=say)
    for line in result.get("warnings", ()):
        print(f"vcjax: warning: falsify: {line}", file=sys.stderr)
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


def _sweep_scenarios(args) -> int:
    """``vcjax sweep CONFIG --scenario worst.json``: the scenarios of a ``worst.json`` (their
    parameters, seed and scenario numbers) run with the config's loop, gains and settings;
    ``scenarios.json`` holds every metric of each and the value ``worst.json`` recorded."""
    import json
    from pathlib import Path

    from vcjax.search.config import load_config, metric_label, read_worst, replay_worst

    try:  # everything checked before --out is touched
        try:
            doc = json.loads(Path(args.scenario).read_text())
        except (OSError, json.JSONDecodeError) as err:
            raise ValueError(f"--scenario: {args.scenario}: {err}") from None
        metric = doc.get("metric") if isinstance(doc, dict) else None
        if not isinstance(metric, str):
            raise ValueError(f"--scenario: {args.scenario}: expected a worst.json with a metric")
        cfg = load_config(args.config, metric=metric, loss_metric=_loss_metric)
        read_worst(args.scenario, cfg["envelope"], cfg["metric"])
    except (OSError, ValueError) as err:
        return fail(f"sweep: {str(err).replace('--replay', '--scenario')}")
    out = _prepare(args, args.out, "sweep")
    cfg["figures"] = False
    res = replay_worst(cfg, args.scenario, out, name="scenarios.json", every_metric=True)
    name = metric_label(cfg["metric"])
    for s in res["replay"]["scenarios"]:
        print(f"{name} {s[name]} (recorded {s['recorded']})")
    for f in res["files"]:
        print(f"wrote {f}")
    config = {"file": args.config, "spec": cfg["spec"], "scenario": args.scenario}
    _record(out, "sweep", args, config=config, seeds={"sweep": res["replay"]["seed"]})
    return 0


#: the entry-point group of the search metrics other packages provide (``metric = "loss"``:
#: the tuner's, ``tuning.robust``); found like the commands of ``vcjax.plugins``
METRICS_GROUP = "vcjax.metrics"


def _loss_metric(weights: dict):
    """``--metric loss``: the tuning loss of one scenario with a ``[weights]`` table (the
    tuner's, found through the ``vcjax.metrics`` entry point ``loss``: vcjax never imports
    ``tuning``; loaded only when asked for)."""
    from importlib.metadata import entry_points

    eps = [ep for ep in entry_points(group=METRICS_GROUP) if ep.name == "loss"]
    if not eps:
        raise ValueError(
            f"metric loss: the tuner's metric is not installed (no '{METRICS_GROUP}' entry "
            "point 'loss': the package metadata is missing); from a source tree, run "
            "`pip install -e .`"
        )
    return eps[0].load()(weights)


def interruptible():
    """SIGINT / SIGTERM ask the running loop to stop at its next safe point and write what is
    done (``interrupt_guard``)."""
    from vcjax.runtime.interrupts import interrupt_guard

    return interrupt_guard()


def _interrupted(command: str, what: str) -> int:
    """The one line of an interrupted run; exit code 130."""
    from vcjax.runtime.interrupts import EXIT_INTERRUPTED, stop_signal

    print(f"vcjax: {command}: interrupted ({stop_signal() or 'signal'}): {what}", file=sys.stderr)
    return EXIT_INTERRUPTED


def _size_check(args, command: str, spec=None, cfg=None) -> None:
    """Refuse (ValueError, exit 2) work that cannot fit
    ([`vcjax.runtime.sizing`][vcjax.runtime.sizing]), before
    anything is compiled. Seeds were checked by the config parser against the sampler's range
    (``vcjax.config.SEED_MAX``, the same in both precisions)."""
    from vcjax.environment import waves
    from vcjax.runtime import sizing

    sizing.check_limits_options(args.max_steps, args.max_memory_gb)
    notes = []  # the sea's validity (linear theory), printed with the size's warnings
    if spec is not None:
        est = sizing.sweep_estimate(spec)
        sc = spec.scenario
        if sc.waves:
            notes = waves.envelope_warnings(sc.waves.hs, sc.waves.tp, sc.waves.origin_depth)
    else:
        est = sizing.tune_estimate(cfg)
        if wav := cfg.get("waves"):
            notes = waves.envelope_warnings(wav["hs"], wav["tp"], wav.get("origin_depth"))
    sizing.check_estimate(est, f"{args.config}", args.max_steps, args.max_memory_gb, notes)


def fit(args) -> int:
    from vcjax.runtime.sizing import check_limits_options

    try:
        check_limits_options(None, args.max_memory_gb)
    except ValueError as err:
        raise CLIError(str(err)) from None
    _enable_x64(args.x64)
    from vcjax.identify import load_fit_config, run_fit_config

    try:
        cfg = load_fit_config(args.config)  # parsed once, recorded in run.json
        _check_fit_inputs(args, cfg)
    except (OSError, ValueError) as err:
        return fail(f"fit: {err}")
    _prepare(args, args.out, "fit")  # every input checked: only now is --out touched
    print(f"fit: {args.config} (compiling the multiple-shooting Jacobian first)")
    try:
        with _early_end(), interruptible():
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


def _check_gains_file(loop, path, where: str) -> None:
    """A gains file a config names, read and checked for ``loop`` before ``--out`` is touched
    (the run reads it again; ``ValueError`` naming ``where``)."""
    import json

    try:
        loop.gains_from_json(json.loads(Path(path).read_text()))
    except (OSError, json.JSONDecodeError, ValueError) as err:
        raise ValueError(f"{where}: {err}") from None


def _check_fit_inputs(args, cfg) -> None:
    """The logs read and checked (time and angle units, sampling) and the work sized, before
    ``--out`` is touched (``fit_logs`` checks them again when it runs; both are cheap)."""
    from vcjax.identify import get_fit_model, load_log
    from vcjax.identify.checks import check_logs
    from vcjax.identify.shooting import seg_count
    from vcjax.runtime import sizing

    model = get_fit_model(cfg.model.vehicle)
    base = Path(args.config).parent
    logs = [
        load_log(base / name, model.state_columns, model.command_columns) for name in cfg.data.files
    ]
    check_logs(model, logs)
    steps = cfg.fit.segment_steps
    est = sizing.fit_estimate(seg_count(logs, steps), steps, model.n_x, len(cfg.fit.params))
    sizing.check_estimate(est, "fit", max_memory_gb=args.max_memory_gb)


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


@contextlib.contextmanager
def _early_end():
    """Around a command's work after ``_prepare``: if it ends by an exception (a second
    Ctrl-C, an error), what it wrote is recorded (``_ended_early``) before it goes on."""
    try:
        yield
    except BaseException as err:
        _ended_early(f"{type(err).__name__}: {err}".rstrip(": "))
        raise


def release_outputs() -> None:
    """Release the output folder of a command that ended early (an error, an interrupt)."""
    while _OUT:
        _OUT.pop().release()
