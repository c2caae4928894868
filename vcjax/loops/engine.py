"""The generic engine as a controller: any mechanical system whose point ``p(q)`` must follow a
path becomes a loop ([`EngineLoop`][vcjax.loops.engine.EngineLoop]), rolled out, swept and tuned
like the marine ones.

Virtual constraints (paper Sections 2–3, [`vcjax.mechanics`][vcjax.mechanics]): a path particle
``varpi``
(controller state) moves as in (22), ``varpi_dot = (u_d + sigma s) / |p_bar'(varpi)|``, and the
holonomic constraints are the path errors of the point in the particle's frame (23),
``G(q, varpi) = [s, e] = R(psi_p)^T (p(q) - p_bar(varpi))`` — horizontal (north, east) for a
craft, the plane of motion for a manipulator. ``Phi = G_dot + P_G G`` and ``Phi_dot + P_Phi Phi =
0`` give, on the design model, ``G_ddot + (P_G + P_Phi) G_dot + P_G P_Phi G = 0`` for each row:
the engine's reaction force (16) is the control torque. The plant applies it through actuators
with limits ``tau_max`` (hard clip, or ``tanh`` when the loop is ``smooth``) plus a constant
generalised disturbance; its parameters may differ from the design's (model error).

A subclass supplies the mechanics and the point that follows the path::

    @dataclasses.dataclass(frozen=True)
    class MyLoop(EngineLoop):
        vehicle: ClassVar[str] = "my_system"
        def mass_matrix(self, q, p): ...        # (n, n)
        def bias_force(self, q, qd, p): ...     # (n,)
        def point(self, q, p): ...              # (2,) or (3,) position that follows the path
        def default_params(self, dtype=None): ...   # NamedTuple with a field tau_max (n,)
        @classmethod
        def default_path(cls): ...
        def default_gains(self): ...            # EngineGains

(plus ``initial_keys`` / ``initial_from``); ``tests/test_loops.py`` does exactly this for a point
mass, and [`vcjax.loops.arm`][vcjax.loops.arm] for the two-link arm.

**Currents.** The plant's bias force sees the velocity relative to the water,
``n(q, qd - qd_c, p)``, where ``qd_c``
([`EngineLoop.water_velocity`][vcjax.loops.engine.EngineLoop.water_velocity]) is the generalised
velocity at which the point would move with the water: by default the solution of
``J(q) qd_c = V_c`` with ``J = dp/dq`` (the point's Jacobian; least squares when not square)
and ``V_c`` the first 2 or 3 NED components of the water's velocity (``args.water.velocity``:
[`EngineArgs`][vcjax.loops.engine.EngineArgs] holds the water in the one door of every plant,
[`WaterMotion`][vcjax.environment.component.WaterMotion]; a point that moves in a plane cannot
feel the vertical component) — right for a body whose drag is written on its velocity over
ground (a puck, a craft in its own coordinates). The current's acceleration
(added-mass force) is not modelled; a time-varying (Gauss–Markov) current is taken the same way.
A system without water ([`vcjax.loops.arm`][vcjax.loops.arm]) leaves ``"current"`` and
``"varying_current"`` out of ``feels``: configs asking for a current are
then refused ([`vcjax.loops.check_disturbances`][vcjax.loops.scenario.check_disturbances]) and the
plant ignores
``Scenario.current``. No engine loop feels waves (``feels["waves"]`` is its reason): the orbital
motion's
acceleration would need the added-mass and Froude–Krylov forces the engine's plant does not
model, so a scenario or config with a sea is refused.
"""

from __future__ import annotations

import dataclasses
import functools
import warnings
from typing import Any, ClassVar, NamedTuple

import jax
import jax.numpy as jnp

from vcjax import paths
from vcjax._checks import check_positive
from vcjax.environment import WaterMotion
from vcjax.linalg import rot2, saturate, smooth_saturate, spd_solve_small
from vcjax.loops.law import Law
from vcjax.loops.loop import Loop
from vcjax.loops.params import gain_spec
from vcjax.loops.types import Scenario, Signals
from vcjax.mechanics import MechanicalSystem, VCMGains, VirtualConstraints, reaction_force

__all__ = ["EngineGains", "engine_gains", "EngineAux", "EngineArgs", "EngineLaw", "EngineLoop"]


class EngineGains(NamedTuple):
    """Gains of an engine loop (traced).

    Attributes:
        P_G: (2,) holonomic-row gains of ``[s, e]`` [1/s]; P_Phi: (2,) gains of (14) [1/s];
        sigma: () particle-speed gain of ``u_d + sigma s`` [1/s].
    """

    P_G: Any
    P_Phi: Any
    sigma: Any


def engine_gains(P_G=(2.0, 2.0), P_Phi=(3.0, 3.0), sigma=1.0) -> EngineGains:
    """Validated [`EngineGains`][vcjax.loops.engine.EngineGains] (every gain > 0)."""
    check_positive("P_G", P_G, (2,))
    check_positive("P_Phi", P_Phi, (2,))
    check_positive("sigma", sigma, ())
    f = lambda x: jnp.asarray(x, dtype=float)
    return EngineGains(f(P_G), f(P_Phi), f(sigma))


class EngineAux(NamedTuple):
    """Signals recorded per step.

    Attributes:
        eps: (2,) ``[s, e]`` (23) [m]; speed_err: () along-path speed of the point minus
        ``u_d`` [m/s]; Phi: (2,) unified constraint; residual: () of (14); rank: () of W;
        tau: (n,) reaction (control) force.
    """

    eps: Any
    speed_err: Any
    Phi: Any
    residual: Any
    rank: Any
    tau: Any


class _Args(NamedTuple):
    params: Any  # design parameters
    path: Any  # path coefficients
    u_d: Any
    sigma: Any


class EngineArgs(NamedTuple):
    """The plant's traced arguments: parameters, constant disturbance (n,), and the water
    ([`WaterMotion`][vcjax.environment.component.WaterMotion]: velocity and material
    acceleration, (3,) NED each; the engine's plant uses the velocity,
    [`EngineLoop.water_velocity`][vcjax.loops.engine.EngineLoop.water_velocity])."""

    params: Any
    disturbance: Any
    water: WaterMotion

    @property
    def current(self):
        """Deprecated: the water's velocity (3,) NED, ``water.velocity`` (the name of the
        door before every plant took the water through one
        [`WaterMotion`][vcjax.environment.component.WaterMotion])."""
        warnings.warn(
            "EngineArgs.current is deprecated: use args.water.velocity (every plant takes the "
            "water through one door, vcjax.environment.WaterMotion)",
            DeprecationWarning,
            stacklevel=2,
        )
        return self.water.velocity


@dataclasses.dataclass(frozen=True)
class EngineLaw(Law):
    """The generic engine's law: the reaction force (16) of the virtual constraints (module
    docstring) on the loop's design mechanics; gains
    [`EngineGains`][vcjax.loops.engine.EngineGains].

    ``params(loop, gains, sc, design)`` (``design``: ``sc.design``, the design parameters);
    ``step(loop, params, t, (q, qd), z) -> (tau, z_dot, aux)``.
    """

    def default_gains(self, loop) -> EngineGains:
        return engine_gains()

    def gain_specs(self, loop):
        return (gain_spec("P_G", size=2), gain_spec("P_Phi", size=2), gain_spec("sigma"))

    def symmetric_pairs(self, loop):
        return (("P_G", 0, "P_Phi", 0), ("P_G", 1, "P_Phi", 1))

    def validate_gains(self, gains):
        return engine_gains(gains.P_G, gains.P_Phi, gains.sigma)

    def params(self, loop, gains, sc, design):
        return gains, _Args(design, sc.path, sc.u_d, gains.sigma)

    def initial_state(self, loop, sc):
        return jnp.atleast_1d(sc.varpi0)

    def particle(self, z):
        return z[..., 0]

    def heading_error(self, aux):
        return jnp.zeros_like(aux.speed_err)

    def step(self, loop, params, t, x, z):
        gains, args = params
        q, qd = x
        vg = VCMGains(P_G=gains.P_G, P_Phi=gains.P_Phi)
        cons = loop._constraints
        tau, _, diag = reaction_force(loop._system, cons, vg, q, qd, t, None, args, z=z)
        z_dot = cons.state_rate(q, t, z, args)
        eps, frame = loop._eps(q, args, z[0])
        v = jax.jvp(lambda q_: loop.position(q_, args.params)[:2], (q,), (qd,))[1]
        tangent = jnp.stack([jnp.cos(frame.psi_p), jnp.sin(frame.psi_p)])
        aux = EngineAux(
            eps=eps,
            speed_err=tangent @ v - args.u_d,
            Phi=diag.Phi,
            residual=diag.residual,
            rank=diag.rank,
            tau=tau,
        )
        return tau, z_dot, aux


@dataclasses.dataclass(frozen=True)
class EngineLoop(Loop):
    """A mechanical system held on a path by the generic engine (module docstring)."""

    act_signals: ClassVar[tuple[str, ...] | None] = ("torque",)

    laws: ClassVar[dict[str, Law]] = {"vcm": EngineLaw()}
    default_controller: ClassVar[str] = "vcm"
    feels: ClassVar[dict[str, bool | str]] = {
        "force": True,
        "current": True,
        "varying_current": True,
        "waves": "the engine's plant takes the water's velocity at its point only, not the "
        "orbital motion's acceleration (added mass, Froude-Krylov) that waves need",
    }

    # ---------------------------------------------------------------- what a subclass gives
    def mass_matrix(self, q, p):
        raise NotImplementedError

    def bias_force(self, q, qd, p):
        raise NotImplementedError

    def point(self, q, p):
        raise NotImplementedError

    def water_velocity(self, q, current, p):
        """(n,) generalised velocity of the water at ``q``: ``J(q) qd_c = V_c`` (module
        docstring), ``current`` (3,) NED [m/s]. Override for another model of the current."""
        d = jnp.shape(self.point(q, p))[0]
        J = jax.jacfwd(lambda q_: jnp.asarray(self.point(q_, p)))(q)
        if J.shape[0] == J.shape[1]:
            return jnp.linalg.solve(J, current[:d])
        return jnp.linalg.pinv(J) @ current[:d]

    # ---------------------------------------------------------------- engine pieces
    def position(self, eta, params):
        x = jnp.asarray(self.point(eta, params))
        return x if x.shape == (3,) else jnp.concatenate([x, jnp.zeros(1, x.dtype)])

    def _eps(self, q, args: _Args, varpi):
        # path_pose: the engine differentiates these constraints twice
        frame = paths.path_pose(self.path, args.path, varpi)
        return rot2(frame.psi_p).T @ (self.position(q, args.params)[:2] - frame.p[:2]), frame

    @functools.cached_property
    def _system(self) -> MechanicalSystem:
        return MechanicalSystem(
            mass_matrix=lambda q, a: self.mass_matrix(q, a.params),
            bias_force=lambda q, qd, a: self.bias_force(q, qd, a.params),
        )

    @functools.cached_property
    def _constraints(self) -> VirtualConstraints:
        def rate(q, t, z, a):
            eps, frame = self._eps(q, a, z[0])
            return jnp.atleast_1d((a.u_d + a.sigma * eps[0]) / frame.speed_bar)

        return VirtualConstraints(
            holonomic=lambda q, t, a, z: self._eps(q, a, z[0])[0], state_rate=rate
        )

    # ---------------------------------------------------------------- the loop
    def plant(self, t, x, u, args: EngineArgs):
        p = args.params
        q, qd = x
        sat = smooth_saturate if self.smooth else saturate
        tau = sat(u, p.tau_max) + args.disturbance
        felt = self.can_feel("current")
        qd_r = qd - self.water_velocity(q, args.water.velocity, p) if felt else qd
        qdd = spd_solve_small(self.mass_matrix(q, p), tau - self.bias_force(q, qd_r, p))
        return qd, qdd

    def control(self, t, x, z, ctrl):
        return self.law.step(self, ctrl, t, x, z)

    def plant_args(self, sc: Scenario, current, current_dot):
        return EngineArgs(sc.plant, sc.disturbance, WaterMotion(current, current_dot))

    def with_current(self, args, current, current_dot):
        return args._replace(water=WaterMotion(current, current_dot))

    def ctrl_params(self, gains, sc: Scenario):
        return self.law.params(self, gains, sc, self.law_design(sc))

    def initial_state(self, sc: Scenario):
        return (sc.eta0, sc.nu0), self.law.initial_state(self, sc)

    def signals(self, traj, sc: Scenario) -> Signals:
        """True errors: the point of the *plant* (its parameters may differ from the design's)."""
        n = traj.u.shape[0]
        q, qd = traj.x[0][:n], traj.x[1][:n]
        args = _Args(sc.plant, sc.path, sc.u_d, jnp.zeros_like(sc.u_d))

        def one(q_, qd_, w):
            eps, frame = self._eps(q_, args, w)
            pos, v = jax.jvp(lambda a: self.position(a, sc.plant), (q_,), (qd_,))
            tangent = jnp.stack([jnp.cos(frame.psi_p), jnp.sin(frame.psi_p)])
            return eps, pos, pos - frame.p, tangent @ v[:2] - sc.u_d

        eps, pos, p_err, speed_err = jax.vmap(one)(q, qd, self.law.particle(traj.z[:n]))
        tau_max = sc.plant.tau_max
        return Signals(
            eps=eps,
            pos=pos,
            p_err=p_err,
            u_err=speed_err,
            psi_err=jnp.zeros(n, q.dtype),
            depth_err=jnp.zeros(n, q.dtype),
            cmd_ratio=traj.u / tau_max,
            sat=jnp.any(jnp.abs(traj.u) > tau_max, axis=1),
            act={"torque": jnp.max(jnp.abs(traj.u), axis=1)},
        )
