"""Small numerical building blocks: planar rotations, angle wrapping, NaN-safe norms and
saturations (hard and smooth), and unrolled dense solves for small matrices (LU with partial
pivoting, Cholesky, Householder least squares) that batch without per-trajectory LAPACK calls.

Everything here is pure ``jax.numpy``, works in float32 and float64, and keeps gradients finite
at the singular points (zero vectors) using the double-``where`` trick.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

__all__ = [
    "Rzyx",
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
    "SMALL_MAX",
    "solve_small",
    "cholesky_small",
    "cho_solve_small",
    "lstsq_small",
    "spd_solve_small",
]

# Largest static size the unrolled routines below handle; larger systems go to LAPACK.
SMALL_MAX = 12


def rot2(a):
    """Planar rotation ``R(a) = [[cos a, -sin a], [sin a, cos a]]``, shape (2, 2)."""
    c, s = jnp.cos(a), jnp.sin(a)
    return jnp.stack([jnp.stack([c, -s]), jnp.stack([s, c])])


def Rzyx(phi, theta, psi):
    """(3, 3) body-to-NED rotation ``R = Rz(psi) Ry(theta) Rx(phi)`` (zyx Euler angles [rad])."""
    cphi, sphi = jnp.cos(phi), jnp.sin(phi)
    cth, sth = jnp.cos(theta), jnp.sin(theta)
    cpsi, spsi = jnp.cos(psi), jnp.sin(psi)
    return jnp.stack(
        [
            jnp.stack(
                [cpsi * cth, -spsi * cphi + cpsi * sth * sphi, spsi * sphi + cpsi * cphi * sth]
            ),
            jnp.stack(
                [spsi * cth, cpsi * cphi + sphi * sth * spsi, -cpsi * sphi + sth * spsi * cphi]
            ),
            jnp.stack([-sth, cth * sphi, cth * cphi]),
        ]
    )


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


# ------------------------------------------------------------------ small dense linear algebra
#
# Under ``vmap`` on the CPU, ``jnp.linalg.solve``/``cholesky``/``qr`` of tiny per-trajectory
# matrices become one LAPACK call per batch element (the FFI loops over the batch), ~0.3-1 us
# each: a 6-DOF loop made ~26 such calls per trajectory-step. The routines below unroll the
# same factorisations for a static size n <= SMALL_MAX into elementwise operations, which XLA
# fuses and vectorises across the batch. Same algorithms as LAPACK's (partial pivoting,
# Cholesky, Householder QR), so the same accuracy; they differentiate as ordinary jnp code.


def _as_matrix_rhs(b, n, name):
    b = jnp.asarray(b)
    if b.ndim not in (1, 2) or b.shape[0] != n:
        raise ValueError(
            f"{name}: right-hand side of shape (n,) or (n, k) with n = {n}, got {b.shape}"
        )
    return (b[:, None], True) if b.ndim == 1 else (b, False)


def _back_substitute(U, Y):
    """``U^-1 Y`` for an upper-triangular (n, n) ``U`` (only the upper triangle is read)."""
    n = U.shape[0]
    x = [None] * n
    for i in reversed(range(n)):
        s = Y[i]
        for j in range(i + 1, n):
            s = s - U[i, j] * x[j]
        x[i] = s / U[i, i]
    return jnp.stack(x)


def _forward_substitute(L, Y):
    """``L^-1 Y`` for a lower-triangular (n, n) ``L`` (only the lower triangle is read)."""
    n = L.shape[0]
    x = [None] * n
    for i in range(n):
        s = Y[i]
        for j in range(i):
            s = s - L[i, j] * x[j]
        x[i] = s / L[i, i]
    return jnp.stack(x)


def solve_small(A, b):
    """``A^-1 b`` for a small square ``A``: Gaussian elimination with partial pivoting,
    unrolled (LAPACK ``getrf``/``getrs``'s algorithm); ``b`` of shape (n,) or (n, k).

    For ``n > SMALL_MAX`` it calls ``jnp.linalg.solve``. Row exchanges are written as
    one-hot blends, so under ``vmap`` everything stays elementwise (no gather or scatter). A
    singular ``A`` gives inf/NaN, as LAPACK's solve does.
    """
    A = jnp.asarray(A)
    if A.ndim != 2 or A.shape[0] != A.shape[1]:
        raise ValueError(f"solve_small: A must be square (n, n), got shape {A.shape}")
    n = A.shape[0]
    if n > SMALL_MAX:
        return jnp.linalg.solve(A, b)
    B, vec = _as_matrix_rhs(b, n, "solve_small")
    dtype = jnp.result_type(A, B)
    M = jnp.concatenate([A.astype(dtype), B.astype(dtype)], axis=1)  # (n, n + k)
    rows = [M[i] for i in range(n)]
    for j in range(n - 1):
        # pivot: the row of largest |entry| in column j among rows j..n-1
        col = jnp.stack([jnp.abs(r[j]) for r in rows[j:]])
        onehot = (jnp.arange(n - j) == jnp.argmax(col)).astype(dtype)
        piv_row = sum(onehot[i] * rows[j + i] for i in range(n - j))
        top = rows[j]
        # swap: the pivot row moves to j, row j moves to where the pivot row was
        rest = [rows[j + i] + onehot[i] * (top - piv_row) for i in range(1, n - j)]
        rows[j] = piv_row
        inv_p = 1.0 / piv_row[j]
        rows[j + 1 :] = [r - (r[j] * inv_p) * piv_row for r in rest]
    U = jnp.stack(rows)
    X = _back_substitute(U[:, :n], U[:, n:])
    return X[:, 0] if vec else X


def cholesky_small(A):
    """Lower Cholesky factor ``L`` (``A = L L^T``) of a small symmetric positive-definite
    ``A``, unrolled (reads the lower triangle). Not positive definite: NaN entries, as
    ``jnp.linalg.cholesky``. For ``n > SMALL_MAX`` it calls ``jnp.linalg.cholesky``."""
    A = jnp.asarray(A)
    if A.ndim != 2 or A.shape[0] != A.shape[1]:
        raise ValueError(f"cholesky_small: A must be square (n, n), got shape {A.shape}")
    n = A.shape[0]
    if n > SMALL_MAX:
        return jnp.linalg.cholesky(A)
    L = [[None] * n for _ in range(n)]
    zero = jnp.zeros((), A.dtype)
    for j in range(n):
        d = A[j, j] - sum((L[j][k] * L[j][k] for k in range(j)), zero)
        L[j][j] = jnp.sqrt(d)  # NaN when not positive definite
        for i in range(j + 1, n):
            L[i][j] = (A[i, j] - sum((L[i][k] * L[j][k] for k in range(j)), zero)) / L[j][j]
    return jnp.stack([jnp.stack([L[i][j] if j <= i else zero for j in range(n)]) for i in range(n)])


def cho_solve_small(L, b):
    """``(L L^T)^-1 b`` from the lower factor of [`cholesky_small`][vcjax.linalg.cholesky_small];
    ``b`` (n,) or (n, k)."""
    n = L.shape[0]
    if n > SMALL_MAX:
        return jax.scipy.linalg.cho_solve((L, True), b)
    B, vec = _as_matrix_rhs(b, n, "cho_solve_small")
    X = _back_substitute(L.T, _forward_substitute(L, B))
    return X[:, 0] if vec else X


def spd_solve_small(A, b):
    """``A^-1 b`` for a small symmetric positive-definite ``A`` (a mass matrix, a regularised
    Gram matrix): [`cholesky_small`][vcjax.linalg.cholesky_small] then two triangular solves, about
    half the operations
    of [`solve_small`][vcjax.linalg.solve_small] and no pivot search. Reads ``A``'s lower
    triangle."""
    return cho_solve_small(cholesky_small(A), b)


def lstsq_small(W, h):
    """Least-squares ``x = argmin |W x - h|`` for a small (p, n) ``W`` of full column rank,
    p >= n: Householder QR of ``[W | h]`` (LAPACK ``geqrf``'s reflections), unrolled, then
    ``R^-1 (Q^T h)[:n]``; ``h`` of shape (p,) or (p, k). For ``n > SMALL_MAX`` a reduced
    ``jnp.linalg.qr``. Rank-deficient ``W``: inf/NaN, as the triangular solve of a QR."""
    W = jnp.asarray(W)
    if W.ndim != 2 or W.shape[0] < W.shape[1]:
        raise ValueError(f"lstsq_small: W must be (p, n) with p >= n, got shape {W.shape}")
    p, n = W.shape
    H, vec = _as_matrix_rhs(h, p, "lstsq_small")
    if n > SMALL_MAX:
        Q, R = jnp.linalg.qr(W, mode="reduced")
        X = jax.scipy.linalg.solve_triangular(R, Q.T @ H, lower=False)
        return X[:, 0] if vec else X
    dtype = jnp.result_type(W, H)
    A = jnp.concatenate([W.astype(dtype), H.astype(dtype)], axis=1)  # (p, n + k)
    one = jnp.ones((), dtype)
    for j in range(min(n, p - 1)):
        x = A[j:, j]
        x0 = x[0]
        sigma = jnp.sum(x[1:] * x[1:])
        norm = jnp.sqrt(x0 * x0 + sigma)
        alpha = jnp.where(x0 >= 0, -norm, norm)  # the sign that avoids cancellation
        v0 = x0 - alpha
        vv = v0 * v0 + sigma  # |v|^2 = 2 norm (norm + |x0|)
        # a zero column (vv = 0) is left as it is (the reflection is the identity)
        beta = jnp.where(vv > 0, 2.0 / jnp.where(vv > 0, vv, one), 0.0 * one)
        v = jnp.concatenate([v0[None], x[1:]])
        blk = A[j:, j:]
        blk = blk - (beta * v)[:, None] * jnp.sum(v[:, None] * blk, axis=0)[None, :]
        A = A.at[j:, j:].set(blk)
    X = _back_substitute(A[:n, :n], A[:n, n:])
    return X[:, 0] if vec else X
