"""The paper's Simulation 2 (Section 4.3, Figs. 6–7; docs/experiments): ODIN-class AUV on a 3-D
helix.

Scenario (paper): from rest at ``p0 = [0, 0, -102]`` (used as NED coordinates, as printed),
constant body disturbance ``tau_dist = [0, 5, 0]`` N, helix
``p_p(w) = [10 sin(w/5), 8 cos(w/5), 0.1 w - 100]``
([`vcjax.paths.paper_helix`][vcjax.paths.paper_helix]). The paper
does not give the speed, the initial heading or the gains; here ``u_d = 0.5 m/s`` (ODIN-class
cruise limit ~1 m/s at full surge force), ``psi0 = 0`` (the helix's tangent at ``w = 0``), and
the gains of ``default_gains``.

Control loop: [`vcjax.loops.odin.OdinLoop`][vcjax.loops.odin.OdinLoop] (horizontal VCM law + depth
PID + roll/pitch
PD + thruster allocation), continuous-time, evaluated inside the integrator like Simulation 1;
controller ``"vcm"`` (underactuated, the paper) or ``"vcm_full"`` (sway thrust available).

Options (``vcjax simulate sim2``): ``--actuation`` (the headline mode; the other is run for
comparison), ``--diverge-e``, ``--waves``/``--wave-seed``
([`vcjax.experiments.seas`][vcjax.experiments.seas]).

Metrics ([`Sim2.metrics`][vcjax.experiments.sim2.Sim2.metrics]) are evaluated after the first 20 %
of the run (the approach from
8 m away is a transient): ``rms_dist_3d`` / ``max_dist_3d`` (3-D distance between the vehicle and
the path particle ``p_p(w)``), ``rms_depth_err``, ``thruster_sat_fraction`` (fraction of steps in
which at least one thruster is commanded at its limit, whole run).
"""

from __future__ import annotations

import dataclasses
from typing import Literal

import jax.numpy as jnp
import numpy as np

from vcjax import loops
from vcjax.experiments.base import Experiment, PathBound, option
from vcjax.experiments.seas import WaveOptions, option_sea, option_sea_record
from vcjax.metrics import path_bound, run_metrics
from vcjax.vehicles import odin

__all__ = [
    "SIM2",
    "Sim2",
    "Sim2Options",
    "ACTUATIONS",
    "REPORTED",
    "WAVE_ORIGIN_DEPTH",
    "sim2_extras",
]

#: the actuation modes: the ``odin`` loop's controller of each
ACTUATIONS = {"underactuated": "vcm", "full": "vcm_full"}
#: The paper's start ``p0`` (NED [m]) and heading [rad], the body disturbance ``[X, Y, Z]`` [N],
#: the desired speed [m/s]; the vehicle starts level and at rest, the particle at ``w = 0``.
P0, PSI0, TAU_DIST, U_D = (0.0, 0.0, -102.0), 0.0, (0.0, 5.0, 0.0), 0.5
#: the metrics' window: after the first ``SKIP`` of the run
SKIP = 0.2
#: depth of the NED origin below the mean free surface with ``--waves`` [m]: the paper's start
#: ``z = -102`` (as printed) then lies 5 m below the surface, the helix descending from 7 m
WAVE_ORIGIN_DEPTH = 107.0


@dataclasses.dataclass(frozen=True)
class Sim2Options(PathBound, WaveOptions):
    """Options of ``vcjax simulate sim2`` (``--diverge-e`` default: 25 % of ``u_d x
    horizon``, at least 50 m, [`vcjax.metrics.path_bound`][vcjax.metrics.path_bound]). The loop's
    own options
    (integral action, the VCM heading row, allocation polish) are the ``odin`` loop's defaults."""

    actuation: Literal["underactuated", "full"] = option(
        "underactuated",
        "headline mode (the paper: underactuated); the other is run for comparison",
    )


#: ``metrics.json`` per actuation mode: its name -> the name in
#: [`vcjax.metrics.run_metrics`][vcjax.metrics.run_metrics]'s result (generic metrics and
#: [`sim2_extras`][vcjax.experiments.sim2.sim2_extras])
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
    """Simulation 2's own metrics as extras of
    [`vcjax.metrics.run_metrics`][vcjax.metrics.run_metrics] (jnp): the
    ODIN-class diagnostics over the steady-state window ``win`` (states before each step) —
    ``mean_abs_sideslip_deg`` (``atan2(v, u)``), ``mean_speed`` (of the linear velocity),
    ``max_abs_roll_pitch_deg`` (the window's states and the final one); over the whole run —
    ``alloc_infeasible_fraction``, ``max_alloc_residual`` (the thruster allocation),
    ``final_varpi``; the window's start ``settled_from_s`` and the run's ``horizon_s`` [s]; and
    ``run_healthy``: no step diverged and the vehicle never further than ``bound`` [m] from the
    path particle's point ([`vcjax.metrics.path_bound`][vcjax.metrics.path_bound])."""
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


@dataclasses.dataclass(frozen=True)
class Sim2(Experiment):
    """Simulation 2: the ``odin`` loop on the paper's helix, the headline actuation mode and the
    other for comparison (variants: the modes)."""

    def variants(self, options=None) -> tuple[str, ...]:
        actuation = "underactuated" if options is None else options.actuation
        return (actuation, *(m for m in ACTUATIONS if m != actuation))

    def loop(self, variant: str, options=None) -> loops.Loop:
        if variant not in ACTUATIONS:
            raise ValueError(f"actuation: expected one of {tuple(ACTUATIONS)}, got {variant!r}")
        return loops.make_loop("odin", ACTUATIONS[variant])

    def scenario(self, variant: str = "underactuated", setup=None) -> loops.Scenario:
        """The paper's scenario (the same for both modes); with ``--waves`` the sea, the NED
        origin ``WAVE_ORIGIN_DEPTH`` below the mean free surface."""
        setup = self.setup() if setup is None else setup
        vehicle = odin.odin_params()
        args = odin.odin_args(vehicle, TAU_DIST)  # tau_dist (3,) -> (6,)
        eta0 = np.concatenate([np.asarray(P0, float), [0.0, 0.0], [float(PSI0)]])
        waves = setup.options.waves
        self.loop(variant)  # a known mode: both run the same scenario
        sc = loops.make_scenario(
            self.loop("underactuated"),
            eta0=eta0,
            nu0=np.zeros(6),
            current=args.water.velocity,
            u_d=U_D,
            plant=vehicle,
            disturbance=args.tau_dist,
            varpi0=0.0,
            dtype=args.tau_dist.dtype,
        )
        if waves is None:
            return sc
        sea = option_sea(waves, setup.options.seed)
        return sc._replace(sea=sea, origin_depth=jnp.asarray(WAVE_ORIGIN_DEPTH, sc.eta0.dtype))

    def metrics(self, outcome, setup) -> dict:
        """``REPORTED`` of one run as Python values:
        [`vcjax.metrics.run_metrics`][vcjax.metrics.run_metrics]
        from ``SKIP x T`` on (``thruster_sat_fraction`` is its ``sat_fraction``, whole run)
        with [`sim2_extras`][vcjax.experiments.sim2.sim2_extras]; ``healthy`` also needs the vehicle
        within the path-error
        bound ([`vcjax.metrics.path_bound`][vcjax.metrics.path_bound], scaled to ``u_d x horizon``,
        or
        ``--diverge-e`` [m])."""
        traj, sc = outcome.traj, outcome.scenario
        sig = outcome.loop.signals(traj, sc)
        t = np.asarray(traj.t)
        u_d = float(np.asarray(sc.u_d))
        bound = path_bound(u_d, float(t[-2] + (t[1] - t[0])), setup.options.diverge_e)
        dt = traj.t[1] - traj.t[0]
        m = run_metrics(sig, traj.finite, dt, start=SKIP, extras=sim2_extras(traj, bound))
        out = {}
        for ours, theirs in REPORTED.items():
            v = np.asarray(m[theirs])
            out[ours] = bool(v) if v.dtype == bool else float(v)
        return out

    def report(self, results, setup) -> dict:
        """The headline mode's metrics at the top level, every mode's under ``by_actuation``,
        the sea under ``waves``."""
        actuation = setup.options.actuation
        report = {"actuation": actuation, **results[actuation], "by_actuation": results}
        if setup.options.waves is not None:
            o = setup.options
            report["waves"] = option_sea_record(o.waves, o.seed, WAVE_ORIGIN_DEPTH)
        return report

    def figures(self, outcomes, setup, out):
        from vcjax.plots.sim2 import sim2_figures

        trajs = {v: o.traj for v, o in outcomes.items()}
        first = next(iter(outcomes.values()))
        return sim2_figures(trajs, first.scenario, first.loop.path, out)

    def printed(self, results) -> dict:
        def number(v):
            return isinstance(v, int | float) and not isinstance(v, bool)

        return {mode: {k: v for k, v in m.items() if number(v)} for mode, m in results.items()}

    def unhealthy(self, results, outcomes, setup) -> list[str]:
        return [
            f"sim2 {mode} diverged (see metrics.json)"
            for mode, m in results.items()
            if not m.get("healthy", True)
        ]

    def label(self, variant: str) -> str:
        return f"ODIN-class, {variant}"


SIM2 = Sim2(
    "sim2",
    "Simulation 2 (ODIN-class, helix, Figs. 6-7), both actuation modes",
    horizon=300.0,
    dt=0.05,
    options=Sim2Options,
)
