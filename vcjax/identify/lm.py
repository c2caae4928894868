"""Levenberg–Marquardt for block-arrow least squares (multiple shooting), in numpy.

The unknowns are global parameters ``z`` (p,) and per-block nuisance variables ``s_j`` (n,), one
block per shooting segment ``j``; block ``j``'s residuals ``r_j`` (m,) depend on ``z`` and ``s_j``
only. With the Jacobians ``Jz_j = dr_j/dz`` (m, p) and ``Js_j = dr_j/ds_j`` (m, n), the damped
Gauss–Newton system ::

    [ A + lam D_A     B_1   ...   B_J  ] [dz  ]     [g_z]     A   = sum_j Jz_j^T Jz_j
    [ B_1^T      C_1 + lam D_1         ] [ds_1] = - [g_1]     B_j = Jz_j^T Js_j
    [  ...                 ...         ] [... ]     [...]     C_j = Js_j^T Js_j
                                                              g_z = sum_j Jz_j^T r_j
                                                              g_j = Js_j^T r_j

is solved by eliminating the blocks (Schur complement)::

    (A + lam D_A - sum_j B_j C_j^-1 B_j^T) dz = -(g_z - sum_j B_j C_j^-1 g_j)
    ds_j = -C_j^-1 (g_j + B_j^T dz)

with Marquardt's scaling ``D = diag(J^T J)`` (floored). The cost is ``0.5 |r|^2``. The damping
follows Nielsen (1999): on a step with gain ratio ``rho > 0``,
``lam *= max(1/3, 1 - (2 rho - 1)^3)``; on a rejected step ``lam *= nu, nu *= 2``. A step that
gives a non-finite cost is rejected.

[`schur_information`][vcjax.identify.lm.schur_information] is the same elimination at ``lam = 0``:
the Gauss–Newton information
matrix of ``z`` with the nuisance variables profiled out, whose inverse times the residual
variance is the covariance of ``z``.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable

import numpy as np

__all__ = ["LMOptions", "LMResult", "levenberg_marquardt", "schur_information", "lm_step"]


def _blocks(r, Jz, Js):
    A = np.einsum("jmp,jmq->pq", Jz, Jz)
    B = np.einsum("jmp,jmn->jpn", Jz, Js)
    C = np.einsum("jmn,jmk->jnk", Js, Js)
    gz = np.einsum("jmp,jm->p", Jz, r)
    gs = np.einsum("jmn,jm->jn", Js, r)
    return A, B, C, gz, gs


def _floor(d):
    return np.maximum(d, 1e-12 * max(float(np.max(d, initial=0.0)), 1e-300))


def schur_information(Jz, Js) -> np.ndarray:
    """(p, p) ``sum_j Jz_j^T Jz_j - B_j C_j^-1 B_j^T``: information of ``z`` with every block's
    nuisance variables eliminated (``Jz`` (J, m, p), ``Js`` (J, m, n))."""
    r = np.zeros(Jz.shape[:2])
    A, B, C, _, _ = _blocks(r, Jz, Js)
    BCi = np.einsum("jpn,jnk->jpk", B, np.linalg.inv(C))
    S = A - np.einsum("jpk,jqk->pq", BCi, B)
    return 0.5 * (S + S.T)


def lm_step(r, Jz, Js, lam):
    """The damped step ``(dz (p,), ds (J, n))`` and the predicted cost reduction."""
    A, B, C, gz, gs = _blocks(r, Jz, Js)
    dA = _floor(np.diag(A))
    dC = np.stack([_floor(np.diag(c)) for c in C])
    A_l = A + lam * np.diag(dA)
    C_l = C + lam * np.einsum("jn,nk->jnk", dC, np.eye(C.shape[1]))
    Ci = np.linalg.inv(C_l)
    BCi = np.einsum("jpn,jnk->jpk", B, Ci)
    S = A_l - np.einsum("jpk,jqk->pq", BCi, B)
    rhs = -(gz - np.einsum("jpk,jk->p", BCi, gs))
    dz = np.linalg.lstsq(S, rhs, rcond=None)[0]
    ds = -np.einsum("jnk,jk->jn", Ci, gs + np.einsum("jpn,p->jn", B, dz))
    r_lin = r + np.einsum("jmp,p->jm", Jz, dz) + np.einsum("jmn,jn->jm", Js, ds)
    predicted = 0.5 * (np.sum(r * r) - np.sum(r_lin * r_lin))
    return dz, ds, predicted


@dataclasses.dataclass
class LMResult:
    """Outcome of [`levenberg_marquardt`][vcjax.identify.lm.levenberg_marquardt].

    Attributes:
        z: (p,) parameters; s: (J, n) nuisance variables.
        r, Jz, Js: residuals (J, m) and Jacobians (J, m, p), (J, m, n) at the solution.
        cost_history: cost ``0.5 |r|^2`` before the first iteration and after every iteration
            (a rejected step repeats the previous cost).
        iterations: iterations run (accepted + rejected steps); accepted: accepted steps.
        converged: a convergence test passed (else the iteration limit or the damping limit
            stopped it); reason: which.
    """

    z: np.ndarray
    s: np.ndarray
    r: np.ndarray
    Jz: np.ndarray
    Js: np.ndarray
    cost_history: list
    iterations: int
    accepted: int
    converged: bool
    reason: str


@dataclasses.dataclass(frozen=True)
class LMOptions:
    """Settings of [`levenberg_marquardt`][vcjax.identify.lm.levenberg_marquardt].

    Attributes:
        max_iters: iteration limit.
        lam0: initial damping (relative to ``diag(J^T J)``).
        ftol: stop when an accepted step lowers the cost by less than ``ftol`` x the cost.
        xtol: stop when an accepted step has ``max |dz| < xtol`` and lowered the cost by less
            than ``1e-6`` x the cost (``z`` on a log scale: a relative parameter change).
        rtol_cost: stop when the cost is below ``rtol_cost`` x the initial cost (noise-free
            data fitted to round-off).
    """

    max_iters: int = 50
    lam0: float = 1e-3
    ftol: float = 1e-6
    xtol: float = 1e-8
    rtol_cost: float = 1e-20


class _State:
    """The iterate of [`levenberg_marquardt`][vcjax.identify.lm.levenberg_marquardt]: ``z``,
    ``s``, the residuals and Jacobians there, the cost, the damping ``lam`` and its factor
    ``nu``, the cost history and the accepted steps."""

    def __init__(self, linearize, z, s, lam):
        self.linearize = linearize
        self.move(z, s)
        self.history = [self.cost]
        self.lam, self.nu = float(lam), 2.0
        self.accepted = 0

    def move(self, z, s) -> None:
        self.z, self.s = z, s
        self.r, self.Jz, self.Js = (np.asarray(a, np.float64) for a in self.linearize(z, s))
        self.cost = 0.5 * float(np.sum(self.r * self.r))

    def iterate(self, residual, o: LMOptions) -> str | None:
        """One damped step (accepted or rejected; the history grows by one); the reason to
        stop after it, if any."""
        dz, ds, predicted = lm_step(self.r, self.Jz, self.Js, self.lam)
        z_new, s_new = self.z + dz, self.s + ds
        r_new = np.asarray(residual(z_new, s_new), np.float64)
        cost_new = 0.5 * float(np.sum(r_new * r_new))
        rho = (self.cost - cost_new) / predicted if predicted > 0 else -1.0
        if not (np.isfinite(cost_new) and rho > 0):
            self.lam *= self.nu
            self.nu *= 2.0
            self.history.append(self.cost)
            return "no further decrease (damping limit)" if self.lam > 1e16 else None
        decrease = self.cost - cost_new
        self.move(z_new, s_new)
        self.lam *= max(1.0 / 3.0, 1.0 - (2.0 * rho - 1.0) ** 3)
        self.nu = 2.0
        self.accepted += 1
        self.history.append(self.cost)
        if decrease <= o.ftol * cost_new:
            return "relative cost decrease below ftol"
        if np.max(np.abs(dz), initial=0.0) < o.xtol and decrease <= 1e-6 * cost_new:
            return "parameter step below xtol"
        return None


def levenberg_marquardt(
    linearize: Callable,
    residual: Callable,
    z0,
    s0,
    options: LMOptions | None = None,
    *,
    callback: Callable | None = None,
    should_stop: Callable[[], bool] | None = None,
    **kwargs,
) -> LMResult:
    """Minimise ``0.5 |r(z, s)|^2`` over ``z`` and the blocks ``s``.

    Args:
        linearize: ``(z, s) -> (r (J, m), Jz (J, m, p), Js (J, m, n))``.
        residual: ``(z, s) -> r (J, m)``.
        z0: (p,) initial parameters; s0: (J, n) initial nuisance variables.
        options: [`LMOptions`][vcjax.identify.lm.LMOptions] (iteration limit, initial damping,
            tolerances); its fields are also accepted by name (``max_iters=30``).
        callback: called as ``callback(iteration, cost, lam)`` after every iteration.
        should_stop: polled before every iteration (default
            ``stop_requested``: SIGINT / SIGTERM in the CLI); True
            stops with the last accepted iterate, ``converged = False``, ``reason = "interrupted"``.
    """
    from vcjax._checks import with_options
    from vcjax.runtime.interrupts import stop_requested

    o = with_options(LMOptions, options, kwargs, "levenberg_marquardt")
    should_stop = stop_requested if should_stop is None else should_stop
    st = _State(linearize, np.asarray(z0, np.float64), np.asarray(s0, np.float64), o.lam0)
    if not np.isfinite(st.cost):
        return LMResult(
            st.z, st.s, st.r, st.Jz, st.Js, st.history, 0, 0, False, "non-finite cost at the start"
        )
    cost0, reason, it = st.cost, None, 0
    for it in range(1, o.max_iters + 1):
        if should_stop():
            reason, it = "interrupted", it - 1
            break
        if st.cost <= o.rtol_cost * cost0:
            reason, it = "cost at round-off level", it - 1
            break
        reason = st.iterate(residual, o)
        if callback:
            callback(it, st.cost, st.lam)
        if reason is not None:
            break
    converged = reason is not None and reason != "interrupted"
    reason = "iteration limit" if reason is None else reason
    return LMResult(st.z, st.s, st.r, st.Jz, st.Js, st.history, it, st.accepted, converged, reason)
