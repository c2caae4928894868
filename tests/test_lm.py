"""Levenberg-Marquardt (identify.lm) on one-parameter problems worked out by hand: Nielsen's
damping update, the stopping rules as documented, the iteration count of every exit."""

import numpy as np
import pytest

from vcjax.identify.lm import levenberg_marquardt


def _problem(targets):
    """``r(z) = exp(z) - targets`` (one block, no nuisance variables)."""
    t = np.asarray(targets, dtype=float)

    def linearize(z, s):
        e = np.exp(z[0])
        return (e - t)[None], np.full((1, t.size, 1), e), np.zeros((1, t.size, 0))

    return linearize, lambda z, s: linearize(z, s)[0]


def _fit(targets, z0, **kw):
    lin, res = _problem(targets)
    log = []
    kw.setdefault("should_stop", lambda: False)
    out = levenberg_marquardt(
        lin, res, [z0], np.zeros((1, 0)), callback=lambda *a: log.append(a), **kw
    )
    return out, log


def test_nielsen_damping_after_an_accepted_step():
    """First step from z0 = 0 towards exp(z) = 2.5 with lam0 = 0.1, by hand: the damped
    Gauss-Newton step, its predicted and actual decrease, the gain ratio rho and the new
    damping lam0 max(1/3, 1 - (2 rho - 1)^3)."""
    t, z0, lam0 = np.array([2.0, 3.0]), 0.0, 0.1
    e = np.exp(z0)
    r, J = e - t, np.array([e, e])
    A, g = J @ J, J @ r
    dz = -g / (A * (1.0 + lam0))  # Marquardt scaling: D = diag(J^T J) = A
    cost = 0.5 * r @ r
    predicted = cost - 0.5 * np.sum((r + J * dz) ** 2)
    cost_new = 0.5 * np.sum((np.exp(z0 + dz) - t) ** 2)
    rho = (cost - cost_new) / predicted
    assert 0.0 < rho < 0.5  # a poor model: the update raises lam (rho = 0.117, x1.45)
    out, log = _fit(t, z0, lam0=lam0, max_iters=1)
    it, c, lam = log[0]
    assert it == 1 and c == pytest.approx(cost_new, rel=1e-12)
    assert lam == pytest.approx(lam0 * max(1.0 / 3.0, 1.0 - (2.0 * rho - 1.0) ** 3), rel=1e-12)
    assert out.z[0] == pytest.approx(z0 + dz, rel=1e-12)


def test_rejected_steps_double_the_growth():
    """From z0 = 0 with lam0 = 1e-3 the first steps overshoot (cost up): lam x2, x4, x8."""
    out, log = _fit([2.0, 3.0], 0.0, max_iters=3)
    lams = [entry[2] for entry in log]
    np.testing.assert_allclose(lams, [2e-3, 8e-3, 64e-3], rtol=1e-12)
    assert out.cost_history == [2.5, 2.5, 2.5, 2.5] and out.accepted == 0


def test_xtol_stops_at_the_first_relative_decrease_below_1e_6():
    """ftol off, xtol large: the fit stops at the first accepted step that lowers the cost by
    at most 1e-6 of the new cost, not before (the optimum's cost is 0.25, exp(z) = 2.5)."""
    out, _ = _fit([2.0, 3.0], 0.8, ftol=0.0, xtol=10.0)
    h = np.asarray(out.cost_history)
    assert out.converged and out.reason == "parameter step below xtol"
    assert h[-2] - h[-1] <= 1e-6 * h[-1]
    earlier = [(a, b) for a, b in zip(h[:-2], h[1:-1], strict=True) if b < a]
    assert earlier and all(a - b > 1e-6 * b for a, b in earlier)
    assert np.exp(out.z[0]) == pytest.approx(2.5, rel=1e-3)


def test_iteration_count_of_every_exit():
    # interrupted before the first iteration: nothing run
    out, _ = _fit([2.0, 3.0], 0.8, should_stop=lambda: True)
    assert (out.iterations, out.converged, out.reason) == (0, False, "interrupted")
    assert len(out.cost_history) == 1
    # interrupted at the third poll: two iterations ran
    polls = iter([False, False, True])
    out, _ = _fit([2.0, 3.0], 0.8, should_stop=lambda: next(polls))
    assert (out.iterations, out.reason) == (2, "interrupted")
    assert len(out.cost_history) == 3
    # an exact fit reaches round-off: every iteration run is counted, the last check is free
    out, _ = _fit([2.0], 0.3)
    assert out.converged and out.reason == "cost at round-off level"
    assert out.iterations == len(out.cost_history) - 1
    assert out.cost_history[-1] <= 1e-20 * out.cost_history[0]


def test_options_object_or_keywords():
    """LMOptions or its fields by name: the same iterations; another name is refused."""
    from vcjax.identify.lm import LMOptions

    a, _ = _fit([2.0, 3.0], 0.0, lam0=0.1, max_iters=3)
    lin, res = _problem([2.0, 3.0])
    b = levenberg_marquardt(
        lin, res, [0.0], np.zeros((1, 0)), LMOptions(lam0=0.1, max_iters=3), should_stop=lambda: 0
    )
    assert a.cost_history == b.cost_history and a.reason == b.reason
    with pytest.raises(TypeError, match="max_iter"):
        levenberg_marquardt(lin, res, [0.0], np.zeros((1, 0)), max_iter=3)
