"""Gradient scenario search ([`falsify`][vcjax.search.core.falsify]): multi-start projected gradient
ascent of a sweep
metric over an [`Envelope`][vcjax.search.envelope.Envelope], with plain random sampling of the same
envelope as its baseline, and [`evaluate`][vcjax.search.core.evaluate] (the metric of given
parameter vectors: a
replay)."""

from __future__ import annotations

import dataclasses
import functools
import time
from collections.abc import Callable
from typing import Any, NamedTuple, Protocol

import jax
import jax.numpy as jnp
import numpy as np

from vcjax.metrics import metric_names, metrics_finalize, metrics_init, metrics_update, window_start
from vcjax.rollout import Reduction
from vcjax.runtime import compiler
from vcjax.runtime.interrupts import stop_requested
from vcjax.search.envelope import Envelope, Setting, make_setting, scenario_from
from vcjax.sweep.run import _act_names, check_act_names, simulate_scenario

__all__ = [
    "ALIASES",
    "FalsifyOptions",
    "FalsifyResult",
    "SegmentMetric",
    "falsify",
    "evaluate",
    "gradient_mode",
    "FORWARD_MAX",
    "AscentSpec",
    "metric_name",
    "soft_metric",
]

#: other spellings of the sweep metrics
ALIASES = {
    "max_cross_track": "max_abs_e",
    "rms_cross_track": "rms_cross_track_e",
    "rms_depth": "rms_depth_err",
    "max_dist": "max_dist_3d",
    "rms_dist": "rms_dist_3d",
}
#: power of the power-mean surrogate of a max metric: ``(mean x^p)^(1/p)`` (smooth, <= max)
SHARPNESS = 16.0
_FLOOR = -1.0e6  # log-domain stand-in for an empty or masked sample (finite: no NaN gradients)


class SegmentMetric(Protocol):
    """A metric of one rollout that is not a sweep metric (e.g. the tuning loss:
    ``tuning.robust.TuningLossMetric``), folded segment by segment like the sweep metrics.

    A hashable, frozen object (it is a static argument of the compiled search): ``name`` (the
    key it is reported under), ``init(dtype)`` (an accumulator pytree), ``update(acc, seg,
    sig, ks)`` (fold the segment's [`Trajectory`][vcjax.rollout.Trajectory] ``seg``, its
    [`Signals`][vcjax.loops.types.Signals] ``sig`` and its (L,) step indices ``ks``),
    ``value(acc, n)`` (the () metric after ``n`` steps). A smooth metric: its gradient is
    ascended as is.
    """

    name: str

    def init(self, dtype) -> Any: ...

    def update(self, acc, seg, sig, ks) -> Any: ...

    def value(self, acc, n: int) -> Any: ...


def _name(metric) -> str:
    return metric if isinstance(metric, str) else metric.name


def metric_name(loop, gains, setting: Setting, name):
    """The sweep metric ``name`` (or an alias of ``ALIASES``) of ``loop``'s metrics
    (``ValueError`` listing them); a [`SegmentMetric`][vcjax.search.core.SegmentMetric] is
    returned as it is."""
    if not isinstance(name, str):
        if not all(hasattr(name, a) for a in ("name", "init", "update", "value")):
            raise ValueError(f"metric: expected a metric name or a SegmentMetric, got {name!r}")
        return name
    env = Envelope.build(loop, {})
    sc = scenario_from(jnp.asarray(env.lo), 0, env, dataclasses.replace(setting, sea=None))
    from vcjax.sweep.run import to_scenario

    s = to_scenario(
        loop, sc, *setting.nominal, dataclasses.replace(setting.config, model_fields=())
    )
    valid = metric_names(_act_names(loop, gains, s))
    m = ALIASES.get(name, name)
    if m not in valid:
        raise ValueError(f"metric: unknown metric {name!r}; choose among {list(valid)}")
    return m


def soft_metric(name: str) -> bool:
    """Whether ``name`` is a maximum (searched through its power-mean surrogate)."""
    return name.startswith("max_")


def _metrics(x, index, gains, env: Envelope, setting: Setting, metric, sharpness: float):
    """``(surrogate, metrics)`` of one scenario: the metrics of a streamed rollout and, for a
    max metric, its power mean over the same samples (else the metric itself); a
    [`SegmentMetric`][vcjax.search.core.SegmentMetric] is added to the metrics under its
    name."""
    custom = not isinstance(metric, str)
    loop, config = setting.loop, setting.config
    sc = scenario_from(x, index, env, setting)
    n = config.num_steps
    k0 = window_start(n, 1.0 - config.tail)
    dtype = x.dtype
    p = sharpness

    def reduction(s):
        names = _act_names(loop, gains, s)

        def update(acc, seg, ks):
            macc, soft, healthy, cacc = acc
            sig = loop.signals(seg, s)
            check_act_names(loop, sig, names)
            macc = metrics_update(macc, sig, seg.finite, ks, k0)
            if custom:
                cacc = metric.update(cacc, seg, sig, ks)
            elif soft_metric(metric):
                if metric == "max_abs_e":
                    a, mask = jnp.abs(sig.eps[:, 1]), jnp.ones(ks.shape, bool)
                elif metric == "max_dist_3d":
                    a, mask = jnp.sqrt(jnp.sum(sig.p_err**2, axis=1) + 1e-30), ks >= k0
                else:
                    a, mask = sig.act[metric.removeprefix("max_abs_")], jnp.ones(ks.shape, bool)
                la = jnp.where(mask, p * jnp.log(jnp.abs(a) + 1e-30), _FLOOR)
                soft = jnp.logaddexp(soft, jax.scipy.special.logsumexp(la))
            return (macc, soft, healthy & seg.healthy, cacc), None

        cacc = metric.init(dtype) if custom else ()
        init = (metrics_init(names, dtype), jnp.asarray(_FLOOR, dtype), jnp.array(True), cacc)
        L = min(100, n)
        return Reduction(init, update, L)

    (acc, _), _ = simulate_scenario(loop, gains, setting.nominal, sc, config, setting.dt, reduction)
    macc, soft, healthy, cacc = acc
    m = metrics_finalize(macc, n, k0, jnp.asarray(setting.dt, dtype), setting.diverge_e)
    m["diverged"] = m["diverged"] | ~healthy
    if custom:
        m[metric.name] = surrogate = metric.value(cacc, n)
    elif soft_metric(metric):
        count = n - k0 if metric == "max_dist_3d" else n
        surrogate = jnp.exp((soft - jnp.log(count)) / p)
    else:
        surrogate = m[metric]
    return surrogate, m


#: ``mode = "auto"`` differentiates in forward mode up to this many searched parameters
FORWARD_MAX = 16


def gradient_mode(mode: str, searched: int) -> str:
    """``"forward"`` or ``"reverse"``: the mode that differentiates a search of ``searched``
    parameters (``mode``: ``"auto"``, ``"forward"`` or ``"reverse"``). Forward mode carries
    one tangent per searched parameter through the rollout (a program about as large as the
    forward one: it compiles several times faster than the reverse pass on a CPU, and runs in
    a few forward rollouts' time for a handful of parameters); reverse mode costs a few
    rollouts whatever their number, but its program stores the rollout's intermediates and
    compiles slowly. ``"auto"``: forward up to ``FORWARD_MAX`` searched parameters."""
    if mode not in ("auto", "forward", "reverse"):
        raise ValueError(f"gradient: expected 'auto', 'forward' or 'reverse', got {mode!r}")
    if mode == "auto":
        return "forward" if searched <= FORWARD_MAX else "reverse"
    return mode


class AscentSpec(NamedTuple):
    """What the ascent differentiates, and how (static: part of the program's key).

    Attributes:
        metric: the metric (a name or a [`SegmentMetric`][vcjax.search.core.SegmentMetric]);
        sharpness: power of a max metric's power-mean surrogate;
        axes: the searched parameters' indices (the others' gradient entries are zeros);
        mode: ``"forward"`` or ``"reverse"`` ([`gradient_mode`][vcjax.search.core.gradient_mode]).
    """

    metric: Any
    sharpness: float
    axes: tuple[int, ...]
    mode: str


@functools.partial(compiler.jit, static_argnames=("env", "setting", "how"))
def _value_and_grad(z, index, gains, nom, env, setting, how: AscentSpec):
    """Batched: the surrogate's gradient in unit coordinates along ``how.axes`` (zeros
    elsewhere) and the true metrics, in forward or reverse mode."""
    setting = dataclasses.replace(setting, nominal=nom)
    axes = jnp.asarray(how.axes, jnp.int32)

    def one(z1, i):
        def f(zs):  # the searched coordinates only
            zz = z1.at[axes].set(zs)
            return _metrics(env.from_unit(zz), i, gains, env, setting, how.metric, how.sharpness)

        if not how.axes:  # a point envelope: nothing to differentiate
            return f(z1[axes])[1], jnp.zeros_like(z1)
        if how.mode == "forward":
            gs, m = jax.jacfwd(f, has_aux=True)(z1[axes])
        else:
            (_, m), gs = jax.value_and_grad(f, has_aux=True)(z1[axes])
        return m, jnp.zeros_like(z1).at[axes].set(gs)

    return jax.vmap(one)(z, index)


@functools.partial(compiler.jit, static_argnames=("env", "setting", "metric"))
def _forward(x, index, gains, nom, env, setting, metric):
    setting = dataclasses.replace(setting, nominal=nom)
    return jax.vmap(lambda x1, i: _metrics(x1, i, gains, env, setting, metric, SHARPNESS)[1])(
        x, index
    )


def _key(setting: Setting):
    """The static part of a setting (its nominal arrays travel as an argument)."""
    return dataclasses.replace(setting, nominal=None)


def evaluate(loop, gains, env: Envelope, setting: Setting, metric, x, index) -> dict:
    """The metrics (name -> (B,) numpy) of parameter vectors ``x`` (B, P) in config units with
    the random draws of scenarios ``index`` (B,): e.g. a replay of ``worst.json``."""
    x = jnp.asarray(np.asarray(x, dtype=float), _dtype(setting))
    index = jnp.asarray(index, jnp.int32)
    out = _forward(x, index, gains, setting.nominal, env, _key(setting), metric)
    return {k: np.asarray(v) for k, v in jax.device_get(out).items()}


def _dtype(setting: Setting):
    return jnp.asarray(jax.tree_util.tree_leaves(setting.nominal)[0]).dtype


def _rank(v) -> np.ndarray:
    """A metric for ranking: NaN (a run that blew up) counts as the worst."""
    v = np.asarray(v, dtype=float)
    return np.where(np.isnan(v), np.inf, v)


@dataclasses.dataclass
class FalsifyResult:
    """What [`falsify`][vcjax.search.core.falsify] found.

    Attributes:
        metric: the metric's name; envelope: the [`Envelope`][vcjax.search.envelope.Envelope].
        x: (S, P) each start's worst parameters found (config units); index: (S,) their random
            draws' scenario numbers; value: (S,) their metric; diverged: (S,) flags.
        curve: (rollouts, worst so far) after each ascent step (rollouts = starts x steps);
            curve_s: the seconds since the search began at each of them (compilation
            included).
        random_x, random_index, random_value, random_diverged: the random baseline's samples.
        random_curve: the same curve for the random samples (one point per rollout);
            random_curve_s: ``(rollouts, seconds)`` after each of its batches.
        rollouts, random_rollouts: rollouts run; wall_s, random_wall_s: seconds, compilation
            included; first_step_s: the first ascent step (compilation included, unless a
            call of the same shapes compiled it before).
        falsified: a scenario exceeded ``bound``; interrupted: stopped by a signal.
    """

    metric: str
    envelope: Envelope
    x: np.ndarray
    index: np.ndarray
    value: np.ndarray
    diverged: np.ndarray
    curve: list
    random_x: np.ndarray
    random_index: np.ndarray
    random_value: np.ndarray
    random_diverged: np.ndarray
    random_curve: list
    rollouts: int
    random_rollouts: int
    wall_s: float
    random_wall_s: float
    first_step_s: float | None
    bound: float | None = None
    falsified: bool = False
    random_falsified: bool = False
    interrupted: bool = False
    curve_s: list = dataclasses.field(default_factory=list)
    random_curve_s: list = dataclasses.field(default_factory=list)

    @property
    def beat_random(self) -> tuple[int, float] | None:
        """``(rollouts, seconds)`` at the first ascent step whose worst exceeded the random
        baseline's worst (seconds since the search began, compilation included), or ``None``:
        the gradient search never found a worse scenario than random sampling."""
        if not self.random_value.size:
            return None
        target = float(np.max(_rank(self.random_value)))
        for (n, w), t in zip(self.curve, self.curve_s, strict=False):
            if w > target:
                return int(n), float(t)
        return None

    @property
    def worst(self) -> float:
        return float(self.value[np.argmax(_rank(self.value))]) if self.value.size else np.nan

    @property
    def random_worst(self) -> float:
        v = self.random_value
        return float(v[np.argmax(_rank(v))]) if v.size else np.nan

    def scenarios(self, keep: int = 10) -> list[dict]:
        """Worst first, both searches: ``{metric: value, "params": {...}, "seed", "index",
        "search", "diverged"}``."""
        rows = [
            (v, x, i, d, "gradient")
            for v, x, i, d in zip(self.value, self.x, self.index, self.diverged, strict=True)
        ]
        rows += [
            (v, x, i, d, "random")
            for v, x, i, d in zip(
                self.random_value,
                self.random_x,
                self.random_index,
                self.random_diverged,
                strict=True,
            )
        ]
        rows.sort(key=lambda r: -_rank(r[0]))
        return [
            {
                self.metric: float(v),
                "params": self.envelope.params(x),
                "index": int(i),
                "search": s,
                "diverged": bool(d),
            }
            for v, x, i, d, s in rows[:keep]
        ]


@dataclasses.dataclass(frozen=True)
class FalsifyOptions:
    """How [`falsify`][vcjax.search.core.falsify] searches.

    Attributes:
        starts: gradient ascents run together (under ``vmap``).
        steps: ascent steps of each.
        step_size: Adam's step in the envelope's unit box.
        random_rollouts: rollouts of the random baseline (default: as many as the ascent ran).
        random_batch: rollouts per batch of the baseline (at least ``starts``).
        bound: stop (each search) as soon as a scenario's metric exceeds it.
        sharpness: power of the power-mean surrogate of a ``max_*`` metric.
        progress: receives a line per step / batch.
        stop: polled between steps (default: ``stop_requested``); the result keeps what was
            found.
        first_index: the scenario number of the first start (the starts are ``first_index``,
            ``first_index + 1``, ...: their random draws; the baseline's follow them): another
            set of draws under the same seed without compiling again (the seed is static), as
            robust tuning's rounds do; its starting points are drawn from it too.
        gradient: how the ascent differentiates: ``"forward"`` (one tangent per searched
            parameter), ``"reverse"``, or ``"auto"`` (forward up to ``FORWARD_MAX`` searched
            parameters; [`gradient_mode`][vcjax.search.core.gradient_mode]). The same
            gradient either way (to rounding); what differs is the time to compile and run.
    """

    starts: int = 8
    steps: int = 20
    step_size: float = 0.05
    random_rollouts: int | None = None
    random_batch: int = 256
    bound: float | None = None
    sharpness: float = SHARPNESS
    progress: Callable[[str], Any] | None = None
    stop: Callable[[], bool] | None = None
    first_index: int = 0
    gradient: str = "auto"


_OPTION_FIELDS = frozenset(f.name for f in dataclasses.fields(FalsifyOptions))


class _Search(NamedTuple):
    """What both searches of [`falsify`][vcjax.search.core.falsify] share."""

    envelope: Envelope
    setting: Setting
    key: Setting  # the static part (``_key``)
    metric: str
    gains: Any
    dtype: Any
    width: Any  # (P,) 1 where the envelope has a range, 0 where it is a point
    o: FalsifyOptions
    say: Callable[[str], Any]
    stop: Callable[[], bool]


def _ascent(c: _Search) -> dict:
    """Multi-start projected gradient ascent (Adam in the unit box): each start's worst point,
    its metric and divergence flag, the curve, and how the ascent ended."""
    o, metric, starts = c.o, c.metric, c.o.starts
    name = _name(metric)
    i0 = int(o.first_index)
    rng = np.random.default_rng([c.setting.seed, 1] + ([i0] if i0 else []))
    # the ascent's own arithmetic runs on the host (NumPy, the setting's dtype): (starts, P)
    # arrays, where eager JAX would compile a kernel for each new operation on the first step
    ftype = np.dtype(c.dtype)
    width = np.asarray(c.width, ftype)
    z = rng.random((starts, len(c.envelope.names))).astype(ftype) * width
    index = jnp.asarray(np.arange(i0, i0 + starts, dtype=np.int32))
    m1, m2 = np.zeros_like(z), np.zeros_like(z)
    best_v, best_val = np.full(starts, -np.inf), np.full(starts, np.nan)
    best_z, best_div = z, np.zeros(starts, bool)
    out = {"curve": [], "curve_s": [], "falsified": False, "interrupted": False}
    out |= {"first_s": None, "done": 0}
    t0 = time.perf_counter()
    axes = tuple(int(i) for i in np.flatnonzero(width > 0))
    how = AscentSpec(metric, float(o.sharpness), axes, gradient_mode(o.gradient, len(axes)))
    compiled = functools.partial(_value_and_grad, env=c.envelope, setting=c.key, how=how)
    b1, b2 = 0.9, 0.999
    for k in range(o.steps):
        if k and c.stop():
            out["interrupted"] = True
            break
        m, g = jax.device_get(compiled(jnp.asarray(z), index, c.gains, c.setting.nominal))
        v = np.asarray(m[name])
        out["first_s"] = time.perf_counter() - t0 if out["first_s"] is None else out["first_s"]
        r = _rank(v)
        better = r > best_v
        best_v = np.where(better, r, best_v)
        best_val = np.where(better, v, best_val)
        best_z = np.where(better[:, None], z, best_z)
        best_div = np.where(better, np.asarray(m["diverged"]), best_div)
        out["done"] += starts
        worst = float(np.max(best_v))
        out["curve"].append((out["done"], worst))
        out["curve_s"].append(time.perf_counter() - t0)
        c.say(f"gradient step {k + 1}/{o.steps}: {out['done']} rollouts, worst {name} {worst:.4g}")
        if o.bound is not None and worst > o.bound:
            out["falsified"] = True
            break
        g = np.nan_to_num(np.asarray(g, ftype), nan=0.0, posinf=0.0, neginf=0.0) * width
        m1 = b1 * m1 + (1 - b1) * g
        m2 = b2 * m2 + (1 - b2) * g * g
        mh = m1 / (1 - b1 ** (k + 1))
        vh = m2 / (1 - b2 ** (k + 1))
        z = (np.clip(z + o.step_size * mh / (np.sqrt(vh) + 1e-8), 0.0, 1.0) * width).astype(ftype)
    out["wall_s"] = time.perf_counter() - t0
    x = c.envelope.from_unit(np.asarray(best_z, c.dtype))
    out.update(x=x, index=np.asarray(index), value=best_val, diverged=best_div.astype(bool))
    return out


def _baseline(c: _Search, n_rand: int, interrupted: bool) -> dict:
    """Plain random sampling of the same envelope, new scenario numbers, in equal batches of at
    most ``random_batch`` (at least ``starts``: no padded work in the timing)."""
    o, metric, starts, P = c.o, c.metric, c.o.starts, len(c.envelope.names)
    name = _name(metric)
    t1 = time.perf_counter()
    i0 = int(o.first_index)
    rng = np.random.default_rng([c.setting.seed, 2] + ([i0] if i0 else []))
    rx, ri, rv, rd, rcurve, rtimes = [], [], [], [], [], []
    rworst, rfals = -np.inf, False
    fwd = None
    batch = max(starts, -(-n_rand // max(1, -(-n_rand // o.random_batch)))) if n_rand else starts
    j = 0
    while j < n_rand and not interrupted:
        if j and c.stop():
            interrupted = True
            break
        zb = rng.random((batch, P)) * np.asarray(c.width)
        xb = c.envelope.from_unit(np.asarray(zb, c.dtype))
        ib = np.arange(i0 + starts + j, i0 + starts + j + batch, dtype=np.int32)
        if fwd is None:
            fwd = functools.partial(_forward, env=c.envelope, setting=c.key, metric=metric)
        m = jax.device_get(fwd(jnp.asarray(xb, c.dtype), ib, c.gains, c.setting.nominal))
        nb = min(batch, n_rand - j)
        rx.append(xb[:nb])
        ri.append(ib[:nb])
        rv.append(np.asarray(m[name])[:nb])
        rd.append(np.asarray(m["diverged"])[:nb])
        for k, r in enumerate(_rank(rv[-1])):  # one point per rollout
            rworst = max(rworst, float(r))
            rcurve.append((j + k + 1, rworst))
        j += nb
        rtimes.append((j, time.perf_counter() - t1))
        c.say(f"random: {j}/{n_rand} rollouts, worst {name} {rworst:.4g}")
        if o.bound is not None and rworst > o.bound:
            rfals = True
            break
    cat = lambda parts, shape: np.concatenate(parts) if parts else np.zeros(shape)
    return {
        "random_x": cat(rx, (0, P)),
        "random_index": cat(ri, (0,)).astype(np.int64),
        "random_value": cat(rv, (0,)),
        "random_diverged": cat(rd, (0,)).astype(bool),
        "random_curve": rcurve,
        "random_curve_s": rtimes,
        "random_rollouts": j,
        "random_wall_s": time.perf_counter() - t1,
        "random_falsified": rfals,
        "interrupted": interrupted,
    }


def falsify(
    loop,
    gains,
    envelope,
    metric,
    setting: Setting | None = None,
    options: FalsifyOptions | None = None,
    **kwargs,
) -> FalsifyResult:
    """Search the envelope for the scenarios that make ``metric`` largest.

    Multi-start projected gradient ascent (Adam steps in the envelope's unit box, clipped into
    it after every step) of ``metric`` (for a ``max_*`` metric: its power mean of power
    ``sharpness``, a smooth surrogate; the true metric is what is reported and ranked),
    ``starts`` starts under ``vmap``, each with the random draws (sea phases, noise) of its own
    scenario number held fixed. Each ascent step of each start is one rollout. Then plain
    random sampling of the same envelope (``random_rollouts``, default the same number, new
    scenario numbers) in batches of ``random_batch`` (at least ``starts``): the baseline.

    Args:
        loop, gains: the closed loop and its gains; envelope: an
            [`Envelope`][vcjax.search.envelope.Envelope], or a
            mapping name -> ``(lo, hi)`` or number
            ([`Envelope.build`][vcjax.search.envelope.Envelope.build]);
        metric: a sweep metric of the loop (or an alias, ``ALIASES``), or a
            [`SegmentMetric`][vcjax.search.core.SegmentMetric] (e.g. the tuning loss).
        setting: [`Setting`][vcjax.search.envelope.Setting] (horizon, dt, nominal parameters, sea,
            seed); default:
            [`make_setting`][vcjax.search.envelope.make_setting] of the keyword arguments that
            are not search options (``horizon=60.0``, ``dt=0.05``, ...).
        options: [`FalsifyOptions`][vcjax.search.core.FalsifyOptions] (starts, steps, step size,
            baseline, ``bound``, sharpness, ``progress``, ``stop``); its fields are also
            accepted by name (``starts=8``, ``bound=2.0``, ...).
    """
    from vcjax._checks import with_options

    opts = {k: v for k, v in kwargs.items() if k in _OPTION_FIELDS}
    setting_options = {k: v for k, v in kwargs.items() if k not in _OPTION_FIELDS}
    o = with_options(FalsifyOptions, options, opts, "falsify")
    if not isinstance(envelope, Envelope):
        envelope = Envelope.build(loop, envelope, dt=setting_options.get("dt", 0.05))
    if setting is None:
        setting = make_setting(loop, envelope, **setting_options)
    elif setting_options:
        raise ValueError(f"give a setting or its options, not both: {sorted(setting_options)}")
    if o.starts < 1 or o.steps < 1:
        raise ValueError(f"starts, steps: expected >= 1, got {o.starts}, {o.steps}")
    metric = metric_name(loop, gains, setting, metric)
    setting = dataclasses.replace(setting, loop=loop)
    dtype = _dtype(setting)
    width = jnp.asarray(np.asarray(envelope.hi) > np.asarray(envelope.lo), dtype)
    stop = stop_requested if o.stop is None else o.stop
    say = o.progress or (lambda line: None)
    c = _Search(envelope, setting, _key(setting), metric, gains, dtype, width, o, say, stop)
    a = _ascent(c)
    n_rand = a["done"] if o.random_rollouts is None else int(o.random_rollouts)
    b = _baseline(c, n_rand, a["interrupted"])
    return FalsifyResult(
        metric=_name(metric),
        envelope=envelope,
        x=a["x"],
        index=a["index"],
        value=a["value"],
        diverged=a["diverged"],
        curve=a["curve"],
        curve_s=a["curve_s"],
        rollouts=a["done"],
        wall_s=a["wall_s"],
        first_step_s=a["first_s"],
        bound=o.bound,
        falsified=a["falsified"],
        **b,
    )
