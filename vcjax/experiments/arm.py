"""The arm demo (``vcjax demo``): the generic engine on a non-marine system, a two-link arm
whose end effector is held on a circle by virtual constraints.

The ``arm`` loop ([`vcjax.loops.ArmLoop`][vcjax.loops.arm.ArmLoop]:
[`vcjax.vehicles.arm`][vcjax.vehicles.arm]' two-link arm,
joint-torque limits 40 and 15 N m) on its default circle (centre (1.0, 0.6) m, radius 0.35 m,
counter-clockwise), travelled at ``ARM_SPEED``; built with
[`vcjax.loops.make_loop`][vcjax.loops.registry.make_loop],
[`vcjax.loops.make_scenario`][vcjax.loops.scenario.make_scenario] and
[`vcjax.loops.simulate`][vcjax.loops.disturbances.simulate], RK4 at ``ARM_DT``. The
end effector starts 0.2 m off the circle, moving (joint angles (0.35, 1.3) rad, rates
(0.2, -0.1) rad/s). The virtual constraints are the path errors ``[s, e]`` of the end effector
in the particle's frame; the engine's reaction force makes each row of
``Phi = G_dot + P_G G`` decay as ``exp(-P_Phi t)`` (14), which the figure checks against the
exact exponential and ``metrics.json`` reports (``phi_decay_error``).
"""

from __future__ import annotations

import dataclasses

import jax.numpy as jnp
import numpy as np

from vcjax import loops, metrics
from vcjax.experiments.base import Experiment

__all__ = ["ARM", "Arm", "ARM_DT", "ARM_SPEED", "Q0", "QD0", "REPORTED", "decay_extra"]

#: RK4 step of the arm demo [s].
ARM_DT = 2e-3
#: speed of the end effector along the circle [m/s]
ARM_SPEED = 0.5
#: initial joint angles [rad] and rates [rad/s]
Q0, QD0 = (0.35, 1.3), (0.2, -0.1)
#: what ``metrics.json`` holds: the generic metrics of the run and the demo's extra
REPORTED = ("ss_abs_e", "max_abs_e", "iae_e", "max_abs_torque", "sat_fraction", "phi_decay_error")


def decay_extra(traj, gains) -> dict:
    """``phi_decay_error``: the largest ``|Phi_i(t) - Phi_i(0) exp(-P_Phi_i t)| / |Phi_i(0)|``
    over the run and both rows (0 for the exact decay (14)), an extra of
    [`vcjax.metrics.run_metrics`][vcjax.metrics.run_metrics]."""
    phi = traj.aux.Phi
    t = traj.t[:-1] - traj.t[0]
    exact = phi[0] * jnp.exp(-gains.P_Phi[None, :] * t[:, None])
    return {"phi_decay_error": lambda sig, win: jnp.max(jnp.abs(phi - exact) / jnp.abs(phi[0]))}


@dataclasses.dataclass(frozen=True)
class Arm(Experiment):
    """The arm demo: one run (variant ``vcm``) of the ``arm`` loop on its default circle."""

    def variants(self, options=None) -> tuple[str, ...]:
        return ("vcm",)

    def loop(self, variant: str = "vcm", options=None) -> loops.Loop:
        return loops.make_loop("arm", variant)

    def scenario(self, variant: str = "vcm", setup=None) -> loops.Scenario:
        return loops.make_scenario(self.loop(variant), eta0=Q0, nu0=QD0, u_d=ARM_SPEED)

    def default_gains(self, variant: str = "vcm", options=None) -> loops.EngineGains:
        """``P_G = (2, 2)``, ``P_Phi = (1.5, 3)`` [1/s] (the two rows decay at different rates,
        so the figure tells them apart), ``sigma = 1`` [1/s]."""
        return loops.engine_gains(P_G=(2.0, 2.0), P_Phi=(1.5, 3.0), sigma=1.0)

    def metrics(self, outcome, setup) -> dict:
        """``REPORTED`` and ``healthy`` (no state diverged)."""
        traj = outcome.traj
        sig = outcome.loop.signals(traj, outcome.scenario)
        m = metrics.run_metrics(sig, traj.finite, setup.dt, extras=decay_extra(traj, outcome.gains))
        return {k: float(m[k]) for k in REPORTED} | {"healthy": bool(~m["diverged"])}

    def report(self, results, setup) -> dict:
        return results["vcm"]

    def label(self, variant: str) -> str:
        return "the two-link arm"

    def printed(self, results) -> None:
        return None

    def unhealthy(self, results, outcomes, setup) -> list[str]:
        bad = not results["vcm"]["healthy"]
        return ["arm: a non-finite or runaway state (see metrics.json)"] if bad else []

    def figures(self, outcomes, setup, out):
        from vcjax.plots.arm import arm_figure

        o = outcomes["vcm"]
        traj, sc = o.traj, o.scenario
        sig = o.loop.signals(traj, sc)
        ee = np.asarray(sig.pos)[:, :2]
        center, radius = np.asarray(sc.path.center)[:2], float(sc.path.radius)
        e = np.asarray(sig.eps)[:, 1]
        png = out / "arm_demo.png"
        return [arm_figure(traj.t, ee, traj.aux.Phi, e, traj.u, o.gains.P_Phi, center, radius, png)]


ARM = Arm(
    "arm",
    "two-link arm drawing a circle with the generic engine (vcjax demo)",
    horizon=6.0,
    dt=ARM_DT,
    gains=False,
)
