"""One metrics function for every closed loop (JAX: jit/vmap-safe), on a loop's
:class:`~vcjax.loops.base.Signals`.

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
"""

from __future__ import annotations

import math

import jax.numpy as jnp

__all__ = ["METRICS", "FLAGS", "metric_names", "run_metrics"]

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


def run_metrics(sig, finite, dt, start: float = 0.8, diverge_e=jnp.inf) -> dict:
    """Metrics and health flags of one run.

    Args:
        sig: :class:`~vcjax.loops.base.Signals` (N steps).
        finite: (N,) bool, the rollout's ``Trajectory.finite``.
        dt: () step [s].
        start: static fraction of the run where the steady-state window begins.
        diverge_e: () cross-track bound [m] of the ``diverged`` flag.

    Returns:
        dict name -> () array: :func:`metric_names` and :data:`FLAGS`.
    """
    n = sig.eps.shape[0]
    k0 = int(math.floor(start * n))
    eps = sig.eps
    abs_e = jnp.abs(eps[:, 1])
    dist = jnp.sqrt(jnp.sum(sig.p_err[k0:] ** 2, axis=1))
    max_abs_e = jnp.max(abs_e)
    nonfinite = ~jnp.all(finite)
    m = {
        "ss_abs_e": jnp.mean(abs_e[k0:]),
        "ss_abs_s": jnp.mean(jnp.abs(eps[k0:, 0])),
        "ss_abs_u_err": jnp.mean(jnp.abs(sig.u_err[k0:])),
        "iae_e": jnp.sum(abs_e) * dt,
        "max_abs_e": max_abs_e,
    }
    for name, a in sig.act.items():
        m[f"max_abs_{name}"] = jnp.max(a)
    m |= {
        "rms_along_track_s": jnp.sqrt(jnp.mean(eps[k0:, 0] ** 2)),
        "rms_cross_track_e": jnp.sqrt(jnp.mean(eps[k0:, 1] ** 2)),
        "rms_dist_3d": jnp.sqrt(jnp.mean(dist**2)),
        "max_dist_3d": jnp.max(dist),
        "rms_depth_err": jnp.sqrt(jnp.mean(sig.depth_err[k0:] ** 2)),
        "sat_fraction": jnp.mean(sig.sat.astype(abs_e.dtype)),
        "nonfinite": nonfinite,
    }
    m["diverged"] = nonfinite | ~(max_abs_e <= diverge_e)
    return m
