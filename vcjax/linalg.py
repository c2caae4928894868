"""Small numerical building blocks: planar rotations, angle wrapping, NaN-safe norms and
saturations (hard and smooth).

Everything here is pure ``jax.numpy``, works in float32 and float64, and keeps gradients finite
at the singular points (zero vectors) using the double-``where`` trick.
"""

from __future__ import annotations

import jax.numpy as jnp

__all__ = [
    "rot2",
    "matvec",
    "skew2",
    "wrap_angle",
    "safe_norm",
    "safe_sqrt",
    "saturate",
    "smooth_saturate",
    "saturation_excess",
    "solve_surge_decoupled",
    "signed_square_sums",
]


def rot2(a):
    """Planar rotation ``R(a) = [[cos a, -sin a], [sin a, cos a]]``, shape (2, 2)."""
    c, s = jnp.cos(a), jnp.sin(a)
    return jnp.stack([jnp.stack([c, -s]), jnp.stack([s, c])])


def matvec(A, x):
    """``A @ x`` for a small (m, n) matrix and (n,) vector, as n elementwise multiply-adds.

    Same value as ``A @ x`` (the same sum, in the same order). Under ``vmap`` a ``@`` of tiny
    per-trajectory matrices becomes a batched ``dot`` kernel of its own; multiply-adds fuse with
    the elementwise code around them. Whether that is faster depends on what XLA then fuses
    (measured, ``benchmarks/README.md``: faster for the plant's Coriolis/damping products, 1.4x
    slower when used in the VCM law too, where bigger fusions recompute shared terms).
    """
    out = A[:, 0] * x[0]
    for j in range(1, A.shape[1]):
        out = out + A[:, j] * x[j]
    return out


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


def signed_square_sums(a, b, n: int):
    """``(S0, S1)``: ``S0 = sum_i h_i |h_i|`` and ``S1 = sum_i i h_i |h_i|`` over
    ``i = 0, ..., n`` for the arithmetic sequence ``h_i = a + b i``, in closed form.

    Strip theory's cross-flow drag sums ``h |h|`` of the strip velocity ``h = v + x r``, which is
    linear along the hull: ``h_i`` changes sign at most once, at ``i = -a / b``. With ``m`` the
    number of leading indices on one side of the sign change (``m = clip(ceil(-a / b), 0, n+1)``)
    and ``sigma = -sign(b)`` the sign of those leading terms,
    ``S_k = sigma (2 P_k(m) - P_k(n + 1))`` where ``P_k(q) = sum_{i<q} i^k (a + b i)^2`` expands
    into the power sums ``sum_{i<q} i^j = q (q-1) / 2, (q-1) q (2q-1) / 6, (q (q-1) / 2)^2``
    (``j = 1, 2, 3``). A term with ``h_i = 0`` contributes 0 on either side, so the value is
    exact however the boundary is rounded, and the gradient with ``m`` held fixed (``ceil`` has
    zero derivative) is the sum's gradient ``2 |h_i|``: continuous and finite everywhere.

    Equal to the direct ``n + 1``-term sum within round-off (the expansion cancels by at most a
    factor ~ n between terms), for a few dozen scalar operations instead of ``n + 1``-wide
    arrays: inside a vmapped rollout everything fuses into one elementwise kernel.

    Args:
        a, b: () first term and step of the sequence (any float dtype, traced).
        n: static number of intervals (``n + 1`` terms).
    """
    one = jnp.ones_like(a)
    pos, neg = b > 0, b < 0
    b_safe = jnp.where(pos | neg, b, one)
    big = jnp.asarray(n + 2, a.dtype)
    # b == 0: all terms have the sign of a; take "leading side negative" (sigma = -1), m = n + 1
    # when a < 0 (every term negative), else 0.
    t = jnp.where(pos | neg, -a / b_safe, jnp.where(a < 0, big, -big))
    m = jnp.clip(jnp.ceil(t), 0, n + 1)
    sigma = jnp.where(neg, one, -one)

    def moments(q):
        s1 = 0.5 * q * (q - 1)
        s2 = (q - 1) * q * (2 * q - 1) / 6
        s3 = s1 * s1
        aa, ab2, bb = a * a, 2 * a * b, b * b
        return q * aa + ab2 * s1 + bb * s2, aa * s1 + ab2 * s2 + bb * s3

    p0m, p1m = moments(m)
    p0n, p1n = moments(jnp.asarray(n + 1, a.dtype))
    return sigma * (2 * p0m - p0n), sigma * (2 * p1m - p1n)
