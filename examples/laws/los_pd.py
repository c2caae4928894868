"""A control law of your own for an existing vehicle: line-of-sight guidance with a PD heading
loop and a P surge-speed loop for the INFANTE-class AUV, with its own gains, registered as
controller "los_pd" of vehicle "infante" (the last line). Nothing else in vcjax changes: the law
is then simulated, swept and tuned like the built-in ones. Configs load this file with
``[scenario] module = "../laws/los_pd.py"`` (relative to the config file); Python imports it.

    vcjax sweep examples/sweeps/own_law.toml --out out/sweep-own-law
    vcjax tune examples/tuning/own_law.toml --out out/tune-own-law
"""

import dataclasses
from typing import Any, NamedTuple

import jax.numpy as jnp

from vcjax import loops, paths
from vcjax.linalg import rot2, wrap_angle


class LosPDGains(NamedTuple):
    Delta: Any  # () look-ahead [m]
    sigma: Any  # () particle-speed gain [1/s]
    k_u: Any  # () surge-speed gain [1/s]
    k_p: Any  # () heading stiffness [1/s^2]
    k_d: Any  # () heading damping [1/s]


class LosPDParams(NamedTuple):
    gains: LosPDGains
    path: Any
    u_d: Any
    model: Any


class LosPDState(NamedTuple):
    varpi: Any


class LosPDAux(NamedTuple):
    eps: Any
    psi_tilde: Any


@dataclasses.dataclass(frozen=True)
class LosPDLaw(loops.Law):
    """Particle on the path at ``u_d + sigma s``; heading to the LOS point ``Delta`` ahead,
    PD on the heading error; P on the surge speed (both through the design inertia)."""

    def default_gains(self, loop):
        f = lambda x: jnp.asarray(x, float)
        return LosPDGains(f(6.0), f(0.5), f(1.0), f(0.6), f(1.6))

    def gain_specs(self, loop):
        return tuple(loops.gain_spec(n) for n in LosPDGains._fields)

    def validate_gains(self, gains):
        if not all(float(g) > 0 for g in gains):
            raise ValueError("los_pd gains: every gain must be > 0")
        return gains

    def params(self, loop, gains, sc, design):  # design: INFANTE's model and rudder ratio
        return LosPDParams(gains, sc.path, sc.u_d, design.model)

    def initial_state(self, loop, sc):
        return LosPDState(varpi=sc.varpi0)

    def step(self, loop, params, t, x, z):
        g, m = params.gains, params.model
        frame = paths.path_pose(loop.path, params.path, z.varpi)  # no rates needed
        s, e = rot2(frame.psi_p).T @ (x.eta[:2] - frame.p[:2])
        psi_d = frame.psi_p + jnp.arctan2(-e, g.Delta)
        psi_tilde = wrap_angle(x.eta[2] - psi_d)
        tau_u = m.m11 * g.k_u * (params.u_d - x.nu[0]) + m.d11 * x.nu[0]
        tau_r = -m.m33 * (g.k_p * psi_tilde + g.k_d * x.nu[2])
        tau = jnp.stack([tau_u, jnp.zeros_like(tau_u), tau_r])
        w_dot = (params.u_d + g.sigma * s) / frame.speed_bar
        return tau, LosPDState(varpi=w_dot), LosPDAux(jnp.stack([s, e]), psi_tilde)


loops.register_law("infante", "los_pd", LosPDLaw())  # the one registry line
