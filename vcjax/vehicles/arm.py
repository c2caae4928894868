"""Non-marine example systems for the generic engine (the engine knows nothing about craft).

``TWO_LINK_ARM`` is a planar two-link arm in a vertical plane (y up, gravity -y), joint angles
``q = [q1, q2]`` (q1 from the x axis, q2 relative), point-mass-plus-inertia links.
"""

from __future__ import annotations

from typing import Any, NamedTuple

import jax.numpy as jnp

from vcjax._checks import check_positive
from vcjax.mechanics import MechanicalSystem

__all__ = [
    "ArmParams",
    "arm_params",
    "TWO_LINK_ARM",
    "arm_end_effector",
    "arm_energy",
]


class ArmParams(NamedTuple):
    """Two-link arm parameters (all scalars).

    Attributes:
        l1, l2: link lengths [m]; lc1, lc2: joint-to-centre-of-mass distances [m];
        m1, m2: link masses [kg]; I1, I2: link inertias about their centres [kg m^2];
        g: gravity [m/s^2] (0 for a horizontal arm).
    """

    l1: Any
    l2: Any
    lc1: Any
    lc2: Any
    m1: Any
    m2: Any
    I1: Any
    I2: Any
    g: Any


def arm_params(l1=1.0, l2=0.8, lc1=0.5, lc2=0.4, m1=2.0, m2=1.5, I1=0.2, I2=0.1, g=9.81):
    """Validated [`ArmParams`][vcjax.vehicles.arm.ArmParams] (lengths, masses, inertias > 0; ``g >=
    0``)."""
    for name, v in dict(l1=l1, l2=l2, lc1=lc1, lc2=lc2, m1=m1, m2=m2, I1=I1, I2=I2).items():
        check_positive(name, v, ())
    check_positive("g", g, (), strict=False)
    vals = (l1, l2, lc1, lc2, m1, m2, I1, I2, g)
    return ArmParams(*(jnp.asarray(v, dtype=float) for v in vals))


def _arm_terms(p: ArmParams):
    a = p.I1 + p.I2 + p.m1 * p.lc1**2 + p.m2 * (p.l1**2 + p.lc2**2)
    b = p.m2 * p.l1 * p.lc2
    d = p.I2 + p.m2 * p.lc2**2
    return a, b, d


def _arm_mass(q, p: ArmParams):
    a, b, d = _arm_terms(p)
    c2 = jnp.cos(q[1])
    return jnp.stack([jnp.stack([a + 2 * b * c2, d + b * c2]), jnp.stack([d + b * c2, d])])


def _arm_bias(q, qd, p: ArmParams):
    _, b, _ = _arm_terms(p)
    s2 = jnp.sin(q[1])
    cor = jnp.stack([-b * s2 * (2 * qd[0] * qd[1] + qd[1] ** 2), b * s2 * qd[0] ** 2])
    c1, c12 = jnp.cos(q[0]), jnp.cos(q[0] + q[1])
    grav = jnp.stack(
        [
            (p.m1 * p.lc1 + p.m2 * p.l1) * p.g * c1 + p.m2 * p.lc2 * p.g * c12,
            p.m2 * p.lc2 * p.g * c12,
        ]
    )
    return cor + grav


#: The arm as a [`MechanicalSystem`][vcjax.mechanics.MechanicalSystem]; ``args`` is an
#: [`ArmParams`][vcjax.vehicles.arm.ArmParams].
TWO_LINK_ARM = MechanicalSystem(mass_matrix=_arm_mass, bias_force=_arm_bias)


def arm_end_effector(q, p: ArmParams):
    """(2,) end-effector position [m]."""
    return jnp.stack(
        [
            p.l1 * jnp.cos(q[0]) + p.l2 * jnp.cos(q[0] + q[1]),
            p.l1 * jnp.sin(q[0]) + p.l2 * jnp.sin(q[0] + q[1]),
        ]
    )


def arm_energy(q, qd, p: ArmParams):
    """() total mechanical energy (kinetic + gravitational potential) [J]."""
    T = 0.5 * qd @ _arm_mass(q, p) @ qd
    y1 = p.lc1 * jnp.sin(q[0])
    y2 = p.l1 * jnp.sin(q[0]) + p.lc2 * jnp.sin(q[0] + q[1])
    return T + p.g * (p.m1 * y1 + p.m2 * y2)
