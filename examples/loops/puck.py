"""A loop of your own: an air-hockey puck (a planar point mass, m q'' + b q' = f + d) whose
centre the generic engine holds on a path, with force limits. Registered as vehicle "puck";
configs load it with [scenario] module = "../loops/puck.py" (relative to the config file).
The water's current acts through the drag: EngineLoop's plant passes the velocity relative to the
water to bias_force (see vcjax.loops.engine)."""

import dataclasses
from typing import Any, ClassVar, NamedTuple

import jax.numpy as jnp

from vcjax import loops, paths


class PuckParams(NamedTuple):
    m: Any  # () mass [kg]
    b: Any  # () linear drag [kg/s]
    tau_max: Any  # (2,) force limits [N]


@dataclasses.dataclass(frozen=True)
class PuckLoop(loops.EngineLoop):
    vehicle: ClassVar[str] = "puck"
    initial_keys: ClassVar[dict[str, float]] = {"x": 0.6, "y": 0.0, "vx": 0.0, "vy": 0.0}
    default_speed: ClassVar[float] = 0.5  # m/s along the path

    @classmethod
    def default_path(cls):
        return paths.circle(center=(0.0, 0.0), radius=0.5)

    def default_params(self, dtype=None):
        f = lambda x: jnp.asarray(x, dtype)
        return PuckParams(m=f(0.2), b=f(0.05), tau_max=f([2.0, 2.0]))

    def mass_matrix(self, q, p):  # M(q)
        return p.m * jnp.eye(2, dtype=q.dtype)

    def bias_force(self, q, qd, p):  # n(q, qd)
        return p.b * qd

    def point(self, q, p):  # what follows the path
        return q

    def initial_from(self, v):  # [initial] keys -> (q0, qd0)
        return jnp.stack([v["x"], v["y"]]), jnp.stack([v["vx"], v["vy"]])


loops.register(PuckLoop)
