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

Metrics (:func:`mission_metrics`, numpy, from the trajectory alone): the 3-D distance to the
path is measured geometrically (nearest point of a dense polyline of the path), independent of
each law's own error signals.
"""

from __future__ import annotations

from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from vcjax import loops, paths
from vcjax import waves as wv
from vcjax.loops.remus100 import REMUS_CONTROLLERS
from vcjax.outputs import write_json_atomic
from vcjax.rollout import RolloutConfig
from vcjax.vehicles import remus100 as r100

__all__ = [
    "VARIANTS",
    "LABELS",
    "mission_path",
    "mission_scenario",
    "mission_sea",
    "simulate",
    "mission_metrics",
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
    """The sea of ``vcjax simulate remus100 --waves HS TP DIR_DEG``: a long-crested JONSWAP sea
    (``gamma = 3.3``, 64 components) drawn from ``PRNGKey(seed)``
    (:func:`vcjax.waves.sea_state`); the mean free surface at NED depth 0."""
    hs, tp, direction_deg = (float(v) for v in waves)
    key = jax.random.PRNGKey(seed)
    return wv.sea_state(key, hs, tp, np.radians(direction_deg), spectrum="jonswap")


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


def _nearest_on_path(pos, path, coeffs, w_range, dw=0.25):
    """For each position (N, 3): ``(dist (N,), w (N,), e (N,), h (N,))``: the distance to the
    path's dense polyline (point-to-segment), the parameter of the nearest point, and the
    horizontal cross-track and depth components of the offset."""
    ws = np.arange(w_range[0], w_range[1] + dw, dw)
    pts = np.asarray(jax.vmap(lambda w: paths.path_point(path, coeffs, w))(jnp.asarray(ws)))
    seg = np.diff(pts, axis=0)
    seg_len2 = np.maximum(np.sum(seg * seg, axis=1), 1e-12)
    dist = np.empty(len(pos))
    w_near = np.empty(len(pos))
    off = np.empty((len(pos), 3))
    for i0 in range(0, len(pos), 512):
        P = pos[i0 : i0 + 512]
        d = P[:, None, :] - pts[None, :-1, :]
        a = np.clip(np.einsum("ijk,jk->ij", d, seg) / seg_len2, 0.0, 1.0)
        proj = pts[None, :-1, :] + a[..., None] * seg[None]
        r = P[:, None, :] - proj
        d2 = np.sum(r * r, axis=2)
        j = np.argmin(d2, axis=1)
        k = np.arange(len(P))
        dist[i0 : i0 + 512] = np.sqrt(d2[k, j])
        w_near[i0 : i0 + 512] = ws[j] + a[k, j] * dw
        off[i0 : i0 + 512] = r[k, j]
    tang = seg / np.sqrt(seg_len2)[:, None]
    jn = np.clip(np.searchsorted(ws, w_near) - 1, 0, len(seg) - 1)
    t = tang[jn]
    th = np.hypot(t[:, 0], t[:, 1])
    lateral = np.stack([-t[:, 1] / th, t[:, 0] / th], axis=1)  # right of the path (NED)
    e = np.sum(off[:, :2] * lateral, axis=1)
    return dist, w_near, e, off[:, 2]


def mission_metrics(traj, path, coeffs, settle=150.0) -> dict:
    """The mission's metrics from a trajectory (numpy; module docstring).

    * ``rms_dist_3d``, ``max_dist_3d`` [m]: distance to the path once the first leg is done;
    * ``ss_cross_track``, ``ss_depth_err`` [m]: max |horizontal cross-track| and |depth error| on
      the straight legs after the first, ``settle`` metres after each turn;
    * ``ss_dist_3d`` [m]: max 3-D distance there;
    * ``sat_fraction``: fraction of steps with any actuator command beyond its limit;
    * ``healthy``: every step finite and the vehicle within 25 m of the path throughout.
    """
    c = coeffs
    L, R, n = float(c.leg), float(c.radius), int(c.n_legs)
    period = L + np.pi * R
    total = n * L + (n - 1) * np.pi * R
    pos = np.asarray(traj.x.eta[:, :3])
    dist, w, e, h = _nearest_on_path(pos, path, coeffs, (-20.0, total + 600.0))
    after_first = w > L
    k = np.clip(np.floor(w / period), 0, n - 1)
    om = w - k * period
    straight = (k >= 1) & (om >= settle) & (om <= L) & (w <= total)
    raw = np.asarray(traj.aux.raw)
    lim = np.asarray(r100.remus100_params().act_max)
    sat = np.any(np.abs(raw) > lim, axis=1)
    finite = bool(np.asarray(traj.healthy))  # every state finite and within the bound

    def mx(a, m):
        return float(np.max(np.abs(a[m]))) if np.any(m) else float("nan")

    return {
        "rms_dist_3d": float(np.sqrt(np.mean(dist[after_first] ** 2)))
        if np.any(after_first)
        else float("nan"),
        "max_dist_3d": mx(dist, after_first),
        "ss_cross_track": mx(e, straight),
        "ss_depth_err": mx(h, straight),
        "ss_dist_3d": mx(dist, straight),
        "sat_fraction": float(np.mean(sat)),
        "healthy": bool(finite and np.max(dist) < 25.0),
        "end_w": float(w[-1]),
    }


def run_remus100(
    out,
    horizon=880.0,
    dt=0.05,
    current=(0.0, 0.3),
    variants=VARIANTS,
    gains=None,
    waves=None,
    wave_seed=0,
) -> dict:
    """Run every variant of the survey mission; write ``metrics.json`` and figures to ``out``
    (``gains``: of every controller, default: the loop's defaults; ``waves``: ``(hs, tp,
    direction_deg)`` of one sea for every variant, :func:`mission_sea`)."""
    from vcjax.plots.remus100 import remus100_figures

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    trajs, metrics = {}, {}
    for v in variants:
        traj, (path, coeffs) = simulate(
            v, horizon, dt, current, gains=gains, waves=waves, wave_seed=wave_seed
        )
        trajs[v] = jax.device_get(traj)
        metrics[v] = mission_metrics(trajs[v], path, coeffs)
    meta = {"horizon": horizon, "dt": dt, "current_ned": [float(c) for c in current]}
    if waves is not None:
        hs, tp, direction = (float(x) for x in waves)
        meta["waves"] = {
            "hs": hs,
            "tp": tp,
            "direction_deg": direction,
            "seed": int(wave_seed),
            "spectrum": "jonswap",
            "gamma": 3.3,
            "components": 64,
            "origin_depth": 0.0,
        }
    clean = {v: {k: (None if isinstance(x, float) and not np.isfinite(x) else x)
                 for k, x in m.items()} for v, m in metrics.items()}  # fmt: skip
    write_json_atomic(out / "metrics.json", {"config": meta, "variants": clean}, newline=False)
    files = [out / "metrics.json"]
    files += remus100_figures(trajs, path, coeffs, out, LABELS)
    return {"metrics": metrics, "files": files}


def load_gains(d: dict, **_options):
    """Gains of every REMUS 100 controller from a gains-JSON object (what ``vcjax tune`` writes
    for a ``remus100`` config; missing entries: the defaults), validated."""
    return loops.make_loop("remus100", VARIANTS[0]).gains_from_json(d)


def run_experiment(
    out, gains, *, horizon, dt, current, progress=print, waves=None, wave_seed=0
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
    )
    result["printed"] = result["metrics"]
    result["unhealthy"] = [
        f"remus100 {name}: a non-finite or runaway state, or more than 25 m off the path "
        "(see metrics.json)"
        for name, m in result["metrics"].items()
        if not m.get("healthy", True)
    ]
    return result
