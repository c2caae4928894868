"""The paper's Simulation 2 (Section 4.3, Figs. 6–7; docs/experiments): ODIN-class AUV on a 3-D
helix.

Scenario (paper): from rest at ``p0 = [0, 0, -102]`` (used as NED coordinates, as printed),
constant body disturbance ``tau_dist = [0, 5, 0]`` N, helix
``p_p(w) = [10 sin(w/5), 8 cos(w/5), 0.1 w - 100]`` (:func:`vcjax.paths.paper_helix`). The paper
does not give the speed, the initial heading or the gains; here ``u_d = 0.5 m/s`` (ODIN-class
cruise limit ~1 m/s at full surge force), ``psi0 = 0`` (the helix's tangent at ``w = 0``), and
the gains of :func:`default_gains`.

Control loop: :class:`vcjax.loops.odin.OdinLoop` (horizontal VCM law + depth PID + roll/pitch
PD + thruster allocation), continuous-time, evaluated inside the integrator like Simulation 1;
controller ``"vcm"`` (underactuated, the paper) or ``"vcm_full"`` (sway thrust available).

Metrics (:func:`sim2_metrics`) are evaluated after the first 20 % of the run (the approach from
8 m away is a transient): ``rms_dist_3d`` / ``max_dist_3d`` (3-D distance between the vehicle and
the path particle ``p_p(w)``), ``rms_depth_err``, ``thruster_sat_fraction`` (fraction of steps in
which at least one thruster is commanded at its limit, whole run).
"""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Any, Literal

import jax
import jax.numpy as jnp
import numpy as np

from vcjax import loops, paths
from vcjax._checks import check_array, check_positive
from vcjax.experiments.seas import option_sea, option_sea_record
from vcjax.loops.odin import OdinGains, OdinLoop, default_odin_gains, odin_gains
from vcjax.metrics import path_bound, run_metrics
from vcjax.rollout import RolloutConfig
from vcjax.runtime.outputs import write_json_atomic
from vcjax.vehicles import odin

__all__ = [
    "PATH",
    "ACTUATIONS",
    "sim2_scenario",
    "sim2_gains",
    "default_gains",
    "gains_from_json",
    "Sim2Config",
    "run_variant",
    "sim2_extras",
    "sim2_metrics",
    "REPORTED",
    "run_sim2",
    "sim2_sea",
    "WAVE_ORIGIN_DEPTH",
]

#: Simulation 2's path kind (the helix); its coefficients live in the scenario's ``path``.
PATH, _PATH_COEFFS = paths.paper_helix()
ACTUATIONS = ("underactuated", "full")


def sim2_scenario(
    p0=(0.0, 0.0, -102.0),
    psi0=0.0,
    tau_dist=(0.0, 5.0, 0.0),
    current=(0.0, 0.0, 0.0),
    u_d=0.5,
    varpi0=0.0,
    vehicle=None,
    path_coeffs=None,
) -> loops.Scenario:
    """The paper's Simulation 2 scenario (defaults), validated; starts level and at rest.

    Args:
        p0: (3,) NED start [m]; psi0: () heading [rad]; tau_dist: (3,) or (6,) body disturbance;
        current: (3,) water velocity in NED [m/s]; u_d: () desired speed [m/s];
        varpi0: () particle start; vehicle: :class:`~vcjax.vehicles.odin.OdinParams` (default
        ``odin_params()``); path_coeffs: coefficients for the path kind of the
        :class:`Sim2Config` used (default: the paper's helix).

    Returns:
        :class:`~vcjax.loops.Scenario` (:func:`vcjax.loops.make_scenario` of the ``odin``
        loop; ``plant`` and ``design`` both ``vehicle``).
    """
    check_array("p0", p0, (3,))
    check_array("psi0", psi0, ())
    check_positive("u_d", u_d, ())
    check_array("varpi0", varpi0, ())
    vehicle = odin.odin_params() if vehicle is None else odin.validate(vehicle)
    args = odin.odin_args(vehicle, tau_dist, current)  # tau_dist (3,) -> (6,), both validated
    dtype = args.tau_dist.dtype
    eta0 = np.concatenate([np.asarray(p0, float), [0.0, 0.0], [float(psi0)]])
    return loops.make_scenario(
        Sim2Config().loop(),  # the scenario is the same for every Simulation 2 loop
        _PATH_COEFFS if path_coeffs is None else path_coeffs,
        eta0=eta0,
        nu0=np.zeros(6),
        current=args.v_c,
        u_d=u_d,
        plant=vehicle,
        disturbance=args.tau_dist,
        varpi0=varpi0,
        dtype=dtype,
    )


def sim2_gains(vcm=None, depth=(0.09, 0.6, 0.005), attitude=(10.0, 8.0), int_z_limit=20.0):
    """Validated :class:`~vcjax.loops.odin.OdinGains` (:func:`vcjax.loops.odin.odin_gains`)."""
    return odin_gains(vcm=vcm, depth=depth, attitude=attitude, int_z_limit=int_z_limit)


def default_gains(actuation: str = "underactuated") -> OdinGains:
    """Gains used for the paper's Simulation 2, per actuation mode
    (:func:`vcjax.loops.odin.default_odin_gains`, which explains them)."""
    if actuation not in ACTUATIONS:
        raise ValueError(f"actuation: expected one of {ACTUATIONS}, got {actuation!r}")
    return default_odin_gains(actuation)


def gains_from_json(d: dict, actuation: str = "underactuated") -> OdinGains:
    """Gains from the JSON ``vcjax tune`` writes for the ODIN-class loop (missing entries take
    the defaults of ``actuation``), validated."""
    return Sim2Config(actuation=actuation).loop().gains_from_json(d)


@dataclasses.dataclass(frozen=True)
class Sim2Config:
    """Static choices of the Simulation 2 loop (:meth:`loop` gives the
    :class:`~vcjax.loops.odin.OdinLoop`).

    Attributes:
        path: path kind (default: the paper's helix).
        actuation: ``"underactuated"`` (paper; ``tau_v = 0``) or ``"full"``.
        integral: integral action (41) in the VCM law (gains ``P_int``).
        edd: ``"paper"`` or ``"implied"`` (see :mod:`vcjax.control.vcm`).
        polish: projected-gradient steps of the allocation (see :mod:`vcjax.allocation`).
    """

    path: Any = PATH
    actuation: Literal["underactuated", "full"] = "underactuated"
    integral: bool = True
    edd: Literal["paper", "implied"] = "paper"
    polish: int = 50

    def __post_init__(self):
        if self.actuation not in ACTUATIONS:
            raise ValueError(f"actuation: expected one of {ACTUATIONS}, got {self.actuation!r}")

    def loop(self) -> OdinLoop:
        ctrl = "vcm" if self.actuation == "underactuated" else "vcm_full"
        return loops.make_loop(
            "odin", ctrl, path=self.path, integral=self.integral, edd=self.edd, polish=self.polish
        )


_run = jax.jit(loops.simulate, static_argnames=("loop", "config"))


def run_variant(
    config: Sim2Config | None = None,
    gains: OdinGains | None = None,
    scenario: loops.Scenario | None = None,
    horizon: float = 300.0,
    dt: float = 0.05,
    timing: str = "continuous",
):
    """Roll the Simulation 2 loop out; returns the :class:`~vcjax.rollout.Trajectory`.

    ``traj.x`` is an :class:`~vcjax.vehicles.odin.OdinState`, ``traj.z`` an
    :class:`~vcjax.loops.odin.OdinCtrlState`, ``traj.u`` the (N, 8) thruster commands,
    ``traj.aux`` an :class:`~vcjax.loops.odin.OdinAux`.
    """
    if not (horizon > 0 and dt > 0 and horizon / dt >= 1):
        raise ValueError(f"horizon and dt must be positive with horizon >= dt, got {horizon}, {dt}")
    config = Sim2Config() if config is None else config
    gains = default_gains(config.actuation) if gains is None else gains
    sc = sim2_scenario() if scenario is None else scenario
    rc = RolloutConfig(num_steps=int(round(horizon / dt)), integrator="rk4", timing=timing)
    return _run(config.loop(), gains, sc, rc, dt)


#: ``metrics.json`` per actuation mode: its name -> the name in
#: :func:`vcjax.metrics.run_metrics`'s result (generic metrics and :func:`sim2_extras`)
REPORTED = {
    "rms_dist_3d": "rms_dist_3d",
    "max_dist_3d": "max_dist_3d",
    "rms_depth_err": "rms_depth_err",
    "thruster_sat_fraction": "sat_fraction",
    "rms_along_track_s": "rms_along_track_s",
    "rms_cross_track_e": "rms_cross_track_e",
    "mean_abs_sideslip_deg": "mean_abs_sideslip_deg",
    "mean_speed": "mean_speed",
    "max_abs_roll_pitch_deg": "max_abs_roll_pitch_deg",
    "alloc_infeasible_fraction": "alloc_infeasible_fraction",
    "max_alloc_residual": "max_alloc_residual",
    "final_varpi": "final_varpi",
    "settled_from_s": "settled_from_s",
    "horizon_s": "horizon_s",
    "healthy": "run_healthy",
}


def sim2_extras(traj, bound: float) -> dict:
    """Simulation 2's own metrics as extras of :func:`vcjax.metrics.run_metrics` (jnp): the
    ODIN-class diagnostics over the steady-state window ``win`` (states before each step) —
    ``mean_abs_sideslip_deg`` (``atan2(v, u)``), ``mean_speed`` (of the linear velocity),
    ``max_abs_roll_pitch_deg`` (the window's states and the final one); over the whole run —
    ``alloc_infeasible_fraction``, ``max_alloc_residual`` (the thruster allocation),
    ``final_varpi``; the window's start ``settled_from_s`` and the run's ``horizon_s`` [s]; and
    ``run_healthy``: no step diverged and the vehicle never further than ``bound`` [m] from the
    path particle's point (:func:`vcjax.metrics.path_bound`)."""
    nu = traj.x.nu[:-1]
    t = traj.t[:-1]

    def mean(a, win):
        return jnp.sum(jnp.where(win, a, 0.0)) / jnp.sum(win.astype(a.dtype))

    def roll_pitch(sig, win):
        win1 = jnp.concatenate([win, jnp.ones(1, bool)])  # and the final state
        rp = jnp.where(win1[:, None], jnp.abs(traj.x.eta[:, 3:5]), -jnp.inf)
        return jnp.degrees(jnp.max(rp))

    def healthy(sig, win):
        dist = jnp.sqrt(jnp.sum(sig.p_err**2, axis=1))
        return ~jnp.any(traj.diverged) & ~jnp.any(~(dist <= bound))

    infeasible = (~traj.aux.alloc_feasible).astype(nu.dtype)
    return {
        "mean_abs_sideslip_deg": lambda sig, win: jnp.degrees(
            mean(jnp.abs(jnp.arctan2(nu[:, 1], nu[:, 0])), win)
        ),
        "mean_speed": lambda sig, win: mean(jnp.sqrt(jnp.sum(nu[:, :3] ** 2, axis=1)), win),
        "max_abs_roll_pitch_deg": roll_pitch,
        "alloc_infeasible_fraction": lambda sig, win: jnp.mean(infeasible),
        "max_alloc_residual": lambda sig, win: jnp.max(traj.aux.alloc_residual),
        "final_varpi": lambda sig, win: traj.z.vcm.varpi[-1],
        "settled_from_s": lambda sig, win: t[jnp.argmax(win)],
        "horizon_s": lambda sig, win: t[-1] + (t[1] - t[0]),
        "run_healthy": healthy,
    }


def sim2_metrics(
    traj, scenario: loops.Scenario | None = None, skip: float = 0.2, config=None, diverge_e=None
) -> dict:
    """Metrics of one run (module docstring; :data:`REPORTED`) as Python values; ``skip``:
    fraction of the run left out.

    :func:`vcjax.metrics.run_metrics` from :math:`0.2 T` on (``thruster_sat_fraction`` is its
    ``sat_fraction``, whole run) with the ODIN-specific diagnostics of this experiment added
    (:func:`sim2_extras`); ``healthy`` also needs the vehicle within the path-error bound
    (:func:`vcjax.metrics.path_bound`, scaled to ``u_d x horizon``, or ``diverge_e`` [m]).
    """
    sc = sim2_scenario() if scenario is None else scenario
    loop = (Sim2Config() if config is None else config).loop()
    sig = loop.signals(traj, sc)
    t = np.asarray(traj.t)
    bound = path_bound(float(np.asarray(sc.u_d)), float(t[-2] + (t[1] - t[0])), diverge_e)
    dt = traj.t[1] - traj.t[0]
    m = run_metrics(sig, traj.finite, dt, start=skip, extras=sim2_extras(traj, bound))
    out = {}
    for ours, theirs in REPORTED.items():
        v = np.asarray(m[theirs])
        out[ours] = bool(v) if v.dtype == bool else float(v)
    return out


#: depth of the NED origin below the mean free surface with ``--waves`` [m]: the paper's start
#: ``z = -102`` (as printed) then lies 5 m below the surface, the helix descending from 7 m
WAVE_ORIGIN_DEPTH = 107.0


def sim2_sea(waves, seed=0):
    """``(sea, origin_depth)`` of ``vcjax simulate sim2 --waves HS TP DIR_DEG``: a long-crested
    JONSWAP sea (``gamma = 3.3``, 64 components) drawn from ``PRNGKey(seed)``
    (:func:`vcjax.environment.waves.sea_state`), and :data:`WAVE_ORIGIN_DEPTH`."""
    return option_sea(waves, seed), WAVE_ORIGIN_DEPTH


def run_sim2(
    out: Path,
    gains: OdinGains | None = None,
    horizon: float = 300.0,
    dt: float = 0.05,
    actuation: str = "underactuated",
    compare: bool = True,
    progress=print,
    diverge_e: float | None = None,
    waves=None,
    wave_seed: int = 0,
) -> dict:
    """Run Simulation 2, write ``metrics.json`` and the figures (PNG) into ``out``
    (``diverge_e``: path-error bound [m] of ``healthy``, default :func:`vcjax.metrics.path_bound`).

    Args:
        out: output folder (created).
        gains: :class:`~vcjax.loops.odin.OdinGains` for both modes (default:
            :func:`default_gains` of each mode).
        horizon, dt: run length and RK4 step [s].
        actuation: the headline mode, ``"underactuated"`` (paper) or ``"full"``; its metrics are
            the top-level entries of ``metrics.json``.
        compare: also run the other actuation mode (overlaid in the figures; its metrics under
            ``metrics["by_actuation"]``).
        progress: callback taking a status line.
        waves: ``(hs [m], tp [s], direction [deg])`` of one random sea for every run
            (:func:`sim2_sea`, from ``wave_seed``), or None.

    Returns:
        ``{"metrics": dict, "files": [Path, ...]}``.
    """
    from vcjax.plots.sim2 import sim2_figures

    if actuation not in ACTUATIONS:
        raise ValueError(f"actuation: expected one of {ACTUATIONS}, got {actuation!r}")
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    sc = sim2_scenario()
    if waves is not None:
        sea, origin_depth = sim2_sea(waves, wave_seed)
        sc = sc._replace(sea=sea, origin_depth=jnp.asarray(origin_depth, sc.eta0.dtype))
    modes = [actuation] + ([m for m in ACTUATIONS if m != actuation] if compare else [])
    trajs, by_mode = {}, {}
    for i, mode in enumerate(modes):
        progress(
            f"[{i + 1}/{len(modes)}] simulating ODIN-class, {mode} ({horizon:g} s, dt {dt:g} s)"
        )
        cfg = Sim2Config(actuation=mode)
        trajs[mode] = jax.device_get(run_variant(cfg, gains, sc, horizon, dt))
        by_mode[mode] = sim2_metrics(trajs[mode], sc, config=cfg, diverge_e=diverge_e)
    metrics = {"actuation": actuation, **by_mode[actuation], "by_actuation": by_mode}
    if waves is not None:
        metrics["waves"] = option_sea_record(waves, wave_seed, WAVE_ORIGIN_DEPTH)
    write_json_atomic(out / "metrics.json", metrics)
    files = sim2_figures(trajs, sc, PATH, out)
    return {"metrics": metrics, "files": [out / "metrics.json", *files]}


def load_gains(d: dict, actuation: str = "underactuated", **_options) -> OdinGains:
    """The experiment's gains from a gains-JSON object (:func:`gains_from_json`)."""
    return gains_from_json(d, actuation)


def run_experiment(
    out,
    gains,
    *,
    horizon,
    dt,
    current,
    progress=print,
    actuation="underactuated",
    diverge_e=None,
    waves=None,
    wave_seed=0,
) -> dict:
    """``vcjax simulate sim2`` (:mod:`vcjax.experiments`): :func:`run_sim2` (no current)."""
    assert current is None  # the registry declares no current for sim2
    result = run_sim2(
        out,
        gains,
        horizon=horizon,
        dt=dt,
        actuation=actuation,
        progress=progress,
        diverge_e=diverge_e,
        waves=waves,
        wave_seed=wave_seed,
    )
    by_mode = result["metrics"]["by_actuation"]
    result["printed"] = {
        mode: {k: v for k, v in m.items() if isinstance(v, int | float) and not isinstance(v, bool)}
        for mode, m in by_mode.items()
    }
    result["unhealthy"] = [
        f"sim2 {mode} diverged (see metrics.json)"
        for mode, m in by_mode.items()
        if not m.get("healthy", True)
    ]
    return result
