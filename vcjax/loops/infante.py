"""INFANTE-class loops: the VCM law (and its integral / integral-LOS variants) and the LOS-PID /
ILOS / ALOS baselines on the underactuated INFANTE-class plant (Simulation 1's loop, any path kind).

Every controller maps its ``[tau_u, tau_r]`` to thrust and rudder commands with the *design*
vehicle's actuator model ([`actuator_commands`][vcjax.vehicles.infante.actuator_commands]), using
the
*measured* velocity over ground (the current is unknown to the controllers).

Controllers (the laws of ``InfanteLoop.laws``): ``vcm`` (31)/(38); ``vcm_integral``
(+ integral action (41)); ``vcm_ilos`` (``vcm_integral`` with the integral-LOS approach angle
inside the VCM heading row); ``ilos`` (40), ``los_pid`` (39) and ``alos`` (Fossen's adaptive LOS,
2023) with a heading PD.

A law of this vehicle ([`Law`][vcjax.loops.law.Law]) is called with

* ``params(loop, gains, sc, design)`` — ``design``: an
  [`InfanteDesign`][vcjax.loops.infante.InfanteDesign], ``design.model`` the design model
  ([`design_model`][vcjax.vehicles.infante.design_model] of ``sc.design``) and
  ``design.k_rudder`` the rudder's sway force per unit yaw moment
  ([`rudder_ratio`][vcjax.loops.infante.rudder_ratio]);
* ``step(loop, params, t, x, z) -> (tau, z_dot, aux)`` — ``x``: the measured
  [`InfanteState`][vcjax.vehicles.infante.InfanteState] (pose ``x.eta = [x, y, psi]``, velocity over
  ground ``x.nu = [u, v, r]``), ``tau``: (3,) ``[tau_u, tau_v, tau_r]`` (``tau_v`` is not
  actuated: ignored), ``aux``: a per-step record with the heading error ``psi_tilde``
  (or the law's [`heading_error`][vcjax.loops.law.Law.heading_error]);
* ``initial_state(loop, sc)`` — a state whose particle is ``z.varpi`` (or
  [`particle`][vcjax.loops.law.Law.particle]).
"""

from __future__ import annotations

import dataclasses
from typing import Any, ClassVar, Literal, NamedTuple

import jax.numpy as jnp

from vcjax import paths
from vcjax.control.baselines import (
    BaselineConfig,
    baseline_gains,
    baseline_law,
    baseline_params,
    baseline_state,
)
from vcjax.control.vcm import VCMLoopOptions, pm_gains, vcm_law, vcm_params, vcm_state
from vcjax.environment import WaterMotion
from vcjax.loops.geometry import path_errors, path_frames, path_poses
from vcjax.loops.law import Law
from vcjax.loops.loop import Loop
from vcjax.loops.params import gain_spec
from vcjax.loops.pm import PM_PAIRS, pm_gain_specs, rh_bound
from vcjax.loops.types import Scenario, Signals
from vcjax.vehicles import infante

__all__ = [
    "InfanteDesign",
    "InfanteGains",
    "infante_gains",
    "InfanteVCMLaw",
    "InfanteBaselineLaw",
    "InfanteLoop",
    "rh_bound",
    "rudder_ratio",
    "pm_gain_specs",
    "path_frames",
    "path_errors",
]


class InfanteGains(NamedTuple):
    """Gains of the INFANTE-class controllers (traced).

    Attributes:
        vcm: [`PMGains`][vcjax.control.vcm.PMGains] of ``vcm``, ``vcm_integral``, ``vcm_ilos``.
        baseline: [`BaselineGains`][vcjax.control.baselines.BaselineGains] of ``ilos``, ``los_pid``,
            ``alos``.
    """

    vcm: Any
    baseline: Any


class InfanteDesign(NamedTuple):
    """What an INFANTE law is designed on ([`Law.params`][vcjax.loops.law.Law.params]'s
    ``design``, from ``sc.design``).

    Attributes:
        model: [`Design3DOF`][vcjax.vehicles.design3dof.Design3DOF], the design model
            ([`design_model`][vcjax.vehicles.infante.design_model]).
        k_rudder: () the rudder's sway force per unit yaw moment
            ([`rudder_ratio`][vcjax.loops.infante.rudder_ratio]).
    """

    model: Any
    k_rudder: Any


def infante_gains() -> InfanteGains:
    """docs/method.md's order-one VCM gains, with integral action on the along-track error only.

    In the underactuated configuration the cross-track integral of (41) can act only through
    the sway row, which the vehicle cannot actuate: ``v_d`` absorbs it (38), the resulting
    sideslip needs a cross-track offset to follow the path, and the integral grows — positive
    feedback (measured: with ``P_int = (0.05, 0.01)`` the run settles with the integrator on its
    anti-windup clamp and |e| = 0.29 m). The along-track integral removes the current-induced
    speed and along-track offsets without that problem.
    """
    return InfanteGains(vcm=pm_gains(P_int=(0.05, 0.0)), baseline=baseline_gains())


def _validate(gains: InfanteGains) -> InfanteGains:
    """Both sections checked by their constructors (positivity, shapes)."""
    return InfanteGains(
        vcm=pm_gains(**gains.vcm._asdict()), baseline=baseline_gains(**gains.baseline._asdict())
    )


@dataclasses.dataclass(frozen=True)
class _InfanteLaw(Law):
    """What every INFANTE law shares: the two-section gains and their checks."""

    def default_gains(self, loop) -> InfanteGains:
        return infante_gains()

    def validate_gains(self, gains):
        return _validate(gains)


@dataclasses.dataclass(frozen=True)
class InfanteVCMLaw(_InfanteLaw):
    """The planar VCM law ([`vcjax.control.vcm.vcm_law`][vcjax.control.vcm.vcm_law]), underactuated
    in sway.

    Attributes:
        integral: integral action (41) (gains ``P_int``).
        guidance: ``"los"`` or ``"ilos"`` (the integral-LOS approach angle; gain ``sigma_i``).
    """

    integral: bool = False
    guidance: Literal["los", "ilos"] = "los"

    def gain_specs(self, loop):
        return pm_gain_specs("vcm", self.integral, self.guidance == "ilos")

    def symmetric_pairs(self, loop):
        return PM_PAIRS

    def params(self, loop, gains, sc, design):
        return vcm_params(gains.vcm, design.model, sc.path, u_d=sc.u_d, k_rudder=design.k_rudder)

    def initial_state(self, loop, sc):
        return vcm_state(varpi0=sc.varpi0)

    def step(self, loop, params, t, x, z):
        cfg = loop.vcm_config(
            actuation="underactuated", integral=self.integral, guidance=self.guidance
        )
        return vcm_law(cfg, params, t, x.eta, x.nu, z)


@dataclasses.dataclass(frozen=True)
class InfanteBaselineLaw(_InfanteLaw):
    """A LOS-family baseline with a heading PD
    ([`baseline_law`][vcjax.control.baselines.baseline_law]).

    Attributes:
        kind: the baseline (``"ilos"``, ``"los_pid"``, ``"alos"``;
            [`BaselineConfig`][vcjax.control.baselines.BaselineConfig]).
        extra: its own tunable gains besides the shared ``Delta, sigma, k_u, k_psi_p,
            k_psi_d``.
    """

    kind: str = "los_pid"
    extra: tuple[str, ...] = ("k_ep", "k_ed", "k_ei")

    def gain_specs(self, loop):
        names = ("Delta", "sigma", "k_u", "k_psi_p", "k_psi_d", *self.extra)
        return tuple(gain_spec(n, f"baseline.{n}") for n in names)

    def params(self, loop, gains, sc, design):
        m, k = design
        return baseline_params(gains.baseline, m, sc.path, u_d=sc.u_d, k_rudder=k)

    def initial_state(self, loop, sc):
        return baseline_state(varpi0=sc.varpi0)

    def step(self, loop, params, t, x, z):
        cfg = BaselineConfig(path=loop.path, kind=self.kind)
        return baseline_law(cfg, params, t, x.eta, x.nu, z)


#: Model-error fields of the INFANTE-class plant (every scalar of InfanteParams).
_SCALAR_FIELDS = tuple(f for f in infante.InfanteParams._fields if f != "cf_x")


@dataclasses.dataclass(frozen=True)
class InfanteLoop(VCMLoopOptions, Loop):
    """INFANTE-class craft (3-DOF horizontal plant, thrust + rudder) under one controller.

    Attributes: [`Loop`][vcjax.loops.loop.Loop]'s and the VCM law's option
    ([`VCMLoopOptions`][vcjax.control.vcm.VCMLoopOptions]).
    """

    act_signals: ClassVar[tuple[str, ...] | None] = ("tau_u", "rudder_deg")

    vehicle: ClassVar[str] = "infante"
    #: the columns of ``Signals.cmd_ratio``
    actuator_names: ClassVar[tuple[str, ...]] = ("thrust", "rudder")
    laws: ClassVar[dict[str, Law]] = {
        "vcm": InfanteVCMLaw(),
        "vcm_integral": InfanteVCMLaw(integral=True),
        "vcm_ilos": InfanteVCMLaw(integral=True, guidance="ilos"),
        "ilos": InfanteBaselineLaw("ilos", ("sigma_i",)),
        "los_pid": InfanteBaselineLaw("los_pid"),
        "alos": InfanteBaselineLaw("alos", ("gamma",)),
    }
    default_controller: ClassVar[str] = "vcm_integral"
    initial_keys: ClassVar[dict[str, float]] = {
        "x": 0.0,
        "y": 0.0,
        "heading_deg": 90.0,
        "speed": 2.0,
    }
    noise_channels: ClassVar[dict[str, int]] = {
        "position_std": 2,
        "heading_std_deg": 1,
        "velocity_std": 2,
        "yaw_rate_std_deg": 1,
    }

    default_speed: ClassVar[float] = 2.0
    feels: ClassVar[dict[str, bool | str]] = {
        "current": True,
        "varying_current": True,
        "waves": "its plant is a horizontal-plane (3-DOF) model with no depth, while a wave's "
        "orbital motion is as much vertical as horizontal and decays with depth",
    }

    # ---------------------------------------------------------------- parameters and gains
    @classmethod
    def default_path(cls):
        """Simulation 1's line ``[10, w]``."""
        return paths.paper_line()

    def position(self, eta, params):
        return jnp.stack([eta[0], eta[1], jnp.zeros_like(eta[0])])

    def default_params(self, dtype=None):
        return infante.infante_params(dtype=dtype)

    def validate_params(self, params, name: str = "plant"):
        return infante.validate(params, name)

    def param_names(self):
        return _SCALAR_FIELDS

    def default_model_fields(self):
        return infante.INERTIA_FIELDS + infante.HYDRODYNAMIC_FIELDS

    def plant(self, t, x, u, args):
        if self.smooth:
            return infante.infante_plant_smooth(t, x, u, args)
        return infante.infante_plant(t, x, u, args)

    def control(self, t, x, z, ctrl):
        law_params, vehicle = ctrl
        tau, z_dot, aux = self.law.step(self, law_params, t, x, z)
        return infante.actuator_commands(vehicle, x.nu, tau[0], tau[2]), z_dot, aux

    def plant_args(self, sc: Scenario, current, current_dot):
        return infante.PlantArgs(vehicle=sc.plant, water=WaterMotion(current, current_dot))

    def with_current(self, args, current, current_dot):
        return args._replace(water=WaterMotion(current, current_dot))

    def law_design(self, sc: Scenario) -> InfanteDesign:
        """The design model and rudder sway ratio of ``sc.design``."""
        return InfanteDesign(infante.design_model(sc.design), rudder_ratio(sc.design))

    def ctrl_params(self, gains: InfanteGains, sc: Scenario):
        """The law's params (design model derived from ``sc.design``, rudder sway ratio,
        desired speed, path) and the design vehicle (actuator map)."""
        return self.law.params(self, gains, sc, self.law_design(sc)), sc.design

    def initial_state(self, sc: Scenario):
        x0 = infante.InfanteState(eta=sc.eta0, nu=sc.nu0, act=jnp.zeros(2, sc.eta0.dtype))
        return x0, self.law.initial_state(self, sc)

    def initial_from(self, v: dict):
        zero = jnp.zeros_like(v["x"])
        return jnp.stack([v["x"], v["y"], v["heading_deg"]]), jnp.stack([v["speed"], zero, zero])

    def measure(self, x, noise):
        return x._replace(eta=x.eta + noise[:3], nu=x.nu + noise[3:])

    def signals(self, traj, sc: Scenario) -> Signals:
        """Errors of the *true* pose: from the pose and the particle (so sensor noise, which
        the controller's own ``aux.eps`` contains, does not enter)."""
        n = traj.u.shape[0]
        eta = traj.x.eta[:n]
        frames = path_poses(self.path, sc.path, self.law.particle(traj.z)[:n])
        eps = path_errors(frames, eta)
        p_err = jnp.concatenate([eta[:, :2] - frames.p[:, :2], -frames.p[:, 2:]], axis=1)
        veh = sc.plant
        cmd = traj.u
        limits = jnp.stack([veh.thrust_max, veh.rudder_max])
        sat = (jnp.abs(cmd[:, 0]) > veh.thrust_max) | (jnp.abs(cmd[:, 1]) > veh.rudder_max)
        act = traj.x.act
        return Signals(
            eps=eps,
            pos=jnp.concatenate([eta[:, :2], jnp.zeros((n, 1), eta.dtype)], axis=1),
            p_err=p_err,
            u_err=traj.x.nu[:n, 0] - sc.u_d,
            psi_err=self.law.heading_error(traj.aux),
            depth_err=jnp.zeros(n, eta.dtype),
            cmd_ratio=cmd / limits,
            sat=sat,
            act={"tau_u": jnp.abs(act[:, 0]), "rudder_deg": jnp.degrees(jnp.abs(act[:, 1]))},
        )


def rudder_ratio(vehicle):
    """Sway force per unit yaw moment of the rudder (speed-independent: both scale with U^2)."""
    Y, N = infante.rudder_gains(vehicle, jnp.array([1.0, 0.0, 0.0], dtype=vehicle.mass.dtype))
    return Y / N
