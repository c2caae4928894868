"""Levenberg-Marquardt (identify.lm) against independent computations: the damped step of the
Schur-complement solver against the full damped normal equations (with the damping floor of a
parameter the data hardly inform), the documented exits (non-finite start, a start at an exact
fit, a stationary point, the iteration limit of zero), the damping rule on rejected steps, and
the options' contract. Written for the survivors of the mutation run of ``vcjax/identify/lm.py``
(``docs/development/testing.md``)."""

import dataclasses

import numpy as np
import pytest

from vcjax.identify.lm import LMOptions, levenberg_marquardt, lm_step


def _floored(d):
    """The damping diagonal, written out: each entry at least 1e-12 x the largest."""
    return np.maximum(d, 1e-12 * max(d.max(), 1e-300))


def test_the_damped_step_solves_the_full_damped_normal_equations():
    """``lm_step`` eliminates each block's nuisance variables (Schur complement); the same
    step solves ``(J^T J + lam D) x = -J^T r`` over all unknowns at once, ``D`` the floored
    diagonal of ``J^T J`` (per block for the nuisance variables). One parameter's column is
    1e-9 of the others' (its diagonal below the floor) and the scale is small (largest
    diagonal < 1), so the floor decides that direction's step."""
    rng = np.random.default_rng(3)
    J_blocks, m, p, n, lam = 3, 6, 3, 2, 0.7
    Jz = 0.05 * rng.standard_normal((J_blocks, m, p))
    Jz[:, :, 2] *= 1e-9
    Js = 0.05 * rng.standard_normal((J_blocks, m, n))
    r = rng.standard_normal((J_blocks, m))
    dz, ds, predicted = lm_step(r, Jz, Js, lam)

    # the full problem: unknowns [z (p), s_0 (n), s_1 (n), ...]
    full = np.zeros((J_blocks * m, p + J_blocks * n))
    for j in range(J_blocks):
        full[j * m : (j + 1) * m, :p] = Jz[j]
        full[j * m : (j + 1) * m, p + j * n : p + (j + 1) * n] = Js[j]
    N = full.T @ full
    d = np.diag(N)
    D = np.concatenate(
        [_floored(d[:p])] + [_floored(d[p + j * n : p + (j + 1) * n]) for j in range(J_blocks)]
    )
    assert d[:p].max() < 1 and d[2] < 1e-12 * d[:p].max()  # the floor is active
    x = np.linalg.solve(N + lam * np.diag(D), -full.T @ r.ravel())
    np.testing.assert_allclose(dz, x[:p], rtol=1e-7, atol=0)  # the weak direction: ill-conditioned
    np.testing.assert_allclose(ds, x[p:].reshape(J_blocks, n), rtol=1e-7, atol=1e-12)
    r_lin = r.ravel() + full @ x
    np.testing.assert_allclose(predicted, 0.5 * (r.ravel() @ r.ravel() - r_lin @ r_lin), rtol=1e-9)


def _linear(A, b, n_blocks=1):
    """``r(z) = A z - b`` as ``n_blocks`` blocks (no nuisance variables)."""
    A, b = np.asarray(A, float), np.asarray(b, float)

    def linearize(z, s):
        r = (A @ z - b).reshape(n_blocks, -1)
        return r, A.reshape(n_blocks, -1, A.shape[1]), np.zeros((n_blocks, r.shape[1], 0))

    return linearize, lambda z, s: linearize(z, s)[0]


def _run(lin, res, z0, **kw):
    log = []
    kw.setdefault("should_stop", lambda: False)
    out = levenberg_marquardt(
        lin, res, np.asarray(z0, float), np.zeros((1, 0)), callback=lambda *a: log.append(a), **kw
    )
    return out, log


_A = np.array([[1.0, 0.5], [0.3, 2.0], [1.5, -0.4], [0.2, 0.9]])
_B = np.array([1.0, 2.0, -1.0, 0.5])  # no exact fit: the residual at the optimum is not zero


def test_a_linear_problem_stops_on_ftol_with_the_documented_damping_and_counts():
    """On a linear problem the model is exact (gain ratio 1): the first accepted step divides
    the damping by 3 (Nielsen's max(1/3, 1 - (2 rho - 1)^3)); the run ends on the relative
    cost decrease (the default ftol); ``accepted`` counts the steps that lowered the cost; the
    options may be given by name."""
    lin, res = _linear(_A, _B)
    out, log = _run(lin, res, [3.0, -2.0], options=LMOptions(lam0=0.01))
    assert out.converged and out.reason == "relative cost decrease below ftol"
    assert log[0][2] == pytest.approx(0.01 / 3.0, rel=1e-9)
    h = np.asarray(out.cost_history)
    assert out.accepted == int(np.sum(np.diff(h) < 0)) and out.accepted >= 2
    assert out.iterations == len(h) - 1
    z_opt = np.linalg.lstsq(_A, _B, rcond=None)[0]
    np.testing.assert_allclose(out.z, z_opt, rtol=1e-4)


def test_without_ftol_a_run_ends_on_the_parameter_step_at_the_optimum():
    """``ftol = 0``: the run goes on until a step is below ``xtol`` (1e-8) with a negligible
    decrease: the optimum of the linear problem to 1e-8."""
    lin, res = _linear(_A, _B)
    out, _ = _run(lin, res, [3.0, -2.0], ftol=0.0)
    assert out.converged and out.reason == "parameter step below xtol"
    z_opt = np.linalg.lstsq(_A, _B, rcond=None)[0]
    np.testing.assert_allclose(out.z, z_opt, rtol=1e-8, atol=1e-12)


def test_with_a_large_residual_the_parameter_step_test_still_waits_for_xtol():
    """A large residual the parameters cannot remove (100 along a direction orthogonal to
    the columns): a relative decrease of 1e-6 of the cost is reached while the parameters are
    still far off, so only the step test (``max |dz| < xtol``, 1e-8) ends the run, at the
    optimum."""
    q = np.linalg.qr(_A, mode="complete")[0][:, -1]  # orthogonal to the range of A
    lin, res = _linear(_A, _B + 100.0 * q)
    out, _ = _run(lin, res, [30.0, -20.0], ftol=0.0, lam0=100.0)
    assert out.converged and out.reason == "parameter step below xtol"
    z_opt = np.linalg.lstsq(_A, _B, rcond=None)[0]
    np.testing.assert_allclose(out.z, z_opt, rtol=1e-7, atol=1e-9)


def test_a_start_at_an_exact_fit_stops_before_any_step():
    lin, res = _linear(_A[:2], _A[:2] @ np.array([0.3, -0.7]))
    out, log = _run(lin, res, [0.3, -0.7])
    assert out.cost_history == [0.0] and not log
    assert out.converged and out.reason == "cost at round-off level"
    assert out.iterations == 0 and out.accepted == 0


def test_a_stationary_start_rejects_until_the_damping_limit():
    """A residual the parameters do not move (zero Jacobian, cost > 0): every step is zero and
    predicts no decrease, so each is rejected and the damping grows by 2, 4, 8, ... until it
    passes 1e16 (the documented exit), long before the iteration limit."""

    def linearize(z, s):
        return np.ones((1, 3)), np.zeros((1, 3, 2)), np.zeros((1, 3, 0))

    out, log = _run(linearize, lambda z, s: np.ones((1, 3)), [1.0, 2.0], max_iters=200)
    assert out.reason == "no further decrease (damping limit)" and out.accepted == 0
    lams = [1e-3] + [lam for _, _, lam in log]
    factors = np.asarray(lams[1:]) / np.asarray(lams[:-1])
    np.testing.assert_allclose(factors, 2.0 ** np.arange(1, len(factors) + 1), rtol=1e-12)
    assert lams[-1] > 1e16 >= lams[-2] and out.iterations == len(log) < 200
    np.testing.assert_array_equal(out.z, [1.0, 2.0])


def test_a_rejection_after_an_accepted_step_doubles_the_damping_again():
    """Rosenbrock's valley from (-1.2, 1) with little damping: some steps overshoot. After an
    accepted step the factor of the next rejection restarts at 2, then doubles."""

    def linearize(z, s):
        r = np.array([[10.0 * (z[1] - z[0] ** 2), 1.0 - z[0]]])
        J = np.array([[[-20.0 * z[0], 10.0], [-1.0, 0.0]]])
        return r, J, np.zeros((1, 2, 0))

    out, log = _run(linearize, lambda z, s: linearize(z, s)[0], [-1.2, 1.0], lam0=1e-6)
    h = np.asarray(out.cost_history)
    lams = [1e-6] + [lam for _, _, lam in log]
    seen, factor = 0, 2.0
    for k in range(1, len(h)):
        if h[k] < h[k - 1]:
            factor = 2.0
            continue
        assert lams[k] == pytest.approx(lams[k - 1] * factor, rel=1e-12), k
        seen += k > 1 and h[k - 1] < h[k - 2]  # a rejection right after an acceptance
        factor *= 2.0
    assert seen >= 1
    np.testing.assert_allclose(out.z, [1.0, 1.0], atol=1e-6)


def test_a_non_finite_start_is_reported_not_iterated():
    def linearize(z, s):
        return np.full((1, 2), np.nan), np.zeros((1, 2, 1)), np.zeros((1, 2, 0))

    out, log = _run(linearize, lambda z, s: np.full((1, 2), np.nan), [0.0])
    assert not log and out.iterations == 0 and out.accepted == 0
    assert not out.converged and out.reason == "non-finite cost at the start"


def test_an_iteration_limit_of_zero_runs_nothing():
    lin, res = _linear(_A, _B)
    out, log = _run(lin, res, [3.0, -2.0], max_iters=0)
    assert not log and out.iterations == 0 and out.reason == "iteration limit"
    assert not out.converged


def test_the_options_are_frozen_and_their_default_is_the_fit_configs():
    """One set of defaults: ``vcjax fit``'s ``[fit] max_iters`` written or omitted means
    the library's ``LMOptions().max_iters``."""
    from vcjax.identify.config import FIT_SCHEMA

    o = LMOptions()
    with pytest.raises(dataclasses.FrozenInstanceError):
        o.max_iters = 3  # type: ignore[misc]
    assert hash(o) == hash(LMOptions())
    assert FIT_SCHEMA["fit"]["max_iters"] == o.max_iters == 50
