"""The arm demo (``vcjax demo``): the generic engine on a non-marine system, a two-link arm
whose end effector is held on a circle by virtual constraints."""

from __future__ import annotations

from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from vcjax.mechanics import VirtualConstraints, reaction_force, vcm_gains
from vcjax.rollout import RolloutConfig, rollout
from vcjax.systems import TWO_LINK_ARM, arm_end_effector, arm_params

__all__ = ["arm_demo", "ARM_CIRCLE", "ARM_DT"]

#: RK4 step of the arm demo [s].
ARM_DT = 2e-3

_CENTER = (1.0, 0.6)
_RADIUS = 0.35


def _circle_G(q, t, p):
    d = arm_end_effector(q, p) - jnp.asarray(_CENTER, q.dtype)
    return jnp.atleast_1d(jnp.sqrt(d @ d) - _RADIUS)


def _tangential_K(q, qd, t, p):
    d = arm_end_effector(q, p) - jnp.asarray(_CENTER, q.dtype)
    tangent = jnp.stack([-d[1], d[0]]) / jnp.sqrt(d @ d)
    v = tangent @ (jax.jacfwd(arm_end_effector)(q, p) @ qd)
    return jnp.atleast_1d(v - 0.5)


#: End effector held on a circle (holonomic) moving at 0.5 m/s along it (velocity constraint).
ARM_CIRCLE = VirtualConstraints(holonomic=_circle_G, velocity=_tangential_K)


def _plant(t, x, u, p):
    q, qd = x
    return qd, jnp.linalg.solve(
        TWO_LINK_ARM.mass_matrix(q, p), u - TWO_LINK_ARM.bias_force(q, qd, p)
    )


def _controller(t, x, z, ctrl):
    gains, p = ctrl
    q, qd = x
    tau, _, diag = reaction_force(TWO_LINK_ARM, ARM_CIRCLE, gains, q, qd, t, None, p)
    return tau, z, diag


def arm_demo(out: Path, horizon: float = 6.0, dt: float = ARM_DT) -> list[Path]:
    """Simulate the arm demo and write ``arm_demo.png``; returns the written files."""
    p = arm_params()
    gains = vcm_gains(P_G=[2.0], P_Phi=[1.5, 3.0])
    x0 = (jnp.array([0.35, 1.3], dtype=p.l1.dtype), jnp.array([0.2, -0.1], dtype=p.l1.dtype))
    cfg = RolloutConfig(num_steps=int(round(horizon / dt)))
    run = jax.jit(rollout, static_argnames=("plant", "controller", "config"))
    traj = run(_plant, _controller, cfg, p, (gains, p), x0, jnp.zeros(0, p.l1.dtype), dt)
    ee = np.asarray(jax.vmap(arm_end_effector, in_axes=(0, None))(traj.x[0], p))
    t = np.asarray(traj.t)

    from vcjax.plots.arm import arm_figure

    f = Path(out) / "arm_demo.png"
    return [arm_figure(t, ee, traj.aux, traj.u, gains, _CENTER, _RADIUS, f)]
