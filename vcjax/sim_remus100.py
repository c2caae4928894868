"""REMUS 100 survey mission: 3-D VCM path maneuvering and baselines on the PVS plant.

Mission (``vcjax simulate remus100``): start at the surface, descend to ``depth`` metres over the
first ``descent`` metres of a lawnmower (:func:`vcjax.paths.lawnmower`, legs along north joined by
half circles), under a constant current of ``V_c`` m/s towards the east — across the legs. The
plant is :func:`vcjax.vehicles.remus100.remus100_plant` (PythonVehicleSimulator's model, hard
actuator limits and lags); every law's body force goes through the same actuator map
(:func:`vcjax.vehicles.remus100_design.actuator_map`). The controller is sampled (zero-order
hold at the step ``dt``), the plant integrated by RK4.

Variants (:data:`VARIANTS`):

* ``vcm3d_ilos``: 3-D VCM (:mod:`vcjax.control.vcm3d`), underactuated in sway and heave,
  integral action and integral-LOS angles in both planes;
* ``vcm3d_paper``: the same with the paper's approach angles (24) (integral action kept);
* ``decoupled``: the paper's design — horizontal VCM (31)/(38) with ILOS and integral action +
  depth through pitch (:func:`vcjax.control.baselines3d.decoupled_law`);
* ``alos3d``: ALOS3D guidance (Fossen & Aguiar 2024) + PID heading/pitch autopilots + surge PI;
* ``pvs_pid``: heading/depth PID autopilots with plain LOS angles (PVS-like sanity run).

Metrics (:func:`mission_metrics`, numpy, from the trajectory alone): the 3-D distance to the
path is measured geometrically (nearest point of a dense polyline of the path), independent of
each law's own error signals.
"""

from __future__ import annotations

import functools
import json
from pathlib import Path
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from vcjax import paths
from vcjax.control.baselines3d import (
    AutopilotConfig,
    DecoupledConfig,
    autopilot_gains,
    autopilot_law,
    autopilot_state,
    baseline3d_params,
    decoupled_law,
    decoupled_state,
)
from vcjax.control.vcm import VCMConfig, pm_gains, vcm_params, vcm_state
from vcjax.control.vcm3d import (
    VCM3DConfig,
    vcm3d_gains,
    vcm3d_law,
    vcm3d_params,
    vcm3d_state,
)
from vcjax.rollout import RolloutConfig, rollout
from vcjax.vehicles import remus100 as r100
from vcjax.vehicles import remus100_design as rd
from vcjax.vehicles.sixdof import kinematics

__all__ = [
    "VARIANTS",
    "LABELS",
    "LoopAux",
    "mission_path",
    "vehicle",
    "initial_state",
    "make_controller",
    "default_gains",
    "controller_params",
    "initial_controller_state",
    "simulate",
    "mission_metrics",
    "run_remus100",
]

VARIANTS = ("vcm3d_ilos", "vcm3d_paper", "decoupled", "alos3d", "pvs_pid")
LABELS = {
    "vcm3d_ilos": "3-D VCM, ILOS + integral",
    "vcm3d_paper": "3-D VCM, paper angles + integral",
    "decoupled": "2-D VCM + depth via pitch",
    "alos3d": "ALOS3D + PID autopilots",
    "pvs_pid": "PID autopilots, plain LOS",
}
_IDX = np.asarray(rd.IDX5)


class LoopAux(NamedTuple):
    """What every variant records per step: eps (3,) [m], psi_d, theta_d [rad], tau (5,) body
    force, raw (3,) actuator commands before clipping."""

    eps: Any
    psi_d: Any
    theta_d: Any
    tau: Any
    raw: Any


def mission_path(leg=250.0, radius=30.0, n_legs=4, depth=15.0, descent=150.0, start_depth=1.0):
    """The survey path ``(path, coeffs)`` (a :func:`vcjax.paths.lawnmower`)."""
    return paths.lawnmower((0.0, 0.0, start_depth), leg, radius, n_legs, depth, descent)


def vehicle(U_design=1.5):
    """``(Remus100Params, Remus100Design)`` with PVS's numbers."""
    p = r100.remus100_params()
    return p, rd.design_model(p, U_design=U_design)


def initial_state(offset=(0.0, 3.0, 0.0), pitch=0.0, u0=1.5, rpm0=1000.0, start_depth=1.0):
    """REMUS at the start of the path, heading north, ``offset`` (3,) NED [m] from the path's start
    point, pitch [rad], surge ``u0`` [m/s], propeller at ``rpm0``."""
    o = np.asarray(offset, float)
    eta = [o[0], o[1], start_depth + o[2], 0.0, float(pitch), 0.0]
    return r100.remus100_state(eta=eta, nu=[u0, 0, 0, 0, 0, 0], act=[0.0, 0.0, rpm0])


def _measure(x):
    """``(q5, qd5, nu5)`` from the plant state (roll dropped)."""
    qd = kinematics(x.eta) @ x.nu
    return x.eta[_IDX], qd[_IDX], x.nu[_IDX]


@functools.cache
def make_controller(variant: str, path: paths.Path):
    """The closed-loop controller ``c(t, x, z, params) -> (act_cmd, z_dot, LoopAux)`` (cached,
    so a jitted rollout compiles once per variant and path kind)."""
    if variant not in VARIANTS:
        raise ValueError(f"variant: expected one of {VARIANTS}, got {variant!r}")
    if variant.startswith("vcm3d"):
        cfg = VCM3DConfig(
            path=path,
            system=rd.design_system(),
            kinematics=rd.kinematics5,
            tied_rows=rd.unactuated_rows,
            actuation="underactuated",
            integral=True,
            guidance="ilos" if variant == "vcm3d_ilos" else "los",
        )

        def law(t, q, qd, nu5, z, params):
            tau, z_dot, aux = vcm3d_law(cfg, params, t, q, qd, z)
            return tau, z_dot, aux.eps, aux.psi_d, aux.theta_d

        dm_of = lambda params: params.model
    elif variant == "decoupled":
        cfg = DecoupledConfig(
            VCMConfig(path=path, actuation="underactuated", integral=True, guidance="ilos")
        )

        def law(t, q, qd, nu5, z, params):
            tau, z_dot, aux = decoupled_law(cfg, params[0], t, q, qd, nu5, z)
            return tau, z_dot, aux.eps, aux.psi_d, aux.theta_d

        dm_of = lambda params: params[1]
    else:
        cfg = AutopilotConfig(path=path, guidance="alos" if variant == "alos3d" else "los")

        def law(t, q, qd, nu5, z, params):
            tau, z_dot, aux = autopilot_law(cfg, params[0], t, q, qd, nu5, z)
            return tau, z_dot, aux.eps, aux.psi_d, aux.theta_d

        dm_of = lambda params: params[1]

    def controller(t, x, z, params):
        q, qd, nu5 = _measure(x)
        tau, z_dot, eps, psi_d, theta_d = law(t, q, qd, nu5, z, params)
        act = rd.actuator_map(dm_of(params), tau, x.nu)
        return act.cmd, z_dot, LoopAux(eps, psi_d, theta_d, tau, act.raw)

    return controller


def default_gains(variant: str):
    """Hand-set gains of each variant (order-one dynamics, slower than the fins)."""
    if variant.startswith("vcm3d"):
        return vcm3d_gains(
            P_G=(0.5, 0.5, 0.2, 0.2, 0.2),
            P_Phi=(0.5, 0.3, 0.3, 1.0, 1.0, 0.4, 0.4, 0.4),
            Delta=(8.0, 8.0),
            sigma=0.3,
            k_int=(0.03, 0.03, 0.03),
            sigma_i=(0.5, 0.5),
        )
    if variant == "decoupled":
        return (
            pm_gains(P_G=(0.5, 0.2, 0.2), P_Phi=(0.5, 0.3, 1.0, 0.4, 0.4), Delta=8.0, sigma=0.3,
                     P_int=(0.001, 0.001), sigma_i=0.5),
            autopilot_gains(Delta=(8.0, 20.0), gamma=(0.5, 0.2)),
        )  # fmt: skip
    return autopilot_gains()


def _inertia_and_drag(dm, u_d):
    M = np.asarray(rd.mass_matrix5(dm))
    nu = jnp.asarray([u_d, 0.0, 0.0, 0.0, 0.0], dtype=jnp.asarray(dm.U_design).dtype)
    drag = rd.body_bias5(dm, jnp.zeros_like(nu), nu)[0]
    return (M[0, 0], M[3, 3], M[4, 4]), drag


def controller_params(variant: str, coeffs, dm, u_d=1.5, gains=None):
    """Traced parameters of a variant's controller (``gains`` default: :func:`default_gains`)."""
    gains = default_gains(variant) if gains is None else gains
    if variant.startswith("vcm3d"):
        return vcm3d_params(gains, dm, coeffs, u_d=u_d)
    inertia, drag = _inertia_and_drag(dm, u_d)
    if variant == "decoupled":
        horiz = vcm_params(
            gains[0],
            rd.horizontal_design(dm),
            coeffs,
            u_d=u_d,
            k_rudder=1.0 / float(dm.vehicle.x_r),
        )
        return (baseline3d_params(gains[1], inertia, drag, coeffs, u_d, horiz), dm)
    return (baseline3d_params(gains, inertia, drag, coeffs, u_d), dm)


def initial_controller_state(variant: str):
    if variant.startswith("vcm3d"):
        return vcm3d_state()
    if variant == "decoupled":
        return decoupled_state(vcm_state())
    return autopilot_state()


_run = jax.jit(rollout, static_argnames=("plant", "controller", "config"))


def simulate(
    variant, horizon=880.0, dt=0.05, current=(0.0, 0.3), path=None, x0=None, gains=None, u_d=1.5
):  # fmt: skip
    """One closed-loop run; returns ``(trajectory, (path, coeffs))``.

    ``current``: (2,) NED water velocity ``[north, east]`` [m/s] (default: 0.3 m/s towards east,
    across the legs).
    """
    path, coeffs = path if path is not None else mission_path()
    p, dm = vehicle()
    args = r100.remus100_args(p, v_c=current)
    params = controller_params(variant, coeffs, dm, u_d, gains)
    x0 = initial_state() if x0 is None else x0
    conf = RolloutConfig(num_steps=int(round(horizon / dt)), timing="sampled")
    ctrl = make_controller(variant, path)
    z0 = initial_controller_state(variant)
    traj = _run(r100.remus100_plant, ctrl, conf, args, params, x0, z0, dt)
    return traj, (path, coeffs)


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
    finite = bool(np.all(np.asarray(traj.finite)))

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


def run_remus100(out, horizon=880.0, dt=0.05, current=(0.0, 0.3), variants=VARIANTS) -> dict:
    """Run every variant of the survey mission; write ``metrics.json`` and figures to ``out``."""
    from vcjax.plots_remus100 import remus100_figures

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    trajs, metrics = {}, {}
    for v in variants:
        traj, (path, coeffs) = simulate(v, horizon, dt, current)
        trajs[v] = jax.device_get(traj)
        metrics[v] = mission_metrics(trajs[v], path, coeffs)
    meta = {"horizon": horizon, "dt": dt, "current_ned": [float(c) for c in current]}
    clean = {v: {k: (None if isinstance(x, float) and not np.isfinite(x) else x)
                 for k, x in m.items()} for v, m in metrics.items()}  # fmt: skip
    (out / "metrics.json").write_text(json.dumps({"config": meta, "variants": clean}, indent=2))
    files = [out / "metrics.json"]
    files += remus100_figures(trajs, path, coeffs, out, LABELS)
    return {"metrics": metrics, "files": files}
