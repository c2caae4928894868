"""The constant generalised force component (``[force]``): one value or ``[lo, hi]`` range per
generalised coordinate of the plant (body frame for craft) [N, N m].

A config is read before its vehicle is known: the registered component (``size`` None) accepts
``tau_0`` .. ``tau_5`` (the largest plant, a 6-DOF craft) and keeps only the keys written; bound
to a loop (``ConstantForce.bind``) it takes the plant's
own number of coordinates, refuses a key beyond it and fills the rest with 0."""

from __future__ import annotations

import dataclasses
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp

from vcjax.environment.component import Component, Key, draw, written

__all__ = ["MAX_FORCES", "ConstantForce", "ForceParams"]

#: the most generalised coordinates of a plant ([force] keys ``tau_0`` .. ``tau_5``)
MAX_FORCES = 6


class ForceParams(NamedTuple):
    """tau: (n,) constant generalised force [N, N m]."""

    tau: Any


@dataclasses.dataclass(frozen=True)
class ConstantForce(Component):
    """A constant generalised force on the plant, ``size`` entries named ``tau_0`` ...

    ``size`` None: not yet bound to a loop (a config read before its vehicle is known): any of
    ``tau_0`` .. ``tau_5`` is accepted and only the keys written are kept."""

    size: int | None = None

    section = "force"
    kind = "force"

    def bind(self, loop):
        """This force for ``loop``: one entry per generalised coordinate of its plant."""
        values = {k: jnp.asarray(float(v)) for k, v in loop.initial_keys.items()}
        _, nu0 = loop.initial_from(values)  # the size of the generalised velocity
        return dataclasses.replace(self, size=int(jnp.shape(nu0)[0]))

    @property
    def schema(self):
        n = MAX_FORCES if self.size is None else self.size
        doc = "generalised force {} [N or N m] (body frame; up to the plant's coordinates)"
        return {f"tau_{i}": Key(0.0, doc.format(i)) for i in range(n)}

    def check(self, raw):
        out = super().check(raw)
        if self.size is None:  # the plant's size is not known yet: no defaults filled in
            given = set(written(raw, self.schema))
            out = {k: v for k, v in out.items() if k in given}
        return out

    def sample(self, key, section):
        if self.size is None:
            raise ValueError(
                "[force]: the force has one entry per generalised coordinate of the plant: "
                "sample it for a loop (vcjax.environment.sample(key, sections, loop))"
            )
        ks = jax.random.split(key, self.size)
        return ForceParams(jnp.stack([draw(ks[i], section[f"tau_{i}"]) for i in range(self.size)]))

    def force(self, params):
        return params.tau
