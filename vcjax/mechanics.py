"""Generic virtually-constrained-motion (VCM) engine (paper Sections 2–3, docs/method.md).

The engine knows nothing about marine craft. A mechanical system

    M(q) q̈ + n(q, q̇) = τ                                     (1)

is subjected to k holonomic virtual constraints ``G(q, t) = 0`` (4) and m linear-in-velocity
constraints ``K = A(q, t) q̇ + B(q, t) = 0`` (6). They are unified and stabilised Baumgarte-style:

    Φ = [K; Ġ + P_G G] = W q̇ + a                              (11)–(13)
    Φ̇ + P_Φ Φ = 0   ⇔   W q̈ = −h,   h = Ẇ q̇ + ȧ + P_Φ Φ      (14)

and the control force is the constraint's reaction force, either from Lagrange multipliers when
W has full row rank (16), or from the pseudo-inverse when W has full column rank (17).

``W = ∂Φ/∂q̇`` and ``Ẇq̇ + ȧ = ∂Φ/∂q · q̇ + ∂Φ/∂t`` are computed by JAX autodiff (one ``jacfwd``
and one ``jvp``); users never differentiate constraints by hand. All solves use Cholesky or QR
factorisations, never explicit inverses. Rank and conditioning of W and the residual of (14) are
returned as data ([`Diagnostics`][vcjax.mechanics.Diagnostics]), never raised inside ``jit``.

Usage::

    system = MechanicalSystem(mass_matrix=M_fn, bias_force=n_fn)        # static
    cons = VirtualConstraints(holonomic=G_fn, velocity=K_fn)             # static
    gains = vcm_gains(P_G=[1.0], P_Phi=[2.0, 3.0])                        # traced
    tau_c, qdd, diag = reaction_force(system, cons, gains, q, qd, t, tau, args)
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from typing import Any, Literal, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from vcjax._checks import check_array, check_spd, is_concrete
from vcjax.linalg import (
    cho_solve_small,
    cholesky_small,
    lstsq_small,
    safe_norm,
    solve_small,
)

__all__ = [
    "MechanicalSystem",
    "VirtualConstraints",
    "VCMGains",
    "vcm_gains",
    "ConstraintTerms",
    "Diagnostics",
    "constraint_terms",
    "reaction_force",
    "constrained_acceleration",
    "check_shapes",
    "from_body_frame",
    "Method",
    "Underactuation",
    "underactuated_reaction_force",
]

Method = Literal["auto", "row", "column"]


@dataclasses.dataclass(frozen=True)
class MechanicalSystem:
    """Static description of ``M(q) q̈ + n(q, q̇) = τ`` (1).

    Attributes:
        mass_matrix: ``M(q, args) -> (n, n)`` symmetric positive-definite inertia matrix.
        bias_force: ``n(q, qd, args) -> (n,)`` Coriolis–centripetal, potential and viscous forces.
    """

    mass_matrix: Callable[[Any, Any], Any]
    bias_force: Callable[[Any, Any, Any], Any]


@dataclasses.dataclass(frozen=True)
class VirtualConstraints:
    """Static description of the virtual constraints.

    Attributes:
        holonomic: ``G(q, t, args) -> (k,)``, the holonomic constraints (4), or ``None``.
        velocity: ``K(q, qd, t, args) -> (m,)``, linear-in-velocity constraints
            ``A(q, t) q̇ + B(q, t)`` (6), or ``None``. Must be affine in ``qd``; the engine
            obtains ``A`` and ``B`` by differentiation.
        state_rate: optional ``z_dot(q, t, z, args)``. When given, the constraints may also
            depend on an auxiliary (controller) state ``z`` that evolves as ``ż = z_dot(q, t, z)``
            — e.g. a path particle — and take it as a trailing argument: ``G(q, t, args, z)``,
            ``K(q, qd, t, args, z)``. ``z_dot`` must not depend on ``q̇``; time derivatives then
            follow ``z`` along its flow (``∂/∂t → ∂/∂t + ż·∂/∂z``).

    Ordering follows the paper: ``Φ = [K; Ġ + P_G G]``, so ``P_Φ`` lists the m velocity rows
    first, then the k holonomic rows.
    """

    holonomic: Callable[..., Any] | None = None
    velocity: Callable[..., Any] | None = None
    state_rate: Callable[..., Any] | None = None

    def __post_init__(self):
        if self.holonomic is None and self.velocity is None:
            raise ValueError("VirtualConstraints: give at least one of `holonomic`, `velocity`")


class VCMGains(NamedTuple):
    """Stabilisation gains (traced).

    Attributes:
        P_G: (k,) diagonal or (k, k) positive-definite gain of the holonomic rows (11).
            Use shape (0,) when there are no holonomic constraints.
        P_Phi: (m+k,) diagonal or (m+k, m+k) positive-definite gain of (14).
    """

    P_G: Any
    P_Phi: Any


def _check_gain(name: str, P) -> None:
    a = check_array(name, P)
    if a is None:
        return
    if a.ndim == 1:
        if np.any(a <= 0):
            raise ValueError(f"{name}: every diagonal gain must be > 0, got {a}")
    elif a.ndim == 2 and a.shape[0] == a.shape[1]:
        if a.size and np.linalg.eigvalsh(0.5 * (a + a.T))[0] <= 0:
            raise ValueError(f"{name}: gain matrix must be positive definite")
    else:
        raise ValueError(f"{name}: expected shape (p,) or (p, p), got {a.shape}")


def _as_gain(name: str, P):
    if not is_concrete(P):
        return P
    try:
        a = np.asarray(P)
    except (TypeError, ValueError) as err:
        raise ValueError(f"{name}: expected a (p,) vector or a (p, p) matrix: {err}") from None
    if a.dtype == object or not (np.issubdtype(a.dtype, np.number) or a.dtype == np.bool_):
        raise ValueError(f"{name}: expected numbers, got {P!r}")
    return jnp.asarray(P)


def vcm_gains(P_G, P_Phi) -> VCMGains:
    """Build validated [`VCMGains`][vcjax.mechanics.VCMGains] (eager: raises ``ValueError`` before
    any compilation)."""
    P_G = _as_gain("P_G", P_G)
    P_Phi = _as_gain("P_Phi", P_Phi)
    _check_gain("P_G", P_G)
    _check_gain("P_Phi", P_Phi)
    return VCMGains(P_G=P_G, P_Phi=P_Phi)


def _apply(P, x):
    """``P x`` for a diagonal (vector) or full (matrix) gain."""
    return P * x if P.ndim == 1 else P @ x


class ConstraintTerms(NamedTuple):
    """Unified constraint quantities at one ``(q, q̇, t)``; p = m + k rows.

    Attributes:
        Phi: (p,) unified constraint function Φ (12).
        W: (p, n) constraint Jacobian W = ∂Φ/∂q̇.
        h: (p,) ``Ẇ q̇ + ȧ + P_Φ Φ``; (14) reads ``W q̈ = −h``.
        G: (k,) holonomic constraint values.
        K: (m,) velocity constraint values.
    """

    Phi: Any
    W: Any
    h: Any
    G: Any
    K: Any


def constraint_terms(cons: VirtualConstraints, gains: VCMGains, q, qd, t, args=None, z=None):
    """Evaluate Φ, W and h by autodiff (one ``jacfwd`` over q̇, one ``jvp`` over (q, t, z)).

    ``z`` is the auxiliary state of ``cons.state_rate`` (ignored when that is ``None``).
    """
    t = jnp.asarray(t, dtype=q.dtype)
    if cons.state_rate is None:
        z = jnp.zeros((0,), q.dtype)
        G_fn = None if cons.holonomic is None else lambda q, t, z: cons.holonomic(q, t, args)
        K_fn = None if cons.velocity is None else lambda q, qd, t, z: cons.velocity(q, qd, t, args)
        rate = lambda q, t, z: z
    else:
        if z is None:
            raise ValueError("constraint_terms: these constraints need the auxiliary state `z`")
        G_fn = None if cons.holonomic is None else lambda q, t, z: cons.holonomic(q, t, args, z)
        K_fn = (
            None if cons.velocity is None else lambda q, qd, t, z: cons.velocity(q, qd, t, args, z)
        )
        rate = lambda q, t, z: cons.state_rate(q, t, z, args)

    def parts(q, qd, t, z):
        K = K_fn(q, qd, t, z) if K_fn is not None else jnp.zeros((0,), q.dtype)
        if G_fn is not None:
            G, G_dot = jax.jvp(G_fn, (q, t, z), (qd, jnp.ones_like(t), rate(q, t, z)))
            Phi_G = G_dot + _apply(gains.P_G, G)
        else:
            G = jnp.zeros((0,), q.dtype)
            Phi_G = G
        return jnp.concatenate([jnp.atleast_1d(K), jnp.atleast_1d(Phi_G)]), (K, G)

    # Total time derivative of Φ at fixed q̇ (q̈ = 0): Ẇ q̇ + ȧ = Φ_q q̇ + Φ_t + Φ_z ż.
    (Phi, (K, G)), (Phi_dot_free, _) = jax.jvp(
        lambda q_, t_, z_: parts(q_, qd, t_, z_), (q, t, z), (qd, jnp.ones_like(t), rate(q, t, z))
    )
    # Φ is affine in q̇: W = ∂Φ/∂q̇ exactly (a jacfwd of an affine map).
    W = jax.jacfwd(lambda qd_: parts(q, qd_, t, z)[0])(qd)
    h = Phi_dot_free + _apply(gains.P_Phi, Phi)
    return ConstraintTerms(Phi=Phi, W=W, h=h, G=jnp.atleast_1d(G), K=jnp.atleast_1d(K))


class Diagnostics(NamedTuple):
    """Health of the constraint solve, returned as data.

    Attributes:
        Phi: (p,) unified constraint function.
        G: (k,) holonomic constraint values.
        K: (m,) velocity constraint values.
        rank: () int, numerical rank of W (SVD, tolerance ``max(p, n) * eps * s_max``).
        cond: () 2-norm condition number of W (``inf`` if rank-deficient).
        full_rank: () bool, ``rank == min(p, n)``.
        residual: () ``‖W q̈ + h‖``: 0 in the full-row-rank case, the least-squares residual
            in the over-determined case (17).
        mass_spd: () bool, ``M(q)`` is symmetric (to ``sqrt(eps)`` relative) and its Cholesky
            factorisation succeeded (positive definite). When False, ``tau_c`` and ``q̈`` are
            meaningless whatever ``rank`` and ``cond`` say about W.
        ok: () bool, the solve is usable: ``mass_spd``, ``full_rank`` and finite ``tau_c``,
            ``q̈`` and ``residual``.
    """

    Phi: Any
    G: Any
    K: Any
    rank: Any
    cond: Any
    full_rank: Any
    residual: Any
    mass_spd: Any
    ok: Any


def _rank_cond(W):
    W = jax.lax.stop_gradient(W)
    s = jnp.linalg.svd(W, compute_uv=False)
    p, n = W.shape
    tol = max(p, n) * float(jnp.finfo(W.dtype).eps) * s[0]
    rank = jnp.sum(s > tol)
    s_min = s[-1]
    cond = jnp.where(s_min > tol, s[0] / jnp.where(s_min > tol, s_min, 1.0), jnp.inf)
    return rank, cond, rank == min(p, n)


def _resolve_method(method: Method, p: int, n: int) -> str:
    if method == "auto":
        return "row" if p <= n else "column"
    if method not in ("row", "column"):
        raise ValueError(f"method: expected 'auto', 'row' or 'column', got {method!r}")
    if method == "row" and p > n:
        raise ValueError(f"method='row' needs m+k <= n, got {p} constraints for {n} DOF")
    if method == "column" and p < n:
        raise ValueError(f"method='column' needs m+k >= n, got {p} constraints for {n} DOF")
    return method


def constrained_acceleration(M, n_vec, tau, W, h, method: Method = "auto"):
    """Solve the constrained forward dynamics for given matrices.

    Args:
        M: (n, n) inertia matrix, SPD.
        n_vec: (n,) bias force n(q, q̇).
        tau: (n,) impressed (non-control) generalised force.
        W: (p, n) constraint Jacobian.
        h: (p,) ``Ẇ q̇ + ȧ + P_Φ Φ``.
        method: ``"row"`` uses (16) (needs p <= n), ``"column"`` uses (17) (needs p >= n),
            ``"auto"`` chooses from the (static) shapes.

    Returns:
        ``(tau_c, qdd)``: (n,) reaction (control) force and (n,) resulting acceleration
        ``q̈ = M⁻¹(τ + τ_c − n)``.
    """
    tau_c, qdd, _ = _constrained_acceleration(M, n_vec, tau, W, h, method)
    return tau_c, qdd


def _mass_spd(M, cM_lower):
    """() bool: M symmetric to ``sqrt(eps)`` relative and its Cholesky factor finite."""
    M = jax.lax.stop_gradient(M)
    scale = jnp.max(jnp.abs(M))
    sym = jnp.max(jnp.abs(M - M.T)) <= float(np.sqrt(jnp.finfo(M.dtype).eps)) * scale
    return sym & jnp.all(jnp.isfinite(jax.lax.stop_gradient(cM_lower))) & (scale > 0)


def _constrained_acceleration(M, n_vec, tau, W, h, method):
    """[`constrained_acceleration`][vcjax.mechanics.constrained_acceleration] plus the () bool
    ``mass_spd`` of [`Diagnostics`][vcjax.mechanics.Diagnostics]."""
    p, n = W.shape
    method = _resolve_method(method, p, n)
    f = tau - n_vec
    if method == "row":
        # (16): W M⁻¹ Wᵀ λ = W M⁻¹ (τ − n) + h,  τ_c = −Wᵀ λ.
        L_M = cholesky_small(M)
        Minv_WT = cho_solve_small(L_M, W.T)
        Minv_f = cho_solve_small(L_M, f)
        S = W @ Minv_WT
        lam = cho_solve_small(cholesky_small(S), W @ Minv_f + h)
        tau_c = -W.T @ lam
        qdd = Minv_f - Minv_WT @ lam
        spd = _mass_spd(M, L_M)
    else:
        # (17): τ_c = n − τ − M W† h, W† h computed by a reduced QR (least squares).
        qdd = -lstsq_small(W, h)
        tau_c = M @ qdd - f
        spd = _mass_spd(M, cholesky_small(jax.lax.stop_gradient(M)))
    return tau_c, qdd, spd


def reaction_force(
    system: MechanicalSystem,
    cons: VirtualConstraints,
    gains: VCMGains,
    q,
    qd,
    t,
    tau=None,
    args=None,
    method: Method = "auto",
    z=None,
):
    """VCM control force: the reaction force of the virtual constraints (16)/(17).

    Args:
        system: the (design) model ``M(q)``, ``n(q, q̇)``.
        cons: the virtual constraints.
        gains: ``P_G``, ``P_Φ``.
        q: (n,) generalised coordinates.
        qd: (n,) generalised velocities.
        t: () time [s].
        tau: (n,) impressed generalised force other than the control (default 0).
        args: any pytree passed through to the model and constraint functions.
        method: see [`constrained_acceleration`][vcjax.mechanics.constrained_acceleration].
        z: auxiliary state for constraints with a ``state_rate`` (see
            [`VirtualConstraints`][vcjax.mechanics.VirtualConstraints]).

    Returns:
        ``(tau_c, qdd, diagnostics)``: (n,) control force, (n,) acceleration it produces on the
        design model, and [`Diagnostics`][vcjax.mechanics.Diagnostics].
    """
    check_shapes(system, cons, gains, q, qd, t, args, z, tau)
    if tau is None:
        tau = jnp.zeros_like(q)
    terms = constraint_terms(cons, gains, q, qd, t, args, z)
    M = system.mass_matrix(q, args)
    if is_concrete(M):  # called outside jit: check M(q) eagerly
        check_spd("mass_matrix(q)", M)
    n_vec = system.bias_force(q, qd, args)
    tau_c, qdd, spd = _constrained_acceleration(M, n_vec, tau, terms.W, terms.h, method)
    rank, cond, full = _rank_cond(terms.W)
    residual = jnp.linalg.norm(terms.W @ qdd + terms.h)
    finite = jnp.all(jnp.isfinite(tau_c)) & jnp.all(jnp.isfinite(qdd)) & jnp.isfinite(residual)
    ok = spd & full & finite
    diag = Diagnostics(
        Phi=terms.Phi,
        G=terms.G,
        K=terms.K,
        rank=rank,
        cond=cond,
        full_rank=full,
        residual=residual,
        mass_spd=spd,
        ok=ok,
    )
    return tau_c, qdd, diag


def _eval_shape(what: str, fn, *args):
    try:
        return jax.eval_shape(fn, *args)
    except Exception as err:  # noqa: BLE001 - re-raised with the function's name
        raise ValueError(f"{what} failed on the given shapes: {type(err).__name__}: {err}") from err


def _shape_of(x):
    return tuple(np.shape(x)) if not hasattr(x, "shape") else tuple(x.shape)


def check_shapes(
    system: MechanicalSystem,
    cons: VirtualConstraints,
    gains: VCMGains,
    q,
    qd,
    t=0.0,
    args=None,
    z=None,
    tau=None,
) -> tuple[int, int, int]:
    """Check every shape of a VCM solve once, abstractly (``jax.eval_shape``: nothing is
    computed or compiled), and raise a ``ValueError`` naming the constraint or gain at fault.

    [`reaction_force`][vcjax.mechanics.reaction_force] calls it at trace time, so a mismatch is
    reported before XLA
    compiles anything, not as an incompatible-shapes error deep inside JAX.

    Returns:
        ``(n, m, k)``: degrees of freedom, velocity rows, holonomic rows.
    """
    q_shape, qd_shape = _shape_of(q), _shape_of(qd)
    if len(q_shape) != 1:
        raise ValueError(f"q: expected a vector (n,), got shape {q_shape}")
    (n,) = q_shape
    if qd_shape != q_shape:
        raise ValueError(f"qd: expected shape {q_shape} like q, got {qd_shape}")
    if tau is not None and _shape_of(tau) != q_shape:
        raise ValueError(f"tau: expected shape {q_shape} like q, got {_shape_of(tau)}")
    M = _eval_shape("mass_matrix(q, args)", system.mass_matrix, q, args)
    if M.shape != (n, n):
        raise ValueError(
            f"q: shape {q_shape} does not match the model: mass_matrix(q, args) has shape "
            f"{M.shape}, expected ({n}, {n})"
        )
    nv = _eval_shape("bias_force(q, qd, args)", system.bias_force, q, qd, args)
    if nv.shape != (n,):
        raise ValueError(f"bias_force(q, qd, args): expected shape ({n},), got {nv.shape}")
    extra = () if cons.state_rate is None else (z,)
    if cons.state_rate is not None and z is None:
        raise ValueError("z: these constraints have a `state_rate` and need the auxiliary state")
    rows = {}
    for name, fn, a in (
        ("velocity", cons.velocity, (q, qd, t, args, *extra)),
        ("holonomic", cons.holonomic, (q, t, args, *extra)),
    ):
        if fn is None:
            rows[name] = 0
            continue
        out = _eval_shape(f"constraint `{name}`", fn, *a)
        if not hasattr(out, "shape") or len(out.shape) > 1:
            shape = getattr(out, "shape", type(out).__name__)
            raise ValueError(
                f"constraint `{name}`: expected a scalar or a vector of rows, got shape {shape}"
            )
        rows[name] = int(np.prod(out.shape))
    m, k = rows["velocity"], rows["holonomic"]
    p = m + k
    layout = f"Φ = [K ({m} rows from `velocity`); Ġ + P_G G ({k} rows from `holonomic`)]"
    for name, size in (("P_G", k), ("P_Phi", p)):
        shape = _shape_of(getattr(gains, name))
        if shape not in ((size,), (size, size)):
            raise ValueError(
                f"{name}: expected shape ({size},) or ({size}, {size}) for {layout}, got {shape}"
            )
    return n, m, k


def from_body_frame(
    body_mass_matrix: Callable,
    body_bias_force: Callable,
    kinematics: Callable,
    kinematics_inverse: Callable | None = None,
) -> MechanicalSystem:
    """Express a quasi-velocity model in generalised coordinates.

    Given ``M_b(q) ν̇ + n_b(q, ν) = τ_b`` with ``q̇ = J(q) ν`` (J invertible), returns the
    [`MechanicalSystem`][vcjax.mechanics.MechanicalSystem] of (1) with ``M(q) = J⁻ᵀ M_b J⁻¹`` and
    ``n(q, q̇) = J⁻ᵀ (n_b(q, ν) − M_b J⁻¹ J̇ ν)``, ``ν = J⁻¹ q̇``; generalised forces map as
    ``τ = J⁻ᵀ τ_b``. ``J̇`` comes from a ``jvp`` of ``J`` along ``q̇``.

    Args:
        body_mass_matrix: ``M_b(q, args) -> (n, n)``.
        body_bias_force: ``n_b(q, nu, args) -> (n,)``.
        kinematics: ``J(q, args) -> (n, n)``.
        kinematics_inverse: optional ``J(q, args)⁻¹`` in closed form (e.g. a rotation's
            transpose); default: one small elimination ([`solve_small`][vcjax.linalg.solve_small]).
    """

    def inverse(q, args, J):
        if kinematics_inverse is not None:
            return kinematics_inverse(q, args)
        return solve_small(J, jnp.eye(J.shape[0], dtype=J.dtype))

    def mass_matrix(q, args):
        J = kinematics(q, args)
        Jinv_T = inverse(q, args, J).T
        M = Jinv_T @ body_mass_matrix(q, args) @ Jinv_T.T
        return 0.5 * (M + M.T)

    def bias_force(q, qd, args):
        J, J_dot = jax.jvp(lambda q_: kinematics(q_, args), (q,), (qd,))
        # one elimination for the three solves with J and Jᵀ (a third of the program)
        Jinv = inverse(q, args, J)
        nu = Jinv @ qd
        Mb = body_mass_matrix(q, args)
        rhs = body_bias_force(q, nu, args) - Mb @ (Jinv @ (J_dot @ nu))
        return Jinv.T @ rhs

    return MechanicalSystem(mass_matrix=mass_matrix, bias_force=bias_force)


def check_state(q, qd, n: int | None = None) -> None:
    """Eager check of an initial state: shapes ``(n,)`` and finite values."""
    if is_concrete(q):
        check_array("q", q, (n,))
        check_array("qd", qd, (np.asarray(q).shape[0],))


# --------------------------------------------------------------------------------------------
# Underactuation: unactuated (or tied) force directions absorbed by free desired velocities
# --------------------------------------------------------------------------------------------


@dataclasses.dataclass(frozen=True)
class Underactuation:
    """Static description of what the actuators cannot set (paper Section 4.1, Remark 4).

    The reaction force of the constraints must satisfy r linear conditions

        A_u(q, q̇, t) τ_c = b_u(q, q̇, t)

    — e.g. a body-frame sway force that must equal the sway force the rudder produces along with
    its yaw moment, ``τ_v − k τ_r = 0`` mapped to generalised forces. In exchange r components of
    the auxiliary state ``z`` (the *free* desired velocities, e.g. ``v_d``, ``w_d``) get their
    rates from the solve instead of from ``state_rate``.

    Attributes:
        unactuated: ``(q, qd, t, args) -> (A_u (r, n), b_u (r,))``, in generalised forces.
        free: indices (static, length r) into the flat auxiliary state ``z`` (n_z,) of the
            constraints' ``state_rate``; those components' rates are ``state_rate`` plus the
            solved ``mu``. Only the *velocity* constraints may depend on them (the holonomic
            rows would need their second derivative).
    """

    unactuated: Callable[..., Any]
    free: tuple[int, ...]

    def __post_init__(self):
        free = tuple(self.free)
        if not free or any(not isinstance(i, int) or i < 0 for i in free):
            raise ValueError(f"free: expected a non-empty tuple of indices >= 0, got {self.free!r}")
        if len(set(free)) != len(free):
            raise ValueError(f"free: repeated indices in {self.free!r}")
        object.__setattr__(self, "free", free)


def underactuated_reaction_force(
    system: MechanicalSystem,
    cons: VirtualConstraints,
    under: Underactuation,
    gains: VCMGains,
    q,
    qd,
    t,
    tau=None,
    args=None,
    method: Method = "auto",
    z=None,
):
    """VCM control force under underactuation: (16)/(17) with free desired velocities.

    Φ (hence W) does not depend on the free rates ``mu``; ``h = Ẇq̇ + ȧ + P_Φ Φ`` is affine in
    them through ``ȧ`` (the velocity rows contain the free desired velocities), and both solves
    (16), (17) are affine in ``h``. So ``τ_c(mu) = τ_0 + T mu`` exactly: one ``jax.linearize``
    gives ``τ_0`` and ``T`` (r tangent evaluations), and the r conditions
    ``A_u τ_c = b_u`` fix ``mu = (A_u T)⁻¹ (b_u − A_u τ_0)`` — an r × r solve, no iteration.
    With r = 1 on the 3-DOF design model this is the paper's (38) with Remark 4.

    Args:
        system, cons, gains, q, qd, t, tau, args, method: as
            [`reaction_force`][vcjax.mechanics.reaction_force].
        under: the [`Underactuation`][vcjax.mechanics.Underactuation] (unactuated rows and free
            rates).
        z: (n_z,) the auxiliary state, required (a flat array).

    Returns:
        ``(tau_c, qdd, mu, diagnostics)``: (n,) control force, (n,) acceleration on the design
        model, (r,) free rates (add them to ``state_rate`` at ``under.free``), and
        [`Diagnostics`][vcjax.mechanics.Diagnostics] whose ``residual`` is that of (14) (the
        unactuated rows' own
        residual ``‖A_u τ_c − b_u‖`` is zero to round-off whenever ``A_u T`` is invertible).
    """
    if cons.state_rate is None or z is None:
        raise ValueError(
            "underactuated_reaction_force: the free desired velocities live in the auxiliary "
            "state; give the constraints a `state_rate` and pass `z`"
        )
    if is_concrete(z) and np.ndim(z) != 1:
        raise ValueError(f"z: expected a flat (n_z,) array, got shape {np.shape(z)}")
    if is_concrete(z) and max(under.free) >= np.shape(z)[0]:
        raise ValueError(f"free: index {max(under.free)} out of range for z of size {len(z)}")
    check_shapes(system, cons, gains, q, qd, t, args, z, tau)
    if tau is None:
        tau = jnp.zeros_like(q)
    idx = np.asarray(under.free)
    r = idx.size
    M = system.mass_matrix(q, args)
    if is_concrete(M):  # called outside jit: check M(q) eagerly
        check_spd("mass_matrix(q)", M)
    n_vec = system.bias_force(q, qd, args)

    def terms_at(mu):
        def rate(q_, t_, z_, a_):
            return cons.state_rate(q_, t_, z_, a_).at[idx].add(mu)

        c = dataclasses.replace(cons, state_rate=rate)
        return constraint_terms(c, gains, q, qd, t, args, z)

    # Only the constraint terms are linearised in mu; the solve (16)/(17), affine in h, then
    # runs once on [h(0); ∂h/∂mu] (a vmap over 1 + r right-hand sides, f = 0 for the slopes)
    # instead of being differentiated: the same numbers, a much smaller program.
    terms0, lin = jax.linearize(terms_at, jnp.zeros((r,), q.dtype))
    dterms = jax.vmap(lin)(jnp.eye(r, dtype=q.dtype))  # leaves (r, ...)
    zero = jnp.zeros_like(q)
    hs = jnp.concatenate([terms0.h[None], dterms.h])
    ns = jnp.concatenate([n_vec[None], jnp.broadcast_to(zero, (r, zero.shape[0]))])
    taus = jnp.concatenate([tau[None], jnp.broadcast_to(zero, (r, zero.shape[0]))])
    tau_cs, qdds = jax.vmap(
        lambda n_, tau_, h_: constrained_acceleration(M, n_, tau_, terms0.W, h_, method)
    )(ns, taus, hs)
    out0 = (tau_cs[0], qdds[0], terms0)
    slopes = (tau_cs[1:], qdds[1:], dterms)
    A_u, b_u = under.unactuated(q, qd, t, args)
    A_u = jnp.atleast_2d(A_u)
    gap0 = A_u @ out0[0] - b_u
    mu = -solve_small(A_u @ slopes[0].T, gap0)
    tau_c, qdd, terms = jax.tree_util.tree_map(
        lambda a, s: a + jnp.tensordot(mu, s, axes=1), out0, slopes
    )
    rank, cond, full = _rank_cond(terms.W)
    residual = safe_norm(terms.W @ qdd + terms.h)
    spd = _mass_spd(M, cholesky_small(jax.lax.stop_gradient(M)))
    finite = jnp.all(jnp.isfinite(tau_c)) & jnp.all(jnp.isfinite(qdd)) & jnp.isfinite(residual)
    diag = Diagnostics(
        Phi=terms.Phi,
        G=terms.G,
        K=terms.K,
        rank=rank,
        cond=cond,
        full_rank=full,
        residual=residual,
        mass_spd=spd,
        ok=spd & full & finite & jnp.all(jnp.isfinite(mu)),
    )
    return tau_c, qdd, mu, diag
