"""Current components: [`ConstantCurrent`][vcjax.environment.flow.ConstantCurrent] (``[current]``)
and [`GaussMarkov`][vcjax.environment.flow.GaussMarkov]
(``[gauss_markov]``, the process of [`vcjax.environment.current`][vcjax.environment.current]). Both
are uniform in
space: the water's velocity in NED (3,) [m/s], its direction the one it flows towards,
clockwise from north."""

from __future__ import annotations

import dataclasses
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp

from vcjax.environment.component import Component, Key, draw
from vcjax.environment.current import GaussMarkovCurrent, current_ned, gm_init, gm_step, gm_value

__all__ = ["ConstantCurrent", "CurrentParams", "GaussMarkov", "GaussMarkovParams"]

_SPEED = Key(0.0, "speed [m/s] (or a [lo, hi] range)", lo=0.0)
_DIRECTION = Key(90.0, "direction the water flows towards [deg, clockwise from north]")


class CurrentParams(NamedTuple):
    """velocity: (3,) the water's velocity in NED [m/s]."""

    velocity: Any


@dataclasses.dataclass(frozen=True)
class ConstantCurrent(Component):
    """A uniform, constant current of a sampled speed and direction."""

    section = "current"
    kind = "current"
    schema = {"speed": _SPEED, "direction_deg": _DIRECTION}

    def sample(self, key, section):
        k1, k2 = jax.random.split(key)
        speed = draw(k1, section["speed"])
        beta = jnp.deg2rad(draw(k2, section["direction_deg"]))
        return CurrentParams(current_ned(speed, beta))

    def water(self, params, held, t, p_ned, current):
        v = params.velocity
        return v, jnp.zeros_like(v)


class GaussMarkovParams(NamedTuple):
    """Traced parameters of [`GaussMarkov`][vcjax.environment.flow.GaussMarkov].

    Attributes:
        current: [`GaussMarkovCurrent`][vcjax.environment.current.GaussMarkovCurrent] (horizontal,
            (2,) mean);
        vertical: (1,) the down component of the water's velocity [m/s] (constant);
        key: PRNG key of the process (``split(key)``: the initial draw, the steps).
    """

    current: Any
    vertical: Any
    key: Any


@dataclasses.dataclass(frozen=True)
class GaussMarkov(Component):
    """A horizontal current ``clip(mean + d)``, ``d`` a first-order Gauss–Markov process
    ([`vcjax.environment.current`][vcjax.environment.current]: exact discretisation per step,
    ``d_0`` stationary),
    linear in time between the step samples (its rate is the slope)."""

    section = "gauss_markov"
    kind = "varying_current"
    process = True
    schema = {
        "speed": _SPEED,
        "direction_deg": _DIRECTION,
        "sigma": Key(0.05, "stationary standard deviation per component [m/s]", lo=0.0),
        "tau": Key(300.0, "correlation time [s]", lo=0.0, strict_lo=True),
        "max_speed": Key(
            2.0, "bound on the speed handed to the plant [m/s]", lo=0.0, strict_lo=True
        ),
    }

    def sample(self, key, section):
        k_speed, k_dir, k_proc = jax.random.split(key, 3)
        beta = jnp.deg2rad(draw(k_dir, section["direction_deg"]))
        mean = current_ned(draw(k_speed, section["speed"]), beta)
        f = lambda name: jnp.asarray(section[name], mean.dtype)
        gm = GaussMarkovCurrent(mean[:2], f("sigma"), f("tau"), f("max_speed"))
        return GaussMarkovParams(gm, mean[2:], k_proc)

    def init(self, params):
        k_init, _ = jax.random.split(params.key)
        return gm_init(params.current, k_init)

    def advance(self, params, d, k, t, dt):
        _, k_steps = jax.random.split(params.key)
        p = params.current
        d_next = gm_step(p, d, dt, jax.random.fold_in(k_steps, k))
        V0, V1 = gm_value(p, d), gm_value(p, d_next)
        dV = (V1 - V0) / dt
        vertical = params.vertical
        held = (jnp.concatenate([V0, vertical]), jnp.concatenate([dV, 0 * vertical]), t)
        return d_next, held

    def water(self, params, held, t, p_ned, current):
        V, dV, t_k = held
        return V + (t - t_k) * dV, dV
