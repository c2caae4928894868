"""REMUS 100 survey mission: 3-D VCM path maneuvering and baselines on the PVS plant.

Mission (``vcjax simulate remus100``): start at the surface, descend to ``depth`` metres over the
first ``descent`` metres of a lawnmower (:func:`vcjax.paths.lawnmower`, legs along north joined by
half circles), under a constant current of ``V_c`` m/s towards the east — across the legs. The
plant is :func:`vcjax.vehicles.remus100.remus100_plant` (PythonVehicleSimulator's model, hard
actuator limits and lags); every law's body force goes through the same actuator map
(:func:`vcjax.vehicles.remus100_design.actuator_map`). The controller is sampled (zero-order
hold at the step ``dt``), the plant integrated by RK4. With ``--waves HS TP DIR_DEG`` every
variant meets the same random sea (:func:`mission_sea`) on top of the current.

Variants (:data:`VARIANTS`):

* ``vcm3d_ilos``: 3-D VCM (:mod:`vcjax.control.vcm3d`), underactuated in sway and heave,
  integral action and integral-LOS angles in both planes;
* ``vcm3d``: the same with the paper's approach angles (24) (integral action kept);
* ``decoupled``: the paper's design — horizontal VCM (31)/(38) with ILOS and integral action +
  depth through pitch (:func:`vcjax.control.baselines3d.decoupled_law`);
* ``alos3d``: ALOS3D guidance (Fossen & Aguiar 2024) + PID heading/pitch autopilots + surge PI;
* ``pvs_pid``: heading/depth PID autopilots with plain LOS angles (PVS-like sanity run).

Metrics (:func:`mission_metrics`): :func:`vcjax.metrics.run_metrics` with the mission's extras
(:func:`mission_extras`): the 3-D distance to the path is measured geometrically (nearest point
of a dense polyline of the path, :func:`vcjax.metrics.polyline_nearest`), independent of each
law's own error signals.
"""

from __future__ import annotations

import math
import sys
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from vcjax import loops, metrics, paths
from vcjax.experiments.seas import option_sea, option_sea_record
from vcjax.loops.remus100 import REMUS_CONTROLLERS
from vcjax.rollout import RolloutConfig
from vcjax.runtime.outputs import write_json_atomic

__all__ = [
    "VARIANTS",
    "LABELS",
    "mission_path",
    "mission_scenario",
    "mission_sea",
    "simulate",
    "mission_geometry",
    "mission_extras",
    "mission_metrics",
    "REPORTED",
    "run_remus100",
]

VARIANTS = REMUS_CONTROLLERS
LABELS = {
    "vcm3d_ilos": "3-D VCM, ILOS + integral",
    "vcm3d": "3-D VCM, paper angles + integral",
    "decoupled": "2-D VCM + depth via pitch",
    "alos3d": "ALOS3D + PID autopilots",
    "pvs_pid": "PID autopilots, plain LOS",
}


def mission_path(leg=250.0, radius=30.0, n_legs=4, depth=15.0, descent=150.0, start_depth=1.0):
    """The survey path ``(path, coeffs)`` (a :func:`vcjax.paths.lawnmower`)."""
    return paths.lawnmower((0.0, 0.0, start_depth), leg, radius, n_legs, depth, descent)


def mission_scenario(
    variant, current=(0.0, 0.3), initial=None, coeffs=None, u_d=1.5, waves=None, wave_seed=0
):
    """``(loop, scenario)`` of the mission for one controller of the ``remus100`` loop.

    ``current``: (2,) NED water velocity ``[north, east]`` [m/s] (default: 0.3 m/s towards east,
    across the legs); ``initial``: the loop's ``initial_keys`` (default: 3 m east of the start,
    1 m deep, heading north at 1.5 m/s); ``waves``: ``(hs [m], tp [s], direction [deg])`` of a
    random sea (:func:`mission_sea`) or None.
    """
    loop = loops.make_loop("remus100", variant)
    coeffs = mission_path()[1] if coeffs is None else coeffs
    sea = None if waves is None else mission_sea(waves, wave_seed)
    sc = loops.make_scenario(loop, coeffs, initial=initial, current=current, u_d=u_d, sea=sea)
    return loop, sc


def mission_sea(waves, seed=0):
    """The sea of ``vcjax simulate remus100 --waves HS TP DIR_DEG``
    (:func:`vcjax.experiments.seas.option_sea`: long-crested JONSWAP, ``gamma = 3.3``, 64
    components, from ``PRNGKey(seed)``); the mean free surface at NED depth 0."""
    return option_sea(waves, seed)


_run = jax.jit(loops.simulate, static_argnames=("loop", "config"))


def simulate(
    variant,
    horizon=880.0,
    dt=0.05,
    current=(0.0, 0.3),
    initial=None,
    gains=None,
    waves=None,
    wave_seed=0,
):
    """One closed-loop run (controller sampled at ``dt``, RK4 plant; ``waves``: see
    :func:`mission_scenario`); returns ``(trajectory, (path, coeffs))``."""
    loop, sc = mission_scenario(variant, current, initial, waves=waves, wave_seed=wave_seed)
    gains = loop.default_gains() if gains is None else gains
    conf = RolloutConfig(num_steps=int(round(horizon / dt)), timing="sampled")
    traj = _run(loop, gains, sc, conf, dt)
    return traj, (loop.path, sc.path)


# ---------------------------------------------------------------------------------- metrics

#: ``metrics.json`` per variant: its name -> the name in :func:`vcjax.metrics.run_metrics`'s
#: result (the mission's extras, :func:`mission_extras`, and the generic ``sat_fraction``)
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


def mission_geometry(pos, path, coeffs, dw=0.25):
    """Where positions (N, 3) are relative to the survey path, geometrically: ``(dist, w, e,
    h)`` (N,) each — the distance to the path's polyline (sampled every ``dw`` from 20 m
    before the start to 600 m past the end, :func:`vcjax.metrics.polyline_nearest`) [m], the
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
    """The mission's metrics as extras of :func:`vcjax.metrics.run_metrics` (jnp).

    The distance to the path is geometric: every state's position against a polyline of the
    path sampled every ``dw`` parameter units (:func:`vcjax.metrics.polyline_nearest`),
    independent of each law's own error signals and particle.

    * ``rms_geo_dist_3d``, ``max_geo_dist_3d`` [m]: distance once the first leg is done;
    * ``ss_cross_track``, ``ss_depth_err`` [m]: max |horizontal cross-track| (the offset's
      component to the right of the path's tangent) and |depth error| on the straight legs
      after the first, ``settle`` metres after each turn; ``ss_geo_dist_3d`` [m]: max 3-D
      distance there;
    * ``mission_healthy``: every step finite and within the rollout's bound
      (:attr:`~vcjax.rollout.Trajectory.healthy`), and the vehicle within ``off_path`` [m]
      (default :data:`OFF_PATH_M`; ``vcjax simulate remus100 --diverge-e M``) of the path
      throughout;
    * ``end_w``: the path parameter nearest to the final position.

    Args:
        traj: the run (every state's position is measured, the final one included).
        path, coeffs: the survey path (:func:`mission_path`).
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


def mission_metrics(
    traj, path, coeffs, settle=150.0, variant=None, loop=None, scenario=None, off_path=None
) -> dict:
    """The mission's metrics of one run (``metrics.json``'s entry per variant, :data:`REPORTED`)
    as Python values: :func:`vcjax.metrics.run_metrics` of the loop's signals with the
    mission's extras (:func:`mission_extras`).

    ``loop``, ``scenario``: the run's; by default the mission's on ``coeffs`` for ``variant``
    (default: the controller whose state has the structure of ``traj.z``). Only the actuator
    limits and the path matter for what is reported. ``off_path``: the distance from the path
    beyond which the run is unhealthy [m] (:func:`vcjax.metrics.path_bound`'s checks; default
    :data:`OFF_PATH_M`).
    """
    bound = OFF_PATH_M if off_path is None else metrics.path_bound(0.0, 0.0, off_path)
    if loop is None or scenario is None:
        loop, scenario = mission_scenario(variant or _variant_of(traj), coeffs=coeffs)
    sig = loop.signals(traj, scenario)
    dt = traj.t[1] - traj.t[0]
    extras = mission_extras(traj, path, coeffs, settle, off_path=bound)
    m = metrics.run_metrics(sig, traj.finite, dt, extras=extras)
    out = {}
    for ours, theirs in REPORTED.items():
        v = np.asarray(m[theirs])
        out[ours] = bool(v) if v.dtype == bool else float(v)
    return out


def _variant_of(traj) -> str:
    """The first controller of the mission whose law state has the structure of ``traj.z``."""
    want = jax.tree_util.tree_structure(traj.z)
    for v in VARIANTS:
        loop, sc = mission_scenario(v)
        if jax.tree_util.tree_structure(loop.initial_state(sc)[1]) == want:
            return v
    raise ValueError(f"variant: no REMUS 100 controller has the state of this run ({want})")


def run_remus100(
    out,
    horizon=880.0,
    dt=0.05,
    current=(0.0, 0.3),
    variants=VARIANTS,
    gains=None,
    waves=None,
    wave_seed=0,
    diverge_e=None,
) -> dict:
    """Run every variant of the survey mission; write ``metrics.json`` and figures to ``out``
    (``gains``: of every controller, default: the loop's defaults; ``waves``: ``(hs, tp,
    direction_deg)`` of one sea for every variant, :func:`mission_sea`; ``diverge_e``: the
    distance from the path [m] beyond which a run is unhealthy, default :data:`OFF_PATH_M`)."""
    from vcjax.plots.remus100 import remus100_figures

    off_path = OFF_PATH_M if diverge_e is None else metrics.path_bound(0.0, 0.0, diverge_e)
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    trajs, results = {}, {}
    for v in variants:
        loop, sc = mission_scenario(v, current, waves=waves, wave_seed=wave_seed)
        traj, (path, coeffs) = simulate(
            v, horizon, dt, current, gains=gains, waves=waves, wave_seed=wave_seed
        )
        trajs[v] = jax.device_get(traj)
        results[v] = mission_metrics(
            trajs[v], path, coeffs, loop=loop, scenario=sc, off_path=off_path
        )
    undefined = {v: u for v, m in results.items() if (u := undefined_reasons(m, coeffs, horizon))}
    meta = {"horizon": horizon, "dt": dt, "current_ned": [float(c) for c in current]}
    meta["off_path_bound_m"] = off_path
    if waves is not None:
        meta["waves"] = option_sea_record(waves, wave_seed, origin_depth=0.0)
    clean = {v: {k: (None if isinstance(x, float) and not np.isfinite(x) else x)
                 for k, x in m.items()} for v, m in results.items()}  # fmt: skip
    doc = {"config": meta, "variants": clean}
    if undefined:  # a metric that cannot be computed says why (null in "variants")
        doc["undefined"] = undefined
    write_json_atomic(out / "metrics.json", doc, newline=False)
    files = [out / "metrics.json"]
    files += remus100_figures(trajs, path, coeffs, out, LABELS)
    return {"metrics": results, "files": files, "undefined": undefined}


def undefined_reasons(m: dict, coeffs, horizon: float, settle: float = 150.0) -> dict:
    """Why each metric of one run's :func:`mission_metrics` ``m`` that is NaN could not be
    computed (:func:`vcjax.metrics.undefined_metrics`): the windows of the mission's metrics
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


def load_gains(d: dict, **_options):
    """Gains of every REMUS 100 controller from a gains-JSON object (what ``vcjax tune`` writes
    for a ``remus100`` config; missing entries: the defaults), validated."""
    return loops.make_loop("remus100", VARIANTS[0]).gains_from_json(d)


def run_experiment(
    out, gains, *, horizon, dt, current, progress=print, waves=None, wave_seed=0, diverge_e=None
) -> dict:
    """``vcjax simulate remus100`` (:mod:`vcjax.experiments`): :func:`run_remus100`."""
    result = run_remus100(
        out,
        horizon=horizon,
        dt=dt,
        current=current,
        gains=gains,
        waves=waves,
        wave_seed=wave_seed,
        diverge_e=diverge_e,
    )
    bound = OFF_PATH_M if diverge_e is None else float(diverge_e)
    for name, u in result["undefined"].items():  # never a bare nan: one line of why
        for why in dict.fromkeys(u.values()):
            keys = ", ".join(k for k, r in u.items() if r == why)
            print(f"vcjax: note: remus100 {name}: {keys} = nan: {why}", file=sys.stderr)
    result["printed"] = result["metrics"]
    result["unhealthy"] = [
        f"remus100 {name}: a non-finite or runaway state, or more than {bound:g} m off the "
        "path (see metrics.json)"
        for name, m in result["metrics"].items()
        if not m.get("healthy", True)
    ]
    return result
