"""REMUS 100 survey mission: 3-D VCM path maneuvering and baselines on the PVS plant.

Mission (``vcjax simulate remus100``): start at the surface, descend to ``depth`` metres over the
first ``descent`` metres of a lawnmower ([`vcjax.paths.lawnmower`][vcjax.paths.lawnmower], legs
along north joined by
half circles), under a constant current of ``V_c`` m/s towards the east — across the legs. The
plant is [`remus100_plant`][vcjax.vehicles.remus100.remus100_plant] (PythonVehicleSimulator's model,
hard
actuator limits and lags); every law's body force goes through the same actuator map
([`actuator_map`][vcjax.vehicles.remus100_design.actuator_map]). The controller is sampled
(zero-order
hold at the step ``dt``), the plant integrated by RK4. With ``--waves HS TP DIR_DEG`` every
variant meets the same random sea ([`vcjax.experiments.seas`][vcjax.experiments.seas]) on top of the
current.

Variants (``VARIANTS``):

* ``vcm3d_ilos``: 3-D VCM ([`vcjax.control.vcm3d`][vcjax.control.vcm3d]), underactuated in sway and
heave,
  integral action and integral-LOS angles in both planes;
* ``vcm3d``: the same with the paper's approach angles (24) (integral action kept);
* ``decoupled``: the paper's design — horizontal VCM (31)/(38) with ILOS and integral action +
  depth through pitch ([`decoupled_law`][vcjax.control.baselines3d.decoupled_law]);
* ``alos3d``: ALOS3D guidance (Fossen & Aguiar 2024) + PID heading/pitch autopilots + surge PI;
* ``pvs_pid``: heading/depth PID autopilots with plain LOS angles (PVS-like sanity run).

Options (``vcjax simulate remus100``): ``--diverge-e`` (default ``OFF_PATH_M``),
``--waves``/``--wave-seed``.

Metrics ([`Remus100.metrics`][vcjax.experiments.remus100.Remus100.metrics]):
[`vcjax.metrics.run_metrics`][vcjax.metrics.run_metrics] with the mission's extras
([`mission_extras`][vcjax.experiments.remus100.mission_extras]): the 3-D distance to the path is
measured geometrically (nearest point
of a dense polyline of the path,
[`vcjax.metrics.polyline_nearest`][vcjax.metrics.polyline_nearest]), independent of each
law's own error signals.
"""

from __future__ import annotations

import dataclasses
import math
import sys

import jax
import jax.numpy as jnp
import numpy as np

from vcjax import loops, metrics, paths
from vcjax.experiments.base import Experiment, PathBound, option
from vcjax.experiments.seas import WaveOptions, option_sea, option_sea_record
from vcjax.loops.remus100 import REMUS_CONTROLLERS

__all__ = [
    "REMUS100",
    "Remus100",
    "Remus100Options",
    "VARIANTS",
    "LABELS",
    "REPORTED",
    "OFF_PATH_M",
    "mission_geometry",
    "mission_extras",
]

VARIANTS = REMUS_CONTROLLERS
LABELS = {
    "vcm3d_ilos": "3-D VCM, ILOS + integral",
    "vcm3d": "3-D VCM, paper angles + integral",
    "decoupled": "2-D VCM + depth via pitch",
    "alos3d": "ALOS3D + PID autopilots",
    "pvs_pid": "PID autopilots, plain LOS",
}
#: desired speed [m/s]
U_D = 1.5

#: ``metrics.json`` per variant: its name -> the name in
#: [`vcjax.metrics.run_metrics`][vcjax.metrics.run_metrics]'s
#: result (the mission's extras, [`mission_extras`][vcjax.experiments.remus100.mission_extras], and
#: the generic ``sat_fraction``)
REPORTED = {
    "rms_dist_3d": "rms_geo_dist_3d",
    "max_dist_3d": "max_geo_dist_3d",
    "ss_cross_track": "ss_cross_track",
    "ss_depth_err": "ss_depth_err",
    "ss_dist_3d": "ss_geo_dist_3d",
    "sat_fraction": "sat_fraction",
    "healthy": "mission_healthy",
    "end_w": "end_w",
}
#: a run further than this from the path, anywhere, is unhealthy [m]
OFF_PATH_M = 25.0


@dataclasses.dataclass(frozen=True)
class Remus100Options(PathBound, WaveOptions):
    """Options of ``vcjax simulate remus100``."""

    diverge_e: float | None = option(
        None,
        "a run more than M metres from the survey path (geometric distance) is unhealthy "
        f"(default {OFF_PATH_M:g} m)",
        "M",
    )


def mission_geometry(pos, path, coeffs, dw=0.25):
    """Where positions (N, 3) are relative to the survey path, geometrically: ``(dist, w, e,
    h)`` (N,) each — the distance to the path's polyline (sampled every ``dw`` from 20 m
    before the start to 600 m past the end,
    [`vcjax.metrics.polyline_nearest`][vcjax.metrics.polyline_nearest]) [m], the
    path parameter of the nearest point, the horizontal cross-track offset (positive to the
    right of the path's tangent) and the depth offset (positive deeper) [m]."""
    c = coeffs
    total = int(c.n_legs) * float(c.leg) + (int(c.n_legs) - 1) * np.pi * float(c.radius)
    ws = np.arange(-20.0, total + 600.0 + dw, dw)
    pts = jax.vmap(lambda w: paths.path_point(path, coeffs, w))(jnp.asarray(ws))
    dist, w, off, tangent = metrics.polyline_nearest(jnp.asarray(pos), pts, ws)
    th = jnp.hypot(tangent[:, 0], tangent[:, 1])
    right = jnp.stack([-tangent[:, 1] / th, tangent[:, 0] / th], axis=1)  # right of the path
    return dist, w, jnp.sum(off[:, :2] * right, axis=1), off[:, 2]


def mission_extras(traj, path, coeffs, settle=150.0, dw=0.25, off_path=OFF_PATH_M) -> dict:
    """The mission's metrics as extras of [`vcjax.metrics.run_metrics`][vcjax.metrics.run_metrics]
    (jnp).

    The distance to the path is geometric: every state's position against a polyline of the
    path sampled every ``dw`` parameter units
    ([`vcjax.metrics.polyline_nearest`][vcjax.metrics.polyline_nearest]),
    independent of each law's own error signals and particle.

    * ``rms_geo_dist_3d``, ``max_geo_dist_3d`` [m]: distance once the first leg is done;
    * ``ss_cross_track``, ``ss_depth_err`` [m]: max |horizontal cross-track| (the offset's
      component to the right of the path's tangent) and |depth error| on the straight legs
      after the first, ``settle`` metres after each turn; ``ss_geo_dist_3d`` [m]: max 3-D
      distance there;
    * ``mission_healthy``: every step finite and within the rollout's bound
      ([`healthy`][vcjax.rollout.Trajectory.healthy]), and the vehicle within ``off_path`` [m]
      (default ``OFF_PATH_M``; ``vcjax simulate remus100 --diverge-e M``) of the path
      throughout;
    * ``end_w``: the path parameter nearest to the final position.

    Args:
        traj: the run (every state's position is measured, the final one included).
        path, coeffs: the survey path (``mission_path``).
    """
    c = coeffs
    L, R, n = float(c.leg), float(c.radius), int(c.n_legs)
    period = L + np.pi * R
    total = n * L + (n - 1) * np.pi * R
    dist, w, e, h = mission_geometry(traj.x.eta[:, :3], path, coeffs, dw)
    after_first = w > L
    k = jnp.clip(jnp.floor(w / period), 0, n - 1)
    om = w - k * period
    straight = (k >= 1) & (om >= settle) & (om <= L) & (w <= total)
    nan = jnp.asarray(jnp.nan, dist.dtype)

    def max_abs(a, m):
        return jnp.where(jnp.any(m), jnp.max(jnp.where(m, jnp.abs(a), -jnp.inf)), nan)

    def rms(a, m):
        mean = jnp.sum(jnp.where(m, a**2, 0.0)) / jnp.sum(m.astype(a.dtype))
        return jnp.where(jnp.any(m), jnp.sqrt(mean), nan)

    healthy = traj.healthy & (jnp.max(dist) < off_path)
    return {
        "rms_geo_dist_3d": lambda sig, win: rms(dist, after_first),
        "max_geo_dist_3d": lambda sig, win: max_abs(dist, after_first),
        "ss_cross_track": lambda sig, win: max_abs(e, straight),
        "ss_depth_err": lambda sig, win: max_abs(h, straight),
        "ss_geo_dist_3d": lambda sig, win: max_abs(dist, straight),
        "mission_healthy": lambda sig, win: healthy,
        "end_w": lambda sig, win: w[-1],
    }


@dataclasses.dataclass(frozen=True)
class Remus100(Experiment):
    """The survey mission: every controller of the ``remus100`` loop on its default lawnmower
    ([`default_path`][vcjax.loops.remus100.Remus100Loop.default_path]), sampled controller."""

    json_newline = False

    def variants(self, options=None) -> tuple[str, ...]:
        return VARIANTS

    def loop(self, variant: str, options=None) -> loops.Loop:
        return loops.make_loop("remus100", variant)

    def scenario(self, variant: str = VARIANTS[0], setup=None) -> loops.Scenario:
        """The loop's default start (3 m east of the path's start, 1 m deep, heading north at
        1.5 m/s) under the setup's current; with ``--waves`` the sea, the mean free surface at
        NED depth 0."""
        setup = self.setup() if setup is None else setup
        o = setup.options
        sea = None if o.waves is None else option_sea(o.waves, o.seed)
        loop = self.loop(variant)
        return loops.make_scenario(loop, current=setup.current, u_d=U_D, sea=sea)

    def off_path(self, options) -> float:
        """The distance from the path beyond which a run is unhealthy [m]."""
        b = options.diverge_e
        return OFF_PATH_M if b is None else metrics.path_bound(0.0, 0.0, b)

    def metrics(self, outcome, setup) -> dict:
        """``REPORTED`` as Python values: [`vcjax.metrics.run_metrics`][vcjax.metrics.run_metrics]
        of the loop's
        signals with the mission's extras
        ([`mission_extras`][vcjax.experiments.remus100.mission_extras])."""
        traj, sc, loop = outcome.traj, outcome.scenario, outcome.loop
        sig = loop.signals(traj, sc)
        dt = traj.t[1] - traj.t[0]
        bound = self.off_path(setup.options)
        extras = mission_extras(traj, loop.path, sc.path, off_path=bound)
        m = metrics.run_metrics(sig, traj.finite, dt, extras=extras)
        out = {}
        for ours, theirs in REPORTED.items():
            v = np.asarray(m[theirs])
            out[ours] = bool(v) if v.dtype == bool else float(v)
        return out

    def report(self, results, setup) -> dict:
        """``{"config": the run's horizon, dt, current, bound (and sea), "variants": metrics
        per variant, non-finite numbers as null}``."""
        meta = {"horizon": setup.horizon, "dt": setup.dt}
        meta["current_ned"] = [float(c) for c in setup.current]
        meta["off_path_bound_m"] = self.off_path(setup.options)
        o = setup.options
        if o.waves is not None:
            meta["waves"] = option_sea_record(o.waves, o.seed, origin_depth=0.0)
        clean = {v: {k: (None if isinstance(x, float) and not np.isfinite(x) else x)
                     for k, x in m.items()} for v, m in results.items()}  # fmt: skip
        doc = {"config": meta, "variants": clean}
        coeffs = self.scenario(next(iter(results)), setup).path
        undefined = {
            v: u for v, m in results.items() if (u := undefined_reasons(m, coeffs, setup.horizon))
        }
        if undefined:  # a metric that cannot be computed says why (null in "variants")
            doc["undefined"] = undefined
        for name, u in undefined.items():  # never a bare nan on the terminal: one line of why
            for why in dict.fromkeys(u.values()):
                keys = ", ".join(k for k, r in u.items() if r == why)
                print(f"vcjax: note: remus100 {name}: {keys} = nan: {why}", file=sys.stderr)
        return doc

    def figures(self, outcomes, setup, out):
        from vcjax.plots.remus100 import remus100_figures

        trajs = {v: o.traj for v, o in outcomes.items()}
        first = next(iter(outcomes.values()))
        return remus100_figures(trajs, first.loop.path, first.scenario.path, out, LABELS)

    def unhealthy(self, results, outcomes, setup) -> list[str]:
        bound = self.off_path(setup.options)
        return [
            f"remus100 {name}: a non-finite or runaway state, or more than {bound:g} m off the "
            "path (see metrics.json)"
            for name, m in results.items()
            if not m.get("healthy", True)
        ]


REMUS100 = Remus100(
    "remus100",
    "3-D survey mission of the PVS REMUS 100 under a cross current, every controller",
    horizon=880.0,
    dt=0.05,
    options=Remus100Options,
    current=(0.0, 0.3),
    timing="sampled",
)


def undefined_reasons(m: dict, coeffs, horizon: float, settle: float = 150.0) -> dict:
    """Why each metric of one run's ``mission_metrics`` ``m`` that is NaN could not be
    computed ([`undefined_metrics`][vcjax.metrics.undefined_metrics]): the windows of the mission's
    metrics
    are where the vehicle went (after the first leg; the straight legs after the first,
    ``settle`` metres past each turn), so a run too short to reach them has none."""
    L, R = float(coeffs.leg), float(coeffs.radius)
    end_w = float(m["end_w"])
    speed = end_w / horizon if horizon > 0 and end_w > 0 else 0.0

    def more(need):
        if speed <= 0:
            return ""
        return f"; a --horizon of about {math.ceil(need / speed / 10.0) * 10:.0f} s reaches it"

    need_ss = L + math.pi * R + settle
    ss = (
        f"the horizon is too short to settle: no straight leg after the first was reached "
        f"{settle:g} m past its turn (the vehicle got {end_w:.0f} m along the path of the "
        f"{need_ss:.0f} m needed){more(need_ss)}"
    )
    first = (
        f"the horizon is too short: the first leg ({L:g} m) was not finished (the vehicle got "
        f"{end_w:.0f} m along the path){more(L)}"
    )
    reasons = {"ss_cross_track": ss, "ss_depth_err": ss, "ss_dist_3d": ss}
    reasons |= {"rms_dist_3d": first, "max_dist_3d": first}
    if not math.isfinite(end_w):
        reasons = {}
    return metrics.undefined_metrics(m, reasons, "a non-finite state (see healthy)")
