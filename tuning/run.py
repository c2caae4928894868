"""``vcjax tune CONFIG.toml --out DIR``: tune the gains of any registered loop from a TOML file.

[`run_tune_config`][tuning.run.run_tune_config] is the entry point (``vcjax tune`` calls it; it
is the one command line of the tuner). It writes into ``out_dir``:

* ``gains.json``: the tuned gains, in the loop's gains-JSON format (``loop.gains_to_json``;
  ``vcjax simulate sim1 --gains DIR/gains.json`` / ``sim2 --gains`` load it);
* ``history.json``: per iteration the training loss, gradient norm, acceptance, evaluations and
  the gains; plus the validated configuration and how the run ended;
* ``summary.json``: ``heldout_loss_before`` / ``heldout_loss_after`` (default vs tuned gains on
  the held-out batch, evaluated with the hard-clipped plant unless configured otherwise), the
  loss terms of each, the training losses, run statistics; with ``[waves]``, ``waves``: the
  realised significant height of every training and held-out sea, and
  ``heldout_surface_before`` / ``_after``: the held-out runs whose vehicle was above the local
  sea surface (``n_above_surface`` of ``n``, the largest fraction of a run, the least clearance
  [m]; a warning when there are any: outside the submerged model);
* ``loss_curve.png``, ``before_after_paths.png``, ``before_after_cross_track.png``,
  ``before_after_loss_terms.png`` (what the loss measures: path, speed and heading errors,
  actuator commands against their limits, and the weighted loss terms, default vs tuned).
"""

from __future__ import annotations

import dataclasses
import json
import sys
import time
from pathlib import Path
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from tuning.config import load_config
from tuning.loss import TERMS, TuningProblem, objective, problem_data
from tuning.loss import loss_weights as make_weights
from tuning.optim import TunerHooks, TunerOptions, run_gradient_tuner
from tuning.params import GainSpace
from tuning.report import (
    ProgressBar,
    plot_before_after,
    plot_loss_curve,
    plot_loss_terms,
)
from tuning.scenarios import (
    SCENARIO_AXES,
    Nominal,
    config_spec,
    sample_scenarios,
    shard_scenarios,
)
from tuning.spec import TuneConfig
from vcjax import loops, paths
from vcjax.config import ConfigError
from vcjax.runtime import compiler, distributed, programs
from vcjax.runtime.interrupts import stop_requested_everywhere
from vcjax.runtime.outputs import write_json_atomic

__all__ = ["build", "distribute", "run_tune_config"]


def _config(cfg) -> TuneConfig:
    """The frozen config (a plain dict of the older form, e.g. a ``run.json`` record, is read
    with [`TuneConfig.from_dict`][tuning.spec.TuneConfig.from_dict])."""
    return cfg if isinstance(cfg, TuneConfig) else TuneConfig.from_dict(cfg)


def build(cfg: TuneConfig):
    """Objects of a validated config: ``(problem, eval_problem, data, train, heldout)``."""
    cfg = _config(cfg)
    p, choice = cfg.problem, cfg.scenario
    loop = choice.loop(p.variant)
    if p.initial_gains:
        try:
            base = loop.gains_from_json(json.loads(Path(p.initial_gains).read_text()))
        except (OSError, json.JSONDecodeError, ValueError) as err:
            raise ConfigError(
                f"problem.initial_gains: cannot use {p.initial_gains}: {err}"
            ) from None
    else:
        base = loop.default_gains()
    space = GainSpace(loop=loop, tune=p.tune or None)
    num_steps = int(round(p.horizon / p.dt))
    problem = TuningProblem(
        space=space,
        num_steps=num_steps,
        integrator=p.integrator,
        timing=p.timing,
        checkpoint=p.checkpoint,
        checkpoint_every=p.checkpoint_every,
        smooth=p.smooth,
        risk=p.risk,
        alpha=p.alpha,
    )
    eval_problem = dataclasses.replace(
        problem, smooth=cfg.heldout.smooth, checkpoint=False, surface=True
    )
    dtype = jnp.asarray(jax.tree_util.tree_leaves(base)[0]).dtype
    weights = make_weights(**cfg.weights, dtype=dtype)
    data = problem_data(problem, base, weights, p.dt, p.log_box, p.box_weight)
    if cfg.train.seed == cfg.heldout.seed:
        raise ConfigError("[heldout] seed: must differ from [train] seed (held-out scenarios)")
    plant, design = choice.nominal(loop, dtype)
    spec = config_spec(cfg, loop)  # the parsed sections, as they are
    kw = dict(loop=loop, nominal=Nominal(plant, design, choice.coeffs()))
    try:
        train = sample_scenarios(cfg.train.seed, cfg.train.size, spec, **kw)
        heldout = sample_scenarios(cfg.heldout.seed, cfg.heldout.size, spec, **kw)
    except ValueError as err:
        raise ConfigError(f"scenarios: {err}") from None
    return problem, eval_problem, data, train, heldout


def _realised_hs(batch) -> list[float]:
    """Per scenario, ``4 sqrt(sum a_i^2 / 2)`` [m] of its sea (rounded to mm)."""
    a = np.asarray(batch.sea.amplitude, np.float64)
    return [round(float(h), 3) for h in 4.0 * np.sqrt(0.5 * np.sum(a * a, axis=-1))]


def _training_step(loss_fn, opts: TunerOptions, cfg, problem, start, args):
    """``(step, future)``: the training step of
    [`run_gradient_tuner`][tuning.optim.run_gradient_tuner], its batch
    ``value_and_grad`` keyed in the program store by what fixes the loss (the config, the
    gains' tiling: a warm run loads it), and for L-BFGS in a single process that program
    building in a thread (``future``; None: built at the first step)."""
    from concurrent.futures import ThreadPoolExecutor

    from tuning.optim import init_state, make_step, replicate_like

    opt = opts.optimizer_fn()
    static = ("vcjax tune", cfg.to_dict(), bool(problem.tile_gains))
    step = make_step(loss_fn, opt, opts.optimizer, opts.grad_mode, static)
    if not hasattr(step, "prebuild") or jax.process_count() > 1:
        return step, None
    theta = jnp.asarray(start)
    theta, _ = replicate_like(args, theta, init_state(opt, theta))  # as the tuner will

    def build():
        try:
            step.prebuild(theta, args)
        except Exception:  # the first step builds it again and reports any error itself
            pass

    pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix="vcjax-compile")
    future = pool.submit(build)
    pool.shutdown(wait=False)
    return step, future


def _evaluate(eval_fn, theta, data, batch) -> dict:
    loss, (losses, terms) = jax.device_get(eval_fn(theta, data, batch))
    losses = np.asarray(losses)
    out = {
        "loss": float(loss),
        "terms": {k: float(np.mean(terms[k])) for k in TERMS},
        "scenario_loss_median": float(np.median(losses)),
        "scenario_loss_max": float(np.max(losses)),
    }
    if "above_surface_fraction" in terms:  # in a sea: the runs whose vehicle broached
        above = np.asarray(terms["above_surface_fraction"], np.float64)
        out["surface"] = {
            "n_above_surface": int(np.sum(above > 0)),
            "n": int(above.size),
            "max_above_surface_fraction": float(np.max(above)),
            "min_surface_clearance_m": float(np.min(terms["min_surface_clearance"])),
        }
    return out


def _trajectory_program(problem, batch, n):
    """``(fn, sub)``: the first ``n`` scenarios of ``batch`` (``sub``) and the program
    ``fn(gains, sub, dt)`` of [`_trajectories`][tuning.run._trajectories]."""
    sub = jax.tree_util.tree_map(
        lambda ax, a: a if ax is None else jax.tree_util.tree_map(lambda x: x[:n], a),
        SCENARIO_AXES,
        batch,
        is_leaf=lambda x: x is None,
    )
    cfg = problem.rollout_config()
    loop = problem.loop

    def one(gains, s, dt):
        tr = loops.simulate(loop, gains, s, cfg, dt)
        sig = loop.signals(tr, s)
        return tr.t, sig.pos[:, :2], sig.eps, sig.u_err, sig.psi_err, sig.cmd_ratio

    return jax.vmap(one, in_axes=(None, SCENARIO_AXES, None)), sub


def _trajectories(problem, gains_list, batch, dt, n, run=None):
    """Times, and for each gains of ``gains_list`` the positions (S, N, 2) [north, east] and
    cross-track errors (S, N) of the first ``n`` scenarios of ``batch``: one program (the gains
    are its argument; ``run``: that program built already), compiled once for all of them."""
    fn, sub = _trajectory_program(problem, batch, n)
    run = compiler.jit(fn) if run is None else run
    out = []
    for gains in gains_list:
        t, xy, eps, u_err, psi_err, ratio = jax.device_get(run(gains, sub, dt))
        out.append(
            {
                "xy": np.asarray(xy),
                "e": np.asarray(eps)[..., 1],
                "eps": np.asarray(eps),
                "u_err": np.asarray(u_err),
                "psi_err": np.asarray(psi_err),
                "cmd_ratio": np.asarray(ratio),
            }
        )
    return np.asarray(t[0]), out


def _path_polyline(loop, batch, xy_before, xy_after):
    """(P, 2) points of the path over the parameter range the runs covered."""
    w = np.linspace(float(np.min(batch.varpi0)) - 5.0, float(np.max(batch.varpi0)) + 5.0, 2)
    reach = max(np.ptp(xy.reshape(-1, 2), axis=0).max() for xy in (xy_before, xy_after))
    w = np.linspace(w[0], w[1] + 2.0 * reach, 400)
    pts = jax.vmap(lambda w_: paths.path_point(loop.path, batch.path, w_))(jnp.asarray(w))
    return np.asarray(pts)[:, :2]


def distribute(train, data, theta0):
    """With more than one device in the run (several processes, or several local devices), the
    training batch is sharded along a global 1-D mesh of every device
    ([`vcjax.runtime.distributed`][vcjax.runtime.distributed]) and ``data``, ``theta0`` are
    replicated on it: each loss
    and gradient is then one SPMD computation whose batch mean reduces across devices and
    processes, equal to the single-device value. With one device, or a batch size that is not a
    multiple of the device count (padding would change the mean loss), returns the inputs
    unchanged: every process then computes the whole batch itself, with the same result.
    """
    n = jax.device_count()
    if n == 1 or int(train.eta0.shape[0]) % n:
        return train, data, theta0
    mesh = distributed.global_mesh("scenarios")
    data, theta0 = distributed.replicate((data, theta0), mesh)
    return distributed.shard_batch(train, mesh, SCENARIO_AXES), data, theta0


@dataclasses.dataclass
class _Tune:
    """What a tune run holds between its stages: the config, the problems (training, held-out),
    the data, the batches (``train``; ``train_d``, ``data_d``, ``start`` as distributed), the
    held-out evaluation and the device count of the training batch."""

    cfg: TuneConfig
    problem: Any
    eval_problem: Any
    data: Any
    train: Any
    heldout: Any
    train_d: Any = None
    data_d: Any = None
    start: Any = None
    eval_fn: Any = None
    trajectories: Any = None  # the figures' program, built with the held-out evaluation
    n_dev: int = 1
    sharded: bool = False
    robust: Any = None  # [robust]: the tuning.robust.RobustSearch


def _prepare(cfg: TuneConfig, say) -> _Tune:
    """The problem and batches of ``cfg``, the training batch distributed over the devices of the
    run ([`distribute`][tuning.run.distribute]); announces the run."""
    problem, eval_problem, data, train, heldout = build(cfg)
    # the held-out batch is evaluated by every process on its own devices; the training batch is
    # sharded over every device of the run below ([`distribute`][tuning.run.distribute])
    heldout, _ = shard_scenarios(heldout)
    n_dev = jax.device_count() if int(train.eta0.shape[0]) % jax.device_count() == 0 else 1
    space, o = problem.space, cfg.optimizer
    say(
        f"tuning {space.loop.describe()}: {space.size} parameters ({', '.join(space.tune)}), "
        f"{cfg.train.size} training / {cfg.heldout.size} held-out scenarios, "
        f"horizon {cfg.problem.horizon:g} s, {o.name} x {o.steps} steps "
        f"({o['grad_mode']} mode); training batch on {n_dev} device(s)"
    )
    t = _Tune(cfg, problem, eval_problem, data, train, heldout, n_dev=n_dev)
    t.eval_fn = compiler.jit(lambda th, d, s: objective(th, d, s, eval_problem))
    start = data.theta_ref + space.symmetry_break(data.base)
    if cfg.robust is not None:  # [robust]: a first search fills the batch's adversarial slot
        from tuning.robust import attach

        t.robust, train = attach(t, start, say, config_spec)
        t.n_dev = jax.device_count() if int(train.eta0.shape[0]) % jax.device_count() == 0 else 1
    t.train_d, t.data_d, t.start = distribute(train, data, start)
    t.sharded = t.train_d is not train
    if t.sharded:
        # gains copied per scenario: their gradient reduces across devices once, not per step
        t.problem = dataclasses.replace(problem, tile_gains=True)
    return t


def _prebuild(t: _Tune, theta0) -> None:
    """Build the held-out evaluation and the figures' trajectories now, concurrently
    (`programs.build_all`, while the training step builds in
    its thread; a warm run loads them from the program store instead of tracing them):
    ``t.eval_fn`` and ``t.trajectories`` then run them (their jitted forms for arguments of
    other shapes or placements). One process only (``vcjax launch``: as before)."""
    if jax.process_count() > 1:
        return
    static = ("vcjax tune", t.cfg.to_dict())
    evaluate = lambda th, d, s: objective(th, d, s, t.eval_problem)  # noqa: E731
    jobs = [("tune:heldout", evaluate, static, (theta0, t.data, t.heldout))]
    n_plot = min(t.cfg.report.plot_scenarios, t.cfg.heldout.size)
    if n_plot:
        fn, sub = _trajectory_program(t.eval_problem, t.heldout, n_plot)
        jobs.append(("tune:trajectories", fn, (*static, n_plot), (t.data.base, sub, t.data.dt)))
    built = programs.build_all(jobs)
    t.eval_fn = programs.for_arguments_like(built[0][0], jobs[0][3], t.eval_fn)
    if n_plot:
        t.trajectories = programs.for_arguments_like(built[1][0], jobs[1][3], compiler.jit(fn))


def _say_timing(res, say) -> None:
    """The training step's compile and per-step times, and any rejected steps."""
    walls = [h["wall_s"] for h in res.history]
    if walls:
        later = np.diff(walls)
        per = float(np.median(later)) if later.size else float("nan")
        say(
            f"training step compiled and run once in {walls[0]:.1f} s "
            f"(compiling ~{max(walls[0] - per, 0.0) if later.size else walls[0]:.1f} s); "
            + (f"then {per:.3g} s per step" if later.size else "one step only")
        )
    if res.n_bad:
        say(f"warning: {res.n_bad} step(s) rejected for non-finite loss/gradient/update")


def _train(t: _Tune, progress, say):
    """``(result, before)``: the gradient tuning of the training batch
    ([`run_gradient_tuner`][tuning.optim.run_gradient_tuner]) and the held-out evaluation of the
    default gains (run while the training step's largest program builds)."""
    cfg, problem, data = t.cfg, t.problem, t.data
    o, B, N = cfg.optimizer, cfg.train.size, problem.num_steps
    theta0 = data.theta_ref  # the default gains: what 'before' means
    say(
        f"compiling the held-out evaluation ({cfg.heldout.size} rollouts x {N} steps) "
        "and evaluating the initial gains ..."
    )
    t0 = time.perf_counter()
    loss_fn = lambda th, d, s: objective(th, d, s, problem)[0]
    opts = TunerOptions.from_section(o)
    # the training step's largest program builds in a thread while the held-out evaluation
    # compiles and runs (XLA compiles outside Python's lock)
    step, building = _training_step(loss_fn, opts, cfg, problem, t.start, (t.data_d, t.train_d))
    _prebuild(t, theta0)  # with the figures' program, while the training step builds
    before = _evaluate(t.eval_fn, theta0, data, t.heldout)
    say(
        f"held-out loss before: {before['loss']:.6g} ({time.perf_counter() - t0:.1f} s incl. "
        f"compiling); compiling the training step ({o['name']}: loss and {o['grad_mode']}-mode "
        f"gradient through {B} rollouts x {N} steps) - the first step includes it ..."
    )
    if building is not None:
        building.result()
    bar = ProgressBar(o["steps"], label="tune ", stream=progress, warmup=1) if progress else None
    if t.sharded:
        say(f"training batch sharded over {jax.device_count()} devices")
    space = problem.space
    refresh = None
    if t.robust is not None:  # [robust]: new adversarial scenarios every K steps
        from tuning.robust import hook

        refresh = hook(t, say, distribute)
    hooks = TunerHooks(
        on_step=lambda k, th, rec: {"gains": space.describe(th, data.base)},
        progress=bar,
        should_stop=stop_requested_everywhere,  # all processes stop at the same step
        refresh=refresh,
    )
    res = run_gradient_tuner(
        loss_fn, t.start, (t.data_d, t.train_d), opts, hooks=hooks, step_fn=step
    )
    if bar is not None and len(res.history) < o["steps"]:
        bar.close()
    _say_timing(res, say)
    return res, before


def _history(t: _Tune, res) -> dict:
    """``history.json``: the config, the gains' labels and initial values, the iterations."""
    space = t.problem.space
    return {
        "config": t.cfg.to_dict(),
        "labels": space.labels(),
        "initial_gains": space.loop.gains_to_json(t.data.base),
        "iterations": res.history,
        "n_bad": res.n_bad,
        "aborted": res.aborted,
        "reason": res.reason,
        "evals": res.evals,
        "rollouts": res.evals * t.cfg.train.size,
    }


def _plots(t: _Tune, res, tuned, before, after, out: Path) -> list:
    """The loss curve and (unless interrupted) the before/after figures of the first
    ``[report] plot_scenarios`` held-out scenarios; their paths."""
    o, data, heldout, space = t.cfg.optimizer, t.data, t.heldout, t.problem.space
    files = [plot_loss_curve(res.history, out / "loss_curve.png", f"{o['name']} tuning")]
    n_plot = min(t.cfg.report.plot_scenarios, t.cfg.heldout.size)
    n_plot = 0 if res.reason == "interrupted" else n_plot  # no new compiles once stopped
    if not n_plot:
        return files
    tr_time, (tr_before, tr_after) = _trajectories(
        t.eval_problem, (data.base, tuned), heldout, data.dt, n_plot, t.trajectories
    )
    currents = np.asarray(heldout.current)[:n_plot]
    path_xy = _path_polyline(space.loop, heldout, tr_before["xy"], tr_after["xy"])
    files += plot_before_after(tr_time, tr_before, tr_after, currents, out, path_xy)
    weights = {k: float(getattr(data.weights, k)) for k in TERMS}
    files.append(
        plot_loss_terms(
            tr_time,
            tr_before,
            tr_after,
            (before["terms"], after["terms"]),
            weights,
            getattr(space.loop, "actuator_names", None),
            out / "before_after_loss_terms.png",
        )
    )
    return files


def _scenario_loss(ev: dict) -> dict:
    return {"median": ev["scenario_loss_median"], "max": ev["scenario_loss_max"]}


def _summary(t: _Tune, res, before, after, t_start: float) -> dict:
    """``summary.json`` (``t_start``: ``time.perf_counter()`` when the run began)."""
    space, data, cfg = t.problem.space, t.data, t.cfg
    lb, la = before["loss"], after["loss"]
    summary = {
        "heldout_loss_before": lb,
        "heldout_loss_after": la,
        "heldout_reduction_pct": 100.0 * (lb - la) / lb if lb > 0 else None,
        "heldout_terms_before": before["terms"],
        "heldout_terms_after": after["terms"],
        "heldout_scenario_loss_before": _scenario_loss(before),
        "heldout_scenario_loss_after": _scenario_loss(after),
        "heldout_smooth_saturation": t.eval_problem.smooth,
        "train_loss_before": res.history[0]["loss"] if res.history else None,
        "train_loss_after": res.loss,
        "loop": space.loop.describe(),
        "tuned_gains": space.describe(res.theta, data.base),
        "initial_gains": space.values(data.base),
        "iterations": len(res.history),
        "n_bad": res.n_bad,
        "aborted": res.aborted,
        "reason": res.reason,
        "evals": res.evals,
        "rollouts": res.evals * cfg.train.size,
        "rollout_convention": "one batch value_and_grad = train.size rollouts (forward+backward)",
        "devices": t.n_dev,
        "tuning_wall_s": res.history[-1]["wall_s"] if res.history else 0.0,
        "total_wall_s": time.perf_counter() - t_start,
    }
    if "surface" in after:  # a sea: the held-out runs' vehicle above the local surface
        summary["heldout_surface_before"] = before["surface"]
        summary["heldout_surface_after"] = after["surface"]
    if cfg.get("waves") is not None:  # the seas trained on and held out (different keys)
        summary["waves"] = {
            "train_hs": _realised_hs(t.train),
            "heldout_hs": _realised_hs(t.heldout),
            "note": "realised significant height 4 sqrt(m0) of each scenario's sea [m]; the "
            "held-out seas are drawn from other keys than the training seas",
        }
    return summary


def run_tune_config(
    config_path, out_dir, progress=sys.stderr, cfg: TuneConfig | None = None
) -> dict:
    """Run the tuning described by the TOML file ``config_path``; write results into ``out_dir``.

    Args:
        config_path: TOML configuration (see [`tuning.config`][tuning.config]).
        out_dir: output folder (created).
        progress: text stream for the progress bar and messages (default ``sys.stderr``);
            ``None`` for silence.
        cfg: the file already parsed by [`tuning.config.load_config`][tuning.config.load_config]
            (the CLI parses it
            once and records it); default: parse ``config_path``.

    Returns:
        dict: ``{"summary": <summary.json content>, "files": [Path, ...]}``.

    Raises:
        tuning.config.ConfigError (a ``ValueError``): invalid configuration.

    The caller chooses the floating-point precision (``vcjax`` enables float64 by default).
    A run that stops after repeated non-finite steps still writes its outputs, with
    ``summary["aborted"] = True``. In a multi-process run (``vcjax launch -n N -- tune ...``)
    every process runs the same steps on its shard of the training batch
    ([`distribute`][tuning.run.distribute])
    and process 0 writes the outputs (the others return no files).
    """
    writer = jax.process_index() == 0
    progress = progress if writer else None
    say = (lambda msg: print(msg, file=progress, flush=True)) if progress else (lambda m: None)
    cfg = load_config(config_path) if cfg is None else _config(cfg)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    t_start = time.perf_counter()
    t = _prepare(cfg, say)
    res, before = _train(t, progress, say)
    say(f"stopped: {res.reason}; evaluating the tuned gains on the held-out batch ...")
    theta = jnp.asarray(np.asarray(res.theta))  # a local copy (replicated in multi-process runs)
    after = _evaluate(t.eval_fn, theta, t.data, t.heldout)
    for when, ev in (("default", before), ("tuned", after)):
        s = ev.get("surface")
        if s and s["n_above_surface"]:
            say(
                f"warning: held-out, {when} gains: in {s['n_above_surface']} of {s['n']} runs the "
                "vehicle was above the local sea surface (up to "
                f"{100 * s['max_above_surface_fraction']:.0f} % of a run, up to "
                f"{-s['min_surface_clearance_m']:.2f} m): outside the submerged model, whose "
                "losses describe no real vehicle there (summary.json heldout_surface_*); start "
                "the runs deeper"
            )
    space = t.problem.space
    tuned = space.decode(theta, t.data.base)
    gains_json = space.loop.gains_to_json(tuned)
    space.loop.gains_from_json(gains_json)  # what `vcjax simulate --gains` will do: validate
    if not writer:
        return {"summary": None, "files": []}
    write_json_atomic(out / "gains.json", gains_json)
    write_json_atomic(out / "history.json", _history(t, res), indent=1)
    files = [out / "gains.json", out / "history.json"]
    files += _plots(t, res, tuned, before, after, out)
    summary = _summary(t, res, before, after, t_start)
    if t.robust is not None:
        from tuning.robust import summarize

        summary["robust"] = summarize(t, tuned, after, out, progress, say, run_tune_config)
    if res.reason == "interrupted":  # SIGINT / SIGTERM: the best gains so far, of planned steps
        summary["interrupted"] = True
        summary["steps_planned"] = cfg.optimizer["steps"]
    write_json_atomic(out / "summary.json", summary)
    files.append(out / "summary.json")
    # the held-out change itself is the result: summary.json, and `vcjax tune`'s last line
    say(f"wrote {len(files)} files to {out}")
    return {"summary": summary, "files": files}
