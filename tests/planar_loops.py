"""The damped planar point mass that several tests define as a loop of their own
(``m q'' + b q' = f``, its position the path point): the plant half of an
:class:`vcjax.loops.EngineLoop`, shared so that each test file states only what differs (name,
path, numbers, sensors). A test's loop: ``class MyLoop(PlanarPointMass, loops.EngineLoop)``
with ``defaults = (m, b, (tau_x, tau_y))``."""

from typing import Any, ClassVar, NamedTuple

import jax.numpy as jnp


class PointMassParams(NamedTuple):
    m: Any  # () mass [kg]
    b: Any  # () linear drag (on the velocity through the water, where there is a current) [kg/s]
    tau_max: Any  # (2,) force limits [N]


class PlanarPointMass:
    """Mixin: mass matrix ``m I``, bias force ``b q'``, the position as the point, initial
    state from ``x, y, vx, vy``; parameters :class:`PointMassParams` of :attr:`defaults`."""

    #: (m [kg], b [kg/s], (tau_x, tau_y) [N])
    defaults: ClassVar[tuple] = (1.0, 1.0, (10.0, 10.0))

    def default_params(self, dtype=None):
        f = lambda x: jnp.asarray(x, jnp.asarray(0.0).dtype if dtype is None else dtype)
        return PointMassParams(*(f(v) for v in self.defaults))

    def mass_matrix(self, q, p):
        return p.m * jnp.eye(2, dtype=q.dtype)

    def bias_force(self, q, qd, p):
        return p.b * qd

    def point(self, q, p):
        return q

    def initial_from(self, v):
        return jnp.stack([v["x"], v["y"]]), jnp.stack([v["vx"], v["vy"]])
