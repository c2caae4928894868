"""Current components: [`ConstantCurrent`][vcjax.environment.flow.ConstantCurrent] (``[current]``)
and [`GaussMarkov`][vcjax.environment.flow.GaussMarkov]
(``[gauss_markov]``, the process of [`vcjax.environment.current`][vcjax.environment.current]). Both
are uniform in
space: the water's velocity in NED (3,) [m/s], its direction the one it flows towards,
clockwise from north."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp

from vcjax._checks import ConfigError
from vcjax.environment.component import Component, Key, draw_unit, written
from vcjax.environment.current import GaussMarkovCurrent, current_ned, gm_init, gm_step, gm_value

__all__ = [
    "CURRENT_SCHEMA",
    "ConstantCurrent",
    "CurrentParams",
    "GaussMarkov",
    "GaussMarkovParams",
    "check_current",
]

#: ``[current]``: THE declaration of the section's keys (sweep, tune and the Python API read it
#: from here; `vcjax.config.schema.Current` is built from it).
#: The defaults are the paper's Simulation 1: 0.5 m/s towards east, constant.
CURRENT_SCHEMA = {
    "model": Key("constant", "current model", choices=("constant", "gauss_markov"), kind="str"),
    "speed": Key(
        0.5,
        "mean current speed",
        lo=0.0,
        unit="m/s",
        aliases=("[scenarios] current_max",),
    ),
    "direction_deg": Key(90.0, "direction the water flows towards", unit="deg"),
    "sigma": Key(0.05, "Gauss-Markov speed standard deviation", lo=0.0, unit="m/s", kind="float"),
    "tau": Key(300.0, "Gauss-Markov time constant", lo=0.0, strict_lo=True, unit="s", kind="float"),
    "max_speed": Key(
        2.0, "Gauss-Markov speed bound", lo=0.0, strict_lo=True, unit="m/s", kind="float"
    ),
}
#: the keys that only the Gauss-Markov model reads
GAUSS_MARKOV_KEYS = ("sigma", "tau", "max_speed")
_DEG = math.pi / 180.0


def _radians(value):
    """A direction [deg] (a number or a ``(lo, hi)`` range) in radians, converted before the
    draw (plain Python float64, the order of operations every sampled direction has had)."""
    return tuple(a * _DEG for a in value) if isinstance(value, tuple) else value * _DEG


def check_current(section: Mapping, given: Mapping) -> None:
    """The Gauss-Markov keys are refused with a constant current (they would be ignored);
    ``given``: the keys the table wrote ([`written`][vcjax.environment.component.written])."""
    if section["model"] == "constant":
        for k in GAUSS_MARKOV_KEYS:
            if k in given:
                raise ConfigError(
                    f"[current] {k}: applies to model = 'gauss_markov' only; with the constant "
                    "current (model = 'constant', the default) it would be ignored"
                )


class CurrentParams(NamedTuple):
    """velocity: (3,) the water's velocity in NED [m/s]."""

    velocity: Any


@dataclasses.dataclass(frozen=True)
class ConstantCurrent(Component):
    """``[current]``: a uniform current of a sampled speed and direction; constant, or with
    ``model = "gauss_markov"`` wandering about that mean
    ([`GaussMarkov`][vcjax.environment.flow.GaussMarkov],
    [`resolve`][vcjax.environment.component.Component.resolve])."""

    section = "current"
    kind = "current"
    schema = CURRENT_SCHEMA

    def check(self, raw):
        out = super().check(raw)
        check_current(out, written(raw, self.schema))
        return out

    def resolve(self, section):
        return GaussMarkov() if section.get("model") == "gauss_markov" else self

    def draw_mean(self, u, key, section):
        """``(speed, direction, velocity)`` of one run: the mean speed [m/s] and direction [rad]
        from two uniform numbers ``u`` (2,) in [0, 1) (``lo + (hi - lo) u``: a fixed value is
        exact; a sweep hands over the first two numbers of its scenario's stream), and the (3,)
        mean water velocity in NED [m/s] they make. ``key``: the component's own PRNG key for
        any further draw of a key of its section (the built-in keys need none)."""
        speed = draw_unit(u[0], section["speed"], u.dtype)
        direction = draw_unit(u[1], _radians(section["direction_deg"]), u.dtype)
        return speed, direction, current_ned(speed, direction)

    def sample(self, key, section):
        k_unit, k_more = jax.random.split(key)
        u = jax.random.uniform(k_unit, (2,), jnp.asarray(0.0).dtype)
        return CurrentParams(self.draw_mean(u, k_more, section)[2])

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
    schema = {k: v for k, v in CURRENT_SCHEMA.items() if k != "model"}

    def sample(self, key, section):
        k_unit, k_more, k_proc = jax.random.split(key, 3)
        u = jax.random.uniform(k_unit, (2,), jnp.asarray(0.0).dtype)
        mean = ConstantCurrent().draw_mean(u, k_more, section)[2]
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
