"""REMUS 100 loops: the PVS REMUS 100 plant under the 3-D VCM law or a 3-D baseline.

Controllers (see [`vcjax.experiments.remus100`][vcjax.experiments.remus100] for the experiment built
on the same laws):

* ``vcm3d_ilos``: 3-D VCM ([`vcjax.control.vcm3d`][vcjax.control.vcm3d]), underactuated in sway and
heave (fin
  forces tied to their moments), integral action and integral-LOS angles in both planes;
* ``vcm3d``: the same with the paper's approach angles (24) (integral action kept);
* ``decoupled``: horizontal VCM (31)/(38) + depth through pitch (the paper's decoupled design;
  the 2-D law's mass matrix is the 3-DOF model's, its body bias the design model's ``X, Y, N``
  rows, see [`vcjax.control.baselines3d`][vcjax.control.baselines3d]);
* ``alos3d``: ALOS3D guidance + PID heading/pitch autopilots + surge PI;
* ``pvs_pid``: the same autopilots with plain LOS angles.

Every law's body force goes through [`actuator_map`][vcjax.vehicles.remus100_design.actuator_map] of
the
*design* vehicle at the measured velocity over ground. The design model is
[`design_model`][vcjax.vehicles.remus100_design.design_model] of ``sc.design`` at ``u_d``.
"""

from __future__ import annotations

import dataclasses
from typing import Any, ClassVar, Literal, NamedTuple

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
from vcjax.control.vcm import VCMLoopOptions, pm_gains, vcm_params, vcm_state
from vcjax.control.vcm3d import (
    VCM3DConfig,
    pose_errors,
    vcm3d_gains,
    vcm3d_law,
    vcm3d_params,
    vcm3d_state,
)
from vcjax.environment import WaterMotion, waves
from vcjax.linalg import Rzyx, wrap_angle
from vcjax.loops.law import Law
from vcjax.loops.loop import Loop
from vcjax.loops.params import gain_spec
from vcjax.loops.types import Scenario, Signals
from vcjax.vehicles import remus100 as r100
from vcjax.vehicles import remus100_design as rd
from vcjax.vehicles.sixdof import kinematics

__all__ = [
    "RemusGains",
    "remus_gains",
    "RemusMeasurement",
    "RemusVCM3DLaw",
    "RemusDecoupledLaw",
    "RemusAutopilotLaw",
    "Remus100Loop",
    "REMUS_CONTROLLERS",
]

_IDX = np.asarray(rd.IDX5)


class RemusGains(NamedTuple):
    """Gains of every REMUS 100 controller (traced).

    Attributes:
        vcm3d: [`VCM3DGains`][vcjax.control.vcm3d.VCM3DGains] (``vcm3d``, ``vcm3d_ilos``).
        horizontal: [`PMGains`][vcjax.control.vcm.PMGains] of ``decoupled``'s 2-D law.
        autopilot: [`AutopilotGains`][vcjax.control.baselines3d.AutopilotGains] (baselines;
            ``decoupled``
            uses its pitch autopilot, ``Delta[1]`` and ``gamma[1]`` as the vertical ILOS gain).
        decoupled_autopilot: the autopilot gains of ``decoupled``.
    """

    vcm3d: Any
    horizontal: Any
    autopilot: Any
    decoupled_autopilot: Any


def remus_gains() -> RemusGains:
    """The hand-set gains of the survey mission (order-one dynamics slower than the fins)."""
    return RemusGains(
        vcm3d=vcm3d_gains(
            P_G=(1.0, 0.8, 0.2, 0.2, 0.2),
            P_Phi=(0.5, 0.3, 0.3, 2.0, 1.5, 0.4, 0.4, 0.4),
            Delta=(8.0, 8.0),
            sigma=0.3,
            k_int=(0.03, 0.03, 0.03),
            sigma_i=(0.5, 0.5),
        ),
        # the 2-D law's heading and position rows at vcm3d's poles (heading 1 and 2 rad/s,
        # eps 0.2 and 0.4 rad/s); at half those heading poles the turns overshoot by 4.6 m
        horizontal=pm_gains(
            P_G=(1.0, 0.2, 0.2),
            P_Phi=(0.5, 0.3, 2.0, 0.4, 0.4),
            Delta=8.0,
            sigma=0.3,
            P_int=(0.001, 0.001),
            sigma_i=0.5,
        ),
        autopilot=autopilot_gains(),
        decoupled_autopilot=autopilot_gains(Delta=(8.0, 20.0), gamma=(0.5, 0.2)),
    )


class RemusAux(NamedTuple):
    """Per-step signals of every controller: eps (3,), psi_d, theta_d, tau (5,), raw (3,)."""

    eps: Any
    psi_d: Any
    theta_d: Any
    tau: Any
    raw: Any


def _inertia_drag(dm, u_d):
    M = rd.mass_matrix5(dm)
    nu = jnp.stack([u_d, 0.0 * u_d, 0.0 * u_d, 0.0 * u_d, 0.0 * u_d])
    drag = rd.body_bias5(dm, jnp.zeros_like(nu), nu)[0]
    return jnp.stack([M[0, 0], M[3, 3], M[4, 4]]), drag


class RemusMeasurement(NamedTuple):
    """What a REMUS 100 law's ``step`` sees: ``q`` (5,) ``[x, y, z, theta, psi]``, ``qd`` (5,)
    their rates, ``nu`` (5,) ``[u, v, w, q, r]`` (measured, over ground)."""

    q: Any
    qd: Any
    nu: Any


def _specs(field: str, names) -> tuple:
    return tuple(gain_spec(n, f"{field}.{n}", size) for n, size in names)


@dataclasses.dataclass(frozen=True)
class _RemusLaw(Law):
    def default_gains(self, loop) -> RemusGains:
        return remus_gains()

    def validate_gains(self, gains):
        return gains._replace(
            vcm3d=vcm3d_gains(**gains.vcm3d._asdict()),
            horizontal=pm_gains(**gains.horizontal._asdict()),
            autopilot=autopilot_gains(**gains.autopilot._asdict()),
            decoupled_autopilot=autopilot_gains(**gains.decoupled_autopilot._asdict()),
        )


@dataclasses.dataclass(frozen=True)
class RemusVCM3DLaw(_RemusLaw):
    """The 3-D VCM law ([`vcjax.control.vcm3d`][vcjax.control.vcm3d]), underactuated in sway and
    heave, with
    integral action; ``guidance``: ``"ilos"`` (integral-LOS angles, gains ``sigma_i``) or
    ``"los"`` (the paper's approach angles (24))."""

    guidance: Literal["los", "ilos"] = "ilos"

    def gain_specs(self, loop):
        names = [("P_G", 5), ("P_Phi", 8), ("Delta", 2), ("sigma", 1), ("k_int", 3)]
        names += [("sigma_i", 2)] if self.guidance == "ilos" else []
        return _specs("vcm3d", names)

    def params(self, loop, gains, sc, design):
        return vcm3d_params(gains.vcm3d, design, sc.path, u_d=sc.u_d)

    def initial_state(self, loop, sc):
        return vcm3d_state(varpi0=sc.varpi0)

    def step(self, loop, params, t, m, z):
        cfg = VCM3DConfig(
            path=loop.path,
            system=rd.design_system(),
            kinematics=rd.kinematics5,
            tied_rows=rd.unactuated_rows,
            actuation="underactuated",
            integral=True,
            guidance=self.guidance,
            kinematics_inverse=rd.kinematics5_inverse,
        )
        return vcm3d_law(cfg, params, t, m.q, m.qd, z)


@dataclasses.dataclass(frozen=True)
class RemusDecoupledLaw(_RemusLaw):
    """Horizontal VCM (31)/(38) + depth through pitch
    ([`vcjax.control.baselines3d`][vcjax.control.baselines3d])."""

    def gain_specs(self, loop):
        names = [("P_G", 3), ("P_Phi", 5), ("Delta", 1), ("sigma", 1), ("sigma_i", 1)]
        return _specs("horizontal", names) + _specs("decoupled_autopilot", [("w_theta", 1)])

    def params(self, loop, gains, sc, design):
        dm = design
        inertia, drag = _inertia_drag(dm, sc.u_d)
        horiz = vcm_params(
            gains.horizontal, rd.horizontal_design(dm), sc.path, u_d=sc.u_d,
            k_rudder=1.0 / sc.design.x_r,
        )  # fmt: skip
        ap = gains.decoupled_autopilot
        return baseline3d_params(ap, inertia, drag, sc.path, sc.u_d, horiz, dm)

    def initial_state(self, loop, sc):
        return decoupled_state(vcm_state(varpi0=sc.varpi0))

    def step(self, loop, params, t, m, z):
        hcfg = loop.vcm_config(actuation="underactuated", integral=True)
        dcfg = DecoupledConfig(dataclasses.replace(hcfg, guidance="ilos"), rd.body_bias5)
        return decoupled_law(dcfg, params, t, m.q, m.qd, m.nu, z)

    def particle(self, z):
        return z.horizontal.varpi


@dataclasses.dataclass(frozen=True)
class RemusAutopilotLaw(_RemusLaw):
    """LOS (``"los"``, ``pvs_pid``) or ALOS3D (``"alos"``, gains ``gamma``) guidance with PID
    heading/pitch autopilots and a surge PI
    ([`vcjax.control.baselines3d`][vcjax.control.baselines3d])."""

    guidance: Literal["los", "alos"] = "los"

    def gain_specs(self, loop):
        names = [("w_psi", 1), ("w_theta", 1), ("Delta", 2), ("k_u", 1)]
        names += [("gamma", 2)] if self.guidance == "alos" else []
        return _specs("autopilot", names)

    def params(self, loop, gains, sc, design):
        inertia, drag = _inertia_drag(design, sc.u_d)
        return baseline3d_params(gains.autopilot, inertia, drag, sc.path, sc.u_d)

    def initial_state(self, loop, sc):
        return autopilot_state(sc.varpi0)

    def step(self, loop, params, t, m, z):
        acfg = AutopilotConfig(path=loop.path, guidance=self.guidance)
        return autopilot_law(acfg, params, t, m.q, m.qd, m.nu, z)


#: the REMUS 100 controllers, in the order of
#: [`Remus100Loop.laws`][vcjax.loops.remus100.Remus100Loop.laws]
REMUS_LAWS = {
    "vcm3d_ilos": RemusVCM3DLaw("ilos"),
    "vcm3d": RemusVCM3DLaw("los"),
    "decoupled": RemusDecoupledLaw(),
    "alos3d": RemusAutopilotLaw("alos"),
    "pvs_pid": RemusAutopilotLaw("los"),
}
REMUS_CONTROLLERS = tuple(REMUS_LAWS)


@dataclasses.dataclass(frozen=True)
class Remus100Loop(VCMLoopOptions, Loop):
    """The PVS REMUS 100 (6-DOF, fins + propeller) under one 3-D path-following controller.

    Attributes: [`Loop`][vcjax.loops.loop.Loop]'s and the VCM law's option
    ([`VCMLoopOptions`][vcjax.control.vcm.VCMLoopOptions]: it selects the heading row of
    ``decoupled``'s 2-D VCM law).
    """

    act_signals: ClassVar[tuple[str, ...] | None] = ("rudder_deg", "stern_deg", "rpm")

    vehicle: ClassVar[str] = "remus100"
    laws: ClassVar[dict[str, Law]] = REMUS_LAWS
    default_controller: ClassVar[str] = "vcm3d_ilos"
    initial_keys: ClassVar[dict[str, float]] = {
        "x": 0.0,
        "y": 3.0,
        "z": 1.0,
        "pitch_deg": 0.0,
        "heading_deg": 0.0,
        "speed": 1.5,
    }
    default_speed: ClassVar[float] = 1.5
    feels: ClassVar[dict[str, bool | str]] = {
        "current": True,
        "varying_current": True,
        "waves": True,
    }

    # ---------------------------------------------------------------- parameters and gains
    @classmethod
    def default_path(cls):
        """The survey lawnmower of ``vcjax simulate remus100``."""
        return paths.lawnmower((0.0, 0.0, 1.0), 250.0, 30.0, 4, 15.0, 150.0)

    def position(self, eta, params):
        return eta[:3]

    def default_params(self, dtype=None):
        return r100.remus100_params(dtype=dtype)

    def param_names(self):
        return ("body.M_A", "body.D", "CL_delta_r", "CL_delta_s", "KT_0", "KT_max", "CD_0")

    def default_model_fields(self):
        return ("body.M_A", "body.D", "CL_delta_r", "CL_delta_s")

    def plant(self, t, x, u, args):
        if self.smooth:
            return r100.remus100_plant_smooth(t, x, u, args)
        return r100.remus100_plant(t, x, u, args)

    def control(self, t, x, z, ctrl):
        law_params, dm = ctrl
        qd = kinematics(x.eta) @ x.nu
        q, qd5, nu5 = x.eta[_IDX], qd[_IDX], x.nu[_IDX]
        tau, z_dot, aux = self.law.step(self, law_params, t, RemusMeasurement(q, qd5, nu5), z)
        act = rd.actuator_map(dm, tau, x.nu)
        return act.cmd, z_dot, RemusAux(aux.eps, aux.psi_d, aux.theta_d, tau, act.raw)

    def plant_args(self, sc: Scenario, current, current_dot):
        return r100.Remus100Args(
            vehicle=sc.plant,
            water=WaterMotion(current, current_dot),
            M_factor=r100.mass_factor(sc.plant),  # M is constant: factored once per scenario
        )

    def with_current(self, args, current, current_dot):
        return args._replace(water=WaterMotion(current, current_dot))

    def plant_in_sea(self, t, x, u, args, water):
        """The PVS plant in a sea: the water at the hull (current + orbital motion) through the
        plant's door, the current named as its uniform share (``Remus100Args.uniform``: PVS's
        yaw-only door; the orbital motion goes through the full rotation on top of it), and the
        pendulum moment of the CG
        below the CB ([`current_door_correction`][vcjax.environment.waves.current_door_correction];
        ``W = B``, CB at the
        CO) joins the force sum. A calm sea changes nothing (every added term is exactly 0)."""
        u_w, a_w = water.waves_at(t, x.eta[:3])
        b = args.vehicle.body
        m = b.M_RB[0, 0]
        R = Rzyx(x.eta[3], x.eta[4], x.eta[5])
        tau_w = waves.current_door_correction(R, a_w, b.M_RB, m * b.B / b.W, b.r_bb)
        at_hull = water.plus(u_w, a_w)
        return self.plant(t, x, u, args._replace(water=at_hull, uniform=args.water, tau_w=tau_w))

    def law_design(self, sc: Scenario) -> rd.Remus100Design:
        """The design model of ``sc.design`` at ``u_d``
        ([`Remus100Design`][vcjax.vehicles.remus100_design.Remus100Design])."""
        return rd.Remus100Design(sc.design, sc.u_d, jnp.asarray(0.5, sc.u_d.dtype))

    def ctrl_params(self, gains: RemusGains, sc: Scenario):
        dm = self.law_design(sc)
        return self.law.params(self, gains, sc, dm), dm

    def initial_state(self, sc: Scenario):
        x0 = r100.Remus100State(
            eta=sc.eta0, nu=sc.nu0, act=jnp.asarray([0.0, 0.0, 1000.0], sc.eta0.dtype)
        )
        z0 = self.law.initial_state(self, sc)
        return x0, jax.tree_util.tree_map(lambda a: jnp.asarray(a, sc.eta0.dtype), z0)

    def initial_from(self, v: dict):
        zero = jnp.zeros_like(v["x"])
        eta0 = jnp.stack([v["x"], v["y"], v["z"], zero, v["pitch_deg"], v["heading_deg"]])
        nu0 = jnp.stack([v["speed"], zero, zero, zero, zero, zero])
        return eta0, nu0

    def signals(self, traj, sc: Scenario) -> Signals:
        n = traj.u.shape[0]
        eta = traj.x.eta[:n]
        w = self.law.particle(traj.z)[:n]
        frames, eps = jax.vmap(lambda w1, p: pose_errors(self.path, sc.path, w1, p))(w, eta[:, :3])
        lim = sc.plant.act_max
        ratio = traj.aux.raw / lim
        act = traj.x.act[:n]
        return Signals(
            eps=eps[:, :2],
            pos=eta[:, :3],
            p_err=eta[:, :3] - frames.p,
            u_err=traj.x.nu[:n, 0] - sc.u_d,
            psi_err=wrap_angle(eta[:, 5] - traj.aux.psi_d),
            depth_err=eps[:, 2],
            cmd_ratio=ratio,
            sat=jnp.any(jnp.abs(ratio) > 1.0, axis=1),
            act={
                "rudder_deg": jnp.degrees(jnp.abs(act[:, 0])),
                "stern_deg": jnp.degrees(jnp.abs(act[:, 1])),
                "rpm": jnp.abs(act[:, 2]),
            },
        )
