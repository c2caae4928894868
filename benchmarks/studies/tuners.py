"""Gradient tuning vs black-box tuners at equal rollout budgets (issue 6).

    python -m benchmarks.studies.tuners CONFIG.toml [--budget ROLLOUTS] [--out DIR] [--json FILE]

The tuning problem (loss, scenario distribution, training and held-out batches) comes from a
``vcjax tune`` TOML file. Tuners: the gradient tuner of the config (``[optimizer]``, L-BFGS by
default), CMA-ES (Hansen's pycma through :func:`tuning.blackbox.run_cmaes`, its default
parameters, ``sigma0`` in log-gain units, one vmapped batch per generation) and random search,
all started from the same initial gains, all minimising the same training loss.

Cost convention: one *rollout* is one scenario simulated once forward. A black-box candidate
costs ``B`` rollouts (``B`` = training batch size). A batch ``value_and_grad`` costs ``r B``
rollouts, where ``r`` = (wall time of the jitted batch value_and_grad) / (wall time of the jitted
batch forward loss), measured here (median of repeats, after compilation) and reported; on a
shared, loaded machine that ratio is noise, so ``--grad-ratio R`` fixes ``r`` to a value measured
on a quiet one (the measured value is still reported). Held-out
evaluations are measurements, not counted in the budget or in the wall-clock; compilation is
done before timing starts and excluded too (reported separately).

For each tuner the incumbent (best training loss so far) is evaluated on the held-out batch after
every iteration / generation. Reported: the best held-out loss against rollouts used and against
wall-clock (table, figure ``tuners.png``, ``--json FILE``), and how many rollouts each tuner
needed to reach CMA-ES's best held-out loss.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from tuning.blackbox import batch_objective, cmaes_popsize, run_cmaes, run_random_search
from tuning.cli import build
from tuning.config import load_config
from tuning.loss import objective
from tuning.optim import init_state, make_optimizer, make_step, run_gradient_tuner, tuner_options
from tuning.report import ProgressBar

__all__ = ["measure_grad_cost", "run_benchmark", "main"]


def _median_time(fn, repeats):
    ts = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        jax.block_until_ready(fn())
        ts.append(time.perf_counter() - t0)
    return float(np.median(ts))


def measure_grad_cost(loss_fn, theta, args, repeats: int = 5) -> dict:
    """Times of the jitted batch forward loss and batch value_and_grad; ``ratio`` = r."""
    fwd = jax.jit(loss_fn)
    vg = jax.jit(jax.value_and_grad(loss_fn))
    t0 = time.perf_counter()
    jax.block_until_ready(fwd(theta, *args))
    jax.block_until_ready(vg(theta, *args))
    compile_s = time.perf_counter() - t0
    t_f = _median_time(lambda: fwd(theta, *args), repeats)
    t_g = _median_time(lambda: vg(theta, *args), repeats)
    return {"forward_s": t_f, "value_and_grad_s": t_g, "ratio": t_g / t_f, "compile_s": compile_s}


def _first_reach(curve, target, key):
    for rec in curve:
        if rec["heldout_best"] <= target:
            return rec[key]
    return None


def run_benchmark(
    config_path,
    budget: int | None = None,
    sigma0: float = 0.5,
    radius: float = 0.5,
    seed: int = 0,
    tuners=("gradient", "cmaes", "random"),
    progress=sys.stderr,
    grad_ratio: float | None = None,
) -> dict:
    """Run the tuners on the problem of ``config_path`` with a budget of ``budget`` rollouts.

    ``budget`` defaults to 3x what the gradient tuner uses with its configured steps (it is run
    first; when it is not among ``tuners`` the default is 20 000).
    """
    say = (lambda m: print(m, file=progress, flush=True)) if progress else (lambda m: None)
    cfg = load_config(config_path)
    problem, eval_problem, data, train, heldout = build(cfg)
    B = cfg["train"]["size"]
    o = cfg["optimizer"]
    loss_fn = lambda th, d, s: objective(th, d, s, problem)[0]
    held_fn = jax.jit(lambda th: objective(th, data, heldout, eval_problem)[0])
    # every tuner starts from the default gains, split where the loss is symmetric
    theta0 = data.theta_ref + problem.space.symmetry_break(data.base.vcm)
    say("measuring the cost of a gradient relative to a forward pass (compiling) ...")
    cost = measure_grad_cost(loss_fn, theta0, (data, train))
    r = cost["ratio"] if grad_ratio is None else float(grad_ratio)
    cost["ratio_used"] = r
    say(
        f"batch forward {cost['forward_s']:.3g} s, value_and_grad {cost['value_and_grad_s']:.3g} s"
        f": one gradient = {r:.2f} forward passes"
    )
    h0 = float(held_fn(data.theta_ref))
    results = {}

    def curve_cb(tag, cum_rollouts_of):
        best = [np.inf]

        def cb(k, theta, rec):
            h = float(held_fn(jnp.asarray(theta)))
            best[0] = min(best[0], h)
            return {"rollouts": cum_rollouts_of(rec), "heldout": h, "heldout_best": best[0]}

        return cb

    if "gradient" in tuners:
        opt = make_optimizer(
            o["name"], o["learning_rate"], o["memory_size"], o["max_linesearch_steps"]
        )
        step = make_step(loss_fn, opt, o["name"], o["grad_mode"])
        say(f"gradient tuner ({o['name']}): compiling the step ...")
        t0 = time.perf_counter()
        st0 = init_state(opt, theta0)
        jax.block_until_ready(step(theta0, st0, jnp.asarray(1.0, theta0.dtype), (data, train)))
        comp = time.perf_counter() - t0
        steps = o["steps"]  # the configured steps (within the budget: history is cut at it)
        bar = ProgressBar(steps, "gradient ", progress) if progress else None
        res = run_gradient_tuner(
            loss_fn,
            theta0,
            (data, train),
            **{**tuner_options(o), "steps": steps},
            on_step=curve_cb("gradient", lambda rec: rec["cum_evals"] * r * B),
            progress=bar,
            step_fn=step,
        )
        if bar is not None:
            bar.close()
        hist = [h for h in res.history if budget is None or h["rollouts"] <= budget]
        results["gradient"] = {
            "history": hist,
            "compile_s": comp,
            "reason": res.reason,
            "n_bad": res.n_bad,
            "optimizer": o["name"],
        }
        if budget is None:
            budget = int(3 * res.history[-1]["rollouts"])
    if budget is None:
        budget = 20000
    say(f"budget: {budget} rollouts per tuner")
    f = batch_objective(loss_fn, (data, train))
    lam = cmaes_popsize(int(np.asarray(theta0).size))
    t0 = time.perf_counter()
    f(np.tile(np.asarray(theta0), (lam, 1)))
    comp_bb = time.perf_counter() - t0
    max_evals = budget // B
    for name in ("cmaes", "random"):
        if name not in tuners:
            continue
        bar = ProgressBar(max_evals // lam, f"{name} ", progress) if progress else None
        cb = curve_cb(name, lambda rec: rec["cum_evals"] * B)
        if name == "cmaes":
            res = run_cmaes(
                f,
                np.asarray(theta0),
                sigma0=sigma0,
                max_evals=max_evals,
                seed=seed,
                on_gen=cb,
                progress=bar,
            )
        else:
            res = run_random_search(
                f,
                np.asarray(theta0),
                radius=radius,
                max_evals=max_evals,
                popsize=lam,
                seed=seed,
                on_gen=cb,
                progress=bar,
            )
        results[name] = {"history": res.history, "compile_s": comp_bb}

    for v in results.values():
        hist = v["history"]
        v["best_heldout"] = min(h["heldout_best"] for h in hist) if hist else None
        v["rollouts_used"] = hist[-1]["rollouts"] if hist else 0
        v["wall_s"] = hist[-1]["wall_s"] if hist else 0.0
    target = results["cmaes"]["best_heldout"] if "cmaes" in results else None
    for v in results.values():
        v["rollouts_to_cmaes_best"] = (
            _first_reach(v["history"], target, "rollouts") if target else None
        )
        v["wall_s_to_cmaes_best"] = _first_reach(v["history"], target, "wall_s") if target else None
        for pct in REACH_PCT:  # within pct % of CMA-ES's best held-out loss
            t = target * (1 + pct / 100) if target else None
            v[f"rollouts_to_cmaes_best+{pct}%"] = (
                _first_reach(v["history"], t, "rollouts") if t else None
            )
    return {
        "config": str(config_path),
        "budget_rollouts": budget,
        "train_size": B,
        "heldout_size": cfg["heldout"]["size"],
        "grad_cost": cost,
        "heldout_initial": h0,
        "cmaes_best_heldout": target,
        "sigma0": sigma0,
        "random_radius": radius,
        "tuners": results,
    }


#: tolerances [%] above CMA-ES's best held-out loss at which "rollouts to reach" is also reported
REACH_PCT = (0.1, 1.0)


def _table(rep: dict) -> str:
    lines = [
        f"budget {rep['budget_rollouts']} rollouts/tuner; 1 gradient = "
        f"{rep['grad_cost']['ratio_used']:.2f} forward rollouts (measured here: "
        f"{rep['grad_cost']['ratio']:.2f}); held-out loss at start "
        f"{rep['heldout_initial']:.4g}",
        f"{'tuner':10s}{'best held-out':>15s}{'rollouts used':>15s}{'wall s':>9s}"
        f"{'rollouts to CMA best':>22s}{'wall s to CMA best':>20s}"
        + "".join(f"{f'to CMA best+{p}%':>18s}" for p in REACH_PCT),
    ]
    for name, v in rep["tuners"].items():
        rt = v["rollouts_to_cmaes_best"]
        wt = v["wall_s_to_cmaes_best"]
        lines.append(
            f"{name:10s}{v['best_heldout']:15.5g}{v['rollouts_used']:15.0f}{v['wall_s']:9.1f}"
            + ("-" if rt is None else f"{rt:.0f}").rjust(22)
            + ("-" if wt is None else f"{wt:.1f}").rjust(20)
            + "".join(
                ("-" if (x := v[f"rollouts_to_cmaes_best+{p}%"]) is None else f"{x:.0f}").rjust(18)
                for p in REACH_PCT
            )
        )
    return "\n".join(lines)


def _figure(rep: dict, path: Path) -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(1, 2, figsize=(11, 4))
    for name, v in rep["tuners"].items():
        h = v["history"]
        x = [0] + [r["rollouts"] for r in h]
        w = [0] + [r["wall_s"] for r in h]
        y = [rep["heldout_initial"]] + [r["heldout_best"] for r in h]
        ax[0].step(x, y, where="post", label=name)
        ax[1].step(w, y, where="post", label=name)
    for a, xl in zip(ax, ("rollouts (forward-pass equivalents)", "wall-clock [s]"), strict=True):
        if rep["cmaes_best_heldout"] is not None:
            a.axhline(rep["cmaes_best_heldout"], color="k", ls=":", lw=1, label="CMA-ES best")
        a.set(xlabel=xl, ylabel="best held-out loss", yscale="log")
        a.grid(True, which="both", alpha=0.3)
        a.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def main(argv=None) -> int:
    doc = __doc__.split("\n")[0]
    ap = argparse.ArgumentParser(prog="python -m benchmarks.studies.tuners", description=doc)
    ap.add_argument("config", help="vcjax tune TOML file (problem, batches, gradient optimiser)")
    ap.add_argument("--budget", type=int, help="rollouts per tuner (default: 3x the gradient's)")
    ap.add_argument("--sigma0", type=float, default=0.5, help="CMA-ES initial step (log-gains)")
    ap.add_argument("--radius", type=float, default=0.5, help="random-search radius (log-gains)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--tuners", default="gradient,cmaes,random")
    ap.add_argument("--out", default="out/tuners", help="folder of the figure")
    ap.add_argument("--json", help="write the full report as JSON to this file")
    ap.add_argument(
        "--grad-ratio",
        type=float,
        help="cost of a batch gradient in forward rollouts (default: measured here)",
    )
    ap.add_argument("--no-x64", dest="x64", action="store_false")
    args = ap.parse_args(argv)
    jax.config.update("jax_enable_x64", bool(args.x64))
    rep = run_benchmark(
        args.config,
        args.budget,
        args.sigma0,
        args.radius,
        args.seed,
        tuple(args.tuners.split(",")),
        grad_ratio=args.grad_ratio,
    )
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    fig = _figure(rep, out / "tuners.png")
    print(_table(rep))
    print(f"wrote {fig}")
    if args.json:
        Path(args.json).write_text(json.dumps(rep, indent=1) + "\n")
        print(f"wrote {args.json}")
    return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
