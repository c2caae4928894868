"""A disturbance of your own: a tidal current whose direction turns in time, as one component of
vcjax.environment plus its registration line (docs/guides/disturbances.md). A sweep config
imports this file with [scenario] module = "../environment/tidal.py" and then takes a [tidal]
section:

    vcjax sweep examples/sweeps/tidal.toml --out out/sweep-tidal
"""

import dataclasses
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp

from vcjax import environment
from vcjax.environment import Key, draw


class TidalParams(NamedTuple):
    speed: Any  # () [m/s]
    omega: Any  # () turning rate [rad/s]
    phase: Any  # () direction at t = 0 [rad, towards, clockwise from north]


@dataclasses.dataclass(frozen=True)
class Tidal(environment.Component):
    section = "tidal"  # its TOML section
    kind = "varying_current"  # what a loop must feel to take it
    schema = {  # its keys: default, meaning, bounds
        "speed": Key(0.3, "speed [m/s]", lo=0.0),
        "period": Key(600.0, "period of one turn [s]", lo=0.0, strict_lo=True),
        "direction_deg": Key(0.0, "direction at t = 0 [deg from north]"),
    }

    def sample(self, key, section):  # traced: one run's parameters
        k1, k2, k3 = jax.random.split(key, 3)
        return TidalParams(
            draw(k1, section["speed"]),  # a number, or a [lo, hi] range
            2 * jnp.pi / draw(k2, section["period"]),
            jnp.deg2rad(draw(k3, section["direction_deg"])),
        )

    def water(self, params, held, t, p_ned, current):  # (3,) NED velocity, acceleration
        phi = params.phase + params.omega * t
        c, s = jnp.cos(phi), jnp.sin(phi)
        v = params.speed * jnp.stack([c, s, jnp.zeros_like(c)])
        a = params.speed * params.omega * jnp.stack([-s, c, jnp.zeros_like(c)])
        return v, a


environment.register(Tidal())  # the one registration line
