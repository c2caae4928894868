"""Small numerical building blocks: planar rotations, angle wrapping, NaN-safe norms and
saturations (hard and smooth).

Everything here is pure ``jax.numpy``, works in float32 and float64, and keeps gradients finite
at the singular points (zero vectors) using the double-``where`` trick.
"""

from __future__ import annotations

import jax.numpy as jnp

__all__ = [
    "rot2",
    "skew2",
    "wrap_angle",
    "safe_norm",
    "safe_sqrt",
    "saturate",
    "smooth_saturate",
    "saturation_excess",
    "solve_surge_decoupled",
]


def rot2(a):
    """Planar rotation ``R(a) = [[cos a, -sin a], [sin a, cos a]]``, shape (2, 2)."""
    c, s = jnp.cos(a), jnp.sin(a)
    return jnp.stack([jnp.stack([c, -s]), jnp.stack([s, c])])


def skew2(w):
    """Planar skew matrix ``S(w) = [[0, -w], [w, 0]]`` so that ``d/dt R(a) = R(a) S(a_dot)``."""
    z = jnp.zeros_like(w)
    return jnp.stack([jnp.stack([z, -w]), jnp.stack([w, z])])


def wrap_angle(a):
    """Wrap an angle [rad] into ``[-pi, pi)``. Smooth (derivative 1) away from the cut."""
    return jnp.mod(a + jnp.pi, 2 * jnp.pi) - jnp.pi


def safe_sqrt(x, eps=0.0):
    """``sqrt(x)`` with a finite (zero) gradient at ``x <= eps``."""
    pos = x > eps
    return jnp.where(pos, jnp.sqrt(jnp.where(pos, x, jnp.ones_like(x))), jnp.zeros_like(x))


def safe_norm(x, axis=-1, keepdims=False):
    """Euclidean norm along ``axis`` whose gradient at the zero vector is zero, not NaN."""
    return safe_sqrt(jnp.sum(x * x, axis=axis, keepdims=keepdims))


def saturate(x, limit):
    """Hard saturation ``clip(x, -limit, limit)`` (``limit`` > 0, broadcastable)."""
    return jnp.clip(x, -limit, limit)


def smooth_saturate(x, limit):
    """Smooth saturation ``limit * tanh(x / limit)``: slope 1 at 0, bounded by ``limit``.

    Use it where gradients must pass through a saturated actuator (gain tuning).
    """
    return limit * jnp.tanh(x / limit)


def saturation_excess(x, limit):
    """How far ``|x|`` goes beyond ``limit`` (0 inside the limits), elementwise, >= 0."""
    return jnp.maximum(jnp.abs(x) - limit, jnp.zeros_like(x))


def solve_surge_decoupled(M, f):
    """Solve ``M x = f`` for a (3, 3) horizontal-plane inertia matrix whose surge row and column
    are decoupled, ``M = [[a, 0, 0], [0, b, c], [0, d, e]]`` (the structure of (20) and of the
    INFANTE-class plant), in closed form (Cramer's rule on the 2x2 sway-yaw block).

    Much cheaper than a general LU solve inside batched rollouts (no LAPACK call per batch
    element) and exact for this structure; the caller guarantees the zeros (``M`` SPD, so
    ``a > 0`` and ``b e - c d > 0``).
    """
    det = M[1, 1] * M[2, 2] - M[1, 2] * M[2, 1]
    return jnp.stack(
        [
            f[0] / M[0, 0],
            (M[2, 2] * f[1] - M[1, 2] * f[2]) / det,
            (M[1, 1] * f[2] - M[2, 1] * f[1]) / det,
        ]
    )
