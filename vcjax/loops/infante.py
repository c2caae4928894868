"""INFANTE-class loops: the VCM law (and its integral / integral-LOS variants) and the LOS-PID /
ILOS baselines on the underactuated INFANTE-class plant (Simulation 1's loop, any path kind).

Every controller maps its ``[tau_u, tau_r]`` to thrust and rudder commands with the *design*
vehicle's actuator model (:func:`vcjax.vehicles.infante.actuator_commands`), using the
*measured* velocity over ground (the current is unknown to the controllers).

Controllers: ``vcm`` (31)/(38); ``vcm_integral`` (+ integral action (41)); ``vcm_ilos``
(``vcm_integral`` with the integral-LOS approach angle inside the VCM heading row); ``ilos``
(40), ``los_pid`` (39) and ``alos`` (Fossen's adaptive LOS, 2023) with a heading PD.
"""

from __future__ import annotations

import dataclasses
import functools
from typing import Any, ClassVar, Literal, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from vcjax import paths
from vcjax.control.baselines import (
    BaselineConfig,
    baseline_gains,
    baseline_law,
    baseline_params,
    baseline_state,
)
from vcjax.control.vcm import VCMConfig, check_edd, pm_gains, vcm_law, vcm_params, vcm_state
from vcjax.linalg import rot2
from vcjax.loops.base import GainSpec, Loop, Scenario, Signals
from vcjax.vehicles import infante

__all__ = [
    "InfanteGains",
    "infante_gains",
    "InfanteLoop",
    "VCM_CONTROLLERS",
    "rh_bound",
    "rudder_ratio",
    "pm_gain_specs",
    "path_frames",
    "path_errors",
]

VCM_CONTROLLERS = ("vcm", "vcm_integral", "vcm_ilos")
BASELINE_CONTROLLERS = ("ilos", "los_pid", "alos")


class InfanteGains(NamedTuple):
    """Gains of the INFANTE-class controllers (traced).

    Attributes:
        vcm: :class:`~vcjax.control.vcm.PMGains` of ``vcm``, ``vcm_integral``, ``vcm_ilos``.
        baseline: :class:`~vcjax.control.baselines.BaselineGains` of ``ilos`` and ``los_pid``.
    """

    vcm: Any
    baseline: Any


def infante_gains() -> InfanteGains:
    """SPEC §3's order-one VCM gains, with integral action on the along-track error only.

    In the underactuated configuration the cross-track integral of (41) can act only through
    the sway row, which the vehicle cannot actuate: ``v_d`` absorbs it (38), the resulting
    sideslip needs a cross-track offset to follow the path, and the integral grows — positive
    feedback (measured: with ``P_int = (0.05, 0.01)`` the run settles with the integrator on its
    anti-windup clamp and |e| = 0.29 m). The along-track integral removes the current-induced
    speed and along-track offsets without that problem.
    """
    return InfanteGains(vcm=pm_gains(P_int=(0.05, 0.0)), baseline=baseline_gains())


def rh_bound(P_G, P_Phi):
    """(2,) Routh–Hurwitz bound ``(P_Geps + P_Phieps) P_Geps P_Phieps`` on ``P_int`` (41)."""
    pg, pphi = P_G[1:], P_Phi[3:]
    return (pg + pphi) * pg * pphi


def _pm_specs(get, put) -> dict[str, GainSpec]:
    """Gain groups of a :class:`~vcjax.control.vcm.PMGains` reached by ``get``/``put``."""

    def spec(name, size, bound=None):
        def g(gains):
            return jnp.atleast_1d(getattr(get(gains), name))

        def s(gains, value):
            v = value if size > 1 else value[0]
            return put(gains, get(gains)._replace(**{name: v}))

        return GainSpec(name, size, g, s, bound)

    def int_bound(gains):
        pm = get(gains)
        return rh_bound(pm.P_G, pm.P_Phi)

    return {
        "P_G": spec("P_G", 3),
        "P_Phi": spec("P_Phi", 5),
        "Delta": spec("Delta", 1),
        "sigma": spec("sigma", 1),
        "P_int": spec("P_int", 2, int_bound),
        "sigma_i": spec("sigma_i", 1),
    }


def pm_gain_specs(controller_integral: bool, ilos: bool, get, put) -> tuple[GainSpec, ...]:
    """The tunable groups of a VCM law: ``P_int`` only with integral action, ``sigma_i`` only
    with the integral-LOS approach angle."""
    specs = _pm_specs(get, put)
    names = ["P_G", "P_Phi", "Delta", "sigma"]
    names += ["P_int"] if controller_integral else []
    names += ["sigma_i"] if ilos else []
    return tuple(specs[n] for n in names)


#: Model-error fields of the INFANTE-class plant (every scalar of InfanteParams).
_SCALAR_FIELDS = tuple(f for f in infante.InfanteParams._fields if f != "cf_x")


@dataclasses.dataclass(frozen=True)
class InfanteLoop(Loop):
    """INFANTE-class craft (3-DOF horizontal plant, thrust + rudder) under one controller.

    Attributes (besides :class:`~vcjax.loops.base.Loop`'s):
        edd: which ``e_ddot`` enters the VCM heading row (``"paper"`` or ``"implied"``).
    """

    edd: Literal["paper", "implied"] = "paper"

    vehicle: ClassVar[str] = "infante"
    #: the columns of ``Signals.cmd_ratio``
    actuator_names: ClassVar[tuple[str, ...]] = ("thrust", "rudder")
    controllers: ClassVar[tuple[str, ...]] = VCM_CONTROLLERS + BASELINE_CONTROLLERS
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

    def __post_init__(self):
        super().__post_init__()
        check_edd(self.edd)

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

    def default_gains(self) -> InfanteGains:
        return infante_gains()

    @property
    def is_vcm(self) -> bool:
        return self.controller in VCM_CONTROLLERS

    def gain_specs(self):
        if self.is_vcm:
            return pm_gain_specs(
                self.controller != "vcm",
                self.controller == "vcm_ilos",
                lambda g: g.vcm,
                lambda g, v: g._replace(vcm=v),
            )
        names = ["Delta", "sigma", "k_u", "k_psi_p", "k_psi_d"]
        names += {"ilos": ["sigma_i"], "alos": ["gamma"]}.get(
            self.controller, ["k_ep", "k_ed", "k_ei"]
        )

        def spec(name):
            return GainSpec(
                name,
                1,
                lambda g: jnp.atleast_1d(getattr(g.baseline, name)),
                lambda g, v: g._replace(baseline=g.baseline._replace(**{name: v[0]})),
            )

        return tuple(spec(n) for n in names)

    def symmetric_pairs(self):
        return (("P_G", 1, "P_Phi", 3), ("P_G", 2, "P_Phi", 4)) if self.is_vcm else ()

    def gains_from_json(self, d: dict, base=None):
        """Sections ``vcm`` / ``baseline`` (the ``vcjax simulate sim1 --gains`` format),
        validated by :func:`~vcjax.control.vcm.pm_gains` / ``baseline_gains``."""
        base = self.default_gains() if base is None else base
        if not isinstance(d, dict):
            raise ValueError(f"gains file: expected an object, got {type(d).__name__}")
        unknown = set(d) - {"vcm", "baseline"}
        if unknown:
            raise ValueError(f"gains file: unknown sections {sorted(unknown)}")
        for section in ("vcm", "baseline"):
            if not isinstance(d.get(section, {}), dict):
                raise ValueError(
                    f"gains file: section '{section}' must be an object of gains, "
                    f"got {type(d[section]).__name__}"
                )
        cur = {k: np.asarray(v).tolist() for k, v in base.vcm._asdict().items()}
        cur_b = {k: np.asarray(v).tolist() for k, v in base.baseline._asdict().items()}
        try:
            vcm = pm_gains(**(cur | d.get("vcm", {})))
            bas = baseline_gains(**(cur_b | d.get("baseline", {})))
        except TypeError as err:
            raise ValueError(f"gains file: {err}") from None
        return InfanteGains(vcm=vcm, baseline=bas)

    # ---------------------------------------------------------------- the loop
    @functools.cached_property
    def _law(self):
        if self.is_vcm:
            cfg = VCMConfig(
                path=self.path,
                actuation="underactuated",
                edd=self.edd,
                integral=self.controller != "vcm",
                guidance="ilos" if self.controller == "vcm_ilos" else "los",
            )
            return functools.partial(vcm_law, cfg)
        return functools.partial(baseline_law, BaselineConfig(path=self.path, kind=self.controller))

    def plant(self, t, x, u, args):
        if self.smooth:
            return infante.infante_plant_smooth(t, x, u, args)
        return infante.infante_plant(t, x, u, args)

    def control(self, t, x, z, ctrl):
        law_params, vehicle = ctrl
        tau, z_dot, aux = self._law(law_params, t, x.eta, x.nu, z)
        return infante.actuator_commands(vehicle, x.nu, tau[0], tau[2]), z_dot, aux

    def plant_args(self, sc: Scenario, current, current_dot):
        return infante.PlantArgs(vehicle=sc.plant, V_c=current[:2], V_c_dot=current_dot[:2])

    def with_current(self, args, current, current_dot):
        return args._replace(V_c=current[:2], V_c_dot=current_dot[:2])

    def ctrl_params(self, gains: InfanteGains, sc: Scenario):
        """The law's params (design model derived from ``sc.design``, rudder sway ratio,
        desired speed, path) and the design vehicle (actuator map)."""
        model = infante.design_model(sc.design)
        k_rudder = rudder_ratio(sc.design)
        if self.is_vcm:
            p = vcm_params(gains.vcm, model, sc.path, u_d=sc.u_d, k_rudder=k_rudder)
        else:
            p = baseline_params(gains.baseline, model, sc.path, u_d=sc.u_d, k_rudder=k_rudder)
        return p, sc.design

    def initial_state(self, sc: Scenario):
        x0 = infante.InfanteState(eta=sc.eta0, nu=sc.nu0, act=jnp.zeros(2, sc.eta0.dtype))
        z0 = vcm_state(varpi0=sc.varpi0) if self.is_vcm else baseline_state(varpi0=sc.varpi0)
        return x0, z0

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
        frames = path_frames(self.path, sc.path, traj.z.varpi[:n])
        eps = path_errors(frames, eta)
        p_err = jnp.concatenate([eta[:, :2] - frames.p_bar, -frames.p[:, 2:]], axis=1)
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
            psi_err=traj.aux.psi_tilde,
            depth_err=jnp.zeros(n, eta.dtype),
            cmd_ratio=cmd / limits,
            sat=sat,
            act={"tau_u": jnp.abs(act[:, 0]), "rudder_deg": jnp.degrees(jnp.abs(act[:, 1]))},
        )


def path_frames(path, coeffs, w):
    """:class:`~vcjax.paths.PathFrame` at every parameter of ``w`` (N,)."""
    return jax.vmap(lambda w1: paths.path_frame(path, coeffs, w1))(w)


def path_errors(frames, eta):
    """(N, 2) ``[s, e]`` (23) of the poses ``eta`` (N, >=2) w.r.t. the frames (N,)."""
    return jax.vmap(lambda psi_p, p_bar, xy: rot2(psi_p).T @ (xy - p_bar))(
        frames.psi_p, frames.p_bar, eta[:, :2]
    )


def rudder_ratio(vehicle):
    """Sway force per unit yaw moment of the rudder (speed-independent: both scale with U^2)."""
    Y, N = infante.rudder_gains(vehicle, jnp.array([1.0, 0.0, 0.0], dtype=vehicle.mass.dtype))
    return Y / N
