"""Time to target: gradient tuning (L-BFGS, Adam) against CMA-ES, Bayesian optimisation and
random search, held-out loss against wall-clock seconds (compile included) and rollouts.

    python -m benchmarks.studies.tuners CONFIG.toml [--tuners lbfgs,adam,cmaes,bayes,random]
        [--seconds S] [--rollouts R] [--warm] [--out DIR] [--json FILE] [--merge FILE] [--quick]

The tuning problem (loss, scenario distribution, training and held-out batches) is a ``vcjax
tune`` TOML file (``examples/tuning/``); one problem per run. Every tuner starts from the same
gains (:meth:`tuning.params.GainSpace.start`) and minimises the same training loss, evaluated the
same way: a batch of ``B`` scenarios simulated by one vmapped, jitted rollout, and for the
black-box tuners a whole generation of candidates in one call (:mod:`tuning.blackbox`,
:mod:`tuning.bayes`), so each gets the same hardware advantage.

* ``lbfgs``, ``adam``: the gradient tuner of :mod:`tuning.optim` (the config's ``[optimizer]``
  settings, only the name changed; ``gradient``: the config's optimiser as it is);
* ``cmaes``: pycma, its default parameters, ``sigma0`` in log-gain units (``--sigma0``);
* ``bayes``: optuna's TPE over the problem's ``log_box`` around the start, as many candidates
  per batch as CMA-ES's population;
* ``random``: random search, radius ``--radius`` (log-gains), same batch size.

Each tuner runs in a fresh Python process, with the XLA CPU code generator ``vcjax tune`` uses
(:func:`vcjax.runtime.compiler.prefer_fast_compile`) and its own, initially empty, JAX
compilation cache (``cold``: compile included, as a first run costs); with ``--warm`` it runs a
second time on the cache its first run filled (``warm``: what a user re-running the same problem
waits). The clock
starts after the problem is built and the held-out evaluation is compiled, and stops while the
incumbent (lowest training loss so far; the iterate for the gradient tuners) is evaluated on the
held-out batch after every step / generation: what is timed is the tuner, its compilation
included. Rollouts: a candidate costs ``B``; a batch ``value_and_grad`` is counted as ``B``
rollouts too (forward and backward: one L-BFGS or Adam evaluation; ``--grad-ratio R`` counts it
as ``R B``, e.g. its measured cost in forward passes). ``--budget`` is ``--rollouts``.

The target is the lowest held-out loss any tuner reached (any cache); the table gives each
tuner's time and rollouts to within 1 % and 5 % of it, or "not reached". Writes ``tuners.png``
into ``--out`` and the whole report with ``--json``. ``--quick`` (the smoke test): every tuner in
this one process, two steps / generations each, cold only.

``--merge FILE`` adds the runs of an earlier report (its ``--json``) of the same problem and
settings to this one's: the config file (and its contents, where the earlier report recorded
them), budgets, gradient counting, precision, seeds and steps must agree (refused otherwise,
before any work). A tuner run now replaces its earlier run, the others are kept, and the target
and table are those of all of them: one tuner can be (re-)measured without running the others
again. The earlier report's machine load is kept beside this one's (``merged``).
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

TUNERS = ("lbfgs", "adam", "cmaes", "bayes", "random", "gradient")
#: the gradient tuners (``gradient``: the config's own ``[optimizer]``, name included)
GRADIENT = ("lbfgs", "adam", "gradient")
#: what ``--tuners`` runs by default
DEFAULT_TUNERS = ("lbfgs", "adam", "cmaes", "bayes", "random")
#: tolerances [%] above the target at which the time / rollouts to reach it are reported
REACH_PCT = (1.0, 5.0)
#: steps given to the gradient tuner (it stops on the time or rollout budget first)
_MANY = 1_000_000

__all__ = [
    "TUNERS",
    "GRADIENT",
    "DEFAULT_TUNERS",
    "REACH_PCT",
    "run_tuner",
    "run_study",
    "summarise",
    "main",
]


def run_tuner(
    config,
    tuner: str,
    seconds: float,
    rollouts: int | None = None,
    sigma0: float = 0.5,
    radius: float = 0.5,
    seed: int = 0,
    max_steps: int | None = None,
    grad_ratio: float = 1.0,
    grad_mode: str | None = None,
) -> dict:
    """Run one tuner on the problem of ``config`` in this process; its curve of held-out loss
    against the tuner's own wall clock (compile included, held-out evaluations excluded) and
    rollouts (a batch ``value_and_grad`` counted as ``grad_ratio`` rollouts per scenario).
    Stops at ``seconds``, ``rollouts``, or ``max_steps`` steps / generations. ``grad_mode``
    (``"reverse"`` / ``"forward"``) replaces the config's for the gradient tuners."""
    import jax
    import jax.numpy as jnp
    import numpy as np

    from tuning.blackbox import batch_objective, cmaes_popsize, run_cmaes, run_random_search
    from tuning.config import load_config
    from tuning.loss import objective
    from tuning.optim import run_gradient_tuner, tuner_options
    from tuning.run import build

    if tuner not in TUNERS:
        raise ValueError(f"tuner: unknown {tuner!r}; expected one of {list(TUNERS)}")
    cfg = load_config(config)
    problem, eval_problem, data, train, heldout = build(cfg)
    B = cfg.train.size
    space = problem.space
    theta0 = space.start(data.base)
    held = jax.jit(lambda th: objective(th, data, heldout, eval_problem)[0])
    h0 = float(held(theta0))  # compiled before the clock starts
    curve = [{"wall_s": 0.0, "rollouts": 0, "heldout": h0, "heldout_best": h0}]
    clock = {"start": time.perf_counter(), "paused": 0.0, "rollouts": 0, "steps": 0}

    def elapsed():
        return time.perf_counter() - clock["start"] - clock["paused"]

    def record(theta, used):
        t = elapsed()
        t_in = time.perf_counter()
        h = float(held(jnp.asarray(np.asarray(theta))))
        h = h if np.isfinite(h) else float("inf")
        best = min(curve[-1]["heldout_best"], h)
        curve.append({"wall_s": t, "rollouts": int(used), "heldout": h, "heldout_best": best})
        clock["rollouts"], clock["steps"] = used, clock["steps"] + 1
        clock["paused"] += time.perf_counter() - t_in

    def stop():
        return (
            elapsed() >= seconds
            or (rollouts is not None and clock["rollouts"] >= rollouts)
            or (max_steps is not None and clock["steps"] >= max_steps)
        )

    loss_fn = lambda th, d, s: objective(th, d, s, problem)[0]
    info: dict = {}
    if tuner in GRADIENT:
        opts = {**tuner_options(cfg.optimizer), "steps": _MANY}
        opts["optimizer"] = opts["optimizer"] if tuner == "gradient" else tuner
        opts["grad_mode"] = grad_mode or opts["grad_mode"]
        # keyed in the program store as `vcjax tune` keys it: a warm run loads, not traces
        opts["program_static"] = ("tuner study", cfg.to_dict(), opts["grad_mode"])
        res = run_gradient_tuner(
            loss_fn,
            theta0,
            (data, train),
            **opts,
            on_step=lambda k, th, rec: record(th, round(rec["cum_evals"] * B * grad_ratio)),
            should_stop=stop,
        )
        info = {"optimizer": opts["optimizer"], "grad_mode": opts["grad_mode"]}
        info.update(reason=res.reason, n_bad=res.n_bad)
        info["evals"] = res.evals
    else:
        f = batch_objective(loss_fn, (data, train), static=("tuner study", cfg.to_dict()))
        lam = cmaes_popsize(space.size)
        cb = lambda g, th, rec: record(th, rec["cum_evals"] * B)
        common = dict(max_evals=_MANY, seed=seed, on_gen=cb, should_stop=stop)
        if tuner == "cmaes":
            res = run_cmaes(f, np.asarray(theta0), sigma0=sigma0, **common)
        elif tuner == "random":
            res = run_random_search(f, np.asarray(theta0), radius=radius, popsize=lam, **common)
        else:
            from tuning.bayes import run_bayes

            box = float(cfg.problem.log_box)
            res = run_bayes(f, np.asarray(theta0), box=box, popsize=lam, **common)
        info = {"popsize": lam, "evals": res.evals}
    first = curve[1]["wall_s"] if len(curve) > 1 else None
    return {
        "tuner": tuner,
        "curve": curve,
        "first_step_s": first,  # compile + one step / generation
        "wall_s": curve[-1]["wall_s"],
        "rollouts": curve[-1]["rollouts"],
        "best_heldout": curve[-1]["heldout_best"],
        "parameters": space.size,
        "train_size": B,
        **info,
    }


def _worker_cmd(args, tuner, out):
    cmd = [sys.executable, "-m", "benchmarks.studies.tuners", str(args.config)]
    cmd += ["--_worker", tuner, "--_result", str(out), "--seconds", str(args.seconds)]
    cmd += ["--sigma0", str(args.sigma0), "--radius", str(args.radius), "--seed", str(args.seed)]
    if args.rollouts is not None:
        cmd += ["--rollouts", str(args.rollouts)]
    cmd += ["--grad-ratio", str(args.grad_ratio)]
    if args.grad_mode:
        cmd += ["--grad-mode", args.grad_mode]
    if not args.x64:
        cmd.append("--no-x64")
    return cmd


def run_study(args, say=lambda m: None) -> dict:
    """Every tuner of ``args.tuners`` in a fresh process each (cold cache, then warm with
    ``--warm``); the raw runs, keyed ``{cache: {tuner: run}}``."""
    from tuning.config import load_config

    load_config(args.config)  # a config error here, before any process starts
    caches = ("cold", "warm") if args.warm else ("cold",)
    runs: dict = {c: {} for c in caches}
    with tempfile.TemporaryDirectory(prefix="vcjax-tuners-") as tmp:
        for tuner in args.tuners:
            cache_dir = Path(tmp) / f"cache-{tuner}"  # empty at the cold run
            for c in caches:
                out = Path(tmp) / f"{tuner}-{c}.json"
                env = {**os.environ, "VCJAX_CACHE_DIR": str(cache_dir)}
                env["PYTHONPATH"] = os.environ.get("PYTHONPATH") or str(Path.cwd())
                say(f"{tuner} ({c} cache): a fresh process, {args.seconds:g} s budget ...")
                t0 = time.perf_counter()
                r = subprocess.run(_worker_cmd(args, tuner, out), env=env)
                if r.returncode:
                    raise RuntimeError(f"{tuner} ({c}): the worker exited {r.returncode}")
                runs[c][tuner] = json.loads(out.read_text())
                runs[c][tuner]["process_s"] = time.perf_counter() - t0
                say(
                    f"  best held-out {runs[c][tuner]['best_heldout']:.6g} after "
                    f"{runs[c][tuner]['wall_s']:.1f} s, {runs[c][tuner]['rollouts']} rollouts"
                )
    return runs


def _read_merge(path: Path) -> dict:
    try:
        rep = json.loads(path.read_text())
    except (OSError, ValueError) as err:
        raise ValueError(f"--merge: cannot read {path}: {err}") from None
    if not isinstance(rep, dict) or not isinstance(rep.get("runs"), dict):
        raise ValueError(f"--merge: {path} is not a report of this study (no 'runs')")
    return rep


def summarise(runs: dict) -> dict:
    """Target (lowest held-out loss of any run), and per cache and tuner the wall-clock seconds
    and rollouts to within each :data:`REACH_PCT` of it, and the ratios of the gradient
    tuners' times to the black-box tuners' at 1 % (``tuning.report.time_to_target``)."""
    from tuning.report import time_to_target  # (JAX is set up by main first)

    return time_to_target(runs, REACH_PCT, GRADIENT)


def _fmt(x, spec):
    return "not reached" if x is None else format(x, spec)


def table_text(rep: dict) -> str:
    s = rep["summary"]
    lines = [
        f"{rep['config']}: target (lowest held-out loss of any tuner) {s['target']:.6g}; "
        f"budget {rep['seconds']:g} s per tuner; machine load {rep['load']}",
        f"{'cache':6s}{'tuner':8s}{'best held-out':>14s}{'1st step s':>11s}"
        + "".join(f"{f's to {p:g}%':>13s}{f'rollouts {p:g}%':>15s}" for p in REACH_PCT),
    ]
    for c, rows in s["table"].items():
        for name, row in rows.items():
            lines.append(
                f"{c:6s}{name:8s}{row['best_heldout']:14.6g}{_fmt(row['first_step_s'], '.1f'):>11s}"
                + "".join(
                    f"{_fmt(row[f'wall_s_to_{p:g}%'], '.1f'):>13s}"
                    f"{_fmt(row[f'rollouts_to_{p:g}%'], 'd'):>15s}"
                    for p in REACH_PCT
                )
            )
    for k, v in s["ratios_wall_s_to_1%"].items():
        lines.append(f"time ratio {k}: {_fmt(v, '.3f')}")
    return "\n".join(lines)


def figure(rep: dict, path: Path) -> Path:
    """Best held-out loss so far against wall-clock seconds and against rollouts."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(1, 2, figsize=(12, 4.5))
    colors = {}
    for c, by_tuner in rep["runs"].items():
        for name, r in by_tuner.items():
            x = [p["wall_s"] for p in r["curve"]]
            n = [p["rollouts"] for p in r["curve"]]
            y = [p["heldout_best"] for p in r["curve"]]
            kw = {"where": "post", "ls": "-" if c == "cold" else "--"}
            if name in colors:
                kw["color"] = colors[name]
            (line,) = ax[0].step(x, y, label=f"{name} ({c})", **kw)
            colors[name] = line.get_color()
            if c == "cold":
                ax[1].step(n, y, label=name, where="post", color=colors[name])
    tgt = rep["summary"]["target"]
    for a, xl in zip(ax, ("wall-clock [s], compile included", "rollouts"), strict=True):
        for p, ls in zip(REACH_PCT, (":", "-."), strict=True):
            a.axhline(tgt * (1 + p / 100), color="k", ls=ls, lw=0.8, label=f"target +{p:g} %")
        a.set(xlabel=xl, ylabel="best held-out loss so far", yscale="log")
        a.grid(True, which="both", alpha=0.3)
    B = next(iter(next(iter(rep["runs"].values())).values()))["train_size"]
    ax[1].set_xscale("symlog", linthresh=B)  # one batch linear, then decades
    ax[1].set_xlim(left=0)
    ax[0].legend(fontsize=7, ncol=2)
    ax[1].legend(fontsize=7)
    fig.suptitle(f"{rep['config']} (load {rep['load']})", fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def _load() -> str:
    try:
        return " ".join(f"{x:.2f}" for x in os.getloadavg()) + f" on {os.cpu_count()} cores"
    except OSError:  # pragma: no cover
        return "unknown"


def _parser():
    doc = __doc__.split("\n")[0]
    ap = argparse.ArgumentParser(prog="python -m benchmarks.studies.tuners", description=doc)
    ap.add_argument("config", type=Path, help="vcjax tune TOML file (the problem)")
    ap.add_argument(
        "--tuners",
        default=",".join(DEFAULT_TUNERS),
        help=f"subset of {','.join(TUNERS)} (gradient: the config's [optimizer])",
    )
    ap.add_argument("--seconds", type=float, default=60.0, help="wall-clock budget per tuner")
    ap.add_argument(
        "--rollouts", "--budget", type=int, help="rollout budget per tuner (default: none)"
    )
    ap.add_argument(
        "--grad-ratio",
        type=float,
        default=1.0,
        help="rollouts one batch value_and_grad counts as, per scenario (default 1)",
    )
    ap.add_argument(
        "--grad-mode",
        choices=("reverse", "forward"),
        help="gradient mode of lbfgs/adam/gradient (default: the config's)",
    )
    ap.add_argument("--warm", action="store_true", help="also a second, warm-cache run each")
    ap.add_argument("--sigma0", type=float, default=0.5, help="CMA-ES initial step (log-gains)")
    ap.add_argument("--radius", type=float, default=0.5, help="random-search radius (log-gains)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--out", type=Path, default=Path("out/tuners"), help="folder of the figure")
    ap.add_argument("--json", type=Path, help="write the whole report as JSON to this file")
    ap.add_argument(
        "--merge", type=Path, help="add the runs of an earlier --json report of the same problem"
    )
    ap.add_argument("--quick", action="store_true", help="smoke test: one process, 2 steps each")
    ap.add_argument("--no-x64", dest="x64", action="store_false", help="float32")
    ap.add_argument("--_worker", help=argparse.SUPPRESS)
    ap.add_argument("--_result", type=Path, help=argparse.SUPPRESS)
    return ap


def main(argv=None) -> int:
    args = _parser().parse_args(argv)
    say = lambda m: print(m, file=sys.stderr, flush=True)
    args.tuners = tuple(t for t in args.tuners.split(",") if t)
    bad = [t for t in args.tuners if t not in TUNERS]
    if bad or not args.tuners:
        say(f"tuners: unknown {bad}; expected a comma-separated subset of {','.join(TUNERS)}")
        return 2
    if not args.config.is_file():
        say(f"config: no such file {args.config}")
        return 2
    if not (args.seconds > 0):
        say(f"--seconds: expected > 0, got {args.seconds}")
        return 2
    if args._worker or args.quick:
        from vcjax.runtime.compiler import prefer_fast_compile

        prefer_fast_compile()  # what `vcjax tune` does, before JAX starts (XLA reads it once)
        import jax

        jax.config.update("jax_enable_x64", bool(args.x64))
    if args._worker:  # one tuner, in this fresh process
        from vcjax.runtime.cache import enable_compilation_cache

        enable_compilation_cache()
        r = run_tuner(
            args.config, args._worker, args.seconds, args.rollouts, args.sigma0, args.radius,
            args.seed, grad_ratio=args.grad_ratio, grad_mode=args.grad_mode,
        )  # fmt: skip
        args._result.write_text(json.dumps(r) + "\n")
        return 0
    load = _load()
    rep = {
        "config": str(args.config),
        "config_sha256": hashlib.sha256(args.config.read_bytes()).hexdigest(),
        "tuners": list(args.tuners),
        "seconds": args.seconds,
        "rollouts_budget": args.rollouts,
        "grad_ratio": args.grad_ratio,
        "grad_mode": args.grad_mode,
        "x64": args.x64,
        "load": load,
        "sigma0": args.sigma0,
        "random_radius": args.radius,
        "seed": args.seed,
    }
    try:
        earlier = None
        if args.merge is not None:
            if args.quick:
                raise ValueError("--merge: a --quick run is not a measurement to merge")
            from tuning.report import merge_runs

            earlier = _read_merge(args.merge)
            merge_runs(earlier, {**rep, "runs": {}})  # the settings agree: before any work
        if args.quick:
            runs = {"cold": {}}
            for t in args.tuners:
                runs["cold"][t] = run_tuner(
                    args.config, t, args.seconds, args.rollouts, args.sigma0, args.radius,
                    args.seed, max_steps=2, grad_ratio=args.grad_ratio,
                    grad_mode=args.grad_mode,
                )  # fmt: skip
        else:
            runs = run_study(args, say)
    except ValueError as err:  # a config error, before any tuning
        say(f"tuners: {err}")
        return 2
    rep["load_after"] = _load()
    rep["runs"] = runs
    if earlier is not None:
        rep["runs"] = merge_runs(earlier, rep)
        rep["tuners"] = list(dict.fromkeys([*earlier.get("tuners", []), *args.tuners]))
        rep["merged"] = {
            "file": str(args.merge),
            "tuners": earlier.get("tuners"),
            "load": earlier.get("load"),
            "load_after": earlier.get("load_after"),
        }
    rep["summary"] = summarise(rep["runs"])
    args.out.mkdir(parents=True, exist_ok=True)
    fig = figure(rep, args.out / "tuners.png")
    print(table_text(rep))
    print(f"wrote {fig}")
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(rep, indent=1) + "\n")
        print(f"wrote {args.json}")
    return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
