"""The constant generalised force component (``[force]``): one value or ``[lo, hi]`` range per
generalised coordinate of the plant (body frame for craft) [N, N m]."""

from __future__ import annotations

import dataclasses
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp

from vcjax.environment.component import Component, Key, draw

__all__ = ["ConstantForce", "ForceParams"]


class ForceParams(NamedTuple):
    """tau: (n,) constant generalised force [N, N m]."""

    tau: Any


@dataclasses.dataclass(frozen=True)
class ConstantForce(Component):
    """A constant generalised force on the plant, ``size`` entries named ``tau_0`` ..."""

    size: int = 3

    section = "force"
    kind = "force"

    def bind(self, loop):
        values = {k: jnp.asarray(float(v)) for k, v in loop.initial_keys.items()}
        _, nu0 = loop.initial_from(values)  # the size of the generalised velocity
        return dataclasses.replace(self, size=int(jnp.shape(nu0)[0]))

    @property
    def schema(self):
        return {f"tau_{i}": Key(0.0, f"generalised force {i} [N or N m]") for i in range(self.size)}

    def sample(self, key, section):
        ks = jax.random.split(key, self.size)
        return ForceParams(jnp.stack([draw(ks[i], section[f"tau_{i}"]) for i in range(self.size)]))

    def force(self, params):
        return params.tau
