"""The paper's Simulation 1 (Section 4.3, Figs. 4–5; docs/experiments) and its baselines.

INFANTE-class (NPS-AUV-derived) plant, underactuated in sway; path ``p_p(w) = [10, w]`` (the
``infante`` loop's default path); ``q0 = [0, 0, pi/2]``, ``nu0 = [2 m/s, 0, 0]``; ocean current
``[0, 0.5] m/s`` (unknown to the controllers). Six controllers on the identical scenario:

* ``vcm``: VCM path maneuvering (31)/(38), no integral action;
* ``vcm_integral``: the same gains plus integral action (41);
* ``ilos``: integral LOS (40) with a heading PD;
* ``los_pid``: LOS heading with the PID yaw law (39);
* ``vcm_ilos`` (an extension, not in the paper): ``vcm_integral`` with the integral-LOS approach
  angle inside the VCM heading row (``VCMConfig(guidance="ilos")``), which removes the
  cross-track offset a cross current leaves with the paper's LOS angle;
* ``alos`` (a baseline not in the paper): Fossen's adaptive LOS (2023) with the same heading PD
  and surge loop as ``ilos`` and ``los_pid``.

Every controller maps its ``[tau_u, tau_r]`` to thrust and rudder commands with the vehicle's
actuator model ([`actuator_commands`][vcjax.vehicles.infante.actuator_commands]), using the
*measured* velocity
over ground (the current is unknown).

Options (``vcjax simulate sim1``): ``--edd`` (which ``e_ddot`` enters ``psi_d_ddot``),
``--timing`` (controller evaluated at every RK4 stage or once per step), ``--diverge-e``.
Metrics: [`vcjax.metrics.run_metrics`][vcjax.metrics.run_metrics] over the last 20 % of the run,
``METRIC_KEYS``,
with the experiment's health extras ([`health_extras`][vcjax.experiments.sim1.health_extras]).
"""

from __future__ import annotations

import dataclasses
from typing import Literal

import jax.numpy as jnp
import numpy as np

from vcjax import loops, metrics
from vcjax.experiments.base import Experiment, PathBound, option

__all__ = [
    "SIM1",
    "Sim1",
    "Sim1Options",
    "VARIANTS",
    "PAPER_VARIANTS",
    "METRIC_KEYS",
    "health_extras",
]

VARIANTS = ("vcm", "vcm_integral", "ilos", "los_pid", "vcm_ilos", "alos")
#: The four controllers of the paper's comparison (Simulation 1).
PAPER_VARIANTS = VARIANTS[:4]
#: What ``metrics.json`` reports per variant (see [`vcjax.metrics`][vcjax.metrics]), plus
#: ``healthy`` and
#: ``unhealthy_step``.
METRIC_KEYS = (
    "ss_abs_e",
    "ss_abs_s",
    "ss_abs_u_err",
    "iae_e",
    "max_abs_tau_u",
    "max_abs_rudder_deg",
    "sat_fraction",
)
#: The paper's start: pose ``[x, y, psi]``, body velocity, desired surge speed [m/s].
ETA0, NU0, U_D = (0.0, 0.0, np.pi / 2), (2.0, 0.0, 0.0), 2.0
#: steady-state window: the last ``TAIL`` of the run
TAIL = 0.2


@dataclasses.dataclass(frozen=True)
class Sim1Options(PathBound):
    """Options of ``vcjax simulate sim1`` (``--diverge-e`` default: 25 % of ``u_d x
    horizon``, at least 50 m, [`vcjax.metrics.path_bound`][vcjax.metrics.path_bound])."""

    edd: Literal["paper", "implied"] = option(
        "paper", "which e_ddot enters psi_d_ddot (paper = reference mode)"
    )
    timing: Literal["continuous", "sampled"] = option(
        "continuous", "controller evaluated at every RK4 stage, or once per step and held"
    )


def health_extras(traj, bound: float) -> dict:
    """Simulation 1's health as extras of [`vcjax.metrics.run_metrics`][vcjax.metrics.run_metrics]
    (jnp):
    ``unhealthy_step``, the first step whose state diverged (non-finite or beyond the rollout's
    bound, ``diverged``) or whose cross-track error left ``bound``
    [m] (NaN counts), -1 if none; ``healthy``, whether there is none."""

    def bad(sig):
        return traj.diverged | ~(jnp.abs(sig.eps[:, 1]) <= bound)

    return {
        "unhealthy_step": lambda sig, win: metrics.first_true(bad(sig)),
        "healthy": lambda sig, win: ~jnp.any(bad(sig)),
    }


@dataclasses.dataclass(frozen=True)
class Sim1(Experiment):
    """Simulation 1: every controller of the ``infante`` loop on the paper's line."""

    def variants(self, options=None) -> tuple[str, ...]:
        return VARIANTS

    def loop(self, variant: str, options=None) -> loops.Loop:
        if variant not in VARIANTS:
            raise ValueError(f"variant: expected one of {VARIANTS}, got {variant!r}")
        edd = "paper" if options is None else options.edd
        return loops.make_loop("infante", variant, edd=edd)

    def scenario(self, variant: str = "vcm", setup=None) -> loops.Scenario:
        """The paper's start under the setup's current; the particle starts abreast of the
        vehicle (the point of the line ``x = 10`` nearest to it)."""
        self.loop(variant)  # a known variant: every variant runs the same scenario
        setup = self.setup() if setup is None else setup
        loop = self.loop("vcm")
        return loops.make_scenario(loop, eta0=ETA0, nu0=NU0, current=setup.current, u_d=U_D)

    def metrics(self, outcome, setup) -> dict:
        """``METRIC_KEYS``, ``healthy`` (no step diverged: every state finite and within
        the rollout's bound, and the cross-track error within the path bound
        [`vcjax.metrics.path_bound`][vcjax.metrics.path_bound], default scaled to ``u_d x horizon``,
        or
        ``--diverge-e`` [m]) and ``unhealthy_step`` (the first such step, or ``None``)."""
        traj, sc = outcome.traj, outcome.scenario
        sig = outcome.loop.signals(traj, sc)
        t = np.asarray(traj.t)
        u_d = float(np.asarray(sc.u_d))
        bound = metrics.path_bound(u_d, t[-1] - t[0], setup.options.diverge_e)
        extras = health_extras(traj, bound)
        m = metrics.run_metrics(sig, traj.finite, traj.t[1] - traj.t[0], 1.0 - TAIL, extras=extras)
        out = {k: float(m[k]) for k in METRIC_KEYS}
        out["healthy"] = bool(m["healthy"])
        k = int(m["unhealthy_step"])
        out["unhealthy_step"] = None if k < 0 else k
        return out

    def figures(self, outcomes, setup, out):
        from vcjax.plots.sim1 import sim1_figures

        trajs = {v: o.traj for v, o in outcomes.items()}
        return sim1_figures(trajs, next(iter(outcomes.values())).scenario, out)

    def unhealthy(self, results, outcomes, setup) -> list[str]:
        lines = []
        for v, m in results.items():
            if m["healthy"]:
                continue
            k = m["unhealthy_step"]
            t = float(np.asarray(outcomes[v].traj.t)[k + 1])
            lines.append(
                f"{v} diverged at step {k} (t = {t:g} s, dt {setup.dt:g} s): its state became "
                "non-finite or left the divergence bound (then frozen there), or it left the "
                "path-error bound (--diverge-e); its metrics and figures after that time are "
                "not meaningful"
            )
        return lines

    def record(self, outcomes, setup) -> dict:
        return {"scenario": next(iter(outcomes.values())).scenario}


SIM1 = Sim1(
    "sim1",
    "Simulation 1 (INFANTE-class, line, Figs. 4-5), every controller",
    horizon=150.0,
    dt=0.05,
    options=Sim1Options,
    current=(0.0, 0.5),
)
