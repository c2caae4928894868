"""One metrics function for every closed loop (JAX: jit/vmap-safe), on a loop's
[`Signals`][vcjax.loops.types.Signals].

Windows: ``ss_*`` and ``rms_*`` / ``max_dist_3d`` use the steady-state window, the steps from
``floor(start n)`` on (``start = 1 - tail`` for a sweep's ``tail``; Simulation 2 reports from 20 %
of the run on); ``iae_e``, ``max_abs_e``, ``sat_fraction`` and the actuator maxima use the whole
run. Units: metres, m/s, seconds; ``sat_fraction`` is the fraction of steps in which some actuator
was commanded at or beyond its limit.

* ``ss_abs_e``, ``ss_abs_s``, ``ss_abs_u_err``: mean |cross-track error|, |along-track error|,
  |speed error| over the window [m, m, m/s];
* ``iae_e``: integral of |e| dt [m s]; ``max_abs_e``: largest |e| [m];
* ``rms_along_track_s``, ``rms_cross_track_e``: RMS of s and e over the window [m];
* ``rms_dist_3d``, ``max_dist_3d``: RMS / largest 3-D distance to the path particle's point over
  the window [m]; ``rms_depth_err``: RMS depth error over the window [m];
* ``sat_fraction``; ``max_abs_<name>``: the largest magnitude of each actuator the loop reports
  (e.g. ``max_abs_tau_u`` [N], ``max_abs_rudder_deg`` [deg]);
* flags: ``nonfinite`` (a step produced NaN/inf: the rollout froze the state) and ``diverged``
  (``nonfinite`` or ``max_abs_e > diverge_e``; NaN counts as diverged).

Experiments add their own metrics *to* this one function, not beside it: ``run_metrics(...,
extras={name: fn})`` computes each ``fn(sig, win)`` (jnp, from the signals, the steady-state
window ``win`` and whatever the experiment closes over: its trajectory, its path) in the same call
and returns them with the generic ones. Helpers for extras: [`first_true`][vcjax.metrics.first_true]
(the first step a
condition holds, e.g. a run's first unhealthy step),
[`polyline_nearest`][vcjax.metrics.polyline_nearest] (the geometric
distance of positions to a path's dense polyline, independent of any law's own error signals).

Path-error bound of single runs (``vcjax simulate``; [`path_bound`][vcjax.metrics.path_bound]): a
run whose largest
cross-track error (or 3-D distance to the path) exceeds it is *diverged* and never
``healthy: true``, even when every state stays finite (a vehicle swept kilometres off the path by
a 50 m/s current). The default scales with the path the run is asked to follow:
``PATH_BOUND_FRACTION`` (25 %) of the distance ``u_d x horizon`` it should travel, and at
least ``PATH_BOUND_MIN_M`` (50 m, a sweep's default ``diverge_e``). Simulation 1 (u_d = 2
m/s, 150 s): 75 m, which its runs (the paper's current and the cross current) stay inside.
``--diverge-e`` sets it explicitly.
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp

__all__ = [
    "METRICS",
    "FLAGS",
    "metric_names",
    "run_metrics",
    "window_start",
    "metrics_init",
    "metrics_update",
    "metrics_finalize",
    "PATH_BOUND_FRACTION",
    "PATH_BOUND_MIN_M",
    "path_bound",
    "first_excursion",
    "first_true",
    "polyline_nearest",
    "check_run_inputs",
    "undefined_metrics",
]

#: Default path-error bound: this fraction of ``u_d x horizon`` ...
PATH_BOUND_FRACTION = 0.25
#: ... and at least this [m].
PATH_BOUND_MIN_M = 50.0


def path_bound(u_d: float, horizon: float, bound: float | None = None) -> float:
    """The path-error bound [m] of a run asked to follow a path at ``u_d`` [m/s] for
    ``horizon`` [s]: ``bound`` when given (> 0), else ``max(PATH_BOUND_MIN_M,
    PATH_BOUND_FRACTION * u_d * horizon)``."""
    if bound is not None:
        b = float(bound)
        if not (math.isfinite(b) and b > 0):
            raise ValueError(f"diverge_e: expected a finite bound > 0 [m], got {bound!r}")
        return b
    return max(PATH_BOUND_MIN_M, PATH_BOUND_FRACTION * abs(float(u_d)) * float(horizon))


def first_excursion(err, bound: float) -> int | None:
    """First index k with ``|err[k]| > bound`` (or non-finite), else None (numpy, eager)."""
    import numpy as np

    a = np.abs(np.asarray(err, dtype=np.float64))
    bad = np.flatnonzero(~(a <= bound))
    return int(bad[0]) if bad.size else None


#: Metrics every loop has (besides its ``max_abs_<actuator>`` ones).
METRICS = (
    "ss_abs_e",
    "ss_abs_s",
    "ss_abs_u_err",
    "iae_e",
    "max_abs_e",
    "rms_along_track_s",
    "rms_cross_track_e",
    "rms_dist_3d",
    "max_dist_3d",
    "rms_depth_err",
    "sat_fraction",
)
#: Health flags (bool).
FLAGS = ("nonfinite", "diverged")


def metric_names(act_names) -> tuple[str, ...]:
    """Metric names of a loop whose signals report actuators ``act_names``."""
    return METRICS[:5] + tuple(f"max_abs_{a}" for a in act_names) + METRICS[5:]


def window_start(n: int, start: float) -> int:
    """First step ``floor(start n)`` of the steady-state window of an ``n``-step run."""
    return int(math.floor(start * n))


def metrics_init(act_names, dtype) -> dict:
    """Empty accumulator of [`metrics_update`][vcjax.metrics.metrics_update] for a loop reporting
    ``act_names``."""
    z = jnp.zeros((), dtype)
    acc = dict.fromkeys(_SUMS + _MAXES, z)
    acc |= {f"max_abs_{a}": z for a in act_names}
    acc["finite"] = jnp.array(True)
    return acc


_SUMS = (
    "abs_e_win",
    "abs_s_win",
    "abs_u_err_win",
    "abs_e",
    "s2_win",
    "e2_win",
    "d2_win",
    "h2_win",
    "sat",
)
_MAXES = ("max_abs_e", "max_dist_3d")


def metrics_update(acc: dict, sig, finite, ks, k0: int) -> dict:
    """Fold the samples ``ks`` (global step indices, (L,)) of a run into ``acc``.

    Args:
        acc: accumulator ([`metrics_init`][vcjax.metrics.metrics_init]); sig:
            [`Signals`][vcjax.loops.types.Signals] of
            the L samples; finite: (L,) the rollout's ``finite`` flags of those steps.
        ks: (L,) int step indices; k0: static first step of the steady-state window.
    """
    win = ks >= k0
    zero = jnp.zeros_like(sig.eps[:, 1])

    def wsum(x):  # sum over the window; where, not a product, so NaN outside stays outside
        return jnp.sum(jnp.where(win, x, zero))

    abs_e = jnp.abs(sig.eps[:, 1])
    s = sig.eps[:, 0]
    dist = jnp.sqrt(jnp.sum(sig.p_err**2, axis=1))
    out = {
        "abs_e_win": wsum(abs_e),
        "abs_s_win": wsum(jnp.abs(s)),
        "abs_u_err_win": wsum(jnp.abs(sig.u_err)),
        "abs_e": jnp.sum(abs_e),
        "s2_win": wsum(s**2),
        "e2_win": wsum(sig.eps[:, 1] ** 2),
        "d2_win": wsum(dist**2),
        "h2_win": wsum(sig.depth_err**2),
        "sat": jnp.sum(sig.sat.astype(abs_e.dtype)),
    }
    new = {k: acc[k] + v for k, v in out.items()}
    new["max_abs_e"] = jnp.maximum(acc["max_abs_e"], jnp.max(abs_e))
    new["max_dist_3d"] = jnp.maximum(acc["max_dist_3d"], jnp.max(jnp.where(win, dist, zero)))
    for name, a in sig.act.items():
        new[f"max_abs_{name}"] = jnp.maximum(acc[f"max_abs_{name}"], jnp.max(a))
    new["finite"] = acc["finite"] & jnp.all(finite)
    return new


def metrics_finalize(acc: dict, n: int, k0: int, dt, diverge_e=jnp.inf) -> dict:
    """The metrics ([`metric_names`][vcjax.metrics.metric_names] and ``FLAGS``) of an ``n``-step run
    from its
    accumulator (every step folded in once); ``k0`` the window's first step, ``dt`` [s]."""
    nw = n - k0
    m = {
        "ss_abs_e": acc["abs_e_win"] / nw,
        "ss_abs_s": acc["abs_s_win"] / nw,
        "ss_abs_u_err": acc["abs_u_err_win"] / nw,
        "iae_e": acc["abs_e"] * dt,
        "max_abs_e": acc["max_abs_e"],
    }
    m |= {k: v for k, v in acc.items() if k.startswith("max_abs_") and k != "max_abs_e"}
    m |= {
        "rms_along_track_s": jnp.sqrt(acc["s2_win"] / nw),
        "rms_cross_track_e": jnp.sqrt(acc["e2_win"] / nw),
        "rms_dist_3d": jnp.sqrt(acc["d2_win"] / nw),
        "max_dist_3d": acc["max_dist_3d"],
        "rms_depth_err": jnp.sqrt(acc["h2_win"] / nw),
        "sat_fraction": acc["sat"] / n,
        "nonfinite": ~acc["finite"],
    }
    m["diverged"] = m["nonfinite"] | ~(m["max_abs_e"] <= diverge_e)
    return m


def run_metrics(sig, finite, dt, start: float = 0.8, diverge_e=jnp.inf, extras=None) -> dict:
    """Metrics and health flags of one run, with an experiment's own metrics added.

    Args:
        sig: [`Signals`][vcjax.loops.types.Signals] (N steps).
        finite: (N,) bool, the rollout's ``Trajectory.finite``.
        dt: () step [s].
        start: static fraction of the run where the steady-state window begins.
        diverge_e: () cross-track bound [m] of the ``diverged`` flag.
        extras: ``{name: fn}``: metrics of an experiment, each ``fn(sig, win) -> ()`` array
            with ``win`` the (N,) bool mask of the steady-state window (jnp; jit/vmap-safe when
            ``fn`` is). A name of the generic metrics or flags is refused (``ValueError``).

    Returns:
        dict name -> () array: [`metric_names`][vcjax.metrics.metric_names], ``FLAGS`` and the
        extras. The generic
        ones: the same accumulator as a streamed run
            ([`metrics_update`][vcjax.metrics.metrics_update] segment by
        segment), folded in one go.
    """
    n = sig.eps.shape[0]
    check_run_inputs(n, finite, dt, start)
    k0 = window_start(n, start)
    acc = metrics_init(sig.act, sig.eps.dtype)
    acc = metrics_update(acc, sig, finite, jnp.arange(n), k0)
    m = metrics_finalize(acc, n, k0, dt, diverge_e)
    extras = dict(extras or {})
    taken = sorted(set(extras) & set(m))
    if taken:
        raise ValueError(f"extras: {taken} are generic metrics; name the experiment's own apart")
    win = jnp.arange(n) >= k0
    for name, fn in extras.items():
        m[name] = fn(sig, win)
    return m


def check_run_inputs(n: int, finite, dt, start: float) -> None:
    """Eager checks of [`run_metrics`][vcjax.metrics.run_metrics]' inputs (``ValueError`` naming the
    argument): ``n``
    >= 1 steps, ``finite`` of shape (n,), ``dt`` a scalar (> 0 and finite when concrete: a
    step <= 0 would give a negative or zero ``iae_e``), ``start`` in [0, 1) so that the
    steady-state window holds at least one step. Shapes are static, so they are checked under
    ``jit`` too; ``dt``'s value only outside it."""
    if n < 1:
        raise ValueError("sig: expected at least one step, got 0")
    if jnp.shape(finite) != (n,):
        raise ValueError(
            f"finite: expected shape ({n},) (one flag per step), got {jnp.shape(finite)}"
        )
    if jnp.shape(dt) != ():
        raise ValueError(f"dt: expected a scalar step [s], got shape {jnp.shape(dt)}")
    try:
        v = float(dt)
    except (TypeError, jax.errors.ConcretizationTypeError):
        v = None  # traced: the caller's own checks hold
    if v is not None and not (math.isfinite(v) and v > 0):
        raise ValueError(f"dt: expected a finite step > 0 [s], got {v:g}")
    if not (0.0 <= float(start) < 1.0):
        raise ValueError(f"start: expected a fraction in [0, 1) of the run, got {start!r}")
    if window_start(n, start) >= n:
        raise ValueError(f"start: {start!r} of {n} steps leaves an empty steady-state window")


def undefined_metrics(values: dict, reasons: dict | None = None, default: str = "") -> dict:
    """``{name: reason}`` for each metric of ``values`` (name -> number, or None) that is not a
    finite number (NaN, inf or None): the reason given for it in ``reasons``, else
    ``default``. A metric that cannot be computed is reported with why, never as a bare NaN
    (``metrics.json`` records these beside the values, the terminal prints them as a note)."""
    reasons = reasons or {}
    out = {}
    for k, v in values.items():
        if isinstance(v, bool):
            continue
        if v is None or (isinstance(v, float | int) and not math.isfinite(v)):
            out[k] = reasons.get(k, default) or "not computable for this run"
    return out


def first_true(mask):
    """() int: the index of the first True entry of ``mask`` (N,), or -1 if none (jnp)."""
    mask = jnp.asarray(mask, bool)
    return jnp.where(jnp.any(mask), jnp.argmax(mask), -1)


def polyline_nearest(pos, pts, ws, batch: int = 512):
    """The nearest point of a polyline to each of ``pos`` (jnp; point-to-segment).

    Args:
        pos: (N, 3) positions.
        pts: (S+1, 3) vertices of the polyline, ``pts[j] = p(ws[j])`` of a path sampled at the
            parameters ``ws`` (S+1,), equally spaced.
        batch: positions per block (the (block, S) distance table is what is held in memory).

    Returns:
        ``(dist (N,), w (N,), offset (N, 3), tangent (N, 3))``: the distance to the polyline
        [m]; the path parameter of the nearest point (``ws[j] + a dw`` on segment ``j`` at
        fraction ``a``); the offset ``pos - nearest point``; the unit tangent of the segment the
        nearest point's parameter falls in (the segment before a vertex when it is one).
        Ties go to the first segment.
    """
    pos = jnp.asarray(pos)
    pts = jnp.asarray(pts, pos.dtype)
    ws = jnp.asarray(ws, pos.dtype)
    dw = ws[1] - ws[0]
    seg = jnp.diff(pts, axis=0)
    seg_len2 = jnp.maximum(jnp.sum(seg * seg, axis=1), 1e-12)

    def one(p):
        d = p[None, :] - pts[:-1]
        a = jnp.clip(jnp.einsum("jk,jk->j", d, seg) / seg_len2, 0.0, 1.0)
        r = p[None, :] - (pts[:-1] + a[:, None] * seg)
        d2 = jnp.sum(r * r, axis=1)
        j = jnp.argmin(d2)
        return jnp.sqrt(d2[j]), ws[j] + a[j] * dw, r[j]

    dist, w, off = jax.lax.map(one, pos, batch_size=batch)
    jn = jnp.clip(jnp.searchsorted(ws, w) - 1, 0, seg.shape[0] - 1)
    tangent = seg[jn] / jnp.sqrt(seg_len2)[jn][:, None]
    return dist, w, off, tangent
