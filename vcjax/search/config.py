"""``vcjax falsify CONFIG``: a sweep-style TOML file whose ranges are the envelope searched,
[`load_config`][vcjax.search.config.load_config],
[`run_falsify_config`][vcjax.search.config.run_falsify_config] (search, outputs) and
[`replay_worst`][vcjax.search.config.replay_worst].

The file is a sweep config ([`vcjax.sweep`][vcjax.sweep]: ``[scenario]``, ``[simulation]``,
``[current]``, ``[waves]``, ``[initial]``, ``[model_error]``, ``[disturbance]``,
``[metrics]``) in which every range ``[lo, hi]`` is a box searched and every number is held
fixed, with a ``[falsify]`` section instead of ``[sweep]``::

    [falsify]
    metric = "max_abs_e"      # any sweep metric of the loop (aliases: max_cross_track, ...)
    bound = 5.0               # optional: "falsified" as soon as a scenario exceeds it
    starts = 16               # int >= 1: gradient-ascent starts, run together under vmap
    steps = 20                # int >= 1: ascent steps per start (one rollout each)
    step_size = 0.05          # > 0: Adam step in the envelope's unit box
    random_rollouts = 320     # int >= 1: the random baseline (default starts x steps)
    seed = 0                  # int >= 0: starts and the scenarios' random draws
    keep = 10                 # int >= 1: scenarios written to worst.json
    controller = "vcm"        # optional: the controller ([scenario] controller otherwise)
    gradient = "auto"         # "forward", "reverse" or "auto" (forward up to 16 searched)

``--metric`` and ``--bound`` on the command line override the file's. ``metric = "loss"``
(or ``"tuning_loss"``) searches the tuning loss of one scenario (``vcjax tune``'s, with the
file's optional ``[weights]`` section, the tune's keys and defaults), simulated as the tune's
held-out batch (hard-clipped actuators).
"""

from __future__ import annotations

import json
import math
import time
from pathlib import Path

import jax
import numpy as np

from vcjax.config import ConfigError, as_choice, as_int, as_number, read_toml, unknown_key
from vcjax.search.core import FalsifyOptions, evaluate, falsify, gradient_mode, metric_name
from vcjax.search.envelope import Envelope, envelope_from_spec, setting_from_spec

__all__ = ["FALSIFY_KEYS", "KEY_DOCS", "load_config", "run_falsify_config", "replay_worst"]

#: ``[falsify]`` keys and defaults (None: no default)
FALSIFY_KEYS = {
    "metric": "max_abs_e",
    "bound": None,
    "starts": 16,
    "steps": 20,
    "step_size": 0.05,
    "random_rollouts": None,
    "seed": 0,
    "keep": 10,
    "controller": None,
    "gradient": "auto",
}

#: (section, key) -> (unit, description): the configuration reference is generated from it (the
#: other sections are a sweep's: every range is searched, every number held fixed)
KEY_DOCS: dict[tuple[str, str], tuple[str, str]] = {
    ("falsify", "metric"): ("", "sweep metric to maximise (--metric overrides)"),
    ("falsify", "bound"): ("", "falsified as soon as a scenario's metric exceeds it (--bound)"),
    ("falsify", "starts"): ("", "gradient-ascent starts, run together under vmap (int >= 1)"),
    ("falsify", "steps"): ("", "ascent steps per start, one rollout each (int >= 1)"),
    ("falsify", "step_size"): ("", "Adam step in the envelope's unit box (> 0)"),
    ("falsify", "random_rollouts"): ("", "random baseline rollouts (default starts x steps)"),
    ("falsify", "seed"): ("", "seed of the starts and of the scenarios' random draws"),
    ("falsify", "keep"): ("", "scenarios written to worst.json (int >= 1)"),
    ("falsify", "gradient"): (
        "",
        "how the ascent differentiates: forward (one tangent per searched parameter: compiles "
        "fast), reverse, or auto (forward up to 16 searched parameters)",
    ),
    ("falsify", "controller"): ("", "the controller searched ([scenario] controller otherwise)"),
}


def _falsify_section(fal, where: str, metric: str | None, bound: float | None) -> dict:
    """The ``[falsify]`` table checked, with its defaults and the command line's ``--metric``,
    ``--bound``."""
    if not isinstance(fal, dict):
        raise ConfigError(f"{where}: [falsify]: expected a table")
    unknown = sorted(set(fal) - set(FALSIFY_KEYS))
    if unknown:
        raise ConfigError(f"{where}: {unknown_key('falsify', unknown[0], FALSIFY_KEYS)}")
    opts = {**FALSIFY_KEYS, **fal}
    if metric is not None:
        opts["metric"] = metric
    if bound is not None:
        opts["bound"] = bound
    try:
        for k in ("starts", "steps", "keep"):
            opts[k] = as_int(f"[falsify] {k}", opts[k], 1)
        opts["seed"] = as_int("[falsify] seed", opts["seed"], 0)
        if opts["random_rollouts"] is not None:
            opts["random_rollouts"] = as_int(
                "[falsify] random_rollouts", opts["random_rollouts"], 1
            )
        opts["step_size"] = as_number("[falsify] step_size", opts["step_size"], lo=0, lo_open=True)
        if opts["bound"] is not None:
            opts["bound"] = as_number("[falsify] bound (--bound)", opts["bound"])
            if not math.isfinite(opts["bound"]):
                raise ConfigError(f"[falsify] bound (--bound): not finite: {opts['bound']}")
        opts["gradient"] = as_choice(
            "[falsify] gradient", opts["gradient"], ("auto", "forward", "reverse")
        )
        if not isinstance(opts["metric"], str):
            raise ConfigError(f"[falsify] metric: expected a string, got {opts['metric']!r}")
    except ConfigError as err:
        raise ConfigError(f"{where}: {err}") from None
    return opts


#: spellings of the tuning loss as a metric
LOSS_METRICS = ("loss", "tuning_loss")


def load_config(
    path, metric: str | None = None, bound: float | None = None, loss_metric=None
) -> dict:
    """Read and check a falsify config (everything, before any work or output).

    ``loss_metric(weights_table) -> SegmentMetric``: how ``metric = "loss"`` is built from the
    file's ``[weights]`` table (the CLI passes ``tuning.robust.TuningLossMetric.of_table``;
    vcjax itself never imports the tuner).

    Returns ``{"spec", "gains_path", "figures", "loop", "gains", "envelope", "setting",
    "metric", "bound", "opts"}``. Raises [`ConfigError`][vcjax.config.values.ConfigError] naming the
    file,
    section and key.
    """
    from vcjax.sweep.config import load_config as load_sweep

    path = Path(path)
    where = str(path)
    raw = read_toml(path)
    opts = _falsify_section(raw.pop("falsify", {}), where, metric, bound)
    weights = raw.pop("weights", None)
    sweep = dict(raw.get("sweep", {}))
    sweep.setdefault("num_scenarios", 1)
    sweep["seed"] = opts["seed"]
    if opts["controller"] is not None:
        sweep["variants"] = [opts["controller"]]
    raw["sweep"] = sweep
    spec, extras = load_sweep(path, raw)
    if len(spec.variants) != 1:
        raise ConfigError(
            f"{where}: a falsification searches one controller: set [scenario] controller or "
            f"[falsify] controller (one of {list(spec.variants)})"
        )
    loop = spec.loop(spec.variants[0])
    gains = loop.default_gains()
    if extras["gains"] is not None:
        try:
            gains = loop.gains_from_json(json.loads(Path(extras["gains"]).read_text()))
        except (OSError, json.JSONDecodeError, ValueError) as err:
            raise ConfigError(f"{where}: [simulation] gains: {extras['gains']}: {err}") from None
    try:
        env = envelope_from_spec(spec)
    except ValueError as err:
        raise ConfigError(f"{where}: {err}") from None
    if not env.searched:
        raise ConfigError(f"{where}: nothing to search: give at least one range [lo, hi]")
    setting = setting_from_spec(spec, env)
    m = opts["metric"]
    if m in LOSS_METRICS:
        if loss_metric is None:
            raise ConfigError(f"{where}: [falsify] metric (--metric): {m}: needs the tuner")
        try:
            m = loss_metric({} if weights is None else weights)
        except ValueError as err:
            raise ConfigError(f"{where}: {err}") from None
    elif weights is not None:
        raise ConfigError(
            f'{where}: [weights]: only with metric = "loss" (the tuning loss), '
            f"not {opts['metric']!r}"
        )
    try:
        m = metric_name(loop, gains, setting, m)
    except ValueError as err:
        raise ConfigError(f"{where}: [falsify] metric (--metric): {err}") from None
    return {
        "spec": spec,
        "gains_path": extras["gains"],
        "figures": extras["figures"],
        "loop": loop,
        "gains": gains,
        "envelope": env,
        "setting": setting,
        "metric": m,
        "bound": opts["bound"],
        "opts": opts,
    }


def run_falsify_config(cfg: dict, out_dir, progress=None) -> dict:
    """Search ([`falsify`][vcjax.search.core.falsify]) and write ``worst.json``, ``summary.json``
    and the
    figures into ``out_dir``. Returns ``{"summary", "files", "result"}``."""
    from vcjax.runtime.outputs import write_json_atomic

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    o = cfg["opts"]
    search = FalsifyOptions(
        starts=o["starts"],
        steps=o["steps"],
        step_size=o["step_size"],
        random_rollouts=o["random_rollouts"],
        bound=cfg["bound"],
        progress=progress,
        gradient=o["gradient"],
    )
    res = falsify(cfg["loop"], cfg["gains"], cfg["envelope"], cfg["metric"], cfg["setting"], search)
    files = [write_worst(res, cfg, out / "worst.json", o["keep"])]
    summary = {
        "metric": res.metric,
        "rollouts": res.rollouts,
        "random_rollouts": res.random_rollouts,
        "worst": _num(res.worst),
        "random_worst": _num(res.random_worst),
        "wall_s": res.wall_s,
        "random_wall_s": res.random_wall_s,
        "first_step_s": res.first_step_s,
        "beat_random_s": None if res.beat_random is None else res.beat_random[1],
        "beat_random_rollouts": None if res.beat_random is None else res.beat_random[0],
        "bound": res.bound,
        "falsified": res.falsified,
        "random_falsified": res.random_falsified,
        "interrupted": res.interrupted,
        "starts": o["starts"],
        "steps": o["steps"],
        "step_size": o["step_size"],
        "seed": o["seed"],
        "gradient": gradient_mode(o["gradient"], len(cfg["envelope"].searched)),
        "controller": cfg["spec"].variants[0],
        "vehicle": cfg["loop"].vehicle,
        "envelope": cfg["envelope"].as_dict(),
        "searched": list(cfg["envelope"].searched),
        "curve": _steps(res.curve),
        "random_curve": _steps(res.random_curve),
        "devices": jax.device_count(),
    }
    run, notes = None, []
    frac = lowest = None
    # the worst scenario is run again for the figures and, in a sea, to check that the vehicle
    # stayed under the surface
    if res.value.size and (cfg["figures"] or cfg["setting"].sea is not None):
        run, (frac, lowest) = _worst_run(res, cfg)
    summary["worst_above_surface_fraction"] = frac
    summary["worst_min_clearance_m"] = lowest
    if frac:
        notes.append(
            f"the worst scenario's vehicle is above the local sea surface for "
            f"{100 * frac:.3g} % of its run (up to {-lowest:.3g} m): outside the submerged "
            "model (no free surface), so its metric describes no real vehicle; narrow the "
            "envelope (deeper origin_depth, lower hs) to search where the model holds"
        )
    summary["warnings"] = notes
    files.append(write_json_atomic(out / "summary.json", summary))
    if cfg["figures"] and run is not None:
        files += figures(res, cfg, out, run)
    return {"summary": summary, "files": files, "result": res, "warnings": notes}


def _worst_run(res, cfg: dict):
    """The worst scenario's trajectory (for the figures) and ``(fraction of its run above the
    local sea surface, its least clearance below it [m])``, both None without a sea."""
    from vcjax.search.figures import worst_run

    row = res.scenarios(1)[0]
    x = cfg["envelope"].vector(row["params"])
    traj, clearance = worst_run(
        cfg["loop"], cfg["gains"], cfg["envelope"], cfg["setting"], x, row["index"]
    )
    if clearance is None:
        return traj, (None, None)
    c = clearance[1]
    return traj, (float(np.mean(c < 0.0)), float(np.min(c)))


def _steps(curve) -> list:
    """``[[rollouts, worst so far], ...]`` at each rise of the curve and its last point (the
    step function, without its flat runs)."""
    out = []
    for j, (a, b) in enumerate(curve):
        if not out or b != out[-1][1] or j == len(curve) - 1:
            out.append([int(a), _num(b)])
    return out


def _num(v):
    v = float(v)
    return v if math.isfinite(v) else None


def write_worst(res, cfg: dict, path, keep: int) -> Path:
    """``worst.json``: ``{"metric", "seed", "scenarios": [{metric: value, "params": {...},
    "index", "search", "diverged"}, ...]}`` worst first (params in config units)."""
    from vcjax.runtime.outputs import write_json_atomic

    rows = res.scenarios(keep)
    for r in rows:
        r[res.metric] = _num(r[res.metric])
    doc = {"metric": res.metric, "seed": cfg["setting"].seed, "scenarios": rows}
    return write_json_atomic(path, doc)


def figures(res, cfg: dict, out: Path, traj) -> list[Path]:
    """The worst trajectory and the search curves (``traj``: the worst scenario's
    [`worst_trajectory`][vcjax.search.figures.worst_trajectory])."""
    from vcjax.search.figures import plot_curve, plot_worst

    rows = res.scenarios(1)
    shown = ", ".join(
        f"{k} {v:.3g}" for k, v in rows[0]["params"].items() if k in cfg["envelope"].searched
    )
    title = f"worst {res.metric} = {rows[0][res.metric]:.4g} ({rows[0]['search']}): {shown}"
    return [
        plot_worst(traj, title, out / "falsify_worst.png"),
        plot_curve(res, out / "falsify_curve.png"),
    ]


def metric_label(metric) -> str:
    """The name a metric (a sweep metric's name or a ``SegmentMetric``) is reported under."""
    return metric if isinstance(metric, str) else metric.name


def read_worst(path, env: Envelope, metric) -> tuple[dict, np.ndarray, np.ndarray]:
    """``(doc, x (B, P), index (B,))`` of a ``worst.json`` (checked against the envelope's
    parameter names and the metric)."""
    path = Path(path)
    try:
        doc = json.loads(path.read_text())
    except OSError as err:
        raise ConfigError(f"--replay: cannot read {path}: {err}") from None
    except json.JSONDecodeError as err:
        raise ConfigError(f"--replay: {path}: not valid JSON: {err}") from None
    if not isinstance(doc, dict) or not isinstance(doc.get("scenarios"), list):
        raise ConfigError(f"--replay: {path}: expected {{'metric': ..., 'scenarios': [...]}}")
    if not doc["scenarios"]:
        raise ConfigError(f"--replay: {path}: no scenarios")
    if not isinstance(doc.get("seed", 0), int) or doc.get("seed", 0) < 0:
        raise ConfigError(f"--replay: {path}: seed: expected an int >= 0")
    try:
        xs, idx = [], []
        for j, s in enumerate(doc["scenarios"]):
            if not isinstance(s, dict) or not isinstance(s.get("params"), dict):
                raise ValueError(f"scenarios[{j}]: expected an object with 'params'")
            xs.append(env.vector(s["params"], f"scenarios[{j}].params"))
            idx.append(int(s.get("index", 0)))
    except (ValueError, TypeError) as err:
        raise ConfigError(f"--replay: {path}: {err}") from None
    return doc, np.stack(xs), np.asarray(idx)


def replay_worst(
    cfg: dict, worst_path, out_dir, name: str = "replay.json", every_metric: bool = False
) -> dict:
    """Run the scenarios of a ``worst.json`` again (its seed, scenario numbers and parameters)
    and write ``replay.json`` (or ``name``): ``{"metric", "seed", "scenarios": [{metric:
    value, "recorded": the value in worst.json, "params", "index", "diverged"}]}``, with
    ``every_metric`` also ``"metrics"``: every metric of the run (``vcjax sweep
    --scenario``)."""
    import dataclasses

    from vcjax.runtime.outputs import write_json_atomic

    metric = cfg["metric"]
    doc, x, idx = read_worst(worst_path, cfg["envelope"], metric)
    m_obj, metric = metric, metric_label(metric)
    setting = dataclasses.replace(cfg["setting"], seed=int(doc.get("seed", 0)))
    t0 = time.perf_counter()
    m = evaluate(cfg["loop"], cfg["gains"], cfg["envelope"], setting, m_obj, x, idx)
    rows = []
    for j, s in enumerate(doc["scenarios"]):
        rows.append(
            {
                metric: _num(m[metric][j]),
                "recorded": s.get(metric),
                "params": s["params"],
                "index": int(idx[j]),
                "diverged": bool(m["diverged"][j]),
            }
        )
        if every_metric:
            rows[-1]["metrics"] = {k: _num(v[j]) for k, v in m.items() if k != "diverged"}
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    rep = {"metric": metric, "seed": setting.seed, "scenarios": rows}
    files = [write_json_atomic(out / name, rep)]
    if cfg["figures"]:
        from vcjax.search.figures import plot_worst, worst_trajectory

        traj = worst_trajectory(cfg["loop"], cfg["gains"], cfg["envelope"], setting, x[0], idx[0])
        title = f"replay: {metric} = {rows[0][metric]}"
        files.append(plot_worst(traj, title, out / "falsify_worst.png"))
    return {"replay": rep, "files": files, "wall_s": time.perf_counter() - t0}
